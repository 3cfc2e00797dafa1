"""Runs that step the drive through levels: amplitude and frequency sweeps, up and down.

A `HarmonicSchedule` is S levels (frequency, amplitude) per run for B runs. Level 0 starts
from rest in the static equilibrium: the amplitude rises from 0 over `ramp_periods` and
holds `periods_per_level` more. Each later level lasts `periods_per_level` periods of its
own frequency; its amplitude moves from the previous level's over the first
`transition_periods` (`drive.smooth_step`; 0 = a step). Every level is whole periods with
the same number of steps per period, so a frequency change is phase-continuous (and the
drive's velocity continuous too: levels start at phase 0, where it is zero): the lab's
sweeper stepping amplitude or frequency within one run. Sweeping up then down over the
same levels traces hysteresis loops.

- `lockin_schedule(chain, schedule, *, bead, quantity, harmonics, window_periods)`: the
  lock-in at the end of every level, (n_harmonics, S, B).
- `record_schedule(chain, schedule, *, beads, contacts, every_steps)`: what a lab records
  through the run (bead displacements and velocities, contact forces, the drive), as
  `DrivenTraces`.
- `record_sampled(chain, displacement_m, dt_s, ...)`: the same for an arbitrary sampled
  drive (e.g. `chirp`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import drive as drives
from . import kernel
from .chain import DrivenChain
from .lockin import AbstractReading, lockin_steps


class HarmonicSchedule(eqx.Module):
    """S drive levels for B runs (see the module docstring).

    **Fields:** `frequency_hz`, `amplitude_m`: (S, B), Hz and m (driver displacement
    amplitude); static `steps_per_period` (N), `ramp_periods`, `periods_per_level`,
    `transition_periods`. Build with `HarmonicSchedule.levels`.
    """

    frequency_hz: jax.Array
    amplitude_m: jax.Array
    steps_per_period: int = eqx.field(static=True)
    ramp_periods: int = eqx.field(static=True)
    periods_per_level: int = eqx.field(static=True)
    transition_periods: int = eqx.field(static=True)

    @classmethod
    def levels(cls, frequency_hz, amplitude_m, *, steps_per_period: int = 64, ramp_periods: int = 25,
               periods_per_level: int = 35, transition_periods: int = 1) -> HarmonicSchedule:
        """Levels from `frequency_hz` and `amplitude_m`, each (S,) (one run) or (S, B), broadcast
        against each other (a scalar holds for every level): e.g. an amplitude loop at one
        frequency, `levels(6850.0, np.r_[up, up[::-1]])`, or up and down frequency sweeps as two
        runs, `levels(np.stack([f, f[::-1]], 1), 5e-9)`."""
        f = jnp.asarray(frequency_hz, dtype=jnp.float64)
        a = jnp.asarray(amplitude_m, dtype=jnp.float64)
        f, a = (x if x.ndim == 2 else x.reshape(-1, 1) for x in (f, a))
        f, a = jnp.broadcast_arrays(f, a)
        for name, value in (("steps_per_period", steps_per_period), ("ramp_periods", ramp_periods),
                            ("periods_per_level", periods_per_level), ("transition_periods", transition_periods)):
            if int(value) != value or value < 0:
                raise ValueError(f"{name}: expected a whole number >= 0, got {value}.")
        if steps_per_period < 8:
            raise ValueError(f"steps_per_period: at least 8 steps per drive period, got {steps_per_period}.")
        if periods_per_level < 1 or transition_periods > periods_per_level:
            raise ValueError(f"periods_per_level ({periods_per_level}) must be >= 1 and >= transition_periods "
                             f"({transition_periods}).")
        for name, values in (("frequency_hz", f), ("amplitude_m", a)):
            if not isinstance(values, jax.core.Tracer):
                array = np.asarray(values)
                if not np.all(np.isfinite(array)) or np.any(array < 0) or (name == "frequency_hz" and np.any(array <= 0)):
                    raise ValueError(f"{name}: values must be finite and {'> 0 Hz' if name == 'frequency_hz' else '>= 0 m'}.")
        return cls(f, a, int(steps_per_period), int(ramp_periods), int(periods_per_level), int(transition_periods))

    @property
    def n_levels(self) -> int:
        return self.frequency_hz.shape[0]

    @property
    def batch(self) -> int:
        return self.frequency_hz.shape[1]


def _levels(chain: DrivenChain, schedule: HarmonicSchedule, window_steps: int, record, unroll: int,
            every_steps: int = 1):
    """Run the schedule; `record(state, u, u_dot)` over the last `window_steps` steps of each
    level (every `every_steps` steps; all of a level's steps when `window_steps` is None).
    **Returns:** (records of level 0, records of levels 1.. stacked (S - 1, ...) or None,
    first step of each level's records within the level, final state)."""
    p = kernel.kernel_params(chain)
    n = schedule.steps_per_period
    f, a = schedule.frequency_hz, schedule.amplitude_m

    def level(state, frequency, from_amplitude, to_amplitude, ramp_periods, periods):
        dt = 1.0 / (frequency * n)
        steps = periods * n
        window = steps if window_steps is None else window_steps
        drive = drives.harmonic_segment(frequency, dt, n, from_amplitude, to_amplitude, ramp_periods * n,
                                        stroke=chain.drive_stroke)
        state, _ = kernel.advance(p, state, dt, drive, jnp.arange(1, steps - window + 1), unroll=unroll)
        first = steps - window + 1
        state, records = kernel.advance_sampled(p, state, dt, drive, first, window // every_steps, every_steps,
                                                record, unroll=unroll)
        return state, records

    state = kernel.static_state(p, f[0])
    first_periods = schedule.ramp_periods + schedule.periods_per_level
    state, first_records = level(state, f[0], 0.0 * a[0], a[0], schedule.ramp_periods, first_periods)
    if schedule.n_levels == 1:
        return first_records, None, state

    def later(state, inputs):
        frequency, from_amplitude, to_amplitude = inputs
        return level(state, frequency, from_amplitude, to_amplitude, schedule.transition_periods,
                     schedule.periods_per_level)

    state, records = jax.lax.scan(later, state, (f[1:], a[:-1], a[1:]))
    return first_records, records, state


class ScheduleLockin(AbstractReading):
    """Lock-in at the end of every level: `complex_amplitude` (n_harmonics, S, B), `.rms`,
    `.phase_rad` (against the drive's cos), `harmonics` (static)."""

    complex_amplitude: jax.Array
    harmonics: tuple[float, ...] = eqx.field(static=True)


def lockin_schedule(chain: DrivenChain, schedule: HarmonicSchedule, *, bead: int = 1, quantity: str = "velocity",
                    harmonics: tuple[float, ...] = (1.0, 0.5), window_periods: int = 4, contact: int | None = None,
                    unroll: int = kernel.DEFAULT_UNROLL) -> ScheduleLockin:
    """The lock-in (RMS, phase) of `bead`'s velocity or displacement (or of the force of
    `contact`, with `quantity="force"`) over the last `window_periods` whole periods of every
    level of `schedule` (arguments as `lockin_grid`'s; `window_periods` ≤ `periods_per_level`).
    **Returns:** `ScheduleLockin`, (n_harmonics, S, B)."""
    harmonics = tuple(float(h) for h in harmonics)
    check_readout(chain, bead, quantity, harmonics, window_periods, schedule.periods_per_level,
                  schedule.steps_per_period, schedule.frequency_hz, contact)
    return eqx.filter_jit(lockin_levels)(chain.for_kernel(), schedule, int(bead), quantity, harmonics, int(window_periods),
                                         int(unroll), contact)


def readout(chain: DrivenChain, quantity: str, bead: int, contact: int | None):
    """`record(state, u, u_dot)` of what the lock-in reads: bead `bead`'s velocity (m/s) or
    displacement (m), or the total force of `contact` (N) for `quantity="force"`."""
    if quantity == "force":
        p = kernel.kernel_params(chain)

        def record(s, u, u_dot):
            return kernel.contact_forces(p, s.displacement_m, s.velocity_m_s, u, u_dot, s.contact_history_m)[contact]

        return record
    field = "velocity_m_s" if quantity == "velocity" else "displacement_m"

    def record(s, u, u_dot):
        return getattr(s, field)[bead - 1]

    return record


def lockin_levels(chain, schedule, bead, quantity, harmonics, window_periods, unroll,
                  contact=None) -> ScheduleLockin:
    """`lockin_schedule` without the checks (traceable; static arguments as Python values)."""
    n = schedule.steps_per_period
    window = window_periods * n
    first, rest, _ = _levels(chain, schedule, window, readout(chain, quantity, bead, contact), unroll)
    # the drive's phase at step j of a level is 2 pi j / N (levels are whole periods)
    start = (schedule.ramp_periods + schedule.periods_per_level) * n - window + 1
    readings = [jnp.stack([lockin_steps(first, n, h, start).complex_amplitude for h in harmonics])[:, None]]
    if rest is not None:
        samples = jnp.moveaxis(rest, 0, 1)  # (window, S - 1, B)
        start = schedule.periods_per_level * n - window + 1
        readings.append(jnp.stack([lockin_steps(samples, n, h, start).complex_amplitude for h in harmonics]))
    return ScheduleLockin(jnp.concatenate(readings, axis=1), harmonics)


QUANTITIES = ("velocity", "displacement", "force")
# The largest (highest linear mode's angular frequency × step) accepted: velocity-Verlet is
# stable below 2, and accurate to about (omega dt)^2 / 24 of the mode's frequency.
MAX_OMEGA_DT = 1.0


def check_readout(chain, bead, quantity, harmonics, window_periods, hold_periods, steps_per_period,
                  frequencies_hz, contact=None) -> None:
    """ValueError naming the argument for a lock-in read-out the run cannot give."""
    if not isinstance(chain, DrivenChain):
        raise TypeError(f"chain: expected a DrivenChain, got {type(chain).__name__}.")
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity: expected one of {QUANTITIES}, got {quantity!r}.")
    if int(bead) != bead or not 1 <= bead <= chain.n_beads:
        raise ValueError(f"bead: beads are numbered 1..{chain.n_beads} from the driver, got {bead}.")
    if quantity == "force":
        if contact is None or int(contact) != contact or not 0 <= contact <= chain.n_beads:
            raise ValueError(f'contact: quantity="force" reads one contact, 0 (driver) .. {chain.n_beads} (wall); '
                             f"got {contact}.")
    elif contact is not None:
        raise ValueError(f'contact: only read with quantity="force" (got quantity={quantity!r}, contact={contact}).')
    if int(window_periods) != window_periods or not 1 <= window_periods <= hold_periods:
        raise ValueError(f"window_periods: must be a whole number 1..{hold_periods} (the periods held), "
                         f"got {window_periods}.")
    if int(steps_per_period) != steps_per_period or steps_per_period < 8:
        raise ValueError(f"steps_per_period: at least 8 steps per drive period, got {steps_per_period}.")
    if not harmonics:
        raise ValueError("harmonics: give at least one multiple of the drive frequency, e.g. (1.0, 0.5).")
    for h in harmonics:
        if h <= 0 or abs(h * window_periods - round(h * window_periods)) > 1e-9:
            raise ValueError(
                f"harmonics: {h} × window_periods ({window_periods}) must be a whole number of periods of "
                f"the demodulated component (h > 0); e.g. an even window for h = 0.5."
            )
        if h * 2 >= steps_per_period:
            raise ValueError(f"harmonics: {h} × f is above the Nyquist frequency of {steps_per_period} steps a period.")
    traced = [leaf for leaf in jax.tree_util.tree_leaves((chain, frequencies_hz)) if isinstance(leaf, jax.core.Tracer)]
    if not traced:
        lowest = float(np.min(np.asarray(frequencies_hz)))
        # the chain's own bound, in NumPy: this check may run while an outer `jit` traces
        concrete = jax.tree_util.tree_map(np.asarray, chain)
        omega_dt = 2.0 * np.pi * float(concrete.highest_frequency_bound_hz()) / (lowest * steps_per_period)
        if omega_dt > MAX_OMEGA_DT:
            needed = int(np.ceil(steps_per_period * omega_dt / MAX_OMEGA_DT))
            raise ValueError(
                f"steps_per_period: {steps_per_period} steps per period of the lowest frequency ({lowest:.6g} Hz) "
                f"under-resolve the chain's highest mode (ω dt = {omega_dt:.3g} > {MAX_OMEGA_DT}); use "
                f"steps_per_period >= {needed}."
            )


class DrivenTraces(eqx.Module):
    """What a lab records through a driven run, for B runs and K samples.

    **Fields:** `time_s` (B, K) from the start, s; `drive_m` (B, K) the driver's
    displacement, m; `displacement_m`, `velocity_m_s` (B, n_recorded_beads, K) of `beads`
    (numbered 1..n from the driver; from the static equilibrium), m and m/s;
    `contact_force_n` (B, n_recorded_contacts, K) total force of `contacts` (0 = driver, n =
    wall; the static F0 included), N."""

    time_s: jax.Array
    drive_m: jax.Array
    displacement_m: jax.Array
    velocity_m_s: jax.Array
    contact_force_n: jax.Array
    beads: tuple[int, ...] = eqx.field(static=True)
    contacts: tuple[int, ...] = eqx.field(static=True)


def _recorder(p, beads, contacts):
    rows = np.asarray(beads, dtype=int) - 1
    picked = np.asarray(contacts, dtype=int)

    def record(s, u, u_dot):
        force = kernel.contact_forces(p, s.displacement_m, s.velocity_m_s, u, u_dot, s.contact_history_m)
        return u, s.displacement_m[rows], s.velocity_m_s[rows], force[picked]

    return record


def _traces(time_s, records, beads, contacts) -> DrivenTraces:
    drive, x, v, force = records  # (K, B), (K, nb, B), ...
    return DrivenTraces(
        time_s=time_s,
        drive_m=drive.T,
        displacement_m=jnp.moveaxis(x, 0, -1).swapaxes(0, 1),
        velocity_m_s=jnp.moveaxis(v, 0, -1).swapaxes(0, 1),
        contact_force_n=jnp.moveaxis(force, 0, -1).swapaxes(0, 1),
        beads=beads,
        contacts=contacts,
    )


def record_schedule(chain: DrivenChain, schedule: HarmonicSchedule, *, beads: tuple[int, ...] = (1,),
                    contacts: tuple[int, ...] = (0,), every_steps: int = 1,
                    unroll: int = kernel.DEFAULT_UNROLL) -> DrivenTraces:
    """Record `beads`' displacement and velocity, `contacts`' forces and the drive every
    `every_steps` steps through the whole `schedule` (`every_steps` must divide N)."""
    beads, contacts = _check_outputs(chain, beads, contacts)
    if int(every_steps) != every_steps or every_steps < 1 or schedule.steps_per_period % every_steps:
        raise ValueError(f"every_steps: must be a whole divisor of steps_per_period ({schedule.steps_per_period}), "
                         f"got {every_steps}.")
    return _record_schedule(chain.for_kernel(), schedule, beads, contacts, int(every_steps), int(unroll))


@eqx.filter_jit
def _record_schedule(chain, schedule, beads, contacts, every_steps, unroll):
    p = kernel.kernel_params(chain)
    first, rest, _ = _levels(chain, schedule, None, _recorder(p, beads, contacts), unroll, every_steps)
    n = schedule.steps_per_period
    dt = 1.0 / (schedule.frequency_hz * n)  # (S, B)
    first_steps = (schedule.ramp_periods + schedule.periods_per_level) * n
    level_steps = schedule.periods_per_level * n
    times = [dt[0][:, None] * every_steps * jnp.arange(1, first_steps // every_steps + 1)]
    if rest is not None:
        starts = first_steps * dt[0] + jnp.concatenate([jnp.zeros((1, dt.shape[1])),
                                                        jnp.cumsum(level_steps * dt[1:-1], axis=0)])
        local = every_steps * jnp.arange(1, level_steps // every_steps + 1)
        later = starts[:, :, None] + dt[1:, :, None] * local  # (S - 1, B, K)
        times.append(jnp.moveaxis(later, 0, 1).reshape(dt.shape[1], -1))
        first = jax.tree_util.tree_map(
            lambda a, b: jnp.concatenate([a, b.reshape((-1,) + b.shape[2:])]), first, rest)
    return _traces(jnp.concatenate(times, axis=1), first, beads, contacts)


def chirp(start_hz: float, stop_hz: float, duration_s: float, dt_s: float, amplitude_m: float,
          taper_s: float) -> np.ndarray:
    """Samples at t = 0, dt, ..., of a linear chirp $a\\,w(t)\\sin(2\\pi(f_0 t + (f_1 - f_0)
    t^2/(2T)))$ from `start_hz` to `stop_hz` over `duration_s`, its amplitude raised from 0 and
    lowered back over `taper_s` at each end (`drive.smooth_step`), m: a drive for
    `record_sampled` that starts and ends at rest."""
    if not 0 < 2 * taper_s <= duration_s or dt_s <= 0:
        raise ValueError("chirp: need dt_s > 0 and 0 < 2 taper_s <= duration_s (s).")
    t = np.arange(round(duration_s / dt_s) + 1) * dt_s
    rise = np.asarray(drives.smooth_step(jnp.asarray(t / taper_s))[0])
    fall = np.asarray(drives.smooth_step(jnp.asarray((duration_s - t) / taper_s))[0])
    phase = 2 * np.pi * (start_hz * t + 0.5 * (stop_hz - start_hz) * t**2 / duration_s)
    return amplitude_m * rise * fall * np.sin(phase)


def record_sampled(chain: DrivenChain, displacement_m, dt_s, *, beads: tuple[int, ...] = (1,),
                   contacts: tuple[int, ...] = (0,), every_steps: int = 1,
                   unroll: int = kernel.DEFAULT_UNROLL) -> DrivenTraces:
    """Drive the chain by sampled displacements of the driver, `displacement_m` (K + 1,) or
    (K + 1, B), m, at t = 0, dt_s, ... (`dt_s` scalar or (B,), s; the first sample must be 0:
    the chain starts at rest), one velocity-Verlet step per sample; record as
    `record_schedule` (K must be a multiple of `every_steps`)."""
    beads, contacts = _check_outputs(chain, beads, contacts)
    displacement = jnp.asarray(displacement_m, dtype=jnp.float64)
    if displacement.ndim == 1:
        displacement = displacement[:, None]
    if displacement.ndim != 2 or displacement.shape[0] < 2:
        raise ValueError(f"displacement_m: expected (K + 1,) or (K + 1, B) samples, got shape {displacement.shape}.")
    if not isinstance(displacement, jax.core.Tracer) and np.any(np.asarray(displacement[0]) != 0.0):
        raise ValueError("displacement_m: the first sample must be 0 m (the run starts in the static equilibrium).")
    steps = displacement.shape[0] - 1
    if int(every_steps) != every_steps or every_steps < 1 or steps % every_steps:
        raise ValueError(f"every_steps: must divide the {steps} steps of the drive, got {every_steps}.")
    dt = jnp.broadcast_to(jnp.asarray(dt_s, dtype=jnp.float64), displacement.shape[1:])
    return _record_sampled(chain.for_kernel(), displacement, dt, beads, contacts, int(every_steps), int(unroll))


@eqx.filter_jit
def _record_sampled(chain, displacement, dt, beads, contacts, every_steps, unroll):
    p = kernel.kernel_params(chain)
    state = kernel.static_state(p, dt)
    n_samples = (displacement.shape[0] - 1) // every_steps
    _, records = kernel.advance_sampled(p, state, dt, drives.sampled(displacement, dt), 1, n_samples, every_steps,
                                        _recorder(p, beads, contacts), unroll=unroll)
    time = dt[:, None] * every_steps * jnp.arange(1, n_samples + 1)
    return _traces(time, records, beads, contacts)


def _check_outputs(chain, beads, contacts):
    beads, contacts = tuple(int(b) for b in beads), tuple(int(k) for k in contacts)
    for b in beads:
        if not 1 <= b <= chain.n_beads:
            raise ValueError(f"beads: beads are numbered 1..{chain.n_beads} from the driver, got {b}.")
    for k in contacts:
        if not 0 <= k <= chain.n_beads:
            raise ValueError(f"contacts: contacts are 0 (driver) .. {chain.n_beads} (wall), got {k}.")
    return beads, contacts
