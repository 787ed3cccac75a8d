"""The fit's kept buffers: a Jacobian is written into the buffer of an earlier one that nothing
holds any more (no fresh pages for the kernel to zero), never into one a caller still holds,
and a fit gives the very same bits with the buffers kept as with new arrays."""

from __future__ import annotations

import numpy as np
import pytest

import hil.identify.fit as fit_module
from hil.identify.experiment import prepare
from hil.identify.fit import OutputErrorFit
from hil.identify.model import IDX, FastModel
from hil.identify.rig import generate_rig
from plant.config import load_config

FREE = ["gain_n_per_a", "ds", "dp", "ks", "k_rod", "c_rod", "skew_s", "strain_offset_n",
        "pc_force_n"]


@pytest.fixture(scope="module")
def model() -> FastModel:
    rig = generate_rig("conrod_fixed", ["pump_coulomb_friction"], seconds=0.6, seed=2)
    return FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))


def _start(model: FastModel) -> np.ndarray:
    theta = model.start_vector()
    theta[IDX["pc_force_n"]] = 30.0  # an effect on: the tangent's columns (their states kept)
    return theta


def _fitter(model: FastModel) -> OutputErrorFit:
    return OutputErrorFit(model, {"skew_s": model.exp.dt, "pc_force_n": 10.0})


def _pointer(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


def test_a_jacobian_reuses_a_free_buffer_and_never_a_held_one(model, monkeypatch):
    monkeypatch.setattr(fit_module, "_BUFFERS", fit_module._Kept(6))
    monkeypatch.setattr(fit_module, "_COLUMN_STATES", fit_module._Kept(8))
    theta = _start(model)
    fitter = _fitter(model)
    fitter._ref = {n: theta[IDX[n]] for n in FREE if n in fit_module.LOG_PARAMS}
    sigma = {c: 1.0 for c in fitter.exp.channels}
    fun, jac = fitter._problem(FREE, theta, sigma, fitter.fit_mask())
    x = fitter._to_x(theta, FREE)
    first = jac(x)
    where, made = _pointer(first), fit_module._BUFFERS.made
    assert made == 2  # the rows and the Jacobian
    assert fit_module._COLUMN_STATES.taken > 0  # the tangent's columns took kept states
    want = first.copy()
    del first  # nothing holds it now: the next Jacobian goes into its buffer
    again = jac(x)
    assert _pointer(again) == where and fit_module._BUFFERS.made == made
    assert again.tobytes() == want.tobytes()
    # held by the caller: the next one, elsewhere, leaves it alone
    x2 = x.copy()
    x2[0] += 0.01
    moved = jac(x2)
    assert not np.shares_memory(moved, again)
    assert again.tobytes() == want.tobytes()
    assert moved.tobytes() != want.tobytes()


def test_a_fit_with_kept_buffers_is_the_fit_with_new_arrays_to_the_bit(model, monkeypatch):
    results = {}
    for reuse in (False, True):
        monkeypatch.setattr(fit_module, "REUSE_BUFFERS", reuse)
        monkeypatch.setattr(fit_module, "_BUFFERS", fit_module._Kept(6))
        fitter = _fitter(model)
        # two passes: the second re-weights the first's Jacobian into a kept buffer
        results[reuse] = fitter.fit(_start(model), FREE, passes=2, max_nfev=12)
        taken = fit_module._BUFFERS.taken
        made = fit_module._BUFFERS.made
        assert (made < taken) if reuse else (taken == made == 0), (taken, made)
    new, kept = results[False], results[True]
    assert kept.n_sims == new.n_sims
    for name in ("theta", "states", "cov", "jac"):
        assert getattr(kept, name).tobytes() == getattr(new, name).tobytes(), name
    assert kept.se == new.se and kept.sigma == new.sigma and kept.weights == new.weights
    for c in new.outputs:
        assert kept.outputs[c].tobytes() == new.outputs[c].tobytes(), c


def test_glibc_takes_the_malloc_settings():
    import platform

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        pytest.skip("glibc's malloc only")
    assert fit_module.keep_freed_memory()


def test_a_parameter_named_twice_is_fitted_once(model):
    # (the seal's J_c-held polish named k_s twice where the search had freed it already: two
    # equal Jacobian columns, singular normal equations, one column dearer every Jacobian)
    once = _fitter(model).fit(_start(model), FREE, passes=1, max_nfev=6)
    twice = _fitter(model).fit(_start(model), FREE + ["ks", "ds"], passes=1, max_nfev=6)
    assert twice.free == FREE
    assert twice.theta.tobytes() == once.theta.tobytes()
    assert twice.jac.shape == once.jac.shape


def test_small_pages_turns_numpy_huge_page_advice_off():
    # numpy's switch returns the advice as it was: off after small_pages, whatever before
    switch = getattr(np._core.multiarray, "_set_madvise_hugepage", None)
    if switch is None:
        pytest.skip("this numpy has no huge-page switch")
    before = switch(True)
    try:
        assert fit_module.small_pages()
        assert switch(True) is False
        fit_module.SMALL_PAGES = False
        assert not fit_module.small_pages()
        assert switch(True) is True  # left as it was
    finally:
        fit_module.SMALL_PAGES = True
        switch(before)
