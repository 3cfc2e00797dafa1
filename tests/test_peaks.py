"""The peak finders of `hertzchain.peaks` that `tests/test_pulses.py` does not reach."""

import numpy as np
import pytest

from hertzchain import peaks


def test_measured_first_peak_is_the_vertex_of_a_parabolic_top_and_ignores_noise():
    t = np.linspace(0.0, 1e-3, 401)
    centre, height, width = 0.40137e-3, 25.0, 0.1e-3  # the vertex lies between samples
    clean = np.clip(height * (1.0 - ((t - centre) / width) ** 2), 0.0, None)
    time_s, force_n = peaks.measured_first_peak(t, clean)
    assert time_s == pytest.approx(centre, abs=1e-12) and force_n == pytest.approx(height, rel=1e-12)
    rng = np.random.default_rng(4)
    noisy = clean + rng.normal(0.0, 0.01 * height, t.size)
    time_s, force_n = peaks.measured_first_peak(t, noisy)
    # tens of samples near the top average the noise: far closer than one sample (2.5 us)
    assert abs(time_s - centre) < 0.2 * (t[1] - t[0])
    assert force_n == pytest.approx(height, rel=0.01)
    assert peaks.measured_first_peak(t, np.zeros_like(t)) is None


def test_first_run_bounds_the_first_pulse_only():
    values = np.array([0.0, 0.2, 1.0, 0.3, 0.0, 0.0, 2.0, 0.5, 0.0])
    # above 0.1 x max (0.2 is not above 0.2): the first run is samples 2..3, peak at 2
    assert peaks.first_run(values, 0.1) == (2, 4, 2)
    assert peaks.first_run(values, 1.0) is None


def test_frequency_response_peaks_are_the_modes_of_two_oscillators():
    """The response of two damped modes (2.1 and 4.97 kHz, velocity |w/(w_k^2 - w^2 + i g w)|, whose
    maximum is at w_k)
    sampled every 5 Hz: the two peaks within a bin of the modes' damped maxima, ascending; a
    third asked for is refused naming how many there are."""
    f = np.arange(1500.0, 6000.0, 5.0)
    w = 2 * np.pi * f
    modes, damping = 2 * np.pi * np.array([2100.0, 4970.0]), 700.0
    response = sum(np.abs(w * 1e9 / (m**2 - w**2 + 1j * damping * w)) for m in modes)
    found = peaks.frequency_response_peaks(f, response, 2)
    np.testing.assert_allclose(found, [2100.0, 4970.0], atol=5.0)
    with pytest.raises(ValueError, match="shows 2 resonance peaks"):
        peaks.frequency_response_peaks(f, response, 3)
