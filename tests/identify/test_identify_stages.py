"""The stage and fit breakdown of one identification (``python -m hil.bench.identify_stages``)."""

from __future__ import annotations

import pytest

from hil.bench import identify_stages
from hil.identify import fit as fitting
from hil.identify import model


@pytest.fixture(scope="module")
def out() -> dict:
    return identify_stages.stages("fixed_piston", ["pump_coulomb_friction"], seconds=2.0,
                                  fits=True)


def test_fits_add_up_within_their_stages(out: dict) -> None:
    fits = out["fits"]
    assert fits, "no fit was logged"
    # every simulation a fit ran is one of the record's, and the fits ran no more CPU
    assert sum(f["sims"] for f in fits) <= out["sims"]
    assert sum(f["cpu_s"] for f in fits) <= out["cpu_s"] + 1e-6
    assert sum(s["sims"] for s in out["stages"]) == out["sims"]
    for f in fits:
        assert 1 <= f["n_free"] and f["n_sub"] >= 1 and f["max_nfev"] >= 1
        assert isinstance(f["converged"], bool)
        # the loop's own calls, never the timing harness's
        assert f["calls"] and "stages" not in f["calls"].split("/")


def test_the_wrapped_methods_are_put_back(out: dict) -> None:
    assert fitting.OutputErrorFit.fit.__qualname__ == "OutputErrorFit.fit"
    assert model.FastModel._simulate_states.__qualname__ == "FastModel._simulate_states"


def test_the_table_is_every_multi_effect_record_once() -> None:
    rows = identify_stages.TABLE
    assert len(set(rows)) == len(rows)
    assert all(len(effects) >= 2 for _, _, effects in rows)


@pytest.mark.parametrize("argv", [["--effect", "bogus"], ["--seconds", "-1"],
                                  ["--threads", "0"]])
def test_bad_arguments_are_one_line_and_exit_2(argv: list[str], capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        identify_stages.main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("python -m hil.bench.identify_stages: error: argument")
