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
