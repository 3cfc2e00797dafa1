"""The forward model of a fit: parameter values -> predicted channels -> whitened residuals.

For each experiment the chain is simulated with `hertzchain.solve` (velocity Verlet) on a
fixed time grid at least as fine as the data, then every channel is evaluated at the data's
times shifted by the trigger offset, $t - t_{off}$, with a differentiable cubic
(Catmull-Rom) interpolation, multiplied by the channel's gain, and compared with the data:
$r = (g\\,F(t - t_{off}) - y)/\\sigma$. Before the impact the model holds its value at
$t = 0$ (the static preload), so records with a pre-trigger segment (t < 0) are fitted
whole. A channel the file lists in `ac_channels` (a piezo sensor behind an AC-coupled
conditioner) is compared with the change of force since before the impact,
$F(t - t_{off}) - F(0^-)$: a static preload is not in it. Samples a file marks as
clipped are whitened with an infinite sigma, so they add nothing to chi^2 or its
derivatives; `n_fitted` counts the samples that do.

Experiments with the same chain structure (number of beads, end, sensor beads) are
simulated together on a common grid: by `hertzchain.batched.record_batched` (the batch on
the SIMD axis, several times faster than `solve` per chain) when the default forward model
runs, or a custom `ForwardModel` gives its `KernelForm` (`fitting.effects`'s does), and every
freed parameter is physics that kernel has (`FAST_PATH_PHYSICS`); otherwise by `solve` under
`vmap` (extra effects of a custom `ForwardModel` without a `KernelForm`). Both integrate the same equations in the same order (they agree to
round-off: `tests/test_fit_model.py`).

Jacobian. The residual's derivative is assembled by a custom JVP: the simulator is
differentiated in forward mode only with respect to the parameters that reach it (the
global physical parameters plus the experiment's own striker velocity, say), once per
experiment, and the cheap post-processing (interpolation, offsets, gains) is
differentiated directly. A fit with per-file and per-channel nuisances therefore costs a
few forward passes per iteration instead of one per free number.

Time step: by default `STEPS_PER_CONTACT = 400` steps per shortest Hertz contact time, twice
the simulator's default (embedded sensors: 40 steps per half period, see `time_step_s`), because with the small standard errors of full-trace fits the
velocity-Verlet bias at coarser steps is several standard errors of C and eta (the bias
is second order in the step).
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import math
from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from hertzchain import native
from hertzchain.batched import contact_law, kernel_flags, record_batched
from hertzchain.chain import ChainSetup
from hertzchain.compliant_sensor import CompliantSensors
from hertzchain.integrate import Recording, solve, stack_setups
from hertzchain.precision import require_float64
from hertzchain.theory import discrete_fwhm_s, discrete_velocity_constant
from hertzchain.timegrid import MIN_STEPS_PER_CONTACT, TimeGrid, choose_time_grid, shortest_contact_time_s

from .data import Experiment
from .parameters import ParameterInstance

STEPS_PER_CONTACT = 400
# Narrowest block of Jacobian columns computed by directional forward mode (see
# `residuals_and_jacobian`).
_MIN_BLOCK = 8
# Steps per half period of an embedded sensor's resonance (a linear spring: velocity Verlet's
# frequency error is (omega dt)^2/24 = 6e-4 at 40 steps per half period).
SENSOR_STEPS_PER_HALF_PERIOD = 40
# Finest needed simulation sampling, as a fraction of the narrowest pulse's half-maximum width.
_SAMPLES_PER_FWHM = 40
# Margin on the striker velocity when the fixed time grid is chosen (the fit may raise it).
_VELOCITY_MARGIN = 1.5
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


@dataclasses.dataclass(frozen=True)
class _Group:
    experiments: tuple[int, ...]  # indices into Problem.experiments
    setups: ChainSetup  # stacked base setups (leading axis = experiments of the group)
    grid: TimeGrid
    recording: Recording
    channels: tuple[str, ...]  # simulated channel names, in output order
    global_index: tuple[int, ...]  # indices into x of global parameters reaching the simulator
    local_index: np.ndarray  # (n_experiments_in_group, n_local) indices into x


def interpolate(values, position):
    """Catmull-Rom cubic interpolation of `values` (n,) at fractional indices `position`.

    Positions outside [0, n-1] take the end values. Differentiable in both arguments
    (C^1 in `position`); the error for a smooth signal is O(h^3) in the sample spacing.
    """
    position = jnp.asarray(position)
    return interpolate_rows(jnp.asarray(values)[None], jnp.zeros(position.shape, jnp.int32), position)


def interpolate_rows(series, rows, position):
    """Catmull-Rom interpolation of `series[rows[j]]` (2-D) at fractional indices `position[j]`.

    The same rule as `interpolate`, for many series at once: one gather per neighbour.
    """
    n = series.shape[-1]
    q = jnp.clip(position, 0.0, n - 1.0)
    i = jnp.clip(jnp.floor(q).astype(jnp.int32), 0, n - 2)
    f = q - i
    flat = series.reshape(-1)
    base = jnp.asarray(rows) * n
    p0 = flat[base + jnp.clip(i - 1, 0, n - 1)]
    p1 = flat[base + i]
    p2 = flat[base + i + 1]
    p3 = flat[base + jnp.clip(i + 2, 0, n - 1)]
    return p1 + 0.5 * f * (
        (p2 - p0) + f * ((2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) + f * (3.0 * (p1 - p2) + p3 - p0))
    )


class Problem:
    """A least-squares problem: experiments, free parameters and the forward model.

    Build it with `make_problem`. The parameter vector `x` holds the physical values
    (SI) of `instances` in order.

    **Methods:** `residuals(x)` (whitened residual vector, jax), `predictions(x)` (per
    experiment, channel -> model on the data's time axis, numpy), `jacobian(x)`.

    `priors`: normal priors (`fitting.priors.NormalRow`), each appended to the residuals
    as $(x_i - \\mathrm{centre})/\\mathrm{sd}$ after the data's samples.

    A plain class, hashed by identity where it is a static argument of a compiled function
    (`_residuals_and_jacobian_jit`, the optimiser), not an `eqx.Module` whose arrays would be traced: what
    it holds is the structure of one compiled model (time grids and recordings chosen from
    the data, the sample layout, the group simulators jitted at construction), so every
    Problem is one compilation by design, and building it twice from the same files gives
    two. What varies between compiled calls is passed as arguments instead: the parameter
    vector, and the measured samples (`residuals(x, data)`, `fitting.fit_datasets`: one
    compiled fit over many data sets). It is never changed after construction
    (`with_setups` builds a new one).
    """

    def __init__(self, experiments, instances, base_setups, forward: ForwardModel, priors=()):
        require_float64("the fit's Problem")
        self.experiments: list[Experiment] = list(experiments)
        self.instances: tuple[ParameterInstance, ...] = tuple(instances)
        self.base_setups: list[ChainSetup] = list(base_setups)
        self.forward = forward
        self.priors = tuple(priors)
        self.labels = tuple(inst.label for inst in self.instances)
        self._index_nuisances()
        self.groups = self._make_groups(self.base_setups)
        self._simulators = [self._group_simulator(group) for group in self.groups]
        self._layout, self._order = self._sample_layout()

    # --- layout -------------------------------------------------------------------------------
    def _index_nuisances(self):
        self.offset_index: list[int | None] = [None] * len(self.experiments)
        self.gain_index: list[dict] = [{} for _ in self.experiments]
        self.global_sim: list[int] = []
        self.local_sim: list[list[int]] = [[] for _ in self.experiments]
        for i, inst in enumerate(self.instances):
            kind, scope = inst.spec.kind, inst.spec.scope
            if kind == "time_offset":
                self.offset_index[inst.experiment] = i
            elif kind == "gain" and scope == "sensor":
                for e, experiment in enumerate(self.experiments):
                    if inst.channel in experiment.channels:
                        self.gain_index[e][inst.channel] = i
            elif kind == "gain":
                self.gain_index[inst.experiment][inst.channel] = i
            elif scope == "global":
                self.global_sim.append(i)
            elif scope == "experiment":
                self.local_sim[inst.experiment].append(i)
            else:
                raise ValueError(f"{inst.label}: channel-scoped parameters must be gains.")

    def _sim_interval(self, experiment: Experiment, setup: ChainSetup) -> float:
        interval = float(experiment.trace.sample_interval_s)
        peak = max(float(np.max(experiment.data(c))) for c in experiment.channels)
        kappa = float(setup.contact_kappa()[min(1, setup.n_beads - 1)])
        mass = float(setup.bead_mass_kg[0])
        radius = float(setup.bead_radius_m[0])
        speed = float(discrete_velocity_constant(radius, mass, kappa)) * max(peak, 1e-6) ** (1 / 6)
        fwhm = discrete_fwhm_s(radius, speed)
        return interval / max(1, math.ceil(interval / (fwhm / _SAMPLES_PER_FWHM)))

    def _make_groups(self, setups) -> list[_Group]:
        keys: dict = {}
        for e, setup in enumerate(setups):
            key = (setup.n_beads, setup.end, setup.sensor_beads)
            keys.setdefault(key, []).append(e)
        groups = []
        offset_margin = max(
            [abs(self.instances[i].spec.lower) for i in self.offset_index if i is not None]
            + [abs(self.instances[i].spec.upper) for i in self.offset_index if i is not None]
            + [0.0]
        )
        for members in keys.values():
            contacts = sorted({k for e in members for k in self.experiments[e].trace.contacts})
            recording = Recording(contacts=tuple(contacts))
            channels = (
                tuple(f"contact_{k}" for k in contacts)
                + tuple(f"sensor_{b}" for b in setups[members[0]].sensor_beads)
                + ("wall",)
            )
            interval = min(self._sim_interval(self.experiments[e], setups[e]) for e in members)
            t_end = max(float(self.experiments[e].time_s[-1]) for e in members)
            t_end = t_end + offset_margin + 4 * interval
            t_end = interval * math.ceil(t_end / interval)
            margin = [
                eqx.tree_at(
                    lambda s: s.striker_velocity_m_s, setups[e],
                    setups[e].striker_velocity_m_s * _VELOCITY_MARGIN,
                )
                for e in members
            ]
            dt = time_step_s(stack_setups(margin), interval, steps_per_contact=self.forward.steps_per_contact)
            grid = choose_time_grid(stack_setups(margin), t_end_s=t_end, sample_interval_s=interval, dt_s=dt)
            n_local = len(self.local_sim[members[0]])
            local = np.array([self.local_sim[e] for e in members], dtype=int).reshape(len(members), n_local)
            groups.append(
                _Group(
                    experiments=tuple(members),
                    setups=stack_setups([setups[e] for e in members]),
                    grid=grid,
                    recording=recording,
                    channels=channels,
                    global_index=tuple(self.global_sim),
                    local_index=local,
                )
            )
        return groups

    def with_setups(self, setups) -> Problem:
        """The same problem with new base setups (new time grids chosen for them)."""
        return Problem(self.experiments, self.instances, setups, self.forward, self.priors)

    # --- the model ------------------------------------------------------------------------------
    def setup_at(self, x, experiment: int) -> ChainSetup:
        """The `ChainSetup` of one experiment at parameter values `x` (extras not included)."""
        setup = self.base_setups[experiment]
        indices = self.global_sim + self.local_sim[experiment]
        for i in sorted(indices, key=lambda i: self.instances[i].spec.stage):
            spec = self.instances[i].spec
            if spec.kind == "setup":
                setup = spec.apply(setup, jnp.asarray(x)[i])
        return setup

    def fast_path_flags(self, group: _Group):
        """The batched kernel's flags for `group`, or None where it takes `solve` under
        `vmap` (a custom forward model, a setup or a freed parameter the kernel lacks)."""
        form = self.forward.kernel
        if self.forward.simulate is not _default_simulate and form is None:
            return None
        indices = list(group.global_index) + [int(i) for i in np.ravel(group.local_index[:1])]
        specs = [self.instances[i].spec for i in indices]
        if any(spec.kind == "setup" and spec.name not in FAST_PATH_PHYSICS for spec in specs):
            return None
        switched_on = {FAST_PATH_PHYSICS[spec.name] for spec in specs if spec.kind == "setup"} - {None}
        if form is not None:
            switched_on |= form.physics({spec.name for spec in specs if spec.kind == "extra"})
        # a fit reads the recorded forces only: no running maxima, no energy books
        flags = kernel_flags(group.setups, switched_on=switched_on)._replace(ledger=False)
        if form is None:
            return flags
        # the law of the chain the extras make (a static field of the setup)
        applied = form.setup(jax.tree_util.tree_map(lambda a: a[0], group.setups), self.forward.extras_defaults)
        sensors = form.compliant_sensors(group.recording, self.forward.extras_defaults)
        return flags._replace(law=contact_law(applied), sensors=() if sensors is None else tuple(sensors.beads))

    def simulates_natively(self) -> bool:
        """Whether every group's simulation runs the C++ kernel (`hertzchain.native`) in a fit."""
        return all(
            flags is not None and native.kernel_for(flags, None) is not None
            for flags in map(self.fast_path_flags, self.groups)
        )

    def _group_simulator(self, group: _Group):
        global_specs = [self.instances[i].spec for i in group.global_index]
        local_specs = (
            [self.instances[i].spec for i in group.local_index[0]] if group.local_index.size else []
        )
        n_global = len(global_specs)
        forward = self.forward
        flags = self.fast_path_flags(group)

        def applied(setup, theta_global, theta_local):
            extras = dict(forward.extras_defaults)
            pairs = list(zip(global_specs, theta_global)) + list(zip(local_specs, theta_local))
            for spec, value in sorted(pairs, key=lambda pair: pair[0].stage):
                if spec.kind == "setup":
                    setup = spec.apply(setup, value)
                else:
                    extras[spec.name] = value
            return setup, extras

        def channels(forces_n, rest, axis):
            # what the channels read at rest (column 0), then the run
            series = jnp.stack([forces_n[name] for name in group.channels], axis=axis)
            start = jnp.broadcast_to(jnp.expand_dims(rest, (-2, -1)), series.shape[:-1] + (1,))
            return jnp.concatenate([start, series], axis=-1)

        def one(setup, theta_global, theta_local):
            setup, extras = applied(setup, theta_global, theta_local)
            traces = forward.simulate(setup, group.grid, group.recording, extras)
            # the static preload, unless the model says otherwise
            return channels(traces.forces_n, getattr(traces, "rest_n", setup.precompression_n), 0)

        # `jax.jit` on the heavy parts: an optimiser traces the residuals many times (init,
        # step, linearisation, covariance); the jitted simulation is traced once per shape
        # and lowered once, which cuts a fit's compile time severalfold.
        # Every function below takes C parameter sets at once (a leading axis: theta_global
        # (C, n_global), theta_local (C, n_experiments, n_local)) and returns
        # (C, n_experiments, n_channels, n_samples + 1); a fit passes C = 1, the posterior's
        # chains C > 1 (one simulation of C x n_experiments chains on the batched kernel).
        if flags is None:
            per_experiment = jax.vmap(one, in_axes=(0, None, 0))

            @jax.jit
            def batch(theta_global, theta_local):
                return jax.vmap(per_experiment, in_axes=(None, 0, 0))(group.setups, theta_global, theta_local)

            def jac_one(setup, theta_global, local):
                def f(p):
                    out = one(setup, p[:n_global], p[n_global:])
                    return out, out

                return jax.jacfwd(f, has_aux=True)(jnp.concatenate([theta_global, local]))

            @jax.jit
            def jacobian(theta_global, theta_local):
                per_chain = jax.vmap(jac_one, in_axes=(0, None, 0))
                return jax.vmap(per_chain, in_axes=(None, 0, 0))(group.setups, theta_global, theta_local)
        else:
            form = forward.kernel

            @jax.jit
            def batch(theta_global, theta_local):
                chains, experiments = theta_local.shape[:2]
                per_experiment = jax.vmap(applied, in_axes=(0, None, 0))
                setups, extras = jax.vmap(per_experiment, in_axes=(None, 0, 0))(group.setups, theta_global, theta_local)
                # chains x experiments on the kernel's batch axis
                setups, extras = jax.tree_util.tree_map(
                    lambda a: jnp.broadcast_to(a, (chains, experiments) + jnp.shape(a)[2:]).reshape(
                        (chains * experiments,) + jnp.shape(a)[2:]), (setups, extras))
                if form is None:
                    recording = group.recording
                else:
                    recording = form.recording(group.recording)
                    setups = jax.vmap(form.setup)(setups, extras)
                # one sample per loop iteration: a fit's batch is small, so the loop overhead
                # that longer unrolled blocks hide matters less than their compile time
                # (fit benchmark: 20 steps per block compiled in 6.7 s, one sample of 6 in 3.4 s,
                # the same run time)
                sensors = None if form is None else form.compliant_sensors(group.recording, extras)
                traces = record_batched(setups, group.grid, recording, flags,
                                        block_steps=group.grid.steps_per_sample, compliant_sensors=sensors)
                if form is None:
                    out = channels(traces.forces_n, setups.precompression_n, 1)
                else:
                    read = jax.vmap(form.readings, in_axes=(0, 0, 0, None, None))
                    out = channels(*read(traces.forces_n, setups, extras, group.grid, group.recording), 1)
                return out.reshape((chains, experiments) + out.shape[1:])

            @jax.jit
            def jacobian(theta_global, theta_local):
                # Experiments and parameter sets are independent, so one tangent that moves
                # a parameter of every experiment and every set at once gives each its own
                # derivative.
                def f(p):
                    out = batch(theta_global + p[:n_global], theta_local + p[n_global:])
                    return out, out

                return jax.jacfwd(f, has_aux=True)(jnp.zeros(n_global + theta_local.shape[2]))

        @jax.custom_jvp
        def simulate(theta_global, theta_local):
            return batch(theta_global, theta_local)

        @simulate.defjvp
        def simulate_jvp(primals, tangents):
            theta_global, theta_local = primals
            d_global, d_local = tangents
            if n_global + theta_local.shape[2] == 0:
                out = batch(theta_global, theta_local)
                return out, jnp.zeros_like(out)

            jac, out = jacobian(theta_global, theta_local)
            chains, experiments = theta_local.shape[:2]
            direction = jnp.concatenate(
                [jnp.broadcast_to(d_global[:, None, :], (chains, experiments, n_global)), d_local], axis=2
            )
            return out, jnp.einsum("cexsp,cep->cexs", jac, direction)

        return simulate, batch

    def simulated(self, x, *, directional: bool = False):
        """Simulated channels per group: list of (n_experiments, n_channels, n_samples + 1).

        Forward-mode derivatives: by default every simulator parameter's sensitivity is
        computed once per experiment whatever the tangent (the custom JVP above, best for a
        full Jacobian); with `directional=True` JAX's own forward mode pushes just the
        given tangents through the solver (best for a few columns).
        """
        return [output[0] for output in self.simulated_many(jnp.asarray(x)[None], directional=directional)]

    def simulated_many(self, xs, *, directional: bool = False):
        """`simulated` at C parameter vectors `xs` (C, p) in one simulation: list of
        (C, n_experiments, n_channels, n_samples + 1). On the batched kernel the C x
        n_experiments chains run as one batch, which costs much less than C simulations
        (`jax.vmap` of `simulated` would run them as C batches)."""
        xs = jnp.asarray(xs)
        outputs = []
        for group, (full, plain) in zip(self.groups, self._simulators):
            simulator = plain if directional else full
            theta_global = xs[:, np.asarray(group.global_index, dtype=int)]
            theta_local = xs[:, group.local_index] if group.local_index.size else jnp.zeros(
                (xs.shape[0], len(group.experiments), 0)
            )
            outputs.append(simulator(theta_global, theta_local))
        return outputs

    def _sample_layout(self):
        """Per group, where each residual's sample comes from (numpy, built once).

        For every sample of the group's experiments, in group order: the row of the
        group's (experiments x channels) output it reads, its data time, the indices
        into x of its experiment's trigger offset and its channel's gain (-1: none), and
        whether its channel is AC-coupled.
        `order` maps the concatenation of the groups' samples to the residual layout.
        """
        layouts, position = [], {}
        start = 0
        for e, experiment in enumerate(self.experiments):
            for name in experiment.channels:
                position[(e, name)] = start
                start += len(experiment.time_s)
        order = []
        for group in self.groups:
            rows, times, offsets, gains, ac = [], [], [], [], []
            for row, e in enumerate(group.experiments):
                experiment = self.experiments[e]
                n = len(experiment.time_s)
                offset = self.offset_index[e]
                for name in experiment.channels:
                    rows.append(np.full(n, row * len(group.channels) + group.channels.index(name)))
                    times.append(np.asarray(experiment.time_s, dtype=float))
                    offsets.append(np.full(n, -1 if offset is None else offset))
                    gains.append(np.full(n, self.gain_index[e].get(name, -1)))
                    ac.append(np.full(n, name in experiment.ac_channels))
                    order.append(np.arange(position[(e, name)], position[(e, name)] + n))
            layouts.append(tuple(np.concatenate(a) for a in (rows, times, offsets, gains, ac)))
        return layouts, np.argsort(np.concatenate(order))

    def model_from_outputs(self, x, outputs):
        """The model at every data sample, in residual layout (jax), from the simulated
        `outputs` of `simulated`: one gather per group."""
        x = jnp.asarray(x)
        x_or_default = lambda index, default: jnp.where(  # noqa: E731
            index >= 0, x[np.maximum(index, 0)], default
        )
        pieces = []
        for group, output, (rows, times, offsets, gains, ac) in zip(self.groups, outputs, self._layout):
            series = output.reshape(-1, output.shape[-1])  # (experiments * channels, samples)
            position = (times - x_or_default(offsets, 0.0)) / group.grid.sample_interval_s
            value = interpolate_rows(series, rows, position)
            if ac.any():  # the change since before the impact (column 0: the state at rest)
                value = value - jnp.where(ac, series[rows, 0], 0.0)
            pieces.append(value * x_or_default(gains, 1.0))
        return jnp.concatenate(pieces)[self._order]

    def data_vector(self) -> np.ndarray:
        """The measured samples of every fitted channel, concatenated like the residuals, N."""
        return np.concatenate([e.data(c) for e in self.experiments for c in e.channels])

    def sigma_vector(self) -> np.ndarray:
        """The noise sigma of every residual, N (inf for samples left out of the fit)."""
        return np.concatenate([
            np.where(e.used(c), e.noise_std_n[c], np.inf) for e in self.experiments for c in e.channels
        ])

    def model_vector(self, x):
        """The model of every fitted channel on the data's times, concatenated, N (jax)."""
        return self.model_from_outputs(x, self.simulated(x))

    def model_many(self, xs):
        """`model_vector` at C parameter vectors `xs` (C, p), one simulation: (C, n), N."""
        return jax.vmap(self.model_from_outputs)(jnp.asarray(xs), self.simulated_many(xs))

    def residuals(self, x, data=None, *, directional: bool = False):
        """Whitened residuals $(g F(t - t_{off}) - y)/\\sigma$ of every channel, concatenated.

        `data`: measured samples in `data_vector` layout (default: the experiments' own);
        passing it as an argument lets one compiled fit run over many data sets (noise seeds).
        `directional`: see `simulated`.
        """
        return self.residuals_from_outputs(x, self.simulated(x, directional=directional), data)

    def residuals_many(self, xs, data=None):
        """`residuals` at C parameter vectors `xs` (C, p), one simulation: (C, n)."""
        outputs = self.simulated_many(xs)
        return jax.vmap(lambda x, out: self.residuals_from_outputs(x, out, data))(jnp.asarray(xs), outputs)

    def residuals_from_outputs(self, x, outputs, data=None):
        """`residuals` from the simulated `outputs` of `simulated` (no simulation here)."""
        data = jnp.asarray(self.data_vector() if data is None else data)
        whitened = (self.model_from_outputs(x, outputs) - data) / jnp.asarray(self.sigma_vector())
        if not self.priors:
            return whitened
        index = np.array([row.index for row in self.priors])
        centre = np.array([row.centre for row in self.priors])
        sd = np.array([row.sd for row in self.priors])
        return jnp.concatenate([whitened, (jnp.asarray(x)[index] - centre) / sd])

    def reaches_simulator(self, column: int) -> bool:
        """Whether parameter `column` changes the simulation (not only offsets and gains)."""
        return column in self.global_sim or any(column in local for local in self.local_sim)

    def predictions(self, x) -> list[dict]:
        """Model of every fitted channel on the data's time axis (numpy), per experiment."""
        model = np.asarray(self._compiled_model_vector(x))
        return [{name: model[part] for name, part in parts.items()} for parts in self.residual_slices()]

    @functools.cached_property
    def _compiled_model_vector(self):
        # one compilation per Problem (a new `jax.jit` wrapper per call would compile again)
        return jax.jit(self.model_vector)

    def residual_slices(self) -> list[dict]:
        """Per experiment, channel -> slice of the residual vector."""
        slices, start = [], 0
        for experiment in self.experiments:
            entry = {}
            for name in experiment.channels:
                n = len(experiment.time_s)
                entry[name] = slice(start, start + n)
                start += n
            slices.append(entry)
        return slices

    @property
    def n_residuals(self) -> int:
        """Length of the residual vector (every sample of every fitted channel, then one
        row per normal prior)."""
        return sum(e.n_residuals for e in self.experiments) + len(self.priors)

    @property
    def n_fitted(self) -> int:
        """Residuals that count (clipped samples left out, prior rows in): the chi^2's
        number of terms."""
        return sum(e.n_fitted for e in self.experiments) + len(self.priors)

    def check_resolution(self, x) -> list[str]:
        """Experiments whose fitted setup is resolved by fewer than half the asked steps."""
        coarse = []
        for group in self.groups:
            for e in group.experiments:
                setup = self.setup_at(np.asarray(x), e)
                needed = time_step_s(setup, group.grid.sample_interval_s,
                                     steps_per_contact=self.forward.steps_per_contact)
                if group.grid.dt_s > 2 * needed:
                    coarse.append(self.experiments[e].label)
        return coarse


def residuals_and_jacobian(problem: Problem, x, columns=None):
    """Whitened residual vector r (n,) and its Jacobian dr/dx (n, p) at physical values x.

    The Jacobian is with respect to the physical (SI) values of `problem.instances`;
    residuals are divided by each channel's noise sigma, so $J^T J$ is the Fisher
    information for the stated noise.

    `columns`: compute only these columns of the Jacobian (the others are NaN). The
    solver is then differentiated along just the requested directions that reach it
    (`Problem.simulated(directional=True)`, in a block of at least 8 columns whose width is
    rounded up to a power of two, so that few sizes compile: a compilation costs as much as
    tens of evaluations), and offsets and gains with the simulation held;
    much cheaper than the full Jacobian when a few of many simulator parameters are free.
    """
    x = jnp.asarray(x, dtype=jnp.float64)
    if columns is None:
        r, jac = _residuals_and_jacobian_jit(problem, x)
        return np.asarray(r), np.asarray(jac)
    columns = [int(c) for c in columns]
    through = [c for c in columns if problem.reaches_simulator(c)]
    after = [c for c in columns if not problem.reaches_simulator(c)]
    bases = []
    for chosen in (through, after):
        width = max(_MIN_BLOCK, 1 << max(len(chosen) - 1, 0).bit_length())
        basis = np.zeros((len(problem.instances), width))
        basis[chosen, np.arange(len(chosen))] = 1.0
        bases.append(jnp.asarray(basis))
    r, block_through, block_after = (np.asarray(a) for a in _columns_jit(problem, x, *bases))
    jac = np.full((problem.n_residuals, len(problem.instances)), np.nan)
    jac[:, through] = block_through[:, : len(through)]
    jac[:, after] = block_after[:, : len(after)]
    return r, jac


@eqx.filter_jit
def _residuals_and_jacobian_jit(problem, x):
    """r and dr/dx from one simulation: the residuals are the primal of the Jacobian's
    forward-mode run (the C++ kernel returns the forces with their tangents)."""

    def both(x):
        r = problem.residuals(x)
        return r, r

    jac, r = jax.jacfwd(both, has_aux=True)(x)
    return r, jac


@eqx.filter_jit
def _columns_jit(problem, x, through_basis, after_basis):
    """r at x and d r(x + B z)/dz at z = 0 for two bases, from one simulation: through the
    solver's forward mode for `through_basis`, with the simulation held for `after_basis`
    (offsets and gains)."""

    def through(z):
        shifted = x + through_basis @ z
        outputs = problem.simulated(shifted, directional=True)
        r = problem.residuals_from_outputs(shifted, outputs)
        return r, (r, outputs)

    block_through, (r, outputs) = jax.jacfwd(through, has_aux=True)(jnp.zeros(through_basis.shape[1]))
    block_after = jax.jacfwd(lambda z: problem.residuals_from_outputs(x + after_basis @ z, outputs))(
        jnp.zeros(after_basis.shape[1])
    )
    return r, block_through, block_after
