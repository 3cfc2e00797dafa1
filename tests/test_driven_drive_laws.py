"""A piezo whose stroke grows with its drive (`RayleighStroke`, Rayleigh's law): the drive's
harmonic content against the Fourier series of the Rayleigh loop, its velocity against finite
differences, and a linear chain's response to it."""

import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain.driven import DrivenChain, RayleighStroke, lockin_grid
from hertzchain.driven import drive as drives


def test_rayleigh_drive_harmonics_follow_the_loops_fourier_series():
    r, a, n = 2e6, 60e-9, 512  # 1/m, m, samples a period: r a = 0.12
    frequency = 1000.0
    dt = 1.0 / (frequency * n)
    drive = drives.harmonic_segment(frequency, dt, n, a, a, 0, stroke=RayleighStroke(r))
    u, _ = drive(jnp.arange(n))
    spectrum = 2.0 * np.fft.rfft(np.asarray(u)) / n  # cos part: real, sin part: -imag
    hysteresis = 0.5 * r * a**2
    assert spectrum[1].real == pytest.approx(a * (1 + r * a), rel=1e-12)
    # |sin| sin = (8 / pi) (sin/3 - sin 3/15 - sin 5/105 - ...)
    for harmonic, coefficient in ((1, 1 / 3), (3, -1 / 15), (5, -1 / 105)):
        assert -spectrum[harmonic].imag == pytest.approx(hysteresis * 8 / np.pi * coefficient, rel=1e-4)
    assert np.max(np.abs(spectrum[2::2])) < 1e-12 * a  # no even harmonics
    assert np.max(np.abs(spectrum[3:12:2].real)) < 1e-12 * a  # the odd ones are sine parts only
    # the velocity is the displacement's derivative, also while the amplitude ramps
    ramp = drives.harmonic_segment(frequency, dt, n, 0.0, a, 3 * n, stroke=RayleighStroke(r))
    j = jnp.arange(1, 3 * n)
    u, u_dot = (np.asarray(x) for x in ramp(j))
    central = (u[2:] - u[:-2]) / (2 * dt)
    # away from sin = 0, where |sin| sin's curvature jumps (a central difference is off by
    # its step there)
    phase = np.asarray(j[1:-1]) % (n // 2)
    smooth = (phase > 1) & (phase < n // 2 - 1)
    np.testing.assert_allclose(u_dot[1:-1][smooth], central[smooth], atol=1e-4 * np.max(np.abs(u_dot)))


@pytest.mark.slow
def test_linear_chain_responds_to_the_rayleigh_fundamental():
    # at 0.1 nm the bead is linear: its lock-in at f scales with the drive's fundamental,
    # |1 + r a - i (4 / 3 pi) r a| times the nominal stroke's (r a = 0.1)
    a, r = 1e-10, 1e9
    chain = DrivenChain([0.028], [1.38e10, 1.38e10], 4.5, 2000.0)
    piezo = DrivenChain([0.028], [1.38e10, 1.38e10], 4.5, 2000.0, drive_stroke=RayleighStroke(r))
    options = dict(harmonics=(1.0,), ramp_periods=6, hold_periods=24, window_periods=4, steps_per_period=32)
    nominal = lockin_grid(chain, [3500.0], [a], kernel="jax", **options)
    grown = lockin_grid(piezo, [3500.0], [a], **options)
    assert grown.kernel == "jax" and not piezo.runs_on_fused_kernel
    ratio = complex(grown.complex_amplitude[0, 0, 0] / nominal.complex_amplitude[0, 0, 0])
    expected = 1 + r * a - 1j * 4 / (3 * np.pi) * r * a
    assert abs(ratio - expected) < 1e-4 * abs(expected)
    with pytest.raises(ValueError, match="rayleigh_per_m"):
        RayleighStroke(-1.0)
