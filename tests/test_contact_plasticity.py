"""The elastic-plastic contact law of measured contacts (`contact.jackson_green_contact`):
Hertz below first yield, closed forms when fully plastic, energy bookkeeping along
load-unload histories, gradients at its branch changes, and its use in the chain."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain as hc
from hertzchain import contact
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording, solve

# 440C hemispheres of Burgoyne & Daraio (2014): R* = R/2, E* = E/(2(1 - nu^2))
RADIUS = 1.5875e-3
NU = 0.3
MODULUS = 200e9 / (2 * (1 - NU**2))
KAPPA = 4 / 3 * MODULUS * math.sqrt(RADIUS)
SIGMA = 1896e6
DELTA_C = float(contact.critical_interference(RADIUS, MODULUS, SIGMA, NU))


def law(overlap, max_overlap, kappa=KAPPA, radius=RADIUS, sigma=SIGMA, nu=NU, hardness=2.84):
    return contact.jackson_green_contact(overlap, max_overlap, kappa, radius, sigma, nu, hardness)


def test_critical_interference_is_jackson_green_closed_form():
    c = 1.295 * math.exp(0.736 * NU)
    assert DELTA_C == pytest.approx((math.pi * c * SIGMA / (2 * MODULUS)) ** 2 * RADIUS, rel=1e-14)
    # von Mises first yield of a Hertz contact (Johnson, Contact Mechanics 4.2.3): p0 = 1.6 sigma_Y
    # for nu = 0.3, i.e. a = pi p0 R / (2 E*) and delta = a^2 / R
    p0 = 1.6 * SIGMA
    assert DELTA_C == pytest.approx((math.pi * p0 / (2 * MODULUS)) ** 2 * RADIUS, rel=0.02)


def test_reduces_to_hertz_below_first_yield():
    max_overlap = np.linspace(0.0, 1.9 * DELTA_C, 41)
    for fraction in (1.0, 0.7, 0.2):
        force, energy, dissipated = law(fraction * max_overlap, max_overlap)
        hertz = contact.hertz_force(fraction * max_overlap, KAPPA)
        np.testing.assert_allclose(force, hertz, rtol=1e-12, atol=1e-12 * float(jnp.max(hertz)))
        np.testing.assert_allclose(energy, contact.hertz_potential(fraction * max_overlap, KAPPA), rtol=1e-12,
                                   atol=1e-30)
        assert np.all(np.asarray(dissipated) == 0.0)


def test_force_is_continuous_at_the_transition_and_monotone_in_overlap():
    overlap = 1.9 * DELTA_C * np.array([1 - 1e-9, 1 + 1e-9])
    force, _, _ = law(overlap, overlap)
    assert float(force[1] / force[0]) == pytest.approx(1.0, abs=1e-8)
    grid = DELTA_C * np.geomspace(0.1, 1e5, 400)
    loading = np.asarray(law(grid, grid)[0])
    assert np.all(np.diff(loading) > 0)


def test_fully_plastic_force_radius_and_residual_overlap_match_closed_forms():
    """At delta* -> infinity: F = (4h/C) P_c delta* = (8/3) pi R* delta H (Jackson & Green 2005,
    Eq. 17's plastic term), contact radius a^2 = R* delta (delta*/1.9)^B with B = 0.14 exp(23
    sigma/E*), residual overlap delta_r = delta_m - 3 F_m / (4 E* a_m) (Hertz about a_m)."""
    hardness = 2.84 * SIGMA
    overlap = 1e6 * DELTA_C
    force, _, _ = law(overlap, overlap)
    # the continuity shift (0.012 P_c) is 2e-9 of the force at delta* = 1e6
    assert float(force) == pytest.approx(8 / 3 * math.pi * RADIUS * overlap * hardness, rel=5e-9)
    b = 0.14 * math.exp(23 * SIGMA / MODULUS)
    radius = float(contact.jackson_green_contact_radius(overlap, KAPPA, RADIUS, SIGMA, NU))
    assert radius**2 == pytest.approx(RADIUS * overlap * (1e6 / 1.9) ** b, rel=1e-12)
    residual = overlap - 3 * float(force) / (4 * MODULUS * radius)
    span = overlap - residual
    below, above = law(residual + span * np.array([-1e-9, 1e-4]), overlap)[0]
    assert float(below) == 0.0
    assert float(above) == pytest.approx(1e-6 * float(force), rel=1e-3)  # (1e-4)^(3/2) of the peak
    # unloading starts with the flat-punch stiffness 2 E* a_m of the flattened contact
    stiffness = jax.grad(lambda d: law(d, overlap)[0])(overlap * (1 - 1e-12))
    assert float(stiffness) == pytest.approx(2 * MODULUS * radius, rel=1e-6)


def _work_along(history):
    """Work done on the contact along `history` (m), J (trapezoid on a fine path)."""
    peak = np.maximum.accumulate(history)
    force, energy, dissipated = (np.asarray(x) for x in law(history, peak))
    work = np.concatenate([[0.0], np.cumsum(0.5 * (force[1:] + force[:-1]) * np.diff(history))])
    return work, energy, dissipated


def test_dissipation_is_nonnegative_and_closes_the_energy_books_on_every_cycle():
    rng = np.random.default_rng(3)
    turning = DELTA_C * np.concatenate([[0.0], np.cumsum(rng.uniform(-30, 60, 12))])
    turning = np.maximum(turning, 0.0)
    history = np.concatenate([np.linspace(a, b, 4000, endpoint=False) for a, b in zip(turning[:-1], turning[1:])])
    work, energy, dissipated = _work_along(history)
    assert np.all(dissipated >= 0.0) and np.all(np.diff(dissipated) >= -1e-12 * dissipated.max())
    assert dissipated[-1] > 0.1 * work.max()
    # work done = energy stored + energy dissipated, at every point of the history
    np.testing.assert_allclose(work, energy + dissipated, rtol=0, atol=2e-4 * work.max())
    # each closed load-unload-reload cycle below the largest overlap dissipates nothing more
    peak = turning.max()
    cycle = np.concatenate([np.linspace(peak, 0.3 * peak, 3000), np.linspace(0.3 * peak, peak, 3000)])
    force = np.asarray(law(cycle, np.full_like(cycle, peak))[0])
    assert abs(np.trapezoid(force, cycle)) < 1e-6 * float(law(peak, peak)[0]) * peak


@pytest.mark.parametrize("ratio", [1.9, 1.9 * (1 + 1e-4), 40.0])
def test_gradients_in_every_constant_are_finite_at_branch_changes_and_equal_finite_differences(ratio):
    args = np.array([0.6 * ratio * DELTA_C, ratio * DELTA_C, KAPPA, RADIUS, SIGMA, NU, 2.84])

    def force(x):
        return law(*x)[0] + law(*x)[2] / DELTA_C  # force and dissipated work

    grad = np.asarray(jax.grad(force)(jnp.asarray(args)))
    assert np.all(np.isfinite(grad))
    if ratio == 1.9:  # on the kink itself: finite, nothing more to compare
        return
    for i in range(args.size):
        step = 1e-7 * args[i]  # well inside the branch: delta*_m is 1e-4 above the transition
        up, down = args.copy(), args.copy()
        up[i] += step
        down[i] -= step
        fd = (float(force(jnp.asarray(up))) - float(force(jnp.asarray(down)))) / (2 * step)
        # abs: the difference quotient's rounding, ~1e-16 |f| / step, with a margin
        assert grad[i] == pytest.approx(fd, rel=1e-5, abs=1e-6 * abs(float(force(jnp.asarray(args)))) / args[i])


def test_gradients_are_finite_at_contact_onset_and_at_the_residual_overlap():
    peak = 50 * DELTA_C
    residual = peak - 3 * float(law(peak, peak)[0]) / (
        4 * MODULUS * float(contact.jackson_green_contact_radius(peak, KAPPA, RADIUS, SIGMA, NU)))
    for overlap in (0.0, residual, -1e-6):
        grad = jax.grad(lambda x: law(x[0], x[1], x[2], x[3], x[4], x[5])[0])(
            jnp.asarray([overlap, peak, KAPPA, RADIUS, SIGMA, NU]))
        assert np.all(np.isfinite(np.asarray(grad)))
    grad = jax.grad(lambda s: law(0.0, 0.0, sigma=s)[0])(SIGMA)
    assert np.isfinite(float(grad))


def test_rate_hardening_is_johnson_cook_rate_term():
    assert float(contact.rate_hardened_yield_stress(600e6, 0.025, 1e-3)) == 600e6
    assert float(contact.rate_hardened_yield_stress(600e6, 0.025, 500.0)) == pytest.approx(
        600e6 * (1 + 0.025 * math.log(5e5)), rel=1e-14)


def _plastic_setup(**kw):
    values = dict(striker_velocity_m_s=2.0, plasticity=True, plastic_law="jackson_green",
                  bead_yield_stress_pa=1e9)
    values.update(kw)
    return hc.ChainSetup(4, **values)


def test_chain_with_jackson_green_contacts_keeps_its_energy_books():
    setup = _plastic_setup()
    run = hc.simulate(setup, t_end_s=2.5e-4, contacts=(1,))
    energy = float(run.initial_energy_j)
    assert float(run.dissipated_plastic_j[-1]) > 0.2 * energy
    assert float(np.max(np.abs(run.energy_error_j))) < 1e-4 * energy
    # elastic below first yield: the same run as Hertz contacts
    slow = hc.simulate(_plastic_setup(striker_velocity_m_s=1e-4), t_end_s=2.5e-4, contacts=(1,), on_yield="ignore")
    hertz = hc.simulate(_plastic_setup(striker_velocity_m_s=1e-4, plasticity=False), t_end_s=2.5e-4, contacts=(1,),
                        on_yield="ignore")
    np.testing.assert_allclose(slow.forces_n["contact_1"], hertz.forces_n["contact_1"], rtol=0,
                               atol=1e-10 * float(np.max(hertz.forces_n["contact_1"])))


def test_rejects_an_unknown_plastic_law():
    with pytest.raises(ValueError, match="plastic_law"):
        hc.ChainSetup(3, plasticity=True, plastic_law="tabor")


@pytest.mark.slow  # default-suite time; test_batched.py's `test_matches_solve_to_round_off[jackson_green_*]`
# hold Jackson-Green chains on the batched kernel to `solve`
def test_solve_batched_gives_solve_for_jackson_green_contacts():
    from hertzchain.batched import stack_setups

    setups = [_plastic_setup(striker_velocity_m_s=v) for v in (1.0, 2.5)]
    setup = stack_setups(setups)
    grid = hc.choose_time_grid(setup, t_end_s=2e-4, sample_interval_s=2e-6)
    batched = solve_batched(setup, grid, Recording((2,)))
    for k, single in enumerate(setups):
        alone = solve(single, hc.choose_time_grid(setup, t_end_s=2e-4, sample_interval_s=2e-6), Recording((2,)))
        np.testing.assert_allclose(np.asarray(batched.forces_n["contact_2"])[k], alone.forces_n["contact_2"],
                                   rtol=1e-12, atol=1e-9)
