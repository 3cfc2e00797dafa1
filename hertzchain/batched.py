"""A fast path for many chains at once: the batch on the SIMD axis, recorded forces only.

`solve` advances one chain (vmapped for batches) and records the full energy ledger at
every sample; that generality costs a loop iteration, a checkpoint and a dozen stores per
step. Sweeps need much less: a few force channels, the largest force of every contact and
the energy balance at the end. `solve_batched` integrates exactly the same equations with
the same velocity-Verlet step as `integrate.verlet_step` (same order of operations, so the
results agree to round-off), but

- the state is laid out as (n_bodies, B), the batch on the fast axis, so every operation of
  a step is one vector instruction over chains;
- a `lax.scan` iteration advances a block of about `block_steps` steps, fully unrolled,
  and records the chosen forces of all its samples at once;
- the batch can be split over several devices (`devices=`) with `jax.shard_map`, e.g. the
  two cores of a CPU run as two host devices
  (`XLA_FLAGS=--xla_force_host_platform_device_count=2`, set before JAX starts), or GPUs.

It covers Hertz contacts, embedded sensors, rigid/elastic walls and free ends, preload and
viscoelastic damping. Track friction and elastic-plastic contacts are not in the fast path:
`solve_batched` then runs the general solver (`solve` under `vmap`), with the same result
type. `fast_path_reason(setup)` says which path a setup takes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from . import contact
from .chain import ChainSetup, build_model, internal_contact_index, internal_sensor_index
from .integrate import Recording, _channel_names, _layout, solve
from .timegrid import TimeGrid

# Steps advanced per scan iteration (fully unrolled): enough to hide the loop overhead,
# small enough to compile in well under a second.
DEFAULT_BLOCK_STEPS = 20


class BatchedTraces(eqx.Module):
    """What `solve_batched` records for B chains.

    **Fields:**

    - `time_s`: (n_samples,) sample times after the impact, s.
    - `forces_n`: channel name -> (B, n_samples) force, N (same channels and names as `Traces`).
    - `channel_names`: the channels in file order.
    - `max_force_n`: (B, N + 1) largest force over every step at contacts 0..N-1 and at the
      wall (last), N.
    - `initial_energy_j`: (B,) energy at the impact (striker's kinetic plus preload), J.
    - `kinetic_j`, `potential_j`: (B,) kinetic and potential (elastic plus preload) energy
      at the end of the run, J.
    - `dissipated_j`: (B,) energy dissipated since the impact, J.
    - `energy_error_j`: (B,) initial energy minus final energy minus dissipated energy: the
      integrator's own error, J.
    """

    time_s: jax.Array
    forces_n: dict[str, jax.Array]
    max_force_n: jax.Array
    initial_energy_j: jax.Array
    kinetic_j: jax.Array
    potential_j: jax.Array
    dissipated_j: jax.Array
    energy_error_j: jax.Array
    channel_names: tuple[str, ...] = eqx.field(static=True, default=())


class _Flags(NamedTuple):
    viscous: bool
    springs: bool
    preload: bool
    wall: bool


def batch_size(setup: ChainSetup) -> int:
    """Number of chains in a batched setup (every leaf has the same leading axis)."""
    sizes = {leaf.shape[0] for leaf in jax.tree_util.tree_leaves(setup) if jnp.ndim(leaf) > 0}
    scalar = [leaf for leaf in jax.tree_util.tree_leaves(setup) if jnp.ndim(leaf) == 0]
    if scalar or len(sizes) != 1:
        raise ValueError(
            "setup must be batched along a leading axis on every field (use "
            "hertzchain.batch_setup(setup, striker_velocity_m_s=[...], ...) or stack_setups)."
        )
    return sizes.pop()


def stack_setups(setups) -> ChainSetup:
    """Stack setups of the same structure (same N, end, sensors) into one batched setup."""
    setups = list(setups)
    if not setups:
        raise ValueError("stack_setups needs at least one setup.")
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *setups)


def build_model_contacts(setup: ChainSetup) -> range:
    """Indices of the model's internal contacts (Hertz contacts and sensor springs)."""
    return range(setup.n_beads + len(setup.sensor_beads))


def fast_path_reason(setup: ChainSetup) -> str | None:
    """None if `solve_batched` can use the fast path for `setup`, else why not."""
    if setup.plasticity:
        return "elastic-plastic contacts (plasticity=True)"
    friction = np.asarray(setup.mu) * np.asarray(setup.gravity_m_s2)
    if np.any(friction != 0.0):
        return "track friction (mu > 0)"
    return None


def _flags(setup: ChainSetup) -> _Flags:
    return _Flags(
        viscous=bool(np.any(np.asarray(setup.eta_s) != 0.0)),
        springs=bool(setup.sensor_beads),
        preload=bool(np.any(np.asarray(setup.precompression_n) != 0.0)),
        wall=setup.end == "wall",
    )


class _Model(NamedTuple):
    mass_kg: jax.Array
    kappa: jax.Array
    spring_n_m: jax.Array
    overlap0_m: jax.Array
    wall_kappa: jax.Array
    wall_overlap0_m: jax.Array
    eta_s: jax.Array
    first_bead_force_n: jax.Array
    last_body_force_n: jax.Array
    striker_velocity_m_s: jax.Array


def _vector_model(setup: ChainSetup) -> _Model:
    """`build_model`'s quantities for a chain without sensors, in whole-array operations.

    `build_model` assembles the bodies bead by bead (it has to, for sensor beads), which
    makes a graph of O(N) operations: slow to compile for N in the thousands. Without
    sensors the same numbers come from a few array operations.
    """
    kappa = setup.contact_kappa()
    preload = setup.precompression_n
    overlap0 = contact.overlap_at_force(preload, kappa).at[0].set(0.0)
    has_wall = setup.end == "wall"
    wall_kappa = setup.wall_kappa() if has_wall else jnp.zeros(())
    return _Model(
        mass_kg=jnp.concatenate([setup.striker_mass_kg[None], setup.bead_mass_kg]),
        kappa=kappa,
        spring_n_m=jnp.zeros_like(kappa),
        overlap0_m=overlap0,
        wall_kappa=wall_kappa,
        wall_overlap0_m=contact.overlap_at_force(preload, setup.wall_kappa()) if has_wall else jnp.zeros(()),
        eta_s=setup.eta_s,
        first_bead_force_n=preload,
        last_body_force_n=jnp.zeros(()) if has_wall else -preload,
        striker_velocity_m_s=setup.striker_velocity_m_s,
    )


def _chain_params(setup: ChainSetup) -> dict:
    """Arrays the kernel needs for one chain (vmapped over the batch)."""
    model = build_model(setup) if setup.sensor_beads else _vector_model(setup)
    return {
        "mass": model.mass_kg,
        "inv_mass": 1.0 / model.mass_kg,
        "kappa": model.kappa,
        "damping": 1.5 * model.eta_s * model.kappa,
        "spring": model.spring_n_m,
        "overlap0": model.overlap0_m,
        "wall_kappa": model.wall_kappa,
        "wall_damping": 1.5 * model.eta_s * model.wall_kappa,
        "wall_overlap0": model.wall_overlap0_m,
        "first_force": model.first_bead_force_n,
        "last_force": model.last_body_force_n,
        "v0": model.striker_velocity_m_s,
    }


def _forces(p, flags: _Flags, x, v):
    """Contact forces (n_contacts, B), wall force (B,), body forces (n_bodies, B), and
    their viscous parts, with the same formulas as `forces.chain_forces`."""
    overlap = x[:-1] - x[1:] + p["overlap0"]
    positive = jnp.maximum(overlap, 0.0)
    root = jnp.sqrt(positive)
    elastic = p["kappa"] * positive * root
    if flags.viscous:
        rate = v[:-1] - v[1:]
        total = jnp.maximum(elastic + p["damping"] * root * rate, 0.0)
    else:
        total = elastic
    if flags.springs:
        total = total + p["spring"] * overlap
        elastic = elastic + p["spring"] * overlap
    if flags.wall:
        wall_overlap = x[-1] + p["wall_overlap0"]
        wall_positive = jnp.maximum(wall_overlap, 0.0)
        wall_root = jnp.sqrt(wall_positive)
        wall_elastic = p["wall_kappa"] * wall_positive * wall_root
        if flags.viscous:
            wall = jnp.maximum(wall_elastic + p["wall_damping"] * wall_root * v[-1], 0.0)
        else:
            wall = wall_elastic
    else:
        wall = wall_elastic = jnp.zeros_like(x[-1])
    zero = jnp.zeros_like(x[:1])
    body = jnp.concatenate([zero, total]) - jnp.concatenate([total, wall[None]])
    if flags.preload:
        body = body.at[1].add(p["first_force"]).at[-1].add(p["last_force"])
    if flags.viscous:
        viscous_c, viscous_w = total - elastic, wall - wall_elastic
        viscous = jnp.concatenate([zero, viscous_c]) - jnp.concatenate([viscous_c, viscous_w[None]])
    else:
        viscous = None
    return total, wall, body, viscous


def _energy(p, flags: _Flags, x, v):
    """Kinetic and potential (elastic plus preload) energy, J, each (B,)."""
    kinetic = 0.5 * jnp.sum(p["mass"] * v**2, axis=0)
    overlap = x[:-1] - x[1:] + p["overlap0"]
    positive = jnp.maximum(overlap, 0.0)
    potential = jnp.sum(0.4 * p["kappa"] * positive**2 * jnp.sqrt(positive), axis=0)
    if flags.springs:
        potential = potential + jnp.sum(0.5 * p["spring"] * overlap**2, axis=0)
    if flags.wall:
        wall_positive = jnp.maximum(x[-1] + p["wall_overlap0"], 0.0)
        potential = potential + 0.4 * p["wall_kappa"] * wall_positive**2 * jnp.sqrt(wall_positive)
    if flags.preload:
        potential = potential - (p["first_force"] * x[1] + p["last_force"] * x[-1])
    return kinetic, potential


class _State(NamedTuple):
    x: jax.Array
    v: jax.Array
    a: jax.Array
    viscous_force: jax.Array | None
    max_contact: jax.Array
    max_wall: jax.Array
    dissipated: jax.Array


def _step(p, flags: _Flags, dt: float, s: _State) -> tuple[_State, jax.Array, jax.Array]:
    """One velocity-Verlet step (the order of `integrate.verlet_step`)."""
    h = 0.5 * dt
    v_half = s.v + h * s.a
    x = s.x + dt * v_half
    total, wall, body, viscous = _forces(p, flags, x, v_half + h * s.a)
    a = body * p["inv_mass"]
    v = v_half + h * a
    dissipated = s.dissipated
    if flags.viscous:
        work = jnp.sum(s.viscous_force * h * 0.5 * (s.v + v_half), axis=0)
        work = work + jnp.sum(viscous * h * 0.5 * (v_half + v), axis=0)
        dissipated = dissipated - work
    state = _State(
        x, v, a, viscous, jnp.maximum(s.max_contact, total), jnp.maximum(s.max_wall, wall), dissipated
    )
    return state, total, wall


def _block_plan(grid: TimeGrid, block_steps: int) -> tuple[int, int, int]:
    """(samples per scan iteration, iterations, leftover samples) for unrolled blocks."""
    per_iteration = max(1, block_steps // grid.steps_per_sample)
    per_iteration = min(per_iteration, grid.n_samples)
    return per_iteration, grid.n_samples // per_iteration, grid.n_samples % per_iteration


def _kernel(p, *, flags: _Flags, grid: TimeGrid, rows: tuple[int, ...], block_steps: int):
    """Integrate chains laid out as (n_bodies, B): recorded rows (n_samples, n_rows + 1, B),
    and the final state."""
    x = jnp.zeros_like(p["mass"])
    v = x.at[0].set(p["v0"])
    total, wall, body, viscous = _forces(p, flags, x, v)
    state = _State(x, v, body * p["inv_mass"], viscous, total, wall, jnp.zeros_like(x[0]))
    steps = grid.steps_per_sample
    unrolled = steps <= block_steps

    def sample(state):
        if unrolled:
            for _ in range(steps):
                state, total, wall = _step(p, flags, grid.dt_s, state)
        else:
            def body(carry, _):
                return _step(p, flags, grid.dt_s, carry)[0], None

            state = jax.lax.scan(body, state, None, length=steps - 1, unroll=block_steps)[0]
            state, total, wall = _step(p, flags, grid.dt_s, state)
        if flags.viscous:
            # Samples record the forces at the step's final velocity, as `solve` does.
            total, wall, _, _ = _forces(p, flags, state.x, state.v)
        return state, jnp.stack([total[r] for r in rows] + [wall])

    def iteration(count):
        def run(state, _):
            records = []
            for _ in range(count):
                state, record = sample(state)
                records.append(record)
            return state, jnp.stack(records)

        return run

    per_iteration, iterations, leftover = _block_plan(grid, block_steps)
    state, records = jax.lax.scan(iteration(per_iteration), state, None, length=iterations)
    records = records.reshape((-1,) + records.shape[2:])
    if leftover:
        state, tail = jax.lax.scan(iteration(1), state, None, length=leftover)
        records = jnp.concatenate([records, tail.reshape((-1,) + tail.shape[2:])])
    return records, state


def _run(params, flags, grid, rows, block_steps, devices):
    """The kernel, sharded over `devices` along the batch (last) axis when there are several."""

    def local(p):
        records, state = _kernel(p, flags=flags, grid=grid, rows=rows, block_steps=block_steps)
        x0 = jnp.zeros_like(p["mass"])
        v0 = x0.at[0].set(p["v0"])
        initial = sum(_energy(p, flags, x0, v0))
        kinetic, potential = _energy(p, flags, state.x, state.v)
        summary = jnp.stack([initial, kinetic, potential, state.dissipated])
        maxima = jnp.concatenate([state.max_contact, state.max_wall[None]])
        return records, maxima, summary

    if devices is None or len(devices) == 1:
        return local(params)
    mesh = Mesh(np.asarray(devices), ("batch",))
    spec = lambda leaf: PartitionSpec(*([None] * (leaf.ndim - 1)), "batch")  # noqa: E731
    in_specs = (jax.tree_util.tree_map(spec, params),)
    out_specs = (
        PartitionSpec(None, None, "batch"),
        PartitionSpec(None, "batch"),
        PartitionSpec(None, "batch"),
    )
    return jax.shard_map(local, mesh=mesh, in_specs=in_specs, out_specs=out_specs)(params)


def _params(setup: ChainSetup, pad_to: int | None):
    batch = batch_size(setup)
    if pad_to is not None and pad_to > batch:
        setup = jax.tree_util.tree_map(
            lambda leaf: jnp.concatenate(
                [leaf, jnp.repeat(leaf[-1:], pad_to - batch, axis=0)], axis=0
            ),
            setup,
        )
    params = jax.vmap(_chain_params)(setup)
    return jax.tree_util.tree_map(lambda leaf: jnp.moveaxis(leaf, 0, -1), params)


def kernel_params(setup: ChainSetup, pad_to: int | None = None) -> dict:
    """Kernel arrays of a batched setup in (…, B) layout, padded to `pad_to` chains by
    repeating the last chain (sharding needs a batch divisible by the device count)."""
    return _params_jit(setup, pad_to)


_params_jit = eqx.filter_jit(_params)


@eqx.filter_jit
def _solve_fast(params, batch, flags, grid, rows, names, user, block_steps, devices):
    """The kernel and the output layout in one compiled call. The parameters are computed
    apart, on one device, so that sharded and unsharded runs see the very same numbers."""
    records, maxima, summary = _run(params, flags, grid, rows, block_steps, devices)
    records, maxima, summary = records[..., :batch], maxima[..., :batch], summary[..., :batch]
    initial, kinetic, potential, dissipated = summary
    return BatchedTraces(
        time_s=grid.sample_interval_s * jnp.arange(1, grid.n_samples + 1, dtype=jnp.float64),
        forces_n={name: records[:, i, :].T for i, name in enumerate(names)},
        max_force_n=maxima[np.asarray(user)].T,
        initial_energy_j=initial,
        kinetic_j=kinetic,
        potential_j=potential,
        dissipated_j=dissipated,
        energy_error_j=initial - kinetic - potential - dissipated,
        channel_names=names,
    )


def solve_batched(
    setup: ChainSetup,
    grid: TimeGrid,
    recording: Recording = Recording(),
    *,
    block_steps: int = DEFAULT_BLOCK_STEPS,
    devices=None,
    pad_to: int | None = None,
) -> BatchedTraces:
    """Simulate a batch of chains, recording forces and the final energy balance.

    **Arguments:**

    - `setup`: a batched `ChainSetup` (every field with a leading axis of length B, e.g. from
      `hertzchain.batch_setup` or `stack_setups`), concrete (not traced).
    - `grid`: the time grid (`choose_time_grid(setup, ...)`: the most demanding chain sets the step).
    - `recording`: contacts to record (`record_all` is not supported here: use `solve`).
    - `block_steps`: steps advanced per loop iteration, unrolled (speed only).
    - `devices`: split the batch over these devices (default: one device).
    - `pad_to`: run at least this many chains (copies of the last one, dropped from the
      result), so that batches of different sizes reuse one compiled kernel.

    **Returns:** `BatchedTraces`. Setups with track friction or plastic contacts run the
    general solver (same result, slower): see `fast_path_reason`.
    """
    if recording.record_all:
        raise ValueError("record_all is not available in solve_batched; use solve (or simulate).")
    batch = batch_size(setup)
    _layout(setup, recording)
    names = _channel_names(setup, recording)
    if fast_path_reason(setup) is not None:
        time = grid.sample_interval_s * jnp.arange(1, grid.n_samples + 1, dtype=jnp.float64)
        return _solve_general(setup, grid, recording, names, time)
    flags = _flags(setup)
    rows = tuple(internal_contact_index(setup, k) for k in recording.contacts) + tuple(
        internal_sensor_index(setup, b) for b in setup.sensor_beads
    )
    devices = None if devices is None or len(devices) <= 1 else tuple(devices)
    padded = max(batch, pad_to or 0)
    if devices is not None:
        padded = len(devices) * math.ceil(padded / len(devices))
    n_internal = len(build_model_contacts(setup))
    user = tuple(internal_contact_index(setup, k) for k in range(setup.n_beads)) + (n_internal,)
    params = kernel_params(setup, pad_to=padded)
    return _solve_fast(params, batch, flags, grid, rows, names, user, int(block_steps), devices)


@eqx.filter_jit
def _vmapped_solve(setup, grid, recording):
    return jax.vmap(lambda s: solve(s, grid, recording))(setup)


def _solve_general(setup, grid, recording, names, time) -> BatchedTraces:
    traces = _vmapped_solve(setup, grid, recording)
    return BatchedTraces(
        time_s=time,
        forces_n={name: traces.forces_n[name] for name in names},
        max_force_n=traces.max_force_n,
        initial_energy_j=traces.initial_energy_j,
        kinetic_j=traces.kinetic_j[:, -1],
        potential_j=traces.potential_j[:, -1],
        dissipated_j=traces.dissipated_j[:, -1],
        energy_error_j=traces.energy_error_j[:, -1],
        channel_names=names,
    )
