"""Simulation groups: experiments of the same chain structure simulated together on one
time grid (and whether it still resolves the fitted setups), and where each parameter acts
(offsets, gains, global and per-experiment simulator parameters)."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import numpy as np

from hertzchain.chain import ChainSetup
from hertzchain.integrate import Recording, stack_setups
from hertzchain.theory import discrete_fwhm_s, discrete_velocity_constant
from hertzchain.timegrid import TimeGrid, choose_time_grid

from .data import Experiment
from .forward_model import time_step_s

# Finest needed simulation sampling, as a fraction of the narrowest pulse's half-maximum width.
_SAMPLES_PER_FWHM = 40
# Margin on the striker velocity when the fixed time grid is chosen (the fit may raise it).
_VELOCITY_MARGIN = 1.5


@dataclasses.dataclass(frozen=True)
class _Group:
    experiments: tuple[int, ...]  # indices into Problem.experiments
    setups: ChainSetup  # stacked base setups (leading axis = experiments of the group)
    grid: TimeGrid
    recording: Recording
    channels: tuple[str, ...]  # simulated channel names, in output order
    global_index: tuple[int, ...]  # indices into x of global parameters reaching the simulator
    local_index: np.ndarray  # (n_experiments_in_group, n_local) indices into x


def parameter_index(experiments, instances):
    """Where each parameter acts: (offset_index, gain_index, global_sim, local_sim) -- per
    experiment the index into x of its trigger offset (or None) and {channel: index} of its
    gains; the indices of global simulator parameters; per experiment those of its own."""
    offset_index: list[int | None] = [None] * len(experiments)
    gain_index: list[dict] = [{} for _ in experiments]
    global_sim: list[int] = []
    local_sim: list[list[int]] = [[] for _ in experiments]
    for i, inst in enumerate(instances):
        kind, scope = inst.spec.kind, inst.spec.scope
        if kind == "time_offset":
            offset_index[inst.experiment] = i
        elif kind == "gain" and scope == "sensor":
            for e, experiment in enumerate(experiments):
                if inst.channel in experiment.channels:
                    gain_index[e][inst.channel] = i
        elif kind == "gain":
            gain_index[inst.experiment][inst.channel] = i
        elif scope == "global":
            global_sim.append(i)
        elif scope == "experiment":
            local_sim[inst.experiment].append(i)
        else:
            raise ValueError(f"{inst.label}: channel-scoped parameters must be gains.")
    return offset_index, gain_index, global_sim, local_sim


def simulation_interval_s(experiment: Experiment, setup: ChainSetup) -> float:
    """The simulation's sampling interval for `experiment` on `setup`, s: the data's, divided
    until the narrowest pulse's half-maximum width holds `_SAMPLES_PER_FWHM` samples."""
    interval = float(experiment.trace.sample_interval_s)
    peak = max(float(np.max(experiment.data(c))) for c in experiment.channels)
    kappa = float(setup.contact_kappa()[min(1, setup.n_beads - 1)])
    mass = float(setup.bead_mass_kg[0])
    radius = float(setup.bead_radius_m[0])
    speed = float(discrete_velocity_constant(radius, mass, kappa)) * max(peak, 1e-6) ** (1 / 6)
    fwhm = discrete_fwhm_s(radius, speed)
    return interval / max(1, math.ceil(interval / (fwhm / _SAMPLES_PER_FWHM)))


def make_groups(problem, setups) -> list[_Group]:
    """The simulation groups of `problem` on base `setups`: experiments with the same chain
    structure (beads, end, sensor beads), each group with its time grid and recording."""
    keys: dict = {}
    for e, setup in enumerate(setups):
        key = (setup.n_beads, setup.end, setup.sensor_beads)
        keys.setdefault(key, []).append(e)
    groups = []
    offset_margin = max(
        [abs(problem.instances[i].spec.lower) for i in problem.offset_index if i is not None]
        + [abs(problem.instances[i].spec.upper) for i in problem.offset_index if i is not None]
        + [0.0]
    )
    for members in keys.values():
        contacts = sorted({k for e in members for k in problem.experiments[e].trace.contacts})
        recording = Recording(contacts=tuple(contacts))
        channels = (
            tuple(f"contact_{k}" for k in contacts)
            + tuple(f"sensor_{b}" for b in setups[members[0]].sensor_beads)
            + ("wall",)
        )
        interval = min(simulation_interval_s(problem.experiments[e], setups[e]) for e in members)
        t_end = max(float(problem.experiments[e].time_s[-1]) for e in members)
        t_end = t_end + offset_margin + 4 * interval
        t_end = interval * math.ceil(t_end / interval)
        margin = [
            eqx.tree_at(
                lambda s: s.striker_velocity_m_s, setups[e],
                setups[e].striker_velocity_m_s * _VELOCITY_MARGIN,
            )
            for e in members
        ]
        dt = time_step_s(stack_setups(margin), interval, steps_per_contact=problem.forward.steps_per_contact)
        grid = choose_time_grid(stack_setups(margin), t_end_s=t_end, sample_interval_s=interval, dt_s=dt)
        n_local = len(problem.local_sim[members[0]])
        local = np.array([problem.local_sim[e] for e in members], dtype=int).reshape(len(members), n_local)
        groups.append(
            _Group(
                experiments=tuple(members),
                setups=stack_setups([setups[e] for e in members]),
                grid=grid,
                recording=recording,
                channels=channels,
                global_index=tuple(problem.global_sim),
                local_index=local,
            )
        )
    return groups


def coarse_experiments(problem, x) -> list[str]:
    """The labels of `problem`'s experiments whose setup at parameter values `x` is resolved
    by fewer than half the steps per contact the forward model asks for: their group's time
    step is more than twice the `time_step_s` the fitted setup needs."""
    coarse = []
    for group in problem.groups:
        for e in group.experiments:
            setup = problem.setup_at(np.asarray(x), e)
            needed = time_step_s(setup, group.grid.sample_interval_s,
                                 steps_per_contact=problem.forward.steps_per_contact)
            if group.grid.dt_s > 2 * needed:
                coarse.append(problem.experiments[e].label)
    return coarse
