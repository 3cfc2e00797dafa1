"""The embedded sensor (Eq. 4): the filter against the simulator's mechanical sensor and an
exact solution, and the FFT deconvolution with and without noise."""

import numpy as np
import pytest

import hertzchain
from hertzchain import pulses, sensor

BETA, F0 = 0.11, 85e3


def test_filter_is_exact_for_a_ramp():
    """u = a t from rest at equilibrium: F_s = a (t - sin(w0 t)/w0) exactly (any sampling)."""
    t = np.arange(400) * 0.7e-6
    a = 2.0e5
    w0 = 2 * np.pi * F0
    # Start in equilibrium with the drive's slope: F_s(0) = 0, dF_s/dt(0) = a, so F_s = a t.
    got = np.asarray(sensor.sensor_signal(t, a * t, a * t, beta=BETA, f0_hz=F0))
    np.testing.assert_allclose(got, a * t, atol=1e-9 * a * t[-1])
    # A step in slope at t1 excites ringing: F_s = u - (a/w0) sin(w0 (t - t1)) after it.
    t1 = t[100]
    u = a * np.maximum(t - t1, 0.0)
    got = np.asarray(sensor.sensor_signal(t, u, u, beta=BETA, f0_hz=F0))
    exact = u - np.where(t > t1, a / w0 * np.sin(w0 * (t - t1)), 0.0)
    np.testing.assert_allclose(got, exact, atol=1e-9 * a * t[-1])


def test_transfer_function_matches_a_sinusoid():
    """Steady state of Eq. 4 for F_+ = cos(w t), F_- = cos(w (t + t0))."""
    f, t0 = 30e3, 49e-6
    h = complex(sensor.sensor_transfer(f, beta=BETA, f0_hz=F0, delay_s=t0))
    w, w0 = 2 * np.pi * f, 2 * np.pi * F0
    expected = ((1 - BETA) + BETA * np.exp(1j * w * t0)) * w0**2 / (w0**2 - w**2)
    assert h == pytest.approx(expected, rel=1e-12)


@pytest.fixture(scope="module")
def sensor_run():
    """The paper's chain at 0.3 m/s with a sensor in bead 10 (contacts 9 and 10 around it)."""
    traces = hertzchain.simulate(
        hertzchain.ChainSetup(sensor_beads=(10,), sensor_beta=BETA, sensor_f0_hz=F0),
        t_end_s=0.9e-3,
        sample_interval_s=0.1e-6,
        contacts=(9, 10),
    )
    return {name: np.asarray(traces.forces_n[name]) for name in traces.channel_names} | {
        "time_s": np.asarray(traces.time_s)
    }


def test_filter_reproduces_the_mechanical_sensor(sensor_run):
    """Eq. 4 applied to the simulated contact forces is the simulator's split-bead sensor."""
    t = sensor_run["time_s"]
    front, back, measured = (
        sensor_run["contact_10"],
        sensor_run["contact_9"],
        sensor_run["sensor_10"],
    )
    model = np.asarray(sensor.sensor_signal(t, front, back, beta=BETA, f0_hz=F0))
    assert np.max(np.abs(model - measured)) < 1e-5 * front.max()
    # Reference: peak F_s / peak F_+ = 0.9217 at 0.3 m/s; the correction is of order beta.
    assert measured.max() / front.max() == pytest.approx(0.9217, abs=0.002)
    assert np.max(np.abs(measured - front)) / front.max() == pytest.approx(0.089, abs=0.01)


def _delay(run):
    wave = pulses.incident_wave(
        run["time_s"], np.stack([run["contact_9"], run["contact_10"]]), (9, 10), 0.013
    )
    return float(sensor.sensor_delay_s(0.013, wave.speed_m_s))


def test_deconvolution_without_noise(sensor_run):
    t, front = sensor_run["time_s"], sensor_run["contact_10"]
    delay = _delay(sensor_run)
    assert delay == pytest.approx(49.0e-6, rel=0.015)
    recovered = np.asarray(
        sensor.deconvolve_sensor(
            t, sensor_run["sensor_10"], beta=BETA, f0_hz=F0, delay_s=delay, noise_std_n=0.0
        )
    )
    assert np.max(np.abs(recovered - front)) < 3e-3 * front.max()
    assert recovered.max() / front.max() == pytest.approx(1.0, abs=2e-3)
    back = np.asarray(
        sensor.deconvolve_sensor(
            t,
            sensor_run["sensor_10"],
            beta=BETA,
            f0_hz=F0,
            delay_s=delay,
            noise_std_n=0.0,
            which="back",
        )
    )
    assert np.max(np.abs(back - sensor_run["contact_9"])) < 1e-2 * front.max()


def test_deconvolution_with_noise(sensor_run):
    """At 1 us sampling with 0.5 % noise the recovered peak is within 1 % of the contact force,
    while the raw sensor is 8 % low: the correction is of order beta and noise stays bounded."""
    t, front, signal = (
        sensor_run["time_s"][9::10],
        sensor_run["contact_10"][9::10],
        sensor_run["sensor_10"][9::10],
    )
    delay = _delay(sensor_run)
    rng = np.random.default_rng(11)
    noise = 0.005 * front.max()
    errors = []
    for _ in range(5):
        noisy = signal + rng.normal(0.0, noise, signal.size)
        recovered = np.asarray(
            sensor.deconvolve_sensor(t, noisy, beta=BETA, f0_hz=F0, delay_s=delay)
        )
        peak = float(pulses.refine_peak(t, recovered)[1])
        errors.append(peak / front.max() - 1)
        # The noise is not amplified: the residual is below the input noise level.
        assert np.std(recovered - front) < noise
    assert np.max(np.abs(errors)) < 0.01
    assert 1 - signal.max() / front.max() == pytest.approx(BETA, rel=0.35)
    with pytest.raises(ValueError, match="beta"):
        sensor.deconvolve_sensor(t, signal, beta=0.6, f0_hz=F0, delay_s=delay)
