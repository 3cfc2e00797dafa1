"""The driven chains' kernel: `verlet.step` with the driver as a boundary, many runs at once.

The state of B runs is laid out as (n, B) arrays, the runs on the fast axis, so that every
operation of a step is one vector instruction over runs (as in `hertzchain.batched`). Runs
may differ in their time step (each run's own `dt_s`, a (B,) array), in the driver's
displacement and in nothing else: the chain's constants are shared, (n, 1) columns.

A step is `verlet.step` with $\\gamma$, the beads' viscous damping rate, as its drag: the
acceleration after the drift is $(F_{i-1} - F_i + S_i + F^{fr}_i)/m_i$, by the contact
forces at the new displacements (the driver at its new position, the contact damping at the
predicted velocity), the supports' static force and their friction, after the contact law's
history (the largest overlap so far) and the supports' friction sliders
(`laws.IwanSupport`) have followed the move. The contact forces are
the chain's laws (`DrivenChain.contact_law` and `.dissipation`, `hertzchain.laws`), their
sum clipped at zero, each law's parameters as (n + 1, 1) columns over the contacts.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .. import laws, verlet
from .chain import DrivenChain

# Steps of a `lax.scan` unrolled into one loop iteration (speed only).
DEFAULT_UNROLL = 8


class KernelParams(NamedTuple):
    """The chain's constants in the kernel's layout: columns that broadcast over runs."""

    inv_mass_per_kg: jax.Array  # (n, 1)
    damping_rate_per_s: jax.Array  # (n, 1)
    kappa_n_m1p5: jax.Array  # (n + 1, 1)
    static_overlap_m: jax.Array  # (n + 1, 1)
    eta_s: jax.Array | None  # () Kuwabara-Kono time where that is the only dissipation law (the fused kernel's)
    contact_law: laws.AbstractContactLaw  # parameters as (n + 1, 1) columns
    constants: laws.ContactConstants  # (n + 1, 1) columns
    dissipation: tuple[laws.AbstractDissipation, ...]  # parameters as (n + 1, 1) columns
    support_force_n: jax.Array | None  # (n, 1) the supports' static force; None: none (one preload)
    support_friction: laws.IwanSupport | None  # parameters as (n, 1) columns; None: none


class State(NamedTuple):
    """B runs' state at a step: displacements from the static equilibrium (m), velocities
    (m/s) and the acceleration by the contacts and supports $(F_{i-1} - F_i + S_i + F^{fr}_i)/m_i$
    (m/s^2), each (n, B); and the contact law's history, the largest overlap of every
    contact so far (n + 1, B), m (None for laws without one); the supports' friction sliders
    (E, n, B), m (`laws.IwanSupport`; None without)."""

    displacement_m: jax.Array
    velocity_m_s: jax.Array
    contact_accel_m_s2: jax.Array
    contact_history_m: jax.Array | None = None
    support_slider_m: jax.Array | None = None


def _columns(tree):
    """`tree` (a law, constants) with every (rows,) array leaf as a (rows, 1) column."""
    return jax.tree_util.tree_map(lambda leaf: leaf[:, None] if jnp.ndim(leaf) == 1 else leaf, tree)


def kernel_params(chain: DrivenChain) -> KernelParams:
    """The chain's constants as (rows, 1) columns."""
    viscous = [law for law in chain.dissipation if type(law) is laws.Viscoelastic]
    only_viscous = len(viscous) == len(chain.dissipation) == 1
    support = None if chain.precompression_n.ndim == 0 else chain.support_force_n()[:, None]
    return KernelParams(
        inv_mass_per_kg=(1.0 / chain.bead_mass_kg)[:, None],
        damping_rate_per_s=chain.damping_rate_per_s[:, None],
        kappa_n_m1p5=chain.contact_kappa_n_m1p5[:, None],
        static_overlap_m=chain.static_overlap_m()[:, None],
        eta_s=viscous[0].eta_s if only_viscous else None,
        contact_law=_columns(chain.contact_law),
        constants=_columns(chain.contact_constants()),
        dissipation=_columns(chain.dissipation),
        support_force_n=support,
        support_friction=None if chain.support_friction is None else _columns(chain.support_friction),
    )


def contact_overlaps(p: KernelParams, x, drive_m) -> jax.Array:
    """Overlap of every contact (n + 1, B), m, from the beads' displacements x (n, B) and
    the driver's displacement (B,)."""
    zero = jnp.zeros_like(x[:1])
    return p.static_overlap_m + jnp.concatenate([drive_m[None] + zero, x]) - jnp.concatenate([x, zero])


def contact_forces(p: KernelParams, x, v, drive_m, drive_m_s, history_m=None) -> jax.Array:
    """Total force of every contact (n + 1, B), N (compression positive), from the beads'
    displacements x and velocities v (n, B), the driver's displacement and velocity (B,)
    and the contact law's history (n + 1, B; None: the overlaps themselves, a first
    loading, and for laws without a history unused)."""
    overlap = contact_overlaps(p, x, drive_m)
    history = p.contact_law.initial_state(overlap) if history_m is None else history_m
    elastic = p.contact_law.force(overlap, history, p.constants)
    if not p.dissipation:
        return elastic
    zero = jnp.zeros_like(x[:1])
    rate = jnp.concatenate([drive_m_s[None] + zero, v]) - jnp.concatenate([v, zero])
    return laws.total_force(elastic, overlap, rate, p.kappa_n_m1p5, p.dissipation)


def contact_accel(p: KernelParams, force_n, x=None, slider_m=None) -> jax.Array:
    """Acceleration of every bead by its two contacts and its supports (their static force,
    and their friction at displacements x (n, B) with sliders `slider_m`), (n, B), m/s^2."""
    net = force_n[:-1] - force_n[1:]
    if p.support_force_n is not None:
        net = net + p.support_force_n
    if slider_m is not None:
        net = net + p.support_friction.force(x, slider_m)
    return net * p.inv_mass_per_kg


def static_state(p: KernelParams, runs: jax.Array) -> State:
    """B runs at rest in the static equilibrium, the driver at 0. `runs`: any (B,) per-run
    array (e.g. the frequencies): the state takes its length, and under `shard_map` its
    sharding (zeros built from it vary along the batch as the runs do)."""
    n = p.inv_mass_per_kg.shape[0]
    rest = 0.0 * jnp.asarray(runs, dtype=jnp.float64)
    zeros = jnp.zeros((n, 1), dtype=jnp.float64) + rest
    history = None
    if p.contact_law.has_history:
        history = p.contact_law.initial_state(contact_overlaps(p, zeros, rest))
    slider = None if p.support_friction is None else p.support_friction.initial_state(zeros)
    accel = contact_accel(p, contact_forces(p, zeros, zeros, rest, rest, history), zeros, slider)
    return State(zeros, zeros, accel, history, slider)


def step(p: KernelParams, state: State, dt_s, drive_m, drive_m_s) -> State:
    """One velocity-Verlet step of every run (`verlet.step`, with the beads' drag). `dt_s`:
    (B,) or scalar step, s; `drive_m`, `drive_m_s`: the driver's displacement and velocity
    at the end of the step, (B,), m and m/s."""

    def accel_at(x, v):
        history, slider = state.contact_history_m, state.support_slider_m
        if history is not None:
            history = p.contact_law.update_state(history, contact_overlaps(p, x, drive_m))
        if slider is not None:
            slider = p.support_friction.update_state(slider, x)
        force = contact_forces(p, x, v, drive_m, drive_m_s, history)
        return contact_accel(p, force, x, slider), (history, slider)

    s = verlet.step(state.displacement_m, state.velocity_m_s, state.contact_accel_m_s2, dt_s,
                    accel_at, drag_rate_per_s=p.damping_rate_per_s)
    return State(s.displacement_m, s.velocity_m_s, s.accel_m_s2, *s.forces)


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
