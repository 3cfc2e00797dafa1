"""Fits of driven chains to lock-in frequency x drive sweeps (`kind = "driven"` experiments).

The model is `hertzchain.driven.lockin_grid`: every (frequency, drive) point of the sweep is
one run from the static equilibrium with a smooth amplitude ramp, and the lock-in reads the
sensed bead's RMS velocity at the drive frequency over whole periods. Its parameters:

- `linear_resonance_hz`: the linearised chain's mode frequencies (one per bead, n = 1 or 2).
  With the precompression they fix the contacts' Hertz constants: a contact of tangent
  stiffness k under F0 has $\\kappa = (k / (1.5 F_0^{1/3}))^{3/2}$. One bead: both contacts
  scale together (their nominal ratio kept), $k_0 + k_1 = m\\omega^2$. Two equal beads:
  the face and wall contacts scale together ($k_0 = k_2 = a$), the bead-bead contact alone
  ($b$): $\\omega_1^2 = a/m$, $\\omega_2^2 = (a + 2b)/m$.
- `precompression_n`: the effective static force $F_0$; at a fixed linear resonance it sets
  the static overlap $\\delta_0 = 1.5 F_0 / k$, and so how strongly the resonance bends.
- `damping_rate_per_s`: the viscous rate $\\gamma$ of every bead (force $-m\\gamma v$).
- `drive_scale`: the piezo's true amplitude over the nominal one (the file's m/V).
- `eta_s` (diagnosis only): Kuwabara-Kono damping time of every contact, a loss that grows
  with the contacts' motion.

Residuals are (model - measured) / each curve's peak, over every frequency the experiment
file does not exclude and every drive level, divided by `NOMINAL_SCALE` so that the
optimiser's tolerance (`fitting.least_squares`, Levenberg-Marquardt of optimistix) is in
sensible units. Standard errors: the Gauss-Newton covariance scaled by the residual variance
and inflated for the residuals' correlation along frequency: with $\\rho$ the lag-1
autocorrelation of the residuals within each curve (pooled), the effective number of
independent points is $n (1-\\rho)/(1+\\rho)$ (an AR(1) noise), so the covariance is
$\\chi^2/(n-p) \\cdot (1+\\rho)/(1-\\rho) \\cdot (J^TJ)^{-1}$.
"""

from __future__ import annotations

import dataclasses
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from hertzchain.driven import DrivenChain, lockin_grid
from hertzchain.driven.linear import frequency_response, normal_modes
from hertzchain.native import kernel_record
from hertzchain.peaks import frequency_response_peaks
from hertzchain.progress import Progress

from ..least_squares import least_squares
from ..uncertainty import ar1_correlation, ar1_inflation, covariance_from_jacobian
from .experiment import DrivenExperiment

# Residuals (fractions of a curve's peak) are divided by this before the optimiser sees them,
# so that its tolerance (0.1 in chi^2) means about a third of a standard error: on measured
# sweeps the misfit is a few % of a peak, correlated over ~50 points along frequency (lag-1
# correlation ~0.96), so a point's effective standard deviation is 3 % x sqrt(1.96/0.04) ~ 0.2.
NOMINAL_SCALE = 0.2
# A fit first runs on every COARSE_ROW_STRIDE-th frequency of every COARSE_LEVEL_STRIDE-th drive
# level (36 levels: 1, 8, ..., 36, the lowest and the highest among them), then on all from there:
# the optimiser's slow early iterations (the effective precompression moves by a factor ~30
# from the file's) cost a twentieth as much.
COARSE_ROW_STRIDE = 3
COARSE_LEVEL_STRIDE = 7
PARAMETERS = ("linear_resonance_hz", "precompression_n", "damping_rate_per_s", "drive_scale", "eta_s")
UNITS = {"linear_resonance_hz": "Hz", "precompression_n": "N", "damping_rate_per_s": "1/s", "drive_scale": "1",
         "eta_s": "s"}
# Lower bounds the optimiser's values are clipped to (a projected Levenberg-Marquardt).
_LOWER = {"linear_resonance_hz": 1.0, "precompression_n": 1e-4, "damping_rate_per_s": 0.0, "drive_scale": 1e-3,
          "eta_s": 0.0}


@dataclasses.dataclass(frozen=True)
class DrivenLayout:
    """Which entry of the parameter vector x is which: `labels` (p,) like
    `linear_resonance_hz[1]`, `names` (p,) the parameter of each entry."""

    labels: tuple
    names: tuple

    @classmethod
    def for_beads(cls, n_beads: int) -> DrivenLayout:
        if n_beads not in (1, 2):
            raise ValueError(f"n_beads = {n_beads}: driven fits parametrise the modes of one or two beads.")
        modes = ["linear_resonance_hz"] if n_beads == 1 else [f"linear_resonance_hz[{j}]" for j in (1, 2)]
        labels = tuple(modes + list(PARAMETERS[1:]))
        names = tuple(label.split("[")[0] for label in labels)
        return cls(labels, names)

    def index(self, name: str) -> list[int]:
        return [i for i, n in enumerate(self.names) if n == name]

    def lower(self) -> np.ndarray:
        return np.array([_LOWER[n] for n in self.names])


def chain_at(experiment: DrivenExperiment, x) -> DrivenChain:
    """The `DrivenChain` of parameter vector `x` (see the module docstring; traceable)."""
    layout = DrivenLayout.for_beads(experiment.n_beads)
    x = jnp.asarray(x)
    modes = x[jnp.asarray(layout.index("linear_resonance_hz"))]
    precompression = x[layout.index("precompression_n")[0]]
    gamma = x[layout.index("damping_rate_per_s")[0]]
    eta = x[layout.index("eta_s")[0]]
    mass = jnp.asarray(experiment.bead_mass_kg)
    nominal = jnp.asarray(experiment.contact_kappa_n_m1p5)
    omega2 = (2 * jnp.pi * modes) ** 2
    if experiment.n_beads == 1:
        ratio = nominal ** (2 / 3) / jnp.sum(nominal ** (2 / 3))  # each contact's share of k0 + k1
        stiffness = mass[0] * omega2[0] * ratio
    else:
        a = mass[0] * omega2[0]
        b = 0.5 * (mass[0] * omega2[1] - a)
        stiffness = jnp.stack([a, b, a])
    kappa = (stiffness / (1.5 * precompression ** (1 / 3))) ** 1.5
    return DrivenChain(mass, kappa, precompression, gamma * jnp.ones_like(mass), eta)


def check_layout(experiment: DrivenExperiment) -> None:
    """Refuse setups the mode parametrisation does not cover (two beads of unequal mass or
    unequal face and wall contacts)."""
    DrivenLayout.for_beads(experiment.n_beads)
    if experiment.n_beads == 2:
        kappa, mass = experiment.contact_kappa_n_m1p5, experiment.bead_mass_kg
        if mass[0] != mass[1] or not math.isclose(kappa[0], kappa[2], rel_tol=1e-9):
            raise ValueError(
                f"{experiment.path}: two-bead fits take equal beads and equal face and wall contacts "
                "(the modes then fix both stiffnesses); give equal bead_mass_kg and face/wall materials."
            )


def nominal_modes_hz(experiment: DrivenExperiment) -> np.ndarray:
    """The linearised chain's mode frequencies (Hz) at the file's nominal constants."""
    chain = DrivenChain(experiment.bead_mass_kg, experiment.contact_kappa_n_m1p5, experiment.precompression_n, 0.0)
    return np.asarray(normal_modes(chain)[0])


@dataclasses.dataclass
class DrivenModel:
    """Residuals of one driven experiment and their Jacobian (the `model` of
    `fitting.least_squares`), on the fitted frequencies x all drive levels.

    `rows`: indices of the frequencies used (default: the file's fit mask), `levels`: the
    drive levels used (default all). Each evaluation is one batched `lockin_grid` run, and
    with the Jacobian one more that carries every column in forward mode (on the CPU both are
    calls of the fused kernel, `hertzchain.driven.fused`). `progress`: a
    `hertzchain.progress.Progress` noting each linearisation's median misfit, or None.
    """

    experiment: DrivenExperiment
    rows: np.ndarray | None = None
    levels: np.ndarray | None = None
    progress: Progress | None = None

    def __post_init__(self):
        check_layout(self.experiment)
        e = self.experiment
        self.layout = DrivenLayout.for_beads(e.n_beads)
        self.rows = np.nonzero(e.fit_mask)[0] if self.rows is None else np.asarray(self.rows)
        self.levels = np.arange(e.sweep.drive_amplitudes_m.size) if self.levels is None else np.asarray(self.levels)
        measured = e.sweep.rms_velocity_m_s
        self.peaks = measured.max(axis=0)[self.levels]  # each curve's peak, over all its frequencies
        self.measured = measured[np.ix_(self.rows, self.levels)]
        self.frequencies = jnp.asarray(e.sweep.frequencies_hz[self.rows])
        self.drives = jnp.asarray(e.sweep.drive_amplitudes_m[self.levels])
        self.evaluations = 0

    def clip(self, x) -> np.ndarray:
        return np.maximum(np.asarray(x, dtype=float), self.layout.lower())

    def curves(self, x) -> np.ndarray:
        """Model RMS velocity (m/s), (frequencies, levels)."""
        return np.asarray(_grid(self.experiment, self.clip(x), self.frequencies, self.drives))

    def residuals(self, x) -> np.ndarray:
        r = (self.curves(x) - self.measured) / self.peaks
        return r.ravel() / NOMINAL_SCALE

    def linearize(self, x, columns):
        x = self.clip(x)
        directions = np.zeros((len(columns), x.size))
        directions[np.arange(len(columns)), list(columns)] = 1.0
        value, tangents = _grid_jvp(self.experiment, x, self.frequencies, self.drives, jnp.asarray(directions))
        r = ((np.asarray(value) - self.measured) / self.peaks).ravel() / NOMINAL_SCALE
        jac = (np.asarray(tangents) / self.peaks).reshape(len(columns), -1).T / NOMINAL_SCALE
        self.evaluations += 1
        if self.progress is not None:
            misfit = np.median(np.sqrt(np.mean((r.reshape(self.measured.shape) * NOMINAL_SCALE) ** 2, axis=0)))
            self.progress.note(f"evaluation {self.evaluations}: median misfit {100 * misfit:.2f} % of peak")
        return r, jac


def lockin_settings(experiment) -> dict:
    """The read-out keywords of `hertzchain.driven.lockin_grid` for `experiment`: its sensor
    bead and quantity, the drive frequency alone, and its model's ramp, hold, window and
    steps per period."""
    m = experiment.model
    return {"bead": experiment.sensor_bead, "quantity": experiment.quantity, "harmonics": (1.0,),
            "ramp_periods": m["ramp_periods"], "hold_periods": m["hold_periods"],
            "window_periods": m["window_periods"], "steps_per_period": m["steps_per_period"]}


def _scale_index(experiment):
    return DrivenLayout.for_beads(experiment.n_beads).index("drive_scale")[0]


def _grid(experiment, x, frequencies, drives):
    chain = chain_at(experiment, x)
    scale = x[_scale_index(experiment)]
    return lockin_grid(chain, frequencies, drives * scale, **lockin_settings(experiment)).rms[0]


@eqx.filter_jit
def _grid_jvp_compiled(settings, n_beads, bead_mass_kg, kappa, scale_index, x, frequencies, drives, directions):
    def curves(xx):
        layout_experiment = _Constants(n_beads, bead_mass_kg, kappa)
        chain = chain_at(layout_experiment, xx)
        return lockin_grid(chain, frequencies, drives * xx[scale_index], **dict(settings)).rms[0]

    # the values once (they do not vary along the directions), the tangents of every direction
    return jax.vmap(lambda d: jax.jvp(curves, (x,), (d,)), out_axes=(None, 0))(directions)


@dataclasses.dataclass(frozen=True)
class _Constants:
    """The parts of a `DrivenExperiment` that `chain_at` reads (a hashable stand-in in jit)."""

    n_beads: int
    bead_mass_kg: object
    contact_kappa_n_m1p5: object


def _grid_jvp(experiment, x, frequencies, drives, directions):
    settings = tuple(sorted(lockin_settings(experiment).items()))
    return _grid_jvp_compiled(settings, experiment.n_beads, jnp.asarray(experiment.bead_mass_kg),
                              jnp.asarray(experiment.contact_kappa_n_m1p5), _scale_index(experiment),
                              jnp.asarray(x), frequencies, drives, directions)


# --- start values ------------------------------------------------------------------------------
def linear_start(experiment: DrivenExperiment) -> np.ndarray:
    """Start values from the lowest drive's curve read as a linear chain's response: each
    mode's frequency at its peak, the damping rate from the first mode's half-power width,
    the drive scale from the first peak's height over the linear chain's response there; the
    precompression at the file's, eta_s 0."""
    layout = DrivenLayout.for_beads(experiment.n_beads)
    sweep = experiment.sweep
    f = sweep.frequencies_hz[experiment.fit_mask]  # the excluded frequencies left out
    curve = sweep.rms_velocity_m_s[experiment.fit_mask, 0]
    try:
        modes = frequency_response_peaks(f, curve, experiment.n_beads)
    except ValueError as error:
        raise ValueError(f"{experiment.path}: the lowest drive's curve: {error}") from None
    first = int(np.argmin(np.abs(f - modes[0])))
    half = curve[first] / math.sqrt(2)
    lo, hi = first, first
    while lo > 0 and curve[lo] > half:
        lo -= 1
    while hi < f.size - 1 and curve[hi] > half:
        hi += 1
    gamma = 2 * math.pi * max(f[hi] - f[lo], 2 * (f[1] - f[0]))
    x = np.zeros(len(layout.labels))
    x[layout.index("linear_resonance_hz")] = modes
    x[layout.index("precompression_n")] = experiment.precompression_n
    x[layout.index("damping_rate_per_s")] = gamma
    x[layout.index("eta_s")] = 0.0
    x[layout.index("drive_scale")] = 1.0
    response, _ = frequency_response(chain_at(experiment, x), np.array([f[first]]))
    velocity_per_m = abs(complex(response[0, experiment.sensor_bead - 1])) * 2 * math.pi * f[first] / math.sqrt(2)
    x[layout.index("drive_scale")] = curve[first] / (velocity_per_m * sweep.drive_amplitudes_m[0])
    return x


# --- results -----------------------------------------------------------------------------------
@dataclasses.dataclass
class DrivenFit:
    """A fitted driven experiment, with the status keys of every fit (`fitting.fit_result.FitResult`'s).

    **Fields:** `labels`, `x` (p,), `stderr` (p,) (NaN where held), `free` (indices fitted);
    `converged` (the shared test of an optimum, `fitting.optimum`) and `message`; `steps`
    (optimiser iterations, both grids); `chi2`, `dof`, `reduced_chi2` of the residuals the
    optimiser saw (fractions of each curve's peak / `NOMINAL_SCALE`, every point); `rho` (their
    lag-1 correlation along frequency), `n_effective`; `correlation` of the fitted columns;
    `model_curves` (F, A) m/s RMS on every frequency; `misfit` (A,) RMS of (model - measured)
    over each curve's fitted frequencies / its peak; `kernel` (`hertzchain.native.kernel_record`:
    which kernel computed the curves); `elapsed_s`."""

    experiment: DrivenExperiment
    labels: tuple
    x: np.ndarray
    stderr: np.ndarray
    free: list
    converged: bool
    message: str
    steps: int
    chi2: float
    dof: int
    reduced_chi2: float
    rho: float
    n_effective: float
    correlation: np.ndarray
    model_curves: np.ndarray
    misfit: np.ndarray
    kernel: dict
    elapsed_s: float


def fit_driven(experiment: DrivenExperiment, *, free=("linear_resonance_hz", "precompression_n",
                                                      "damping_rate_per_s", "drive_scale"),
               x_start=None, max_steps: int = 100, progress: bool = True, precompression_grid=None) -> DrivenFit:
    """Fit the parameters `free` (names of `PARAMETERS`) to a driven experiment.

    Starts from `x_start` (default: `linear_start`, then the best of `precompression_grid`
    (N) on the coarse grid, when the precompression is free). With 14 drive levels or
    more the fit runs first on a coarse grid (`COARSE_ROW_STRIDE`, `COARSE_LEVEL_STRIDE`),
    then on every point from there, by the shared least squares (`fitting.least_squares`) and
    its test of an optimum. `max_steps` optimiser iterations per stage (the fitting
    commands' default, `--max-steps`); each costs one batched grid run and its forward-mode
    tangents. The two-bead sweep of `examples/lydon2015` takes 31 on the coarse grid and 64 on
    every point, where each step lowers chi^2 by under 1 % (30 stopped at chi^2 1713, the
    optimum's is 1562). `progress`: notes on stderr (`hertzchain.progress.Progress`).
    """
    began = time.perf_counter()
    report = Progress(None, "driven fit") if progress else None
    layout = DrivenLayout.for_beads(experiment.n_beads)
    for name in free:
        if name not in PARAMETERS:
            raise ValueError(f"free: {name!r} is not a driven parameter; valid: {', '.join(PARAMETERS)}.")
    columns = [i for i, n in enumerate(layout.names) if n in free]
    x = linear_start(experiment) if x_start is None else np.array(x_start, dtype=float)
    if x_start is None and "precompression_n" in free:
        x = scan_precompression(experiment, x, precompression_grid, progress=report)
    model = DrivenModel(experiment, progress=report)
    if report is not None:
        report.note(f"fitting {', '.join(layout.labels[c] for c in columns)} to {model.measured.size} points")
    # on every point, the optimiser stops when no step gains a third of a standard error: 0.1 in
    # chi^2 of independent points of unit variance is 0.1 s^2 (1 + rho)/(1 - rho) in chi^2 of these
    # residuals, which are fractions of each curve's peak (variance s^2: no noise level is known)
    # correlated along frequency (lag-1 correlation rho). Both are read where the last pass ended
    # (far from an optimum the residuals are all correlated and s^2 too large), so the fit runs
    # again from there while s^2 still fell by more than half (3 passes at most).
    def variance_and_tolerance(x):
        residuals = model.residuals(x)
        inflation = ar1_inflation(ar1_correlation(residuals.reshape(model.measured.shape)))
        variance = float(residuals @ residuals) / max(residuals.size - len(columns), 1)
        return variance, 0.1 * variance * inflation

    every_point = np.ones(model.measured.size)  # the weights: every point counts
    # a given start can be the optimum already (a refit from a saved result): it is tested on
    # every point first (one linearisation), where the coarse grid's optimum would lead away
    if x_start is not None and least_squares(model, x, columns, max_steps=0, weights=every_point,
                                             tolerance=variance_and_tolerance(x)[1]).converged:
        return finish_fit(model, x, columns, True, 0, max_steps, began)
    steps = 0
    if model.levels.size >= 2 * COARSE_LEVEL_STRIDE:  # first on a coarse grid: a twentieth of the cost
        coarse = DrivenModel(experiment, rows=model.rows[::COARSE_ROW_STRIDE], levels=model.levels[::COARSE_LEVEL_STRIDE],
                             progress=report)
        first = least_squares(coarse, x, columns, max_steps=max_steps, extrapolate=True)
        x, steps = coarse.clip(first.x), first.steps
    variance = np.inf
    for _ in range(3):
        previous, (variance, tolerance) = variance, variance_and_tolerance(x)
        if variance > 0.5 * previous:
            break
        result = least_squares(model, x, columns, max_steps=max_steps, extrapolate=True, tolerance=tolerance,
                               weights=every_point)
        x, steps = model.clip(result.x), steps + result.steps
    return finish_fit(model, x, columns, result.converged, steps, max_steps, began)


def scan_precompression(experiment, x, grid=None, *, progress: Progress | None = None) -> np.ndarray:
    """`x` with the precompression set to the best of `grid` (N; default 12 values from 0.01 to
    10 N), each scored on the coarse grid of `fit_driven` with the other parameters at `x`;
    `progress`: a `Progress` noting each value's chi^2, or None."""
    layout = DrivenLayout.for_beads(experiment.n_beads)
    grid = np.geomspace(0.01, 10.0, 12) if grid is None else np.asarray(grid, dtype=float)
    rows = np.nonzero(experiment.fit_mask)[0][::COARSE_ROW_STRIDE]
    levels = np.arange(0, experiment.sweep.drive_amplitudes_m.size, COARSE_LEVEL_STRIDE)
    model = DrivenModel(experiment, rows=rows, levels=levels)
    best, best_chi2 = x, math.inf
    for value in grid:
        trial = x.copy()
        trial[layout.index("precompression_n")] = value
        r = model.residuals(trial)
        chi2 = float(r @ r)
        if progress is not None:
            progress.note(f"start: F0 = {value:.3g} N, chi^2 = {chi2:.4g}")
        if chi2 < best_chi2:
            best, best_chi2 = trial, chi2
    return best


def finish_fit(model: DrivenModel, x, columns, converged, steps, max_steps, began) -> DrivenFit:
    """Status, standard errors (inflated for correlated residuals), curves on every frequency,
    misfits. `max_steps`: the limit the optimiser ran under (for the message)."""
    experiment = model.experiment
    x = model.clip(x)
    r, jac = model.linearize(x, columns)
    chi2 = float(r @ r)
    n, p = r.size, len(columns)
    resid = r.reshape(model.measured.shape) * NOMINAL_SCALE
    rho = ar1_correlation(resid)
    inflation = ar1_inflation(rho)
    labels = DrivenLayout.for_beads(experiment.n_beads).labels
    dof = n - p
    cov = covariance_from_jacobian(jac, [labels[c] for c in columns], chi2=chi2 * inflation, dof=dof,
                                   scale="residual")
    stderr = np.full(x.size, np.nan)
    stderr[columns] = cov.stderr
    everything = DrivenModel(experiment, rows=np.arange(experiment.sweep.frequencies_hz.size))
    curves = everything.curves(x)
    measured = experiment.sweep.rms_velocity_m_s
    fitted = experiment.fit_mask
    misfit = np.sqrt(np.mean((curves[fitted] - measured[fitted]) ** 2, axis=0)) / measured.max(axis=0)
    message = "converged" if converged else (
        f"no optimum reached within {max_steps} steps per stage (chi^2 = {chi2:.6g} after {int(steps)} steps, "
        "and a step still lowers it by more than the test's tolerance); raise --max-steps or fit fewer parameters.")
    return DrivenFit(experiment, labels, x, stderr, list(columns), bool(converged), message, int(steps), chi2, dof,
                     chi2 / dof if dof > 0 else math.nan, rho, n / inflation, cov.correlation, curves,
                     misfit, kernel_record(), time.perf_counter() - began)
