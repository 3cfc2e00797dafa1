"""Conditioning steps of recorded channels against independent numbers: normal noise seen
through a converter, Tektronix-style rounded time columns, trigger crossings, clipping."""

import numpy as np
import pytest

from hertzchain.conditioning import (ConditioningError, NoiseEstimateWarning, baseline, binned_noise_std,
                                     clipped_mask, crossing_time_s, impact_time_s, quantisation_step,
                                     regular_time_grid)


@pytest.mark.parametrize("width_steps", [0.35, 0.7, 2.0, 6.0])
def test_binned_noise_width_recovers_the_analogue_noise(width_steps):
    rng = np.random.default_rng(1)
    step = 0.04
    widths = []
    for seed in range(20):
        level = rng.uniform(-0.5, 0.5) * step + 1.3
        values = step * np.round((level + width_steps * step * rng.standard_normal(400)) / step)
        widths.append(binned_noise_std(values, step))
    # unbiased to a few percent over 20 records of 400 samples; the plain spread is not at low width
    assert np.mean(widths) / (width_steps * step) == pytest.approx(1.0, abs=0.06)


@pytest.mark.parametrize("width_steps", [0.15, 0.25, 0.3])
def test_resting_records_on_two_codes_give_the_noise_of_a_moving_signal(width_steps):
    """Analogue noise below a third of a step leaves a resting 8-bit record on one or two
    codes. What the fit needs is the error of the moving signal, sqrt(sigma^2 + step^2/12),
    measured here directly: a ramp through many codes with the same noise, quantised, less
    the ramp. The baseline's estimate from the resting records matches it on average over
    offsets (the codes' spread, used before, was 1.2-1.5x too large here)."""
    rng = np.random.default_rng(7)
    step = 0.02
    ramp = np.linspace(0.0, 40 * step, 20000)
    moving = step * np.round((ramp + width_steps * step * rng.standard_normal(ramp.size)) / step) - ramp
    truth = float(np.sqrt(np.mean(moving**2)))
    estimates, spreads = [], []
    for seed in range(40):
        level = rng.uniform(0, 1) * step
        values = step * np.round((level + width_steps * step * rng.standard_normal(300)) / step)
        estimates.append(baseline(values, np.ones(values.size, bool), step, "rest").noise_std)
        spreads.append(np.hypot(np.std(values, ddof=1), step / np.sqrt(12)))
    assert np.mean(estimates) / truth == pytest.approx(1.0, abs=0.08)
    assert np.mean(spreads) / truth > 1.15


def test_a_noise_fit_that_does_not_converge_is_said_and_replaced(monkeypatch):
    from scipy import optimize

    rng = np.random.default_rng(3)
    step = 0.01
    values = step * np.round(3 * step * rng.standard_normal(4000) / step)
    failing = optimize.minimize

    def one_step(*args, **kwargs):
        return failing(*args, **(kwargs | {"options": {"maxiter": 2}}))

    monkeypatch.setattr(optimize, "minimize", one_step)
    with pytest.warns(NoiseEstimateWarning, match="did not converge .*codes' variance less step"):
        width = binned_noise_std(values, step)
    # Sheppard's corrected spread: within a few percent of the 3-step noise
    assert width == pytest.approx(3 * step, rel=0.05)


def test_impact_time_from_arrivals_at_several_positions():
    time = np.arange(0, 2e-3, 1e-6)
    transit = 50e-6
    pulses = {k: np.exp(-(((time - 30e-6 - k * transit) / 20e-6) ** 2)) for k in (4, 9, 16)}
    impact, slope = impact_time_s(time, pulses)
    # half-rise of a Gaussian of width 20 us: sqrt(ln 2) x 20 us before its centre
    assert slope == pytest.approx(transit, rel=1e-6)
    assert impact == pytest.approx(30e-6 - np.sqrt(np.log(2)) * 20e-6, abs=1e-7)
    assert impact_time_s(time, {4: pulses[4]}) is None


def test_baseline_adds_the_quantisation_error_of_a_moving_signal():
    rng = np.random.default_rng(2)
    step = 0.01
    values = step * np.round((0.003 + 0.012 * rng.standard_normal(2000)) / step)
    found = baseline(values, np.ones(values.size, bool), step, "test")
    assert found.noise_std == pytest.approx(np.hypot(0.012, step / np.sqrt(12)), rel=0.05)
    assert found.offset == pytest.approx(0.003, abs=3 * 0.012 / np.sqrt(2000))
    assert quantisation_step(values) == pytest.approx(step, rel=1e-9)
    with pytest.raises(ConditioningError, match="only 5 samples before the impact"):
        baseline(values, np.arange(values.size) < 5, step, "shot 1")


def test_rounded_scope_times_become_an_exact_grid_and_gaps_are_refused():
    exact = -2.5e-4 + 1e-6 * np.arange(2500)
    printed = np.array([float(f"{t:.4e}") for t in exact])  # 5 significant digits
    grid, deviation = regular_time_grid(printed, "f")
    np.testing.assert_allclose(grid, exact, atol=1e-12)
    assert deviation < 0.05
    with pytest.raises(ConditioningError, match="not evenly spaced"):
        regular_time_grid(np.delete(exact, 100), "f")
    with pytest.raises(ConditioningError, match="does not increase at sample 11"):
        regular_time_grid(np.concatenate([exact[:10], exact[9:]]), "f")


def test_trigger_crossing_and_clipping():
    time = np.linspace(0, 1e-3, 1001)
    ramp = np.clip((time - 4e-4) * 1e4, 0, 2)  # 0 V, then 10 V/ms from 0.4 ms
    assert crossing_time_s(time, ramp, 1.5, True, "t") == pytest.approx(5.5e-4, abs=1e-12)
    with pytest.raises(ConditioningError, match="never goes above 3 V"):
        crossing_time_s(time, ramp, 3.0, True, "t")
    mask = clipped_mask(ramp, (-1.0, 2.0), 0.01)
    assert mask.sum() == np.sum(ramp >= 1.995)
    assert not clipped_mask(ramp, None, 0.01).any()
