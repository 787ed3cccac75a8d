# Two commands do all set-up on a fresh machine with only python3:
#   make run   - create .venv, install eha-hil, run the main job on the default actuator
#   make test  - create .venv, install eha-hil with its test extra, run the whole suite
#   make test-fast - the same without the tests marked slow, each property test (hypothesis)
#                  on a quarter of its examples (under a minute)
#   make system-deps - (root, apt) the system tools some tests use, else they skip:
#                  tshark + dumpcap (capture tests), iproute2 (ip netns: UDP capture, the
#                  pysoem EtherCAT master on a veth pair; gcc builds pysoem), the Arm cross
#                  compiler + newlib and QEMU (MCU law on a Cortex-M4), Icarus Verilog and
#                  Verilator with g++ (the current loop's RTL: checked, and in the loop)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TSTAMP := $(VENV)/.installed-test

.PHONY: run test test-fast bench lint clean system-deps

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# After each install the numba kernels are compiled into their cache once (hil/sim/warmup.py),
# so that the first run does not spend half a minute compiling.
$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e .
	$(BIN)/python -m hil.sim.warmup
	touch $@

$(TSTAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/python -m hil.sim.warmup
	touch $@ $(STAMP)

run: $(STAMP)
	$(BIN)/eha-hil main
	$(BIN)/eha-hil run thesis

# The suite runs on one pytest-xdist worker per core: its tests are independent (each makes
# its own temporary files, ports, namespaces), and most of its time is single-threaded work.
# worksteal: a worker out of tests takes half of the other's queue; the files with slow tests
# are collected first (tests/conftest.py), so that the run ends on short tests.
# The suite starts the console script as a child process several hundred times: with
# PYTHONDONTWRITEBYTECODE set in the caller's environment, each start compiles the project's
# ~170 modules from source again (0.5-0.6 s of CPU a start here), so the test targets let
# Python cache their bytecode (in __pycache__/, ignored by git).
PYTEST := env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest -q -n auto --dist worksteal

test: $(TSTAMP)
	$(PYTEST)

test-fast: $(TSTAMP)
	$(PYTEST) -m "not slow" --examples-fraction 0.25

bench: $(STAMP)
	$(BIN)/eha-hil bench plant
	$(BIN)/eha-hil bench codecs
	$(BIN)/eha-hil bench fpga
	$(BIN)/eha-hil bench stack
	$(BIN)/eha-hil bench sweep

system-deps:
	echo "wireshark-common wireshark-common/install-setuid boolean false" | debconf-set-selections
	DEBIAN_FRONTEND=noninteractive apt-get update -qq
	DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends tshark iproute2 gcc \
		gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm iverilog verilator g++

lint: $(TSTAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache firmware_model/__pycache__/kernels-*
