"""The velocity-Verlet step of driven chains, many runs at once on the SIMD axis.

The state of B runs is laid out as (n, B) arrays, the runs on the fast axis, so that every
operation of a step is one vector instruction over runs (as in `hertzchain.batched`). Runs
may differ in their time step (each run's own `dt_s`, a (B,) array), in the driver's
displacement and in nothing else: the chain's constants are shared, (n, 1) columns.

One step of length $\\Delta t$ with $h = \\Delta t/2$, $f$ the contact forces' acceleration
$(F_{i-1} - F_i)/m_i$ and $\\gamma$ the beads' viscous damping rate:

    v_half = v + h (f - gamma v)
    x'     = x + dt v_half
    f'     = contact forces at x', the driver at its new position u', the contact damping
             at the predicted velocity v_half + h (f - gamma v) (as `integrate.verlet_step`)
    v'     = (v_half + h f') / (1 + h gamma)

The drag $-\\gamma v$ is treated by the trapezoidal rule (implicit, solved in closed form):
the scheme stays symmetric, second order and stable for any damping. The contact laws are
`hertzchain.laws`' `Hertz` and `Viscoelastic` (Kuwabara-Kono), their sum clipped at zero.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .. import laws
from .chain import DrivenChain

# Steps of a `lax.scan` unrolled into one loop iteration (speed only).
DEFAULT_UNROLL = 8


class KernelParams(NamedTuple):
    """The chain's constants in the kernel's layout: columns that broadcast over runs."""

    inv_mass_per_kg: jax.Array  # (n, 1)
    damping_rate_per_s: jax.Array  # (n, 1)
    kappa_n_m1p5: jax.Array  # (n + 1, 1)
    static_overlap_m: jax.Array  # (n + 1, 1)
    eta_s: jax.Array | None  # (); None: no contact damping (compiled without it)


class State(NamedTuple):
    """B runs' state at a step: displacements from the static equilibrium (m), velocities
    (m/s) and the contact forces' acceleration $(F_{i-1} - F_i)/m_i$ (m/s^2), each (n, B)."""

    displacement_m: jax.Array
    velocity_m_s: jax.Array
    contact_accel_m_s2: jax.Array


def kernel_params(chain: DrivenChain) -> KernelParams:
    """The chain's constants as (rows, 1) columns."""
    return KernelParams(
        inv_mass_per_kg=(1.0 / chain.bead_mass_kg)[:, None],
        damping_rate_per_s=chain.damping_rate_per_s[:, None],
        kappa_n_m1p5=chain.contact_kappa_n_m1p5[:, None],
        static_overlap_m=chain.static_overlap_m()[:, None],
        eta_s=chain.eta_s,
    )


def contact_forces(p: KernelParams, x, v, drive_m, drive_m_s) -> jax.Array:
    """Total force of every contact (n + 1, B), N (compression positive), from the beads'
    displacements x and velocities v (n, B) and the driver's displacement and velocity (B,)."""
    zero = jnp.zeros_like(x[:1])
    front = jnp.concatenate([drive_m[None] + zero, x])
    back = jnp.concatenate([x, zero])
    overlap = p.static_overlap_m + front - back
    elastic = laws.Hertz().force(overlap, None, laws.ContactConstants(p.kappa_n_m1p5))
    if p.eta_s is None:
        return elastic
    rate = jnp.concatenate([drive_m_s[None] + zero, v]) - jnp.concatenate([v, zero])
    return laws.total_force(elastic, overlap, rate, p.kappa_n_m1p5, (laws.Viscoelastic(p.eta_s),))


def contact_accel(p: KernelParams, force_n) -> jax.Array:
    """Acceleration of every bead by its two contacts, (n, B), m/s^2."""
    return (force_n[:-1] - force_n[1:]) * p.inv_mass_per_kg


def static_state(p: KernelParams, runs: jax.Array) -> State:
    """B runs at rest in the static equilibrium, the driver at 0. `runs`: any (B,) per-run
    array (e.g. the frequencies): the state takes its length, and under `shard_map` its
    sharding (zeros built from it vary along the batch as the runs do)."""
    n = p.inv_mass_per_kg.shape[0]
    rest = 0.0 * jnp.asarray(runs, dtype=jnp.float64)
    zeros = jnp.zeros((n, 1), dtype=jnp.float64) + rest
    return State(zeros, zeros, contact_accel(p, contact_forces(p, zeros, zeros, rest, rest)))


def step(p: KernelParams, state: State, dt_s, drive_m, drive_m_s) -> State:
    """One velocity-Verlet step of every run (see the module docstring). `dt_s`: (B,) or
    scalar step, s; `drive_m`, `drive_m_s`: the driver's displacement and velocity at the
    end of the step, (B,), m and m/s."""
    h = 0.5 * dt_s
    x, v, f = state
    kick = h * (f - p.damping_rate_per_s * v)
    v_half = v + kick
    x = x + dt_s * v_half
    force = contact_forces(p, x, v_half + kick, drive_m, drive_m_s)
    f = contact_accel(p, force)
    v = (v_half + h * f) / (1.0 + h * p.damping_rate_per_s)
    return State(x, v, f)


DriveFn = Callable[[jax.Array], tuple[jax.Array, jax.Array]]
RecordFn = Callable[[State, jax.Array, jax.Array], jax.Array]


def advance(
    p: KernelParams,
    state: State,
    dt_s,
    drive: DriveFn,
    steps: jax.Array,
    *,
    record: RecordFn | None = None,
    unroll: int = DEFAULT_UNROLL,
):
    """Advance every run through the given step indices (a 1-D integer array, each the index
    of the step's end point that `drive` understands).

    **Arguments:** `drive(j) -> (u_m, u_m_s)`, the driver's displacement and velocity (B,)
    at the end of step j; `record(state, u_m, u_m_s) -> array` (or None) evaluated after
    every step.

    **Returns:** (final state, records stacked along a new leading axis, or None).
    """

    def body(state, j):
        u, u_dot = drive(j)
        state = step(p, state, dt_s, u, u_dot)
        return state, (None if record is None else record(state, u, u_dot))

    return jax.lax.scan(body, state, steps, unroll=max(1, min(int(unroll), int(steps.shape[0]) or 1)))


def advance_sampled(
    p: KernelParams,
    state: State,
    dt_s,
    drive: DriveFn,
    first_step: int,
    n_samples: int,
    every_steps: int,
    record: RecordFn,
    *,
    unroll: int = DEFAULT_UNROLL,
):
    """`advance` through steps `first_step` .. `first_step` + `n_samples` × `every_steps` - 1,
    recording after every `every_steps`-th step only. **Returns:** (final state, records
    stacked along a new leading axis of length `n_samples`)."""

    def sample(state, start):
        steps = start + jnp.arange(every_steps)
        state, _ = advance(p, state, dt_s, drive, steps, unroll=unroll)
        u, u_dot = drive(steps[-1])
        return state, record(state, u, u_dot)

    return jax.lax.scan(sample, state, first_step + every_steps * jnp.arange(n_samples))
