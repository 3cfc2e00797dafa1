"""A fast path for many chains at once: the batch on the SIMD axis, recorded forces only.

`solve` advances one chain (vmapped for batches) and records the full energy ledger at
every sample; that generality costs a loop iteration, a checkpoint and a dozen stores per
step. Sweeps need much less: a few force channels, the largest force of every contact and
the energy balance at the end. `solve_batched` integrates exactly the same equations with
the same velocity-Verlet step as `integrate.verlet_step` (same order of operations and the
same contact laws from `contact`, so the results agree to round-off), but

- the state is laid out as (rows, B), the batch on the fast axis, so every operation of
  a step is one vector instruction over chains; the wall is one more body (at rest), so
  that all contact forces, wall included, are one elementwise expression;
- the state (displacements, half-step velocities, running maxima) is one packed array,
  rebuilt by each step behind an `optimization_barrier`: XLA compiles a step into two
  fused loops, the new displacements with every contact force, then the velocities and
  maxima from those forces (it would otherwise make one loop per state variable and per
  shifted copy, fuse successive steps' concatenations into each other, or evaluate each
  contact force once for each of the two bodies it pushes), plus a small one for the
  recorded channels; see `benchmarks/README.md`;
- a `lax.scan` iteration advances a block of about `block_steps` steps, fully unrolled,
  and writes the chosen forces of all its samples straight into (B, n_samples) outputs;
- the batch can be split over several devices (`devices=`) with `jax.shard_map`, e.g. the
  two cores of a CPU run as two host devices
  (`XLA_FLAGS=--xla_force_host_platform_device_count=2`, set before JAX starts), or GPUs.

It covers everything `ChainSetup` describes: Hertz, power-law and elastic-plastic contacts
(Thornton's and Jackson-Green's laws, each contact's largest overlap carried in the state),
embedded sensors (split beads; and, in `record_batched` without the books, in compliance
form: `hertzchain.compliant_sensor`), rigid/elastic walls and free ends, preload,
Kuwabara-Kono damping, linear dashpots, any other dissipation law and track friction; the
laws are the setup's `hertzchain.laws` objects, the general solver's. On the CPU,
`solve_batched` runs the same step in a fused C++ kernel instead where one covers the
physics and has every law (`hertzchain.native`, `laws.registry`; Hertz contacts:
blocks of chains kept in cache through all their steps; agrees with this module's kernel to
round-off): the conservative kernel (with or without the books), or the full one for damped
and frictional chains without the books; `kernel="jax"` keeps this one. `record_batched`
(fits) runs the full C++ kernel with its forward-mode tangents (`native.run_full`).
Parameters that are the same in every chain are passed as one column (`share_uniform`).
`record_batched` is the same kernel for setups whose values are traced (inside `jit`,
`jax.jacfwd`): `fitting` runs its model and its Jacobian through it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from . import compliant_sensor, contact, forces, laws, native
from .batched_step import (
    _CONSTANTS,
    KernelFlags,
    _contact_forces,
    _energy,
    _final,
    _forces_at,
    _initial,
    _initial_peak,
    _Layout,
    _sensors_at_rest,
    _start,
    _step,
)
from .chain import (
    ChainSetup,
    build_model,
    end_loads,
    internal_contact_index,
    internal_sensor_index,
)
from .integrate import Recording, _channel_names, _layout, stack_setups  # noqa: F401
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
    - `kernel`: which kernel ran: "jax", or the fused one's physics and backend, e.g.
      "native full (host)".
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
    kernel: str = eqx.field(static=True, default="jax")


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


def build_model_contacts(setup: ChainSetup) -> range:
    """Indices of the model's internal contacts (Hertz contacts and sensor springs)."""
    return range(setup.n_beads + len(setup.sensor_beads))


def contact_law(setup: ChainSetup) -> str:
    """The name of a setup's contact law, `KernelFlags.law` (`laws.registry`)."""
    return laws.registry.native_name(setup.contact_law)


def kernel_flags(setup: ChainSetup, *, switched_on=()) -> KernelFlags:
    """The kernel a concrete (possibly batched) setup needs: damping (Kuwabara-Kono or a
    dashpot), friction and preload where any chain has them, or where named in `switched_on`
    ("viscous", "dashpot", "friction", "preload": e.g. parameters a fit frees from 0), the
    setup's contact law, and the law of the contacts' rate slot: the dashpot, else a
    `laws.VelocitySquared` that is the setup's one further dissipation law."""
    on = set(switched_on)
    unknown = on - {"viscous", "dashpot", "friction", "preload"}
    if unknown:
        raise ValueError(f"switched_on: unknown physics {sorted(unknown)}; use viscous, dashpot, friction, "
                         "preload.")
    friction = np.asarray(setup.mu) * np.asarray(setup.gravity_m_s2)
    dashpot = "dashpot" in on or bool(np.any(np.asarray(setup.dashpot_n_s_m) != 0.0))
    others = setup.dissipation[2:]  # laws beyond Kuwabara-Kono's and the dashpot: rates needed
    return KernelFlags(
        viscous=dashpot or bool(others) or "viscous" in on or bool(np.any(np.asarray(setup.eta_s) != 0.0)),
        springs=bool(setup.sensor_beads),
        preload="preload" in on or bool(np.any(np.asarray(setup.precompression_n) != 0.0)),
        friction="friction" in on or bool(np.any(friction != 0.0)),
        law=contact_law(setup),
        # the native kernels' rate slot holds one law: velocity-squared dissipation where the
        # dashpot leaves it free
        rate_law="dashpot" if dashpot else _rate_slot_law(others),
    )


class _Model(NamedTuple):
    mass_kg: jax.Array
    kappa: jax.Array
    spring_n_m: jax.Array
    overlap0_m: jax.Array
    wall_kappa: jax.Array
    wall_overlap0_m: jax.Array
    eta_s: jax.Array
    dashpot_n_s_m: jax.Array
    friction_decel_m_s2: jax.Array
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
        dashpot_n_s_m=setup.dashpot_n_s_m,
        **end_loads(setup),
    )


def _chain_params(setup: ChainSetup) -> dict:
    """Arrays the kernel needs for one chain (vmapped over the batch), in the kernel's
    layout: n_bodies + 1 rows for bodies (the last one is the wall, at rest, or nothing for
    a free end) and n_bodies rows for contacts (the last one is the wall contact, of zero
    stiffness for a free end); the arrays of the setup's contact law (its fields and, with a
    history, its constants, each under its own name: `_law`), Kuwabara-Kono's time and the
    dashpot, and the other dissipation laws ("dissipation", `_dissipation`)."""
    hertz = isinstance(setup.contact_law, laws.Hertz)
    model = build_model(setup) if setup.sensor_beads or not hertz else _vector_model(setup)
    external = jnp.zeros_like(model.mass_kg).at[1].add(model.first_bead_force_n)
    external = external.at[-1].add(model.last_body_force_n)
    law = {field.name: getattr(setup.contact_law, field.name) for field in dataclasses.fields(setup.contact_law)}
    if setup.contact_law.has_history:
        constants = forces.contact_constants(model)
        law |= {name: getattr(constants, name) for name in _CONSTANTS}
    others = {"dissipation": setup.dissipation[2:]} if len(setup.dissipation) > 2 else {}
    return law | others | {
        "dashpot": setup.dashpot_n_s_m,
        "mass": model.mass_kg,
        "inv_mass": jnp.concatenate([1.0 / model.mass_kg, jnp.zeros(1)]),
        "kappa": jnp.concatenate([model.kappa, model.wall_kappa[None]]),
        "spring": jnp.concatenate([model.spring_n_m, jnp.zeros(1)]),
        "overlap0": jnp.concatenate([model.overlap0_m, model.wall_overlap0_m[None]]),
        "eta": setup.eta_s,
        "friction": model.friction_decel_m_s2,
        "external": jnp.concatenate([external, jnp.zeros(1)]),
        "first_force": model.first_bead_force_n,
        "last_force": model.last_body_force_n,
        "v0": model.striker_velocity_m_s,
    }


# The kernel works on (rows, B) arrays, the batch on the fast axis. Bodies have n_bodies + 1
# rows: the last is the wall (displacement and velocity 0, inverse mass 0), so that the
# overlap of contact k, wall contact included, is x[k] - x[k + 1] + overlap0[k] for every
# k: one elementwise expression of row slices. Contact forces have n_bodies rows.


def _block_plan(grid: TimeGrid, block_steps: int) -> tuple[int, int, int]:
    """(samples per scan iteration, iterations, leftover samples) for unrolled blocks."""
    per_iteration = max(1, block_steps // grid.steps_per_sample)
    per_iteration = min(per_iteration, grid.n_samples)
    return per_iteration, grid.n_samples // per_iteration, grid.n_samples % per_iteration


def _kernel(p, *, flags: KernelFlags, grid: TimeGrid, rows: tuple[int, ...], block_steps: int):
    """Integrate chains laid out as (rows, B): the recorded forces, one (B, n_samples)
    array per channel (the chosen contacts, then the wall), N, and the final packed state."""
    layout = _Layout(p["mass"].shape[0])
    state, _, _ = _initial(p, flags, layout, grid.dt_s)
    steps = grid.steps_per_sample
    channels = rows + (layout.bodies - 1,)
    dt = grid.dt_s

    def sample(state):
        if steps <= block_steps:
            for _ in range(steps):
                state = _step(p, flags, layout, dt, state)
        else:
            def body(carry, _):
                return _step(p, flags, layout, dt, carry), None

            state = jax.lax.scan(body, state, None, length=steps, unroll=block_steps)[0]
        # The recorded channels alone, from the new state (with viscous damping, at the
        # step's final velocity, as `solve` records them).
        s = layout.unpack(flags, state)
        sensor = (s["sensor_force"], s["sensor_rate"]) if flags.sensors else None
        if flags.sensors:  # the sensors shorten contacts that need not be recorded
            force = _contact_forces(p, flags, s["x"], s.get("v"), None, s.get("peak"), sensor)[0]
            force = jnp.stack([force[k] for k in channels])
        else:
            force = _contact_forces(p, flags, s["x"], s.get("v"), channels, s.get("peak"))[0]
        return state, jax.lax.optimization_barrier(force)

    def iteration(count):
        # `count` samples, written straight into the (B, n_samples) outputs at `first`.
        def run(carry, first):
            state, traces = carry
            records = []
            for _ in range(count):
                state, record = sample(state)
                records.append(record)
            block = jax.lax.optimization_barrier(jnp.stack(records))  # (count, channels, B)
            traces = tuple(
                jax.lax.dynamic_update_slice(trace, block[:, i, :].T, (0, first)) for i, trace in enumerate(traces)
            )
            return (state, traces), None

        return run

    per_iteration, iterations, leftover = _block_plan(grid, block_steps)
    # (zeros derived from a batch array, so that under shard_map they vary along the batch)
    traces = tuple(jnp.zeros_like(p["v0"])[:, None] + jnp.zeros(grid.n_samples) for _ in channels)
    starts = per_iteration * jnp.arange(iterations)
    state, traces = jax.lax.scan(iteration(per_iteration), (state, traces), starts)[0]
    if leftover:
        starts = per_iteration * iterations + jnp.arange(leftover)
        state, traces = jax.lax.scan(iteration(1), (state, traces), starts)[0]
    return traces, state, layout


def _native_kernel(p, *, flags: KernelFlags, grid: TimeGrid, rows: tuple[int, ...], which: native.FusedKernel):
    """`_kernel`'s results from a fused kernel (`native`, on the backend `which` names): the
    conservative one (physics "conservative"; the packed state of `_Layout` in and out) or
    the full one ("full": damping and friction; with `flags.ledger` the packed state with
    the books in and out, on the host; without, forward-mode derivatives and no final state)."""
    layout = _Layout(p["mass"].shape[0])
    channels = rows + (layout.bodies - 1,)
    if which.physics == "full" and flags.ledger:
        state, _, _ = _initial(p, flags, layout, grid.dt_s)
        traces, state = native.run_full_books(
            p, state, dt_s=grid.dt_s, steps_per_sample=grid.steps_per_sample, n_samples=grid.n_samples,
            channels=channels, viscous=flags.viscous, friction=flags.friction, preload=flags.preload,
            springs=flags.springs, rate_law=flags.rate_law, law=flags.law,
        )
        return traces, state, layout
    if which.physics == "full":
        x, v, a, _, _ = _start(p, flags)
        sensor_state = None
        if flags.sensors:
            at_rest = _sensors_at_rest(p)
            sensor_state = jnp.concatenate([at_rest[name] for name in ("sensor_force", "sensor_rate", "sensor_drive")])
        traces = native.run_full(
            p, x, v, a, dt_s=grid.dt_s, steps_per_sample=grid.steps_per_sample, n_samples=grid.n_samples,
            channels=channels, viscous=flags.viscous, friction=flags.friction, preload=flags.preload,
            springs=flags.springs, rate_law=flags.rate_law, law=flags.law, backend=which.backend,
            sensors=flags.sensors, sensor_state=sensor_state,
        )
        return traces, None, layout
    state, _, _ = _initial(p, flags, layout, grid.dt_s)
    traces, state = native.run(
        p, state, dt_s=grid.dt_s, steps_per_sample=grid.steps_per_sample, n_samples=grid.n_samples,
        channels=channels, preload=flags.preload, springs=flags.springs, books=flags.ledger, backend=which.backend,
    )
    return traces, state, layout


def _run(params, flags, grid, rows, block_steps, devices, fused=None):
    """The kernel (the C++ one `fused` names, `native.kernel_for`), sharded over `devices`
    along the batch axis when there are several."""

    def local(p):
        if fused:
            traces, state, layout = _native_kernel(p, flags=flags, grid=grid, rows=rows, which=fused)
        else:
            traces, state, layout = _kernel(p, flags=flags, grid=grid, rows=rows, block_steps=block_steps)
        if not flags.ledger:
            nan = jnp.full_like(p["inv_mass"], jnp.nan) + jnp.zeros_like(p["v0"])
            return traces, nan[:-1], jnp.stack([nan[0]] * 4)
        _, x0, v0 = _initial(p, flags, layout, grid.dt_s)
        kinetic0, potential0, _ = _energy(p, flags, x0, v0, _initial_peak(p, flags, x0))
        x, v, dissipated = _final(p, flags, layout, grid.dt_s, state)
        s = layout.unpack(flags, state)
        kinetic, potential, plastic = _energy(p, flags, x, v, s.get("peak"))
        summary = jnp.stack([kinetic0 + potential0, kinetic, potential, dissipated + plastic])
        maxima = s["max"]
        if not flags.full_state:  # largest overlaps: the largest elastic forces are there
            maxima = _forces_at(p, flags, maxima, None, peak=maxima)[0]
        return traces, maxima, summary

    if devices is None or len(devices) == 1:
        return local(params)
    mesh = Mesh(np.asarray(devices), ("batch",))
    batch = params["v0"].shape[-1]

    def spec(leaf):  # parameters shared by every chain (a last axis of 1) go to every device
        shared = leaf.shape[-1] == 1 and batch > 1
        return PartitionSpec(*([None] * (leaf.ndim - 1)), None if shared else "batch")

    in_specs = (jax.tree_util.tree_map(spec, params),)
    out_specs = (
        tuple(PartitionSpec("batch", None) for _ in range(len(rows) + 1)),
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


def kernel_rows(setup: ChainSetup) -> int:
    """The rows of a setup's kernel arrays (`kernel_params`' "inv_mass"), bodies + 1: the
    striker, the beads (a compliant sensor bead as its two halves) and the end's row; known
    from the setup's shape alone, before any array is made."""
    return setup.n_beads + len(setup.sensor_beads) + 2


def share_uniform(params: dict) -> dict:
    """Kernel arrays with every parameter that is the same in all chains reduced to one
    column (…, 1): the kernel broadcasts it, so a sweep over striker speeds and walls reads
    one copy of the bead masses per step instead of one per chain (about 10 % of the
    step's time; `benchmarks/README.md`). Same numbers, same results. The striker speeds
    stay per chain (they carry the batch size). Concrete arrays only."""
    if params["v0"].shape[-1] == 1:
        return params
    names = sorted(params)
    names = [name for name in names if isinstance(params[name], jax.Array)]  # (other laws stay per chain)
    uniform = np.asarray(_uniform_columns([params[name] for name in names]))  # one transfer
    shared = {name for name, same in zip(names, uniform) if same and name != "v0"}
    return {name: leaf[..., :1] if name in shared else leaf for name, leaf in params.items()}


@jax.jit
def _uniform_columns(leaves: list) -> jax.Array:
    """Whether each kernel array has the same value in every chain (last axis), (n,) bool."""
    return jnp.stack([jnp.all(leaf == leaf[..., :1]) for leaf in leaves])


def _assemble(params, batch, flags, grid, rows, names, user, block_steps, devices, fused=None):
    """The kernel and the output layout."""
    traces, maxima, summary = _run(params, flags, grid, rows, block_steps, devices, fused)
    maxima, summary = maxima[..., :batch], summary[..., :batch]
    initial, kinetic, potential, dissipated = summary
    return BatchedTraces(
        time_s=grid.sample_interval_s * jnp.arange(1, grid.n_samples + 1, dtype=jnp.float64),
        forces_n={name: trace[:batch] for name, trace in zip(names, traces)},
        max_force_n=maxima[np.asarray(user)].T,
        initial_energy_j=initial,
        kinetic_j=kinetic,
        potential_j=potential,
        dissipated_j=dissipated,
        energy_error_j=initial - kinetic - potential - dissipated,
        channel_names=names,
        kernel="jax" if fused is None else f"native {fused.physics} ({fused.backend})",
    )


# The kernel and the output layout in one compiled call. The parameters are computed apart,
# on one device, so that sharded and unsharded runs see the very same numbers.
_solve_fast = eqx.filter_jit(_assemble)


def _plan(setup: ChainSetup, recording: Recording):
    """(channel names, kernel rows of the recorded channels, kernel rows of every contact
    and the wall for the maxima) of a setup: its structure only, never its values."""
    if recording.record_all:
        raise ValueError("record_all is not available in solve_batched; use solve (or simulate).")
    _layout(setup, recording)
    names = _channel_names(setup, recording)
    rows = tuple(internal_contact_index(setup, k) for k in recording.contacts) + tuple(
        internal_sensor_index(setup, b) for b in setup.sensor_beads
    )
    n_internal = len(build_model_contacts(setup))
    user = tuple(internal_contact_index(setup, k) for k in range(setup.n_beads)) + (n_internal,)
    return names, rows, user


def solve_batched(
    setup: ChainSetup,
    grid: TimeGrid,
    recording: Recording = Recording(),
    *,
    block_steps: int = DEFAULT_BLOCK_STEPS,
    devices=None,
    pad_to: int | None = None,
    books: bool = True,
    kernel: str = "auto",
) -> BatchedTraces:
    """Simulate a batch of chains, recording forces and the final energy balance.

    **Arguments:**

    - `setup`: a batched `ChainSetup` (every field with a leading axis of length B, e.g. from
      `hertzchain.batch_setup` or `stack_setups`), concrete (not traced; see `record_batched`).
    - `grid`: the time grid (`choose_time_grid(setup, ...)`: the most demanding chain sets the step).
    - `recording`: contacts to record (`record_all` is not supported here: use `solve`).
    - `block_steps`: steps advanced per loop iteration, unrolled (speed only).
    - `devices`: split the batch over these devices (default: one device).
    - `pad_to`: run at least this many chains (copies of the last one, dropped from the
      result), so that batches of different sizes reuse one compiled kernel.
    - `books`: keep the largest force of every contact over every step and the energy
      balance (default). False: the recorded forces only, for callers that read nothing
      else (the maxima and energies of the result are then NaN); one pass over the
      contacts per step less (`benchmarks/README.md`).
    - `kernel`: "auto" (default) runs a fused C++ kernel (`hertzchain.native`) where one
      covers the setup (on the CPU: Hertz contacts, conservative, damped or frictional,
      with or without `books`) and is built, else the JAX kernel; "jax" always runs the JAX kernel
      (the reference; they agree to round-off).

    **Returns:** `BatchedTraces`.
    """
    if kernel not in ("auto", "jax"):
        raise ValueError(f'kernel must be "auto" or "jax", got {kernel!r}.')
    batch = batch_size(setup)
    names, rows, user = _plan(setup, recording)
    flags = kernel_flags(setup)._replace(ledger=bool(books))
    devices = None if devices is None or len(devices) <= 1 else tuple(devices)
    padded = max(batch, pad_to or 0)
    if devices is not None:
        padded = len(devices) * math.ceil(padded / len(devices))
    params = share_uniform(kernel_params(setup, pad_to=padded))
    native_ok = kernel == "auto" and _native_laws(setup, flags)
    fused = native.kernel_for(flags, devices, params["inv_mass"].shape[-2]) if native_ok else None
    if fused is not None and fused.physics == "full":
        flags = flags._replace(full_step=True)
    return _solve_fast(params, batch, flags, grid, rows, names, user, int(block_steps), devices, fused)


def record_batched(
    setup: ChainSetup,
    grid: TimeGrid,
    recording: Recording,
    flags: KernelFlags,
    *,
    block_steps: int = DEFAULT_BLOCK_STEPS,
    kernel: str = "auto",
    compliant_sensors: compliant_sensor.CompliantSensors | None = None,
) -> BatchedTraces:
    """`solve_batched`'s fast kernel for a batched setup whose values may be traced
    (inside `jit`, `vmap`, `jax.jacfwd`), on one device.

    **Arguments:**

    - `setup`: a batched `ChainSetup` (leading axis B on every field).
    - `grid`, `recording`, `block_steps`: as for `solve_batched`.
    - `flags`: the physics compiled in, `kernel_flags(concrete_setup, switched_on=...)`:
      it must include every effect that is non-zero in any chain at any value the caller
      will pass (damping, dashpots, friction and preload that are off in `flags` are not
      simulated), and the setup's contact law.
    - `kernel`: "auto" (default): with `flags.ledger` off, on the CPU, the fused C++ kernel
      with its forward-mode tangents (`native.run_full`: `jax.jvp`, `jax.jacfwd`,
      `jax.linearize` and `jax.vmap` work; a jacfwd's directions, the forces and a vmapped
      batch of setups in one kernel run; reverse mode is not available there); "jax": the
      JAX kernel (every transformation).
    - `compliant_sensors`: embedded sensors in compliance form, as `solve` takes them, with
      `beta` and `inv_omega0_sq_s2` of shape (B,) or (B, n_sensors); their beads must be
      `flags.sensors` (without the books; on the CPU the C++ kernel's sensor libraries run
      them, `native.run_full(..., sensors=)`, elsewhere the JAX kernel).

    **Returns:** `BatchedTraces`; with `flags.ledger` off, its maxima and energies are NaN
    (not computed). The two kernels agree to round-off, values and derivatives.
    """
    if kernel not in ("auto", "jax"):
        raise ValueError(f'kernel must be "auto" or "jax", got {kernel!r}.')
    if flags.law != contact_law(setup):
        raise ValueError(f"record_batched: flags.law is {flags.law!r} but the setup's contacts follow "
                         f"{contact_law(setup)!r}; pass kernel_flags(setup, ...).")
    names, rows, user = _plan(setup, recording)
    batch = batch_size(setup)
    params = _params(setup, None)
    if flags.sensors or compliant_sensors is not None:
        params = _with_compliant_sensors(params, setup, flags, compliant_sensors)
    native_ok = kernel == "auto" and not flags.ledger and _native_laws(setup, flags)
    fused = native.kernel_for(flags, None, params["inv_mass"].shape[-2]) if native_ok else None
    if fused is not None:  # the full kernel carries the tangents, whatever the physics
        fused = fused._replace(physics="full")
    return _assemble(params, batch, flags, grid, rows, names, user, int(block_steps), None, fused)


def _rate_slot_law(others) -> str | None:
    """The native name of a setup's one dissipation law beyond Kuwabara-Kono's and the
    dashpot (`others`) where the native kernels' rate slot carries it (a
    `native.RATE_LAW_DEFINES` key: `laws.VelocitySquared`), else None."""
    name = laws.registry.native_name(others[0]) if len(others) == 1 else None
    return name if name in native.RATE_LAW_DEFINES else None


def _native_laws(setup: ChainSetup, flags: KernelFlags) -> bool:
    """Whether the native kernels have every law of the setup (`laws.registry`) and `flags`
    puts its dissipation beyond Kuwabara-Kono's and the dashpot into their rate slot (which
    holds one law: a chain with a dashpot and velocity-squared dissipation, or with two
    further laws, is not native); where not, the JAX kernel runs (`BatchedTraces.kernel`
    says so)."""
    others = setup.dissipation[2:]
    carried = not others or (flags.rate_law is not None and flags.rate_law == _rate_slot_law(others))
    return carried and laws.registry.runs_natively(setup.contact_law, setup.dissipation)


def _with_compliant_sensors(params: dict, setup: ChainSetup, flags: KernelFlags, sensors) -> dict:
    """The kernel arrays with the compliant sensors' mass fractions, 1/omega0^2 (s^2) and
    back and front compliances (m/N; `compliant_sensor.compliances`), (n_sensors, B) each,
    checked against `flags`."""
    beads = () if sensors is None else compliant_sensor.checked_beads(sensors.beads, setup.n_beads)
    if beads != tuple(flags.sensors):
        raise ValueError(f"compliant_sensors: beads {beads} but flags.sensors is {tuple(flags.sensors)}; pass "
                         "kernel_flags(...)._replace(sensors=<the sensors' beads>).")
    if flags.ledger:
        raise ValueError("compliant_sensors: the kernel keeps no books with compliant sensors; pass flags with "
                         "ledger=False (the recorded forces only) or use solve.")
    if setup.sensor_beads:
        raise ValueError(f"compliant_sensors: the setup already splits sensor beads {setup.sensor_beads}; use one "
                         "sensor model (sensor_beads=() here).")
    shape = (batch_size(setup), len(beads))

    def per_sensor(value):  # (), (B,) or (B, n_sensors) -> (n_sensors, B)
        value = jnp.asarray(value, dtype=jnp.float64)
        return jnp.broadcast_to(value[:, None] if value.ndim == 1 else value, shape).T

    beta, inv = per_sensor(sensors.beta), per_sensor(sensors.inv_omega0_sq_s2)
    back, front, _ = compliant_sensor.compliances(params["mass"][np.asarray(beads, dtype=int)], beta, inv)
    return params | {"sensor_beta": beta, "sensor_inv": inv, "sensor_back": back, "sensor_front": front}
