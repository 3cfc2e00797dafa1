"""`ActuatorMode`: a face that reaches the calibrated stroke through one actuator mode. Its
transfer function against the closed form of a driven damped oscillator, the face's motion
against a DFT and finite differences, and a linear bead's lock-in in the ratio |H(f)|."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain.driven import ActuatorMode, DrivenChain, lockin_grid
from hertzchain.driven.drive import harmonic_segment
from hertzchain.driven.linear import frequency_response

MODE_HZ, ZETA = 6000.0, 0.08


def _closed_form(f):
    """The steady response per unit static stroke of x'' + 2 zeta w_a x' + w_a^2 x = w_a^2 u."""
    w, wa = 2 * np.pi * f, 2 * np.pi * MODE_HZ
    return wa**2 / (wa**2 - w**2 + 2j * ZETA * wa * w)


def test_transfer_is_the_one_mode_oscillator_closed_form():
    law = ActuatorMode(MODE_HZ, ZETA)
    f = np.array([10.0, 3000.0, MODE_HZ, 7200.0, 20000.0])
    real, imaginary = (np.asarray(v) for v in law.transfer(f))
    np.testing.assert_allclose(real + 1j * imaginary, _closed_form(f), rtol=1e-13)
    assert abs(real[2] + 1j * imaginary[2]) == pytest.approx(1 / (2 * ZETA), rel=1e-13)  # at the mode
    assert np.angle(real[2] + 1j * imaginary[2]) == pytest.approx(-np.pi / 2, abs=1e-13)  # lags by 90 degrees


def test_face_motion_is_the_transfer_times_the_stroke():
    law = ActuatorMode(MODE_HZ, ZETA)
    f, n, a = 4500.0, 64, 30e-9
    dt = 1 / (f * n)
    drive = harmonic_segment(f, dt, n, 0.0, a, 0, stroke=law)
    u = np.array([float(drive(jnp.asarray(j))[0]) for j in range(n)])
    theta = 2 * np.pi * np.arange(n) / n
    phasor = 2 * np.mean(u * np.exp(-1j * theta))  # u = Re[c e^{i theta}]
    np.testing.assert_allclose(phasor / a, _closed_form(f), rtol=1e-12)
    # the velocity while the amplitude ramps, against central differences of the displacement
    ramp = harmonic_segment(f, dt, n, 10e-9, a, 5 * n, stroke=law)
    j = 2 * n + 7
    h = 1e-3
    position = jax.vmap(lambda s: ramp(s)[0])
    # differentiate in continuous step index: phase and envelope both advance with j
    x = np.asarray(position(jnp.asarray([j - h, j + h])))
    v = float(ramp(jnp.asarray(float(j)))[1])
    assert (x[1] - x[0]) / (2 * h * dt) == pytest.approx(v, rel=1e-6)


def test_linear_bead_lockin_follows_the_transfer():
    kappa, damping = 6.0e9, 900.0
    nominal = DrivenChain([0.028], [kappa, kappa], 4.5, damping)
    driven = DrivenChain([0.028], [kappa, kappa], 4.5, damping, drive_stroke=ActuatorMode(MODE_HZ, ZETA))
    f = np.array([3500.0, 5500.0, 7200.0])
    drive = np.array([2e-11])
    settings = {"harmonics": (1.0,), "ramp_periods": 30, "hold_periods": 90, "window_periods": 4,
                "steps_per_period": 96}
    ratio = np.asarray(lockin_grid(driven, f, drive, **settings).rms[0][:, 0]) / np.asarray(
        lockin_grid(nominal, f, drive, **settings).rms[0][:, 0])
    np.testing.assert_allclose(ratio, np.abs(_closed_form(f)), rtol=5e-4)
    # and the absolute level: the linear chain's response to a face moving by a |H|
    x, _ = frequency_response(nominal, f)
    linear = np.abs(np.asarray(x[:, 0]) * _closed_form(f)) * 2 * np.pi * f * drive[0] / np.sqrt(2)
    np.testing.assert_allclose(np.asarray(lockin_grid(driven, f, drive, **settings).rms[0][:, 0]), linear, rtol=3e-3)


def test_refuses_a_nonpositive_mode():
    with pytest.raises(ValueError, match="mode_hz"):
        ActuatorMode(0.0, ZETA)
    with pytest.raises(ValueError, match="damping_ratio"):
        ActuatorMode(MODE_HZ, -0.1)
