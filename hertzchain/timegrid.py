"""Choice and validation of the time step and the sampling grid.

The step is chosen from the shortest Hertz contact time the run can produce, so that
every contact is resolved by `steps_per_contact` steps (default 200), and rounded down so
that it divides the sampling interval. Velocity Verlet's error falls as dt^2. Measured on
the paper's chain (V0 = 0.3 m/s, steel or 5 GPa wall; shortest contact 86 us) against the
diffrax reference at rtol 1e-10: dt = 0.5 us gives peak forces within 3.5e-5, peak times
within 1.6e-5 and energy within 2e-5; dt = 0.25 us gives 9e-6, 4e-6 and 5e-6. A step
coarser than 1/20 of the shortest contact time is refused.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import contact
from .chain import ChainSetup

DEFAULT_STEPS_PER_CONTACT = 200
MIN_STEPS_PER_CONTACT = 20
# Largest wall force relative to the striker's first collision force, with margin
# (a rigid wall gives about 2.24 times the incident solitary wave, Job et al. Fig. 3a).
_FORCE_MARGIN = 2.5


class TimeGrid(NamedTuple):
    """Static description of a run's time axis.

    **Fields:** `dt_s` the Verlet step, s; `steps_per_sample` steps between two recorded
    samples; `n_samples` samples recorded, at times (i+1) * dt_s * steps_per_sample.
    """

    dt_s: float
    steps_per_sample: int
    n_samples: int

    @property
    def sample_interval_s(self) -> float:
        return self.dt_s * self.steps_per_sample

    @property
    def t_end_s(self) -> float:
        return self.sample_interval_s * self.n_samples

    @property
    def n_steps(self) -> int:
        return self.steps_per_sample * self.n_samples


def _reduced_striker_mass_kg(setup: ChainSetup):
    bead_mass = setup.bead_mass_kg
    return setup.striker_mass_kg * bead_mass[0] / (setup.striker_mass_kg + bead_mass[0])


def peak_force_estimate_n(setup: ChainSetup):
    """Largest contact force one (unbatched) setup can produce, N (jnp): 2.5 times the peak
    of the striker's Hertz collision with bead 1, plus the preload."""
    kappa = setup.contact_kappa()[0]
    overlap = (1.25 * _reduced_striker_mass_kg(setup) * setup.striker_velocity_m_s**2 / kappa) ** 0.4
    return _FORCE_MARGIN * kappa * overlap**1.5 + setup.precompression_n


def _contact_times(setup: ChainSetup):
    """Contact-time estimates of one (unbatched) setup, s, as a 1-D array (jnp)."""
    bead_mass = setup.bead_mass_kg
    kappa = setup.contact_kappa()
    reduced_striker = _reduced_striker_mass_kg(setup)
    velocity = setup.striker_velocity_m_s
    peak = peak_force_estimate_n(setup)
    times = [contact.collision_time(reduced_striker, kappa[0], velocity)]
    loaded = [(0.5 * jnp.min(bead_mass), jnp.max(kappa))]
    if setup.end == "wall":
        loaded.append((bead_mass[-1], setup.wall_kappa()))
    for mass, stiffness in loaded:
        speed = contact.velocity_for_peak_force(mass, stiffness, peak)
        times.append(contact.collision_time(mass, stiffness, speed))
    if setup.sensor_beads:
        times.append(0.5 / setup.sensor_f0_hz)
    return jnp.stack(times)


def shortest_contact_time_s(setup: ChainSetup) -> float:
    """Shortest contact time the run can produce, s (concrete setups, batched ones too).

    Taken over the striker's collision with bead 1 at the impact velocity, bead-bead and
    bead-wall contacts loaded to 2.5 times that collision's peak force plus the preload,
    and half the period of any embedded sensor. A batched setup (leading axes on every
    field) gives the minimum over the batch.
    """
    # one compiled program: run op by op, the estimate compiles each of its ~30 operations apart
    return float(np.min(np.asarray(batched_program(_contact_times, jnp.ndim(setup.striker_velocity_m_s))(setup))))


@functools.lru_cache(maxsize=None)
def batched_program(function, batch_ndim: int):
    """`function` of one setup, vmapped over `batch_ndim` leading axes and jitted: built once
    per batch rank, so that JAX's cache of compiled programs finds it again."""
    for _ in range(batch_ndim):
        function = jax.vmap(function)
    return jax.jit(function)


def _check_resolution(dt_s: float, t_contact_s: float) -> None:
    if dt_s > t_contact_s / MIN_STEPS_PER_CONTACT:
        raise ValueError(
            f"dt_s = {dt_s:.3g} s cannot resolve the shortest contact of this run "
            f"({t_contact_s:.3g} s); use dt_s <= {t_contact_s / MIN_STEPS_PER_CONTACT:.3g} s "
            f"(or leave dt_s unset to choose it)."
        )


def choose_time_grid(
    setup: ChainSetup,
    *,
    t_end_s: float,
    sample_interval_s: float,
    dt_s: float | None = None,
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT,
) -> TimeGrid:
    """The time grid of a run: a step that resolves every contact and divides the sampling.

    **Arguments:**

    - `setup`: the chain (may be batched: the most demanding element sets the step).
    - `t_end_s`: duration recorded after the impact, s.
    - `sample_interval_s`: interval between recorded samples, s.
    - `dt_s`: force this step (must divide `sample_interval_s`); default: chosen.
    - `steps_per_contact`: steps per shortest contact time when the step is chosen.

    **Raises:** `ValueError` naming the field, for non-positive or non-finite times, a
    sampling interval longer than the run, a given step that does not divide the sampling
    interval, or a step too coarse to resolve the shortest contact.
    """
    for name, value in (("t_end_s", t_end_s), ("sample_interval_s", sample_interval_s)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive time in seconds, got {value!r}.")
    if sample_interval_s > t_end_s:
        raise ValueError(
            f"sample_interval_s ({sample_interval_s:g} s) is longer than t_end_s ({t_end_s:g} s)."
        )
    if steps_per_contact < MIN_STEPS_PER_CONTACT:
        raise ValueError(f"steps_per_contact must be >= {MIN_STEPS_PER_CONTACT}, got {steps_per_contact}.")
    t_contact = shortest_contact_time_s(setup)
    if dt_s is None:
        steps = max(1, math.ceil(sample_interval_s / (t_contact / steps_per_contact)))
        dt = sample_interval_s / steps
    else:
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be a positive time step in seconds, got {dt_s!r}.")
        _check_resolution(dt_s, t_contact)
        steps = round(sample_interval_s / dt_s)
        if steps < 1 or abs(steps * dt_s - sample_interval_s) > 1e-9 * sample_interval_s:
            raise ValueError(
                f"sample_interval_s ({sample_interval_s:g} s) must be a whole multiple of "
                f"dt_s ({dt_s:g} s)."
            )
        dt = dt_s
    _check_resolution(dt, t_contact)
    n_samples = round(t_end_s / sample_interval_s)
    return TimeGrid(dt_s=float(dt), steps_per_sample=int(steps), n_samples=int(n_samples))
