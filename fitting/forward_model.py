"""How a fit's predictions are made: the forward model (`ForwardModel`, its batched-kernel
form `KernelForm`), the physics the batched kernel runs, and the fit's Verlet step."""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from hertzchain.chain import ChainSetup
from hertzchain.compliant_sensor import CompliantSensors
from hertzchain.integrate import Recording, solve
from hertzchain.timegrid import MIN_STEPS_PER_CONTACT, TimeGrid, shortest_contact_time_s

STEPS_PER_CONTACT = 400
# Steps per half period of an embedded sensor's resonance (a linear spring: velocity Verlet's
# frequency error is (omega dt)^2/24 = 6e-4 at 40 steps per half period).
SENSOR_STEPS_PER_HALF_PERIOD = 40
# Setup parameters the batched kernel simulates, and the physics it must compile in when one
# is freed (its start or its optimum may be away from 0 even where the base setup has 0).
# Freeing any other setup parameter sends the group to `solve` under `vmap`.
FAST_PATH_PHYSICS = {
    "eta": "viscous", "mu": "friction", "precompression": "preload", "C": None, "mu_star": None,
    "wall_youngs": None, "wall_poisson": None, "bead_youngs": None, "bead_radius": None,
    "striker_velocity": None,
}


def time_step_s(setup: ChainSetup, sample_interval_s: float, *, steps_per_contact: int = STEPS_PER_CONTACT,
                sensor_steps: int = SENSOR_STEPS_PER_HALF_PERIOD) -> float:
    """Verlet step for a fit: the Hertz contacts by `steps_per_contact`, sensors by `sensor_steps`.

    `hertzchain.choose_time_grid` counts an embedded sensor's half period (5.9 us at 85 kHz)
    as a contact and resolves it with the same number of steps as the Hertz contacts,
    which makes sensor runs 10-20 times longer than needed: the sensor is a linear spring,
    resolved to 6e-4 in frequency by 40 steps per half period. The returned step divides
    `sample_interval_s` (setups may be batched: the most demanding element decides).
    """
    no_sensor = eqx.tree_at(lambda s: s.sensor_f0_hz, setup, jnp.ones_like(setup.sensor_f0_hz))
    target = shortest_contact_time_s(no_sensor) / steps_per_contact
    if setup.sensor_beads:
        target = min(target, 0.5 / float(np.max(np.asarray(setup.sensor_f0_hz))) / sensor_steps)
    return sample_interval_s / max(1, math.ceil(sample_interval_s / target))


def _default_simulate(setup: ChainSetup, grid: TimeGrid, recording: Recording, extras: dict):
    del extras
    return solve(setup, grid, recording)


class KernelForm(abc.ABC):
    """A `ForwardModel`'s simulation in the form the batched kernel (`record_batched`) runs:
    the chain with the extras applied, simulated, and what the channels read from its
    recorded forces. `ForwardModel.simulate` must compute the same (on `solve`), so that the
    two paths agree to round-off (`fitting.effects.EffectsSimulation` is both)."""

    @abc.abstractmethod
    def setup(self, setup: ChainSetup, extras: dict) -> ChainSetup:
        """The chain to simulate: `setup` with the `extras` applied (traced, one chain)."""

    @abc.abstractmethod
    def physics(self, names) -> set:
        """The kernel physics (`kernel_flags`'s `switched_on` names) that extras named `names`
        (those a problem carries as parameters) can switch on."""

    @abc.abstractmethod
    def recording(self, recording: Recording) -> Recording:
        """What the kernel must record for the channels of `recording`."""

    @abc.abstractmethod
    def readings(self, forces_n: dict, setup: ChainSetup, extras: dict, grid: TimeGrid,
                 recording: Recording):
        """(forces_n, rest_n): the channels of `recording` (name -> (S,), N) from the
        simulated forces `forces_n` of the chain `setup` (`setup()`'s), and what they read at
        rest before the impact (N)."""

    def compliant_sensors(self, recording: Recording, extras: dict) -> CompliantSensors | None:
        """Embedded sensors in compliance form the chain has for the channels of `recording`
        (their beads from `recording` alone; strengths from `extras`, which may be batched),
        or None (the default: rigid beads)."""
        del recording, extras
        return None


@dataclasses.dataclass(frozen=True)
class ForwardModel:
    """How predictions are made; replace `simulate` to add model switches.

    **Fields:**

    - `simulate`: `(setup, grid, recording, extras) -> hertzchain.Traces`, pure and
      forward-mode differentiable; its result may carry `rest_n`, what the channels read
      at rest before the impact (default: the setup's static preload). `extras` maps the names of fitted parameters of kind
      `"extra"` to their values (traced scalars), so an effect the core solver lacks
      (plasticity, bead dispersion, ...) can be registered as a parameter and read here.
      Default: `hertzchain.solve`, ignoring `extras`.
    - `steps_per_contact`: Verlet steps per shortest contact time (default 400).
    - `extras_defaults`: values of `extras` entries that are not fitted.
    - `kernel`: the same model as a `KernelForm`, for the batched kernel (None: `simulate`
      under `vmap` whenever it is not the default).
    """

    simulate: Callable = _default_simulate
    steps_per_contact: int = STEPS_PER_CONTACT
    extras_defaults: dict = dataclasses.field(default_factory=dict)
    kernel: KernelForm | None = None

    def __post_init__(self):
        if isinstance(self.steps_per_contact, bool) or not isinstance(self.steps_per_contact, (int, np.integer)) or \
                self.steps_per_contact < MIN_STEPS_PER_CONTACT:
            raise ValueError(
                f"steps_per_contact = {self.steps_per_contact!r}: the Verlet solver needs an integer of at least "
                f"{MIN_STEPS_PER_CONTACT} steps per shortest contact time (default {STEPS_PER_CONTACT}); "
                f"give --steps-per-contact {STEPS_PER_CONTACT} or leave it out.")
