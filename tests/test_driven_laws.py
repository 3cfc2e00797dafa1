"""Every law of `hertzchain.laws` in driven chains: the kernel's trajectories against scipy's
DOP853 on an ODE written here in NumPy (the laws' published forms, not the package's code),
the static state and linear stiffness from the law, the preload per contact and its support
force, the history of an elastic-plastic contact, and which kernel ran."""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hertzchain import laws
from hertzchain.driven import DrivenChain, HarmonicSchedule, lockin_grid, record_schedule
from hertzchain.driven.linear import normal_modes

MASS = np.array([0.028, 0.02])  # kg
KAPPA = np.array([1.38e10, 9.76e9, 1.38e10])  # N/m^1.5
N_STEPS, RAMP, HOLD = 256, 3, 5  # steps per period, periods of the ramp and of the hold


def smooth_step(s):
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s**2), 30 * s**2 * (1 - s) ** 2


def reference_velocities(elastic, damping, static_force, frequency, amplitude, gamma, times):
    """Bead velocities (n, T) at `times` from scipy's DOP853 on the chain's ODE:
    `elastic(overlap)` and `damping(overlap, rate)` are the contact laws (N), the supports
    hold each bead with F_i - F_{i-1} of the static forces."""
    omega, ramp_s = 2 * np.pi * frequency, RAMP / frequency
    static_overlap = np.asarray([_solve(lambda d, k=k: elastic(d)[k] - static_force[k]) for k in range(3)])
    support = static_force[1:] - static_force[:-1]

    def rhs(t, z):
        x, v = z[:2], z[2:]
        shape, slope = smooth_step(t / ramp_s)
        u = amplitude * shape * np.cos(omega * t)
        u_dot = amplitude * (slope / ramp_s * np.cos(omega * t) - omega * shape * np.sin(omega * t))
        overlap = static_overlap + np.r_[u, x] - np.r_[x, 0.0]
        rate = np.r_[u_dot, v] - np.r_[v, 0.0]
        force = np.where(overlap > 0, np.maximum(elastic(overlap) + damping(overlap, rate), 0.0), 0.0)
        return np.r_[v, (force[:-1] - force[1:] + support) / MASS - gamma * v]

    run = solve_ivp(rhs, (0.0, times[-1]), np.zeros(4), method="DOP853", rtol=1e-11, atol=1e-16, t_eval=times)
    return run.y[2:]


def _solve(function):
    from scipy.optimize import brentq

    return brentq(function, 0.0, 1e-4, xtol=1e-20, rtol=1e-15)


def hertz(overlap):
    return KAPPA * np.maximum(overlap, 0.0) ** 1.5


CASES = {
    # contact exponent: F = kappa d_r^1.5 (d / d_r)^n, with a dashpot
    "power_law_dashpot": (
        dict(contact_law=laws.PowerLaw(1.3, 1e-7), dissipation=(laws.Dashpot(20.0),)),
        lambda d: KAPPA * 1e-7**1.5 * (np.maximum(d, 0.0) / 1e-7) ** 1.3,
        lambda d, rate: 20.0 * rate, 3.0),
    # Vergara's velocity-squared loss c |rate| rate
    "velocity_squared": (
        dict(dissipation=(laws.VelocitySquared(3e4),)), hertz,
        lambda d, rate: 3e4 * np.abs(rate) * rate, 3.0),
    # Hunt-Crossley's hysteretic damping 1.5 alpha kappa d^1.5 rate
    "hunt_crossley": (
        dict(dissipation=(laws.HuntCrossley(1.0),)), hertz,
        lambda d, rate: 1.5 * 1.0 * KAPPA * np.maximum(d, 0.0) ** 1.5 * rate, 3.0),
    # a preload per contact (the supports hold the beads), Kuwabara-Kono damping
    "preload_per_contact": (
        dict(eta_s=2e-7), hertz,
        lambda d, rate: 1.5 * 2e-7 * KAPPA * np.sqrt(np.maximum(d, 0.0)) * rate, np.array([4.0, 3.0, 2.5])),
}


@pytest.mark.parametrize("case", [
    pytest.param("power_law_dashpot", marks=pytest.mark.slow), "velocity_squared", "hunt_crossley",
    pytest.param("preload_per_contact", marks=pytest.mark.slow)])
def test_kernel_trajectory_matches_an_independent_integrator(case):
    options, elastic, damping, preload = CASES[case]
    gamma = 300.0
    chain = DrivenChain(MASS, KAPPA, preload, gamma, **options)
    frequency, amplitude = 3000.0, 40e-9
    schedule = HarmonicSchedule.levels(frequency, amplitude, steps_per_period=N_STEPS, ramp_periods=RAMP,
                                       periods_per_level=HOLD, transition_periods=0)
    traces = record_schedule(chain, schedule, beads=(1, 2), contacts=(0,), every_steps=N_STEPS // 8)
    times = np.asarray(traces.time_s[0])
    velocity = np.asarray(traces.velocity_m_s[0])
    static_force = np.broadcast_to(preload, (3,)).astype(float)
    expected = reference_velocities(elastic, damping, static_force, frequency, amplitude, gamma, times)
    scale = np.max(np.abs(expected))
    assert scale > 1e-5  # the beads move (m/s)
    np.testing.assert_allclose(velocity, expected, atol=2e-3 * scale)


def test_static_state_and_linear_stiffness_come_from_the_law():
    force = np.array([4.0, 3.0, 2.5])
    chain = DrivenChain(MASS, KAPPA, force, 0.0, contact_law=laws.PowerLaw(1.7, 2e-7))
    overlap = 2e-7 * (force / (KAPPA * (2e-7) ** 1.5)) ** (1 / 1.7)
    np.testing.assert_allclose(np.asarray(chain.static_overlap_m()), overlap, rtol=1e-13)
    k = 1.7 * force / overlap  # dF/d(delta) of a power law
    np.testing.assert_allclose(np.asarray(chain.contact_stiffness_n_m()), k, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(chain.support_force_n()), [-1.0, -0.5], rtol=1e-15)
    stiffness = np.diag(k[:-1] + k[1:]) - np.diag(k[1:-1], 1) - np.diag(k[1:-1], -1)
    expected = np.sqrt(np.linalg.eigvals(np.diag(1 / MASS) @ stiffness).real) / (2 * np.pi)
    np.testing.assert_allclose(np.asarray(normal_modes(chain)[0]), np.sort(expected), rtol=1e-12)
    # the old spelling still builds the same chain: Hertz, Kuwabara-Kono of eta_s
    old = DrivenChain(MASS, KAPPA, 3.0, 100.0, 1e-7)
    assert type(old.contact_law) is laws.Hertz and old.runs_on_fused_kernel
    assert [type(law) for law in old.dissipation] == [laws.Viscoelastic] and float(old.eta_s) == 1e-7
    assert not chain.runs_on_fused_kernel
    with pytest.raises(ValueError, match="either as eta_s or as laws.Viscoelastic"):
        DrivenChain(MASS, KAPPA, 3.0, 0.0, 1e-7, dissipation=(laws.Viscoelastic(1e-7),))
    with pytest.raises(ValueError, match="precompression_n"):
        DrivenChain(MASS, KAPPA, [1.0, 2.0], 0.0)
    with pytest.raises(ValueError, match="contact_yield_force_n"):
        DrivenChain(MASS, KAPPA, 3.0, 0.0, contact_law=laws.Thornton())
    with pytest.raises(ValueError, match="above the yield force"):
        DrivenChain(MASS, KAPPA, 3.0, 0.0, contact_law=laws.Thornton(), contact_yield_force_n=[2.0, 9.0, 9.0])


def test_thornton_contact_carries_its_history_through_the_run():
    # a contact that yields at 5 N under a 4.5 N preload: a 150 nm drive near resonance
    # pushes it past yield; the largest overlap is the state, and afterwards the contact
    # unloads along Thornton's flatter-seated curve (a residual overlap: at the static
    # overlap it carries less than the preload)
    yield_force = np.array([5.0, np.inf])
    chain = DrivenChain(MASS[:1], KAPPA[:2], 4.5, 2000.0, contact_law=laws.Thornton(),
                        contact_yield_force_n=yield_force)
    schedule = HarmonicSchedule.levels(3600.0, 150e-9, steps_per_period=64, ramp_periods=4, periods_per_level=8)
    traces = record_schedule(chain, schedule, beads=(1,), contacts=(0, 1), every_steps=1)
    x, u = np.asarray(traces.displacement_m[0, 0]), np.asarray(traces.drive_m[0])
    force = np.asarray(traces.contact_force_n[0])
    static_overlap = np.asarray(chain.static_overlap_m())
    overlap = static_overlap[0] + u - x
    peak = np.maximum.accumulate(overlap)
    assert peak[-1] > (5.0 / KAPPA[0]) ** (2 / 3) * 1.05  # it yielded
    # Thornton (J. Appl. Mech. 64, 383, 1997), written out: unloading from (d_m, F_m) along a
    # Hertz curve of radius ratio ((2 F_m + F_y)/3)^1.5 / (F_m sqrt(F_y))
    d_y = (5.0 / KAPPA[0]) ** (2 / 3)
    f_m = 5.0 + 1.5 * 5.0 / d_y * (peak[-1] - d_y)
    kappa_p = KAPPA[0] * np.sqrt(((2 * f_m + 5.0) / 3) ** 1.5 / (f_m * np.sqrt(5.0)))
    residual = peak[-1] - (f_m / kappa_p) ** (2 / 3)
    late = slice(len(overlap) // 2, None)
    unloading = overlap[late] < peak[-1] - 1e-12
    expected = kappa_p * np.maximum(overlap[late] - residual, 0.0) ** 1.5
    np.testing.assert_allclose(force[0, late][unloading], expected[unloading], rtol=1e-9, atol=1e-9)
    # the wall contact never yields (infinite yield force): Hertz throughout
    wall = static_overlap[1] + x
    np.testing.assert_allclose(force[1], KAPPA[1] * np.maximum(wall, 0) ** 1.5, rtol=1e-10, atol=1e-9)


def test_which_kernel_runs_a_chain():
    # the fused kernel has Hertz, Kuwabara-Kono and one preload only (a grid's `kernel` says
    # which ran: tests/test_driven_series_laws.py)
    assert DrivenChain(MASS[:1], KAPPA[:2], 4.5, 2000.0, 1e-7).runs_on_fused_kernel
    squared = DrivenChain(MASS[:1], KAPPA[:2], 4.5, 2000.0, dissipation=(laws.VelocitySquared(1e3),))
    assert not squared.runs_on_fused_kernel
    tiny = dict(harmonics=(1.0,), ramp_periods=1, hold_periods=2, window_periods=2, steps_per_period=16)
    assert lockin_grid(squared, [3600.0], [1e-9], **tiny).kernel == "jax"
    assert squared.describe()["dissipation"] == [{"type": "VelocitySquared", "c_n_s2_m2": 1e3}]
    per_contact = DrivenChain(MASS[:1], KAPPA[:2], jnp.asarray([4.5, 4.5]), 2000.0)
    assert not per_contact.runs_on_fused_kernel
