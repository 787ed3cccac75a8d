# Two commands do all set-up on a fresh machine with only python3:
#   make run   - create .venv, install eha-hil, run the main job on the default actuator
#   make test  - create .venv, install eha-hil with its test extra, run the whole suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TSTAMP := $(VENV)/.installed-test

.PHONY: run test bench lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(TSTAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@ $(STAMP)

run: $(STAMP)
	$(BIN)/eha-hil main
	$(BIN)/eha-hil run thesis

test: $(TSTAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/eha-hil bench plant
	$(BIN)/eha-hil bench codecs
	$(BIN)/eha-hil bench fpga
	$(BIN)/eha-hil bench stack

lint: $(TSTAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
