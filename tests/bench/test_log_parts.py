"""The logging breakdown (``python -m hil.bench.log_parts``) names functions that exist: a
renamed one would silently drop out of the figures."""

from __future__ import annotations

import importlib

from hil.bench.log_parts import PARTS, _install, _Timer


def test_every_part_names_a_function() -> None:
    for module, path, _side in PARTS:
        owner = importlib.import_module(module)
        for name in path.split("."):
            owner = getattr(owner, name)
        assert callable(owner), path


def test_wrapped_parts_count_own_time_and_are_put_back() -> None:
    from hil.framelog import rawpb

    before = rawpb.pack_blocks
    timer = _Timer()
    undo = _install(timer)
    try:
        assert rawpb.pack_blocks is not before
        outer = timer.wrap(lambda: rawpb.pack_block(*_block()), "outer")
        outer()
    finally:
        for owner, name, fn in reversed(undo):
            setattr(owner, name, fn)
    assert rawpb.pack_blocks is before
    assert set(timer.own) == {"outer", "file: pack_blocks"}
    assert all(v >= 0 for v in timer.own.values())


def _block():  # noqa: ANN202
    import numpy as np

    return np.arange(3), np.zeros((3, 2), np.uint16), np.dtype(np.uint16)
