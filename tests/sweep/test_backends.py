"""The same sweep on every backend gives the same table (a point is a pure function of its
configuration and seed)."""

from __future__ import annotations

import pandas as pd
import pytest

from hil.sweep import table
from hil.sweep.backends import DaskCluster, LocalPool, Serial
from hil.sweep.engine import run_sweep
from hil.sweep.space import build_plan, parse_param
from plant.config import load_config


@pytest.mark.slow
def test_serial_local_pool_and_dask_give_identical_tables():
    cfg = load_config("hydra_thesis")
    # 6 points of F3 over two parameters, three per worker of the pool; the gains move the
    # rise times, so the rows differ.
    plan = build_plan(cfg, [parse_param("mcu.kp_force=1.5:3.0:2"),
                            parse_param("mcu.kd_force_s=0.004,0.0055,0.007")])
    frames = {}
    # Dask's LocalCluster with threads (processes=False): the same code path through the
    # scheduler, without a second start-up of the interpreter and the kernels.
    for backend in (Serial(), LocalPool(2), DaskCluster("local", 2, processes=False)):
        try:
            out = run_sweep("f3", cfg, plan, backend)
        finally:
            backend.close()
        assert out.computed == 6
        frames[backend.name] = table.frame(plan, out.records)
    serial = frames.pop("serial")
    assert serial["rise time, current based [ms]"].nunique() > 1
    assert (serial["error"] == "").all()
    for name, df in frames.items():
        pd.testing.assert_frame_equal(df, serial, obj=name)
