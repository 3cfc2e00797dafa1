"""The velocity-Verlet chain solver: a jitted, differentiable `lax.scan` in float64.

One step of length dt, with h = dt/2 and a(u, v) = F(u, v)/m from `forces.chain_forces`:

1. half kick  v' = v + h a_n, then the Coulomb track friction as a clamped kick;
2. drift      u_{n+1} = u_n + dt v';
3. forces at u_{n+1}, with the velocity predicted as v' + h a_n for the viscous term;
4. half kick  v_{n+1} = v' + h a_{n+1}, then the clamped friction kick.

Without dissipation this is the symplectic velocity Verlet (second order). The viscous
force depends on velocity; the predictor keeps the scheme second order (checked by the
convergence test). Track friction is Coulomb's law in its exact limit, applied as a
clamped kick after each half kick: $w \\leftarrow \\mathrm{sign}(w)\\max(|w| - \\mu g h, 0)$.
A bead whose kick is smaller than the friction impulse stays at rest (stick), otherwise it
slides against a force $\\mu m g$. This is differentiable everywhere except on the
measure-zero set where a bead stops exactly at a step boundary; we do not smooth it, because
a `tanh(v/v_reg)` regularisation lets resting beads creep at ~v_reg and biases fitted mu by
+1.5 % at v_reg = 1e-5 m/s.

The energy ledger is exact per step: the kinetic energy change of each kick is split into
the work of the conservative forces, of the viscous forces ($\\sum_i f^v_i h (v_i +
v_i')/2$) and of the friction clamp ($\\Delta K$ of the clamp), so `energy_error_j` holds
only the integrator's own (dt^2) error. Momentum balances to round-off against the
recorded wall, friction and preload impulses.

Memory for gradients: samples are grouped in blocks of about sqrt(n_samples); each block
and each sample are wrapped in `jax.checkpoint`, so reverse mode stores O(sqrt(n_samples)
+ steps_per_sample) states, and forward mode (jvp/jacfwd) works unchanged.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import compliant_sensor as cs
from . import contact, verlet
from .chain import (
    ChainModel,
    ChainSetup,
    build_model,
    internal_contact_index,
    internal_sensor_index,
)
from .forces import (
    chain_forces,
    contact_potentials,
    external_force_n,
    initial_max_overlap,
    initial_velocity,
    overlaps,
    plastic_dissipation,
    preload_potential,
)
from .precision import require_float64
from .progress import Progress
from .timegrid import DEFAULT_STEPS_PER_CONTACT, TimeGrid, choose_time_grid
from .traces import Traces
from .validation import check_step_stability, check_values


class YieldWarning(UserWarning):
    """A contact force exceeded the yield force of the contact (plastic deformation likely).

    `finding` is what happened, without the advice that follows it in the message (the
    command line gives advice in its own options)."""

    def __init__(self, finding: str, advice: str = ""):
        super().__init__(f"{finding} {advice}".strip())
        self.finding = finding


class Recording(NamedTuple):
    """Static choice of what a run records.

    **Fields:** `contacts` paper-numbered contacts recorded as `contact_K`; `record_all`
    also records every contact force, contact energy, position and velocity.
    """

    contacts: tuple[int, ...] = ()
    record_all: bool = False


class ChainState(NamedTuple):
    displacement_m: jax.Array
    velocity_m_s: jax.Array
    accel_m_s2: jax.Array
    viscous_accel_m_s2: jax.Array
    wall_force_n: jax.Array
    dissipated_viscous_j: jax.Array
    dissipated_friction_j: jax.Array
    wall_impulse_n_s: jax.Array
    friction_impulse_n_s: jax.Array
    max_force_n: jax.Array  # (n_contacts + 1,) internal contacts then the wall
    max_overlap_m: jax.Array  # (n_contacts + 1,) largest overlap so far (plastic contacts)
    # compliant sensors (`hertzchain.compliant_sensor`), (n_sensors,) each, empty without
    sensor_force_n: jax.Array
    sensor_rate_n_s: jax.Array
    sensor_drive_n: jax.Array


def initial_state(model: ChainModel) -> ChainState:
    """State at the impact: striker moving, chain at rest (and preloaded if asked)."""
    displacement = jnp.zeros_like(model.mass_kg)
    velocity = initial_velocity(model)
    max_overlap = initial_max_overlap(model)
    forces = chain_forces(model, displacement, velocity, max_overlap)
    zero = jnp.zeros(())
    n_sensors = 0 if model.compliant is None else len(model.compliant.beads)
    at_rest = jnp.broadcast_to(model.first_bead_force_n, (n_sensors,))
    return ChainState(
        displacement_m=displacement,
        velocity_m_s=velocity,
        accel_m_s2=forces.body_force_n / model.mass_kg,
        viscous_accel_m_s2=forces.body_viscous_force_n / model.mass_kg,
        wall_force_n=forces.wall_total_n,
        dissipated_viscous_j=zero,
        dissipated_friction_j=zero,
        wall_impulse_n_s=zero,
        friction_impulse_n_s=zero,
        max_force_n=jnp.concatenate([forces.contact_total_n, forces.wall_total_n[None]]),
        max_overlap_m=max_overlap,
        sensor_force_n=at_rest,
        sensor_rate_n_s=jnp.zeros((n_sensors,)),
        sensor_drive_n=at_rest,
    )


def _friction_kick(model: ChainModel, velocity, half_step_s):
    """Coulomb friction over half a step as a clamped kick: (velocity, (dissipated J, impulse N s))."""
    clamped = contact.track_friction_kick(velocity, model.friction_decel_m_s2, half_step_s)
    dissipated = 0.5 * jnp.sum(model.mass_kg * (velocity**2 - clamped**2))
    impulse = jnp.sum(model.mass_kg * (clamped - velocity))
    return clamped, (dissipated, impulse)


def verlet_step(model: ChainModel, dt_s: float, state: ChainState) -> ChainState:
    """Advance the chain by one velocity-Verlet step of `dt_s` seconds (pure function):
    `verlet.step` with track friction as its kick limit (and again at the step's end), the
    compliant sensors' phases around it, and the books."""
    h = 0.5 * dt_s
    m = model.mass_kg
    sensor = _sensor_drift(model, dt_s, state)

    def accel_at(displacement, velocity):
        contact_overlap, wall_overlap = overlaps(model, displacement, sensor.force_n)
        max_overlap = jnp.maximum(
            state.max_overlap_m, jnp.concatenate([contact_overlap, wall_overlap[None]])
        )
        forces = chain_forces(model, displacement, velocity, max_overlap, sensor.force_n,
                              sensor.predicted_rate_n_s)
        return forces.body_force_n / m, (forces, max_overlap)

    stepped = verlet.step(state.displacement_m, state.velocity_m_s, state.accel_m_s2, dt_s,
                          accel_at, limit=lambda w: _friction_kick(model, w, h))
    forces, max_overlap = stepped.forces
    friction_1, impulse_1 = stepped.limited
    v0, v_half, v_end = state.velocity_m_s, stepped.half_kicked_m_s, stepped.velocity_m_s
    viscous_accel = forces.body_viscous_force_n / m
    viscous_work = jnp.sum(m * state.viscous_accel_m_s2 * h * 0.5 * (v0 + v_half))
    viscous_work += jnp.sum(m * viscous_accel * h * 0.5 * (stepped.half_velocity_m_s + v_end))
    v_end, (friction_2, impulse_2) = _friction_kick(model, v_end, h)
    all_forces = jnp.concatenate([forces.contact_total_n, forces.wall_total_n[None]])
    return ChainState(
        displacement_m=stepped.displacement_m,
        velocity_m_s=v_end,
        accel_m_s2=stepped.accel_m_s2,
        viscous_accel_m_s2=viscous_accel,
        wall_force_n=forces.wall_total_n,
        dissipated_viscous_j=state.dissipated_viscous_j - viscous_work,
        dissipated_friction_j=state.dissipated_friction_j + friction_1 + friction_2,
        wall_impulse_n_s=state.wall_impulse_n_s + h * (state.wall_force_n + forces.wall_total_n),
        friction_impulse_n_s=state.friction_impulse_n_s + impulse_1 + impulse_2,
        max_force_n=jnp.maximum(state.max_force_n, all_forces),
        max_overlap_m=max_overlap,
        **_sensor_kick(model, dt_s, sensor, forces.contact_total_n),
    )


class _SensorDrift(NamedTuple):
    force_n: jax.Array | None
    half_rate_n_s: jax.Array | None
    predicted_rate_n_s: jax.Array | None
    quasi_static: jax.Array | None


def _sensor_drift(model: ChainModel, dt_s: float, state: ChainState) -> _SensorDrift:
    """First half kick and drift of the compliant sensors' forces (`compliant_sensor.drift`)."""
    if model.compliant is None:
        return _SensorDrift(None, None, None, None)
    return _SensorDrift(*cs.drift(model.compliant.inv_omega0_sq_s2, dt_s, state.sensor_force_n,
                                  state.sensor_rate_n_s, state.sensor_drive_n))


def _sensor_kick(model: ChainModel, dt_s: float, sensor: _SensorDrift, contact_force_n) -> dict:
    """Second half kick of the compliant sensors: the state fields they update."""
    if model.compliant is None:
        empty = jnp.zeros((0,))
        return {"sensor_force_n": empty, "sensor_rate_n_s": empty, "sensor_drive_n": empty}
    drive = cs.sensor_drive(model, contact_force_n)
    rate = cs.kick(model.compliant.inv_omega0_sq_s2, dt_s, sensor.force_n, sensor.half_rate_n_s, drive,
                   sensor.quasi_static)
    return {"sensor_force_n": sensor.force_n, "sensor_rate_n_s": rate, "sensor_drive_n": drive}


_LEDGER = ("dissipated_viscous_j", "dissipated_friction_j", "wall_impulse_n_s", "friction_impulse_n_s")


def _sample(model, u, v, ledger, setup_layout, recording, max_overlap=None, sensor=(None, None)):
    """Observables of one recorded sample (a dict of arrays).

    `u`, `v`: displacements and velocities of all bodies; `ledger`: an object with the
    running `_LEDGER` quantities; `max_overlap`: largest overlaps so far (plastic contacts);
    `sensor`: force and rate of the compliant sensors, if any.
    """
    contact_index, sensor_index, user_contacts = setup_layout
    if max_overlap is None:
        max_overlap = initial_max_overlap(model)
    force_s, rate_s = sensor
    forces = chain_forces(model, u, v, max_overlap, force_s, rate_s)
    contact_energy, wall_energy = contact_potentials(model, u, max_overlap, force_s)
    sensor_spring, sensor_kinetic = (cs.sensor_energies(model, force_s, rate_s) if force_s is not None
                                     else (0.0, 0.0))
    record = {
        "contacts": forces.contact_total_n[np.asarray(contact_index, dtype=int)],
        "sensors": forces.contact_total_n[np.asarray(sensor_index, dtype=int)],
        "wall": forces.wall_total_n,
        "kinetic_j": 0.5 * jnp.sum(model.mass_kg * v**2) + sensor_kinetic,
        "elastic_j": jnp.sum(contact_energy) + wall_energy + sensor_spring,
        "wall_elastic_j": wall_energy,
        "preload_potential_j": preload_potential(model, u),
        "momentum_kg_m_s": jnp.sum(model.mass_kg * v),
        "dissipated_plastic_j": plastic_dissipation(model, u, max_overlap, force_s),
    }
    record.update({name: getattr(ledger, name) for name in _LEDGER})
    if recording.record_all:
        users = np.asarray(user_contacts, dtype=int)
        record["contact_forces_n"] = forces.contact_total_n[users]
        record["contact_elastic_j"] = contact_energy[users]
        record["positions_m"] = u
        record["velocities_m_s"] = v
    return record


def _block_size(n_samples: int) -> int:
    """The divisor of n_samples closest to sqrt(n_samples) (checkpoint block length)."""
    root = math.isqrt(n_samples)
    for offset in range(root + 1):
        for candidate in (root - offset, root + offset):
            if 1 <= candidate <= n_samples and n_samples % candidate == 0:
                return candidate
    return 1


def integrate(
    model: ChainModel,
    state: ChainState,
    grid: TimeGrid,
    layout,
    recording: Recording,
    *,
    unroll: int = 1,
):
    """Run `grid.n_samples` samples from `state`: returns (final state, stacked records).

    Pure and differentiable in forward and reverse mode (nested checkpointed scans).
    """

    def one_sample(state, _):
        state = jax.lax.scan(
            lambda s, _: (verlet_step(model, grid.dt_s, s), None),
            state,
            None,
            length=grid.steps_per_sample,
            unroll=unroll,
        )[0]
        sensor = (state.sensor_force_n, state.sensor_rate_n_s) if model.compliant is not None else (None, None)
        return state, _sample(
            model, state.displacement_m, state.velocity_m_s, state, layout, recording,
            state.max_overlap_m, sensor,
        )

    block = _block_size(grid.n_samples)

    def one_block(state, _):
        return jax.lax.scan(jax.checkpoint(one_sample), state, None, length=block)

    state, records = jax.lax.scan(
        jax.checkpoint(one_block), state, None, length=grid.n_samples // block
    )
    records = jax.tree_util.tree_map(
        lambda x: x.reshape((grid.n_samples,) + x.shape[2:]), records
    )
    return state, records


def _layout(setup: ChainSetup, recording: Recording):
    for k in recording.contacts:
        if not 0 <= k < setup.n_beads:
            raise ValueError(
                f"contacts: contact {k} is not in the chain (contacts are 0..{setup.n_beads - 1}; "
                "contact K is between bead K and K+1, 0 the striker's; the wall is always recorded)."
            )
    contact_index = tuple(internal_contact_index(setup, k) for k in recording.contacts)
    sensor_index = tuple(internal_sensor_index(setup, b) for b in setup.sensor_beads)
    user_contacts = tuple(internal_contact_index(setup, k) for k in range(setup.n_beads))
    return contact_index, sensor_index, user_contacts


def _channel_names(setup: ChainSetup, recording: Recording) -> tuple[str, ...]:
    return (
        tuple(f"contact_{k}" for k in recording.contacts)
        + tuple(f"sensor_{b}" for b in setup.sensor_beads)
        + ("wall",)
    )


def _assemble(setup, model, grid, recording, records) -> Traces:
    names = _channel_names(setup, recording)
    forces = {name: records["contacts"][:, i] for i, name in enumerate(names[: len(recording.contacts)])}
    for i, bead in enumerate(setup.sensor_beads):
        forces[f"sensor_{bead}"] = records["sensors"][:, i]
    forces["wall"] = records["wall"]
    time = grid.sample_interval_s * jnp.arange(1, grid.n_samples + 1, dtype=jnp.float64)
    v0 = initial_velocity(model)
    contact_energy0, wall_energy0 = contact_potentials(model, jnp.zeros_like(v0))
    energy0 = 0.5 * jnp.sum(model.mass_kg * v0**2) + jnp.sum(contact_energy0) + wall_energy0
    if model.compliant is not None:
        at_rest = initial_state(model).sensor_force_n
        energy0 = energy0 + cs.sensor_energies(model, at_rest, jnp.zeros_like(at_rest))[0]
    ledger = (
        records["kinetic_j"]
        + records["elastic_j"]
        + records["preload_potential_j"]
        + records["dissipated_viscous_j"]
        + records["dissipated_friction_j"]
        + records["dissipated_plastic_j"]
    )
    yield_force = setup.contact_yield_force_n()
    user_contacts = _layout(setup, recording)[2]
    wall_slot = model.kappa.shape[0]
    user_max = records["max_force_n"][np.asarray(user_contacts + (wall_slot,), dtype=int)]
    return Traces(
        time_s=time,
        forces_n=forces,
        kinetic_j=records["kinetic_j"],
        elastic_j=records["elastic_j"],
        wall_elastic_j=records["wall_elastic_j"],
        preload_potential_j=records["preload_potential_j"],
        dissipated_viscous_j=records["dissipated_viscous_j"],
        dissipated_friction_j=records["dissipated_friction_j"],
        dissipated_plastic_j=records["dissipated_plastic_j"],
        energy_error_j=energy0 - ledger,
        momentum_kg_m_s=records["momentum_kg_m_s"],
        wall_impulse_n_s=records["wall_impulse_n_s"],
        friction_impulse_n_s=records["friction_impulse_n_s"],
        preload_impulse_n_s=external_force_n(model) * time,
        initial_energy_j=energy0,
        initial_momentum_kg_m_s=jnp.sum(model.mass_kg * v0),
        max_force_n=user_max,
        yield_force_n=yield_force,
        contact_forces_n=records.get("contact_forces_n"),
        contact_elastic_j=records.get("contact_elastic_j"),
        positions_m=records.get("positions_m"),
        velocities_m_s=records.get("velocities_m_s"),
        channel_names=names,
    )


def solve(setup: ChainSetup, grid: TimeGrid, recording: Recording = Recording(), *, unroll: int = 1,
          compliant_sensors: cs.CompliantSensors | None = None) -> Traces:
    """Simulate `setup` on a fixed time grid: the pure, differentiable core of `simulate`.

    Use it inside `jax.grad`, `jax.jacfwd`, `jax.vmap` or `jax.jit` (with `grid` and
    `recording` static). It does no input checks on traced values; `simulate` does.
    `compliant_sensors`: embedded sensors in compliance form (`hertzchain.compliant_sensor`),
    for a setup without `sensor_beads`; their beads are shortened by the sensor force, which
    is not itself recorded (record the bead's two contacts).
    """
    require_float64("solve")
    model = build_model(setup)
    if compliant_sensors is not None:
        if setup.sensor_beads:
            raise ValueError("compliant_sensors: the setup already splits sensor beads "
                             f"{setup.sensor_beads}; use one sensor model (sensor_beads=() here).")
        model = cs.with_compliant_sensors(model, compliant_sensors.beads, beta=compliant_sensors.beta,
                                          inv_omega0_sq_s2=compliant_sensors.inv_omega0_sq_s2)
    state0 = initial_state(model)
    final, records = integrate(model, state0, grid, _layout(setup, recording), recording, unroll=unroll)
    records["max_force_n"] = final.max_force_n
    return _assemble(setup, model, grid, recording, records)


_solve_jit = eqx.filter_jit(solve)


@eqx.filter_jit
def _advance(setup, state, grid, recording, unroll):
    model = build_model(setup)
    return integrate(model, state, grid, _layout(setup, recording), recording, unroll=unroll)


# Runs longer than this many steps are done in chunks, with progress reported between them.
_PROGRESS_STEPS = 2_000_000
_PROGRESS_CHUNKS = 20


def _solve_with_progress(setup, grid, recording, unroll) -> Traces:
    """`solve` in chunks of samples, reporting progress between them (same result)."""
    model = build_model(setup)
    state = initial_state(model)
    chunk = max(1, grid.n_samples // _PROGRESS_CHUNKS)
    progress = Progress(grid.n_steps, "simulate (steps)")
    pieces, done = [], 0
    while done < grid.n_samples:
        size = min(chunk, grid.n_samples - done)
        state, records = _advance(setup, state, grid._replace(n_samples=size), recording, unroll)
        pieces.append(records)
        done += size
        progress.advance(size * grid.steps_per_sample)
    records = jax.tree_util.tree_map(lambda *parts: jnp.concatenate(parts), *pieces)
    records["max_force_n"] = state.max_force_n
    return _assemble(setup, model, grid, recording, records)


def check_yield(traces: Traces, on_yield: str = "warn", *, plastic: bool = False) -> None:
    """Warn (or raise) if any contact force exceeded its yield force during the run.

    Nothing to report when the contacts are modelled as plastic (`plastic=True`).
    """
    if on_yield not in ("warn", "raise", "ignore"):
        raise ValueError(f"on_yield must be 'warn', 'raise' or 'ignore', got {on_yield!r}.")
    if on_yield == "ignore" or plastic:
        return
    ratio = np.asarray(traces.max_force_n) / np.asarray(traces.yield_force_n)
    if np.all(ratio <= 1.0):
        return
    worst = np.unravel_index(np.argmax(ratio), ratio.shape)
    n_contacts = ratio.shape[-1] - 1
    index = worst[-1]
    name = "the wall contact" if index == n_contacts else f"contact {index}"
    warning = YieldWarning(
        f"The force at {name} reached {np.asarray(traces.max_force_n)[worst]:.4g} N, above its "
        f"yield force {np.asarray(traces.yield_force_n)[worst]:.4g} N (mean contact pressure "
        "above bead_yield_stress_pa): the contact would deform plastically, which this elastic "
        "model does not describe.",
        "Lower striker_velocity_m_s, model it with an elastic-plastic contact law "
        "(contact_law=hertzchain.laws.JacksonGreen()), or set on_yield='ignore'.",
    )
    if on_yield == "raise":
        raise ValueError(str(warning))
    warnings.warn(warning, stacklevel=3)


def _run_plan(setup: ChainSetup, run_setup: ChainSetup, contacts, record_all: bool, **grid_options):
    """The recording and time grid of a run of `run_setup` (`setup`, or its batch), checked
    before anything runs: the contacts exist in `setup`, and the step is stable for the
    damping of every chain of `run_setup`."""
    recording = Recording(tuple(int(k) for k in contacts), bool(record_all))
    _layout(setup, recording)
    grid = choose_time_grid(run_setup, **grid_options)
    check_step_stability(run_setup, grid.dt_s)
    return recording, grid


def simulate(
    setup: ChainSetup,
    *,
    t_end_s: float = 2.5e-3,
    sample_interval_s: float = 1e-6,
    contacts=(),
    dt_s: float | None = None,
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT,
    record_all: bool = False,
    on_yield: str = "warn",
    unroll: int = 1,
    progress: bool = False,
) -> Traces:
    """Simulate a chain from the impact to `t_end_s`.

    **Arguments:**

    - `setup`: the `ChainSetup` (a batched setup works: see `simulate_batch`).
    - `t_end_s`: recorded duration after the impact, s (default 2.5 ms, the paper's Fig. 1).
    - `sample_interval_s`: interval between recorded samples, s.
    - `contacts`: paper-numbered contacts to record as `contact_K` (the wall is always
      recorded, embedded sensors always as `sensor_K`).
    - `dt_s`: Verlet step, s; default: the shortest contact time / `steps_per_contact`.
    - `record_all`: also record all contact forces and energies, positions and velocities.
    - `on_yield`: `"warn"`, `"raise"` or `"ignore"` when a force exceeds the yield force.
    - `unroll`: unrolling of the innermost scan (speed only).
    - `progress`: report progress on stderr for long runs (more than 2e6 steps), which are
      then run in chunks.

    **Returns:** `Traces`.

    **Raises:** `ValueError` before running when the damping (`eta_s`, `dashpot_n_s_m`) is
    beyond the stability of the step (`validation.check_step_stability`).
    """
    require_float64("simulate")
    recording, grid = _run_plan(setup, setup, contacts, record_all, t_end_s=t_end_s,
                                sample_interval_s=sample_interval_s, dt_s=dt_s,
                                steps_per_contact=steps_per_contact)
    if progress and grid.n_steps > _PROGRESS_STEPS:
        traces = _solve_with_progress(setup, grid, recording, unroll)
    else:
        traces = _solve_jit(setup, grid, recording, unroll=unroll)
    check_yield(traces, on_yield, plastic=setup.plasticity)
    return traces


def batch_setup(setup: ChainSetup, **values) -> tuple[ChainSetup, tuple[int, ...]]:
    """A setup batched over the outer product of the given scalar fields.

    `batch_setup(setup, striker_velocity_m_s=[0.1, 0.3], wall_youngs_pa=[5e9, 2e11])`
    returns a setup whose scalar fields have a leading axis of length 4 (the flattened
    2 x 2 grid) and the grid shape (2, 2).
    """
    for name in values:
        if not hasattr(setup, name) or name in ("end", "sensor_beads"):
            raise ValueError(f"Cannot sweep over {name!r}: not a numeric field of ChainSetup.")
        check_values(name, values[name])
    axes = [np.asarray(v, dtype=float).ravel() for v in values.values()]
    shape = tuple(len(a) for a in axes)
    mesh = np.meshgrid(*axes, indexing="ij")
    size = int(np.prod(shape))

    def broadcast(leaf):
        return jnp.broadcast_to(leaf, (size,) + jnp.shape(leaf))

    batched = jax.tree_util.tree_map(broadcast, setup)
    for name, grid_values in zip(values, mesh):
        batched = eqx.tree_at(lambda s, n=name: getattr(s, n), batched, jnp.asarray(grid_values.ravel()))
    return batched, shape


def stack_setups(setups: Sequence[ChainSetup]) -> ChainSetup:
    """One setup whose array fields carry a leading axis over `setups`, for `solve_stacked`
    and `hertzchain.batched.solve_batched`.

    **Raises:** `ValueError` if the list is empty or the setups differ in their static
    structure (number of beads, end, sensor beads), which a single vmapped solve cannot mix.
    """
    setups = list(setups)
    if not setups:
        raise ValueError("setups is empty: give at least one ChainSetup.")
    first = setups[0]
    for i, setup in enumerate(setups[1:], start=1):
        same = (
            setup.n_beads == first.n_beads
            and setup.end == first.end
            and setup.sensor_beads == first.sensor_beads
            and jax.tree_util.tree_structure(setup) == jax.tree_util.tree_structure(first)
        )
        if not same:
            raise ValueError(
                f"setups[{i}] differs from setups[0] in n_beads, end or sensor_beads; "
                "run such setups in separate batches."
            )
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *setups)


@eqx.filter_jit
def solve_stacked(setups: ChainSetup, grid: TimeGrid, recording: Recording, unroll: int = 1) -> Traces:
    """`solve` vmapped over the leading axis of a batched setup (from `stack_setups` or
    `batch_setup`), compiled once per structure, grid and recording: every array of the
    returned `Traces` has that leading axis."""
    return jax.vmap(lambda s: solve(s, grid, recording, unroll=unroll))(setups)


def simulate_batch(setup: ChainSetup, *, t_end_s: float = 2.5e-3, sample_interval_s: float = 1e-6,
                   contacts=(), dt_s: float | None = None,
                   steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT, record_all: bool = False,
                   on_yield: str = "warn", unroll: int = 1, **sweep) -> Traces:
    """Simulate the outer product of scalar parameter values in one vmapped call.

    Keyword arguments other than the run options name `ChainSetup` fields and give their
    values, e.g. `simulate_batch(setup, striker_velocity_m_s=v, wall_youngs_pa=y)`; the
    returned `Traces` has leading axes of shape (len(v), len(y)). One time step, chosen
    for the most demanding element, is used for all.
    """
    batched, shape = batch_setup(setup, **sweep)
    recording, grid = _run_plan(setup, batched, contacts, record_all, t_end_s=t_end_s,
                                sample_interval_s=sample_interval_s, dt_s=dt_s,
                                steps_per_contact=steps_per_contact)
    traces = solve_stacked(batched, grid, recording, unroll)
    check_yield(traces, on_yield, plastic=setup.plasticity)
    return jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), traces)

