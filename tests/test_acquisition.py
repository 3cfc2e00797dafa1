"""Oscilloscope model: sampling, trigger, bandwidth, noise, quantisation, volts <-> newtons."""

import math

import numpy as np
import pytest

import hertzchain
from hertzchain import acquisition as acq
from hertzchain import pulses, theory
from hertzchain.io.tracefile import read_trace, write_trace

FINE = 0.1e-6
T = FINE * np.arange(1, 20001)  # 2 ms after the impact


def _pulse(peak=300.0, center=0.8e-3, tau=47e-6):
    return np.asarray(theory.solitary_profile_n(T, peak, center, tau))


def test_clean_recording_is_the_signal_resampled():
    forces = {"contact_6": _pulse(), "wall": 2 * _pulse(center=1.0e-3)}
    record = acq.acquire(T, forces, acq.Acquisition(sample_interval_s=1e-6))
    assert len(record.time_s) == 2000
    np.testing.assert_allclose(record.time_s[:3], [1e-6, 2e-6, 3e-6])
    np.testing.assert_allclose(record.channels["contact_6"], forces["contact_6"][9::10], atol=1e-9)
    np.testing.assert_allclose(record.channels["wall"], forces["wall"][9::10], atol=1e-9)
    assert record.noise_std_n == {"contact_6": 0.0, "wall": 0.0}
    # Automatic range: 1-2-5 volts holding 1.1 x the peak; the paper's sensitivities.
    assert record.full_scale_v["contact_6"] == pytest.approx(5.0)  # 300 N x 11.24 mV/N = 3.4 V
    assert record.full_scale_v["wall"] == pytest.approx(100.0)  # 600 N x 112.4 mV/N = 67 V


def test_noise_is_seeded_and_has_the_stated_level():
    forces = {"contact_6": _pulse()}
    setting = acq.Acquisition(noise_std_n=0.37)
    a = acq.acquire(T, forces, setting, seed=1).channels["contact_6"]
    b = acq.acquire(T, forces, setting, seed=1).channels["contact_6"]
    c = acq.acquire(T, forces, setting, seed=2).channels["contact_6"]
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    residual = a - forces["contact_6"][9::10]
    assert np.std(residual) == pytest.approx(0.37, rel=0.05)
    assert abs(np.mean(residual)) < 4 * 0.37 / math.sqrt(residual.size)
    assert pulses.estimate_noise_std_n(a) == pytest.approx(0.37, rel=0.1)


def test_quantisation_steps_and_noise_budget():
    forces = {"contact_6": _pulse()}
    # Noise above half a step dithers the converter: the error is then uniform (step^2/12).
    setting = acq.Acquisition(bits=8, full_scale_v=5.0, noise_std_n=3.0)
    record = acq.acquire(T, forces, setting)
    lsb_n = 2 * 5.0 / 256 / acq.EMBEDDED_SENSITIVITY_V_PER_N  # 3.47 N per code
    codes = record.channels["contact_6"] / lsb_n
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-9)
    assert record.noise_std_n["contact_6"] == pytest.approx(
        math.sqrt(3.0**2 + lsb_n**2 / 12), rel=1e-12
    )
    residual = record.channels["contact_6"] - forces["contact_6"][9::10]
    assert np.std(residual) == pytest.approx(record.noise_std_n["contact_6"], rel=0.05)
    # A range too small clips, and says so.
    clipped = acq.acquire(T, forces, acq.Acquisition(bits=8, full_scale_v=2.0))
    assert clipped.clipped["contact_6"].sum() > 0
    assert np.max(clipped.channels["contact_6"]) < 2.0 / acq.EMBEDDED_SENSITIVITY_V_PER_N


def test_trigger_delay_and_jitter_shift_the_time_axis():
    forces = {"contact_6": _pulse()}
    delayed = acq.acquire(T, forces, acq.Acquisition(trigger_delay_s=50e-6))
    peak_time = float(pulses.refine_peak(delayed.time_s, delayed.channels["contact_6"])[0])
    assert peak_time == pytest.approx(0.8e-3 - 50e-6, abs=1e-8)
    early = acq.acquire(T, forces, acq.Acquisition(trigger_delay_s=-20e-6, record_length=1500))
    assert early.channels["contact_6"][0] == 0.0  # before the impact
    jittered = acq.acquire(T, forces, acq.Acquisition(trigger_jitter_s=1e-6), seed=5)
    drawn = jittered.trigger_offset_s
    assert drawn == pytest.approx(
        float(np.random.default_rng(5).standard_normal()) * 1e-6, rel=1e-12
    )
    peak_time = float(pulses.refine_peak(jittered.time_s, jittered.channels["contact_6"])[0])
    assert peak_time == pytest.approx(0.8e-3 - drawn, abs=1e-8)


def test_bandwidth_filters():
    step = np.where(T >= 0.5e-3, 100.0, 0.0)
    rc = acq.acquire(
        T,
        {"wall": step},
        acq.Acquisition(sample_interval_s=FINE, bandwidth_hz=50e3, bandwidth_filter="first_order"),
    )
    t_after = rc.time_s - 0.5e-3
    expected = np.where(
        t_after >= 0, 100.0 * (1 - np.exp(-2 * np.pi * 50e3 * (t_after + FINE))), 0.0
    )
    np.testing.assert_allclose(rc.channels["wall"], expected, atol=1e-6)
    # The Bessel filter passes a slow pulse with gain 1 and delays it by its group delay.
    bessel = acq.acquire(T, {"wall": _pulse()}, acq.Acquisition(bandwidth_hz=100e3))
    fit = pulses.fit_cos6(bessel.time_s, bessel.channels["wall"])
    assert float(fit.peak_force_n) == pytest.approx(300.0, rel=3e-3)
    assert 0.5e-6 < float(fit.center_s) - 0.8e-3 < 5e-6


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="bandwidth_filter"):
        acq.Acquisition(bandwidth_filter="butter")
    with pytest.raises(ValueError, match="noise_std_n"):
        acq.Acquisition(noise_std_n=-1.0)
    with pytest.raises(ValueError, match="finer than the simulation"):
        acq.acquire(T, {"wall": _pulse()}, acq.Acquisition(sample_interval_s=0.01e-6))
    with pytest.raises(ValueError, match="simulate longer"):
        acq.acquire(T, {"wall": _pulse()}, acq.Acquisition(record_length=5000))


def test_trace_file_round_trip(tmp_path):
    setup = hertzchain.ChainSetup(eta_s=2e-6, sensor_beads=(6,))
    forces = {
        "contact_11": _pulse(),
        "sensor_6": _pulse(center=0.5e-3),
        "wall": _pulse(600.0, 1e-3),
    }
    trace = acq.acquire_trace(
        setup, T, forces, acq.Acquisition(noise_std_n=0.5, bits=12), seed=3, truth={"eta_s": 2e-6}
    )
    write_trace(tmp_path / "x.csv", trace)
    back = read_trace(tmp_path / "x.csv")
    assert back.noise_std_n == pytest.approx(
        max(float(v) for k, v in trace.header.items() if k.startswith("noise_std_n_"))
    )
    assert back.header["x_true_eta_s"] == "2e-06"
    assert back.sensor_beads == (6,) and back.contacts == (11,)
    for name in forces:
        np.testing.assert_allclose(back.channels[name], trace.channels[name], rtol=1e-8, atol=1e-9)
    assert float(back.setup().sensor_beta) == pytest.approx(0.11)
