"""Shared pieces of the tests: independent references written in NumPy from their papers, which
several test files compare the library with, the chains several of them build and the
comparisons of the fused kernels with the JAX kernel that several of them make (a test file
imports them from here, never from another test file)."""

import math
import os
import shutil
import subprocess
import sys

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import hertzchain as hc
from hertzchain import native
from hertzchain.batched import solve_batched
from hertzchain.driven import DrivenChain
from hertzchain.integrate import Recording

# The native kernels' tests: skipped only where the kernel cannot be built at all (no C++
# compiler, or switched off on purpose); where a compiler is, a kernel that cannot be built or
# loaded fails every test.
NEEDS_A_COMPILER = pytest.mark.skipif(
    (shutil.which("c++") or native.build._cxx()) is None or os.environ.get("HERTZCHAIN_NATIVE", "1") == "0",
    reason="no C++ compiler (or HERTZCHAIN_NATIVE=0): the fused kernel cannot be built here")


def rerun_at_the_default_xla_level(test_file: str, test_name: str) -> bool:
    """Where the suite lowered XLA's optimisation level (tests/conftest.py), run the test
    `test_name` of `test_file` again in a process of its own at the default level and fail
    with its output unless it passes there: True where it ran there (the caller then returns),
    False where this process is already at the default level (the caller runs its checks)."""
    if "xla_backend_optimization_level=0" not in os.environ.get("XLA_FLAGS", "") or os.environ.get(
            "HERTZCHAIN_TEST_XLA_DEFAULT_LEVEL") == "1":
        return False
    flags = " ".join(f for f in os.environ["XLA_FLAGS"].split() if "xla_backend_optimization_level" not in f)
    env = dict(os.environ, XLA_FLAGS=flags, HERTZCHAIN_TEST_XLA_DEFAULT_LEVEL="1")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "0", "-m", "",
                           f"{test_file}::{test_name}"], env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{test_name} at XLA's default optimisation level:\n{proc.stdout[-4000:]}"
    return True


def binary_collision_loss_j(mass_kg, kappa_n_m1p5, damping_n, speed_m_s):
    """Energy a head-on collision of two equal free beads (mass `mass_kg`) loses, J: the
    relative motion $\\mu\\ddot\\delta = -\\max(\\kappa\\delta^{3/2} + F_d(\\delta,
    \\dot\\delta), 0)$ ($\\mu$ = m/2, `damping_n(overlap, rate)` the dissipation law's force
    in NumPy, N) integrated by SciPy from first touch at `speed_m_s` until the beads separate."""
    reduced = mass_kg / 2.0

    def rhs(_, y):
        delta, rate = y
        force = max(kappa_n_m1p5 * max(delta, 0.0) ** 1.5 + damping_n(delta, rate), 0.0) if delta > 0 else 0.0
        return [rate, -force / reduced]

    def separated(_, y):
        return y[0]
    separated.terminal, separated.direction = True, -1
    solution = solve_ivp(rhs, (0.0, 1e-3), [1e-15, speed_m_s], events=separated, rtol=1e-12, atol=1e-18,
                         max_step=1e-7)
    return 0.5 * reduced * (speed_m_s**2 - solution.y_events[0][0][1] ** 2)


def jackson_green_force(overlap, peak, kappa, radius, sigma, nu, hardness=2.84):
    """Jackson & Green (2005) loading with hardness h sigma_Y, Hertz unloading about the residual:
    the contact force (N) at `overlap` (m) after the largest overlap `peak` (m), for a Hertz
    constant `kappa` (N/m^1.5), reduced radius `radius` (m), yield stress `sigma` (Pa) and
    Poisson ratio `nu`. Written from the paper, independently of `hertzchain.contact`."""
    modulus = 3 * kappa / (4 * np.sqrt(radius))
    c = 1.295 * math.exp(0.736 * nu)
    critical = (math.pi * c * sigma / (2 * modulus)) ** 2 * radius
    exponent = 0.14 * np.exp(23 * sigma / modulus)

    def load(x):
        return np.exp(-0.25 * x ** (5 / 12)) * x**1.5 + 4 * hardness / c * (1 - np.exp(-x ** (5 / 9) / 25)) * x

    ratio = peak / critical
    yielded = ratio > 1.9
    r = np.where(yielded, ratio, 1.9)
    peak_force = np.where(yielded, kappa * critical**1.5 * (load(r) - load(1.9) + 1.9**1.5), kappa * peak**1.5)
    contact_radius = np.sqrt(radius * peak * np.where(yielded, (r / 1.9) ** exponent, 1.0))
    span = np.where(yielded, 3 * peak_force / (4 * modulus * np.maximum(contact_radius, 1e-300)), peak)
    fraction = np.clip((overlap - (peak - span)) / np.maximum(span, 1e-300), 0.0, None)
    return np.where(peak > 0, peak_force * fraction**1.5, 0.0)


# Driven chains (hertzchain.driven)


def lydon_bead(n_beads=1, precompression_n=4.5, damping_rate_per_s=1800.0):
    """316 steel beads of 19.05 mm, 28 g, between steel faces (Lydon et al. 2015's setup)."""
    return DrivenChain.from_materials(
        n_beads=n_beads, bead_radius_m=9.525e-3, bead_mass_kg=0.028, bead_youngs_pa=193e9, bead_poisson=0.3,
        driver_youngs_pa=193e9, driver_poisson=0.3, wall_youngs_pa=193e9, wall_poisson=0.3,
        precompression_n=precompression_n, damping_rate_per_s=damping_rate_per_s,
    )


def lydon_fitted_bead():
    """The single bead as the research notes fitted it: delta_0 = 22.6 nm at F0 = 0.133 N
    (linear resonance 3993 Hz), zeta = 0.036."""
    kappa = 0.133 / (22.6e-9) ** 1.5
    return DrivenChain(bead_mass_kg=[0.028], contact_kappa_n_m1p5=[kappa, kappa], precompression_n=0.133,
                       damping_rate_per_s=2 * 0.036 * 2 * np.pi * 3993.0)


def uneven_chain():
    """A second setup: three unequal beads, unequal contacts, unequal damping."""
    return DrivenChain(
        bead_mass_kg=[0.011, 0.02, 0.015],
        contact_kappa_n_m1p5=[6e9, 9e9, 4e9, 1.2e10],
        precompression_n=2.0,
        damping_rate_per_s=[900.0, 1500.0, 600.0],
    )


def linear_response(chain, frequency_hz):
    """Closed-form steady state of the chain linearised about F0: bead velocities' complex
    amplitudes per metre of drive, (n, F), from (K - w^2 M + i w C) X = k_0 e_1."""
    k = np.asarray(chain.contact_stiffness_n_m())
    m = np.asarray(chain.bead_mass_kg)
    gamma = np.asarray(chain.damping_rate_per_s)
    n = m.size
    stiffness = np.diag(k[:-1] + k[1:]) - np.diag(k[1:-1], 1) - np.diag(k[1:-1], -1)
    force = np.zeros(n)
    force[0] = k[0]
    out = []
    for f in np.atleast_1d(frequency_hz):
        w = 2 * np.pi * f
        x = np.linalg.solve(stiffness - w**2 * np.diag(m) + 1j * w * np.diag(m * gamma), force)
        out.append(1j * w * x)
    return np.asarray(out).T


def linear_mode_frequencies_hz(chain):
    """Frequencies of the chain linearised about F0 (undamped), Hz, ascending."""
    k = np.asarray(chain.contact_stiffness_n_m())
    stiffness = np.diag(k[:-1] + k[1:]) - np.diag(k[1:-1], 1) - np.diag(k[1:-1], -1)
    return np.sqrt(np.sort(np.linalg.eigvals(stiffness / np.asarray(chain.bead_mass_kg)[:, None]).real)) / (2 * np.pi)


# The fused kernels (hertzchain.native) against the JAX kernel


def ten_bead_batch(speeds=(0.3, 1.0), **kwargs):
    """`hc.batch_setup` of a 10-bead chain (`ChainSetup` fields `kwargs`) with striker speeds
    `speeds` (m/s) and walls of Young's modulus 3 GPa and 400 GPa, and its time grid (0.8 ms,
    a sample every 2 us)."""
    setup, _ = hc.batch_setup(hc.ChainSetup(10, **kwargs), striker_velocity_m_s=list(speeds),
                              wall_youngs_pa=[3e9, 4e11])
    return setup, hc.choose_time_grid(setup, t_end_s=0.8e-3, sample_interval_s=2e-6)


def recorded_forces(base, grid, q, kernel):
    """`record_batched` at parameter values q = (eta s, mu, striker-speed factor, preload N,
    bead Young's modulus factor[, dashpot N s/m]): the recorded forces (channels, B, n_samples)."""
    import equinox as eqx
    import jax.numpy as jnp

    from hertzchain.batched import kernel_flags, record_batched

    dashpot = ("dashpot",) if q.shape[0] > 5 else ()
    flags = kernel_flags(base, switched_on=("viscous", "friction", "preload") + dashpot)._replace(ledger=False)
    ones = jnp.ones(base.eta_s.shape)
    setup = eqx.tree_at(
        lambda s: (s.eta_s, s.mu, s.striker_velocity_m_s, s.precompression_n, s.bead_youngs_pa), base,
        (q[0] * ones, q[1] * ones, q[2] * base.striker_velocity_m_s, q[3] * ones, q[4] * base.bead_youngs_pa),
    )
    if dashpot:
        setup = eqx.tree_at(lambda s: s.dashpot_n_s_m, setup, q[5] * ones)
    out = record_batched(setup, grid, Recording((2, 6)), flags, kernel=kernel)
    return jnp.stack([out.forces_n[name] for name in out.channel_names])


TRANSFORMS = {
    # a batch of fits: every parameter vector its own chains
    "vmap": lambda f, q, qs: jax.vmap(f)(qs),
    "jacfwd": lambda f, q, qs: jax.jacfwd(f)(q),
    "vmap_of_jacfwd": lambda f, q, qs: jax.vmap(jax.jacfwd(f))(qs),
    "jacfwd_of_vmap": lambda f, q, qs: jax.jacfwd(lambda s: jax.vmap(f)(qs * s))(np.ones(q.size)),
    "vmap_of_vmap_of_jacfwd": lambda f, q, qs: jax.vmap(jax.vmap(jax.jacfwd(f)))(jax.numpy.stack([qs, qs[::-1]])),
}


def synthetic_fit_problem():
    """The fit problem (eta, mu, C free) of two synthetic 12-bead shots (0.2 and 0.5 m/s,
    contact 4 recorded, noise 0.3 N) and its starting values."""
    from fitting.fit import initial_values, make_problem
    from fitting.synthetic import paper_setups, synthetic_traces

    files = synthetic_traces(paper_setups([0.2, 0.5], n_beads=12), contacts=(4,), t_end_s=0.6e-3,
                             sample_interval_s=2e-6, noise_std_n=0.3, seed=3)
    problem = make_problem(files, ("eta_s", "mu", "C"))
    return problem, initial_values(problem)


def assert_forces_equal_the_jax_kernels(setup, grid, *, books: bool):
    """`solve_batched`'s default kernel against the JAX kernel (contacts 2 and 6 and the
    wall): every recorded force within 2e-12 of its channel's largest force. Returns both
    results (the default kernel's first)."""
    recording = Recording((2, 6))
    ours = solve_batched(setup, grid, recording, books=books)
    reference = solve_batched(setup, grid, recording, books=books, kernel="jax")
    for name in ours.channel_names:
        scale = float(np.max(np.abs(reference.forces_n[name])))
        assert scale > 1.0 or (name == "wall" and setup.end == "free")
        np.testing.assert_allclose(ours.forces_n[name], reference.forces_n[name], rtol=0, atol=2e-12 * scale)
    return ours, reference


def assert_jacfwd_equals_the_jax_kernels(forces, q):
    """`jax.jacfwd` of `forces(q, kernel)` (recorded forces at parameters q) on the default
    kernel against the JAX kernel: every column within 1e-10 of its largest value (friction's
    derivative crosses stick-slip kinks), none of them zero. Returns the default kernel's."""
    jac = np.asarray(jax.jit(jax.jacfwd(lambda q: forces(q, "auto")))(q))
    reference = np.asarray(jax.jit(jax.jacfwd(lambda q: forces(q, "jax")))(q))
    for i in range(q.size):
        scale = np.max(np.abs(reference[..., i]))
        assert scale > 0.0
        np.testing.assert_allclose(jac[..., i], reference[..., i], rtol=0, atol=1e-10 * scale)
    return jac


def assert_transform_is_one_call_equal_to_the_jax_kernel(transform: str, targets) -> None:
    """`record_batched` under `TRANSFORMS[transform]` on the fused kernel: the custom call
    `targets(transform)` names appears once in the compiled program (no loop around it), and
    the values and derivatives are those of the JAX kernel under the same transformation to
    round-off (friction's derivative crosses stick-slip kinks: 1e-10 of each column's largest
    value)."""
    import jax.numpy as jnp

    base, _ = ten_bead_batch(speeds=(0.3, 1.0, 0.5), precompression_n=1.0)
    grid = hc.choose_time_grid(base, t_end_s=0.3e-3, sample_interval_s=2e-6)
    q = jnp.asarray([2e-6, 0.19, 1.0, 1.0, 1.0])
    qs = q * jnp.asarray([[1.0] * 5, [1.3, 0.7, 1.1, 0.5, 1.02], [0.6, 1.2, 0.9, 1.5, 0.98]])
    run = lambda kernel: jax.jit(lambda q, qs: TRANSFORMS[transform](
        lambda p: recorded_forces(base, grid, p, kernel), q, qs))
    hlo = run("auto").lower(q, qs).as_text()
    assert hlo.count(targets(transform)) == 1 and "while" not in hlo
    fused, reference = np.asarray(run("auto")(q, qs)), np.asarray(run("jax")(q, qs))
    assert fused.shape == reference.shape
    columns = tuple(range(reference.ndim - 1)) if "jacfwd" in transform else None
    scale = np.max(np.abs(reference), axis=columns)
    assert np.all(scale > 0.0)
    np.testing.assert_array_less(np.max(np.abs(fused - reference), axis=columns), 1e-10 * scale)


def assert_fit_iteration_equals_the_jax_kernels(monkeypatch) -> None:
    """What a fit iteration computes (`fitting.model.residuals_and_jacobian`: whitened
    residuals and their Jacobian in eta, mu, C and the nuisances) on the fused kernel that
    `native.kernel_for` picks equals the same on the JAX kernel to round-off."""
    from fitting.model import residuals_and_jacobian

    problem, x = synthetic_fit_problem()
    assert problem.simulates_natively()
    r, jac = residuals_and_jacobian(problem, x)
    monkeypatch.setattr(native, "kernel_for", lambda flags, devices, rows=None: None)
    problem_jax, _ = synthetic_fit_problem()
    r_jax, jac_jax = residuals_and_jacobian(problem_jax, x)
    assert r.shape == r_jax.shape and np.linalg.norm(r) > 10.0  # the start is off the data
    np.testing.assert_allclose(r, r_jax, rtol=0, atol=1e-10 * np.max(np.abs(r_jax)))
    for column, label in enumerate(problem.labels):
        scale = np.max(np.abs(jac_jax[:, column]))
        np.testing.assert_allclose(jac[:, column], jac_jax[:, column], rtol=0, atol=1e-9 * scale + 1e-300,
                                   err_msg=label)


# The [chain], [drive] and [sensor] tables of a driven experiment file: one bead between two
# sphere-flat contacts of the Lydon et al. apparatus (the measurement tables follow).
DRIVEN_EXPERIMENT_HEAD = """kind = "driven"
[chain]
n_beads = 1
bead_mass_kg = 0.028
contact_kappa_n_m1p5 = [1.38e10, 1.38e10]
precompression_n = 4.5
[drive]
calibration_m_per_v = 7.517e-7
[sensor]
calibration_m_s_per_v = 0.02125
"""


def driven_bead_lockin(frequencies_hz, drives_m, *, mass_kg, contact_force, static_overlap_m, damping_rate_per_s,
                       support=None, ramp_periods=25, hold_periods=35, window_periods=4, steps_per_period=48):
    """RMS velocity (m/s) at the drive frequency of one bead between a driven face and a wall,
    (F, A), by a fixed-step NumPy RK4 written here (a second code path to
    `hertzchain.driven.lockin_grid`): every (frequency, drive) run at once from rest at the
    static equilibrium, the face's amplitude rising along the quintic smooth step over
    `ramp_periods` periods, held `hold_periods`, the bead's velocity demodulated at the drive
    frequency over the last `window_periods`.

    `contact_force(overlap_m)` (N, NumPy, vectorised) is the law of both contacts, each at
    `static_overlap_m` at rest; viscous drag -m gamma v on the bead. `support`: None, or
    (force(x, state), update(x, state), state at rest (x = 0)) of a force on the bead that
    depends on its displacement x and a history state (an Iwan element's sliders), the state
    updated after each step (operator splitting, first order in the step)."""
    f = np.asarray(frequencies_hz, float)[:, None]
    a = np.asarray(drives_m, float)[None, :]
    omega = 2 * np.pi * f
    dt = 1.0 / (f * steps_per_period)

    def face(t):
        s = np.clip(t * f / ramp_periods, 0.0, 1.0)
        return a * s**3 * (10 - 15 * s + 6 * s**2) * np.cos(omega * t)

    state = None if support is None else support[2](np.zeros(np.broadcast(f, a).shape))

    def rate(t, y):  # y = (displacement, velocity) stacked
        x, v = y
        push = contact_force(static_overlap_m + face(t) - x) - contact_force(static_overlap_m + x)
        if support is not None:
            push = push + support[0](x, state)
        return np.stack([v, push / mass_kg - damping_rate_per_s * v])

    y = np.zeros((2,) + np.broadcast(f, a).shape)
    t = np.zeros_like(f)
    total = (ramp_periods + hold_periods) * steps_per_period
    window = window_periods * steps_per_period
    phasor = np.zeros(y.shape[1:], dtype=complex)
    for step in range(total):
        slopes = [rate(t, y)]
        for fraction in (0.5, 0.5, 1.0):
            slopes.append(rate(t + fraction * dt, y + fraction * dt * slopes[-1]))
        y = y + dt * (slopes[0] + 2 * slopes[1] + 2 * slopes[2] + slopes[3]) / 6
        t = t + dt
        if support is not None:
            state = support[1](y[0], state)
        if step >= total - window:
            phasor += y[1] * np.exp(-1j * omega * t)
    return np.abs(phasor) * 2 / window / math.sqrt(2)


def iwan_support(stiffness_n_m, slip_displacement_m, elements=16):
    """An Iwan element (Iwan 1966) for `driven_bead_lockin`'s `support`: `elements` springs of
    K/E, each in series with a slider that slips where its stretch exceeds phi_j = (j - 1/2)
    phi_max / E; force -(K/E) sum_j (x - s_j). Written here from the paper, in NumPy."""
    limits = (np.arange(elements) + 0.5) / elements * slip_displacement_m

    def force(x, sliders):
        return -(stiffness_n_m / elements) * np.sum(x[None] - sliders, axis=0)

    def update(x, sliders):
        stretch = np.clip(x[None] - sliders, -limits.reshape((-1,) + (1,) * x.ndim),
                          limits.reshape((-1,) + (1,) * x.ndim))
        return x[None] - stretch

    return force, update, lambda x: np.broadcast_to(x, (elements,) + x.shape).copy()
