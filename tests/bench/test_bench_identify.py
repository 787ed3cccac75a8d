"""pytest-benchmark case for the identification tool (no timing asserted).

The suite runs with ``--benchmark-disable`` (each case once, as a smoke test); time it with
``.venv/bin/python -m pytest tests/bench/test_bench_identify.py --benchmark-enable``. The
16 s budget figure comes from ``eha-hil bench identify`` (docs/identify.md).
"""

from __future__ import annotations

import pytest

from hil.identify.pipeline import identify
from hil.identify.synth import generate


@pytest.mark.slow
def test_identify_pulsation_record(benchmark, default_cfg):
    data = generate("fixed_piston", ["pump_pulsation"], seconds=4.0, seed=5).data
    if not benchmark.disabled:  # timed: compile outside the measurement
        identify(data, default_cfg, max_effects=1)
    rep = benchmark(identify, data, default_cfg)
    assert [e.name for e in rep.effects_added] == ["pump_pulsation"]
