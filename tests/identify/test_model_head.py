"""A fit's iterations compare a head of the record: the model maps the states of that head
only, and the rotor-angle order spectrum keeps the orders' exponentials of a record's angle.
Both must give what the whole-record computation gives, bit for bit where no filter reaches
across the head's end."""

from __future__ import annotations

import numpy as np

from hil.identify import residuals
from hil.identify.experiment import prepare
from hil.identify.model import IDX, FastModel, fast_stop
from hil.identify.rig import generate_rig
from plant.config import load_config


def _model() -> FastModel:
    rig = generate_rig("conrod_fixed", ["strain_thermal_drift"], seconds=0.8, seed=2)
    return FastModel(prepare(rig.data, load_config("hydra_default"), "bl"))


def _theta(model: FastModel) -> np.ndarray:
    theta = model.start_vector()
    # the temperature-scheduled terms read the covariate: the head must take its head too
    for name, value in (("pc_force_n", 40.0), ("visc_coeff_per_c", 0.03),
                        ("drift_n_per_c", 1.5), ("lag_pressure_s", 0.0), ("lag_strain_s", 0.0)):
        theta[IDX[name]] = value
    return theta


def test_outputs_of_a_head_are_the_head_of_the_outputs():
    model = _model()
    theta = _theta(model)
    z = model.states(theta)
    whole = model.outputs(theta, z)
    k = model.exp.n // 3
    head = model.outputs(theta, z, n_stop=k)
    n = fast_stop(k, model.exp.n)
    assert k < n < model.exp.n
    for c in model.exp.channels:
        assert head[c].shape == (n,), c
        assert np.array_equal(head[c], whole[c][:n], equal_nan=True), c
    # the pressures: the precharge plus the positive side of the force over k_c
    tq = z[:n, 2]
    pre, kc = model.exp.precharge, model.exp.const.kc
    assert np.array_equal(head["p_pump_a"], pre + np.maximum(tq, 0.0) / kc)
    assert np.array_equal(head["p_pump_b"], pre + np.maximum(-tq, 0.0) / kc)


def test_lagged_sensors_of_a_head_filter_that_head():
    """With the lags on, each lagged channel of the head is the head's unlagged signal
    through ``1/(1 + j w tau)`` on its even extension (written out here)."""
    model = _model()
    theta = _theta(model)
    z = model.states(theta)
    k = model.exp.n // 3
    raw = model.outputs(theta, z, n_stop=k)
    theta[IDX["lag_pressure_s"]] = 6e-5
    theta[IDX["lag_strain_s"]] = 1.5e-4
    lagged = model.outputs(theta, z, n_stop=k)
    dt = model.exp.dt
    acted = 0
    for c, tau in (("p_pump_a", 6e-5), ("p_pump_b", 6e-5), ("p_cyl_b", 6e-5),
                   ("f_strain", 1.5e-4)):
        y = raw[c]
        ext = np.concatenate([y, y[::-1]])
        f = np.fft.rfftfreq(ext.size, dt)
        want = np.fft.irfft(np.fft.rfft(ext) / (1.0 + 2j * np.pi * f * tau), ext.size)[:y.size]
        np.testing.assert_allclose(lagged[c], want, rtol=1e-12, atol=1e-9 * np.ptp(y), err_msg=c)
        acted += bool(np.max(np.abs(lagged[c] - y)) > 1e-4 * np.ptp(y))
    assert acted >= 2  # the lag did act (a side sitting on the precharge does not move)


def test_order_spectrum_with_the_kept_exponentials_is_the_direct_sum(monkeypatch):
    rng = np.random.default_rng(4)
    r = rng.normal(size=3000)
    for step in (0.3, 0.7, 0.3):  # another angle of the same length, then the first again
        angle = np.cumsum(np.full(3000, step) + 0.01 * rng.random(3000))
        want = np.array([2.0 / r.size * abs(np.sum((r - r.mean()) * np.exp(-1j * o * angle)))
                         for o in residuals.ORDERS])
        assert np.array_equal(residuals.order_spectrum(r, angle), want)
        assert np.array_equal(residuals.order_spectrum(r, angle), want)  # kept
        monkeypatch.setattr(residuals, "BASIS_MAX", 0)  # too long to keep: computed as it goes
        assert np.array_equal(residuals.order_spectrum(r, angle), want)
        monkeypatch.undo()


def test_a_kept_run_answers_for_its_head_bit_for_bit():
    """The model keeps its last runs by parameter vector: a head asked after the whole run is
    that run (read-only), and equals a fresh model's head simulation bit for bit; a longer
    run after a head is simulated anew; another parameter vector is another run."""
    model = _model()
    theta = _theta(model)
    k = model.exp.n // 3
    whole = model.states(theta)
    assert not whole.flags.writeable
    assert model.states(theta, k) is whole
    fresh = _model().states(theta, k)
    assert np.array_equal(fresh[:k], whole[:k])
    assert np.all(fresh[k:] == 0.0)
    short = _model()
    head = short.states(theta, k)
    longer = short.states(theta)
    assert longer is not head and np.array_equal(longer, whole)
    other = theta.copy()
    other[IDX["pc_force_n"]] = 41.0
    assert not np.array_equal(model.states(other), whole)
