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

The model's units, one concept a module: this one holds `Problem` (the residual assembly)
and its Jacobian; `fitting.forward_model` how predictions are made (`ForwardModel`,
`KernelForm`, `time_step_s`), `fitting.simulation_groups` which experiments share a
simulation and where each parameter acts, `fitting.group_simulator` one group's compiled
simulation and its custom JVP, `fitting.sampling` the interpolation onto the data's samples
and the residual vector's layout.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from hertzchain import native
from hertzchain.batched import kernel_rows
from hertzchain.chain import ChainSetup
from hertzchain.precision import require_float64

from .data import Experiment
from .forward_model import (  # noqa: F401  (the forward model's names, importable from here too)
    FAST_PATH_PHYSICS,
    SENSOR_STEPS_PER_HALF_PERIOD,
    STEPS_PER_CONTACT,
    ForwardModel,
    KernelForm,
    time_step_s,
)
from .group_simulator import fast_path_flags, group_simulator
from .parameters import ParameterInstance
from .sampling import interpolate, interpolate_rows, residual_slices, sample_layout  # noqa: F401
from .simulation_groups import _Group, coarse_experiments, make_groups, parameter_index

# Narrowest block of Jacobian columns computed by directional forward mode (see
# `residuals_and_jacobian`).
_MIN_BLOCK = 8


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
        self.offset_index, self.gain_index, self.global_sim, self.local_sim = parameter_index(
            self.experiments, self.instances)
        self.groups = make_groups(self, self.base_setups)
        self._simulators = [group_simulator(self, group) for group in self.groups]
        self._layout, self._order = sample_layout(self)

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
        `vmap` (`fitting.group_simulator.fast_path_flags`)."""
        return fast_path_flags(self, group)

    def simulates_natively(self) -> bool:
        """Whether every group's simulation runs the C++ kernel (`hertzchain.native`) in a fit
        (on a GPU, the thread kernel of the group's chain length is built to answer)."""
        return all(
            flags is not None and native.kernel_for(flags, None, kernel_rows(group.setups)) is not None
            for flags, group in zip(map(self.fast_path_flags, self.groups), self.groups, strict=True)
        )

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

    def model_from_outputs(self, x, outputs):
        """The model at every data sample, in residual layout (jax), from the simulated
        `outputs` of `simulated`: one gather per group."""
        x = jnp.asarray(x)
        x_or_default = lambda index, default: jnp.where(
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
        """Per experiment, channel -> slice of the residual vector (`sampling.residual_slices`)."""
        return residual_slices(self.experiments)

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
        """Experiments whose fitted setup is resolved by fewer than half the asked steps
        (`simulation_groups.coarse_experiments`)."""
        return coarse_experiments(self, x)


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
