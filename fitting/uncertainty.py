"""Standard errors, correlations, identifiability and profile likelihoods of a fit.

Covariance. With whitened residuals $r = (\\text{model} - y)/\\sigma$ and their Jacobian
$J$ at the optimum (with respect to the physical parameter values), the Gauss-Newton
covariance is $s^2 (J^T J)^{-1}$. Two choices of $s^2$:

- `"noise"`: $s^2 = 1$, i.e. the noise sigma of each channel is taken as known. This is
  right when the files state `noise_std_n` and the model is adequate; the reduced
  $\\chi^2$ is then reported as a check (about 1 for an adequate model).
- `"residual"`: $s^2 = \\chi^2/\\mathrm{dof}$, i.e. the noise level is re-estimated from
  the fit's residuals (the usual least-squares choice when sigma is not known, and a
  guard against underestimated noise or a model that misses something).

- `"correlated"`: the sandwich $(J^T J)^{-1} B (J^T J)^{-1}$ with $B$ the Newey-West
  (Bartlett-weighted) estimate of the covariance of the score $J^T r$ from the residuals
  themselves, summed over each channel's series up to a lag of the impact's duration in
  samples (`correlated_score_covariance`). It holds where the residuals are correlated
  from sample to sample, as a converter's error is for a slowly moving signal when the
  analogue noise is below half a step (`hertzchain.io.importer.DITHER_STEPS`); for white
  residuals it equals `"residual"` up to its own sampling noise.

`"auto"` (default) uses `"correlated"` where a fitted channel was recorded with analogue
noise below half a converter step (the importer measures it), else `"noise"` unless the
residuals contradict the noise estimate:
`noise_band(dof)` is the range of $\\chi^2/\\mathrm{dof}$ they allow, the $\\chi^2$
distribution's own width, 3 $\\sqrt{2/\\mathrm{dof}}$ on each side, around
[1/(1 + `MODEL_ERROR_ALLOWANCE`), 1 + `MODEL_ERROR_ALLOWANCE`]. The allowance (0.25:
the residual RMS within about 12 % of the stated sigma) covers what a noise estimate
from a few hundred pre-trigger samples (its variance is uncertain by sqrt(2/m), 6-9 % for
m = 250-500), a calibration or the model's conventions (time step, friction law) can
err by without the model being wrong. Outside the band the covariance is scaled by
$\\chi^2/\\mathrm{dof}$, both ways (a noise estimate 1.5 times too large in sigma gives
$\\chi^2/\\mathrm{dof}$ = 0.45 and standard errors 1.5 times too wide), and
`covariance_choice` says why.

Identifiability. The columns of $J$ are normalised to unit length and decomposed by SVD;
a singular value below `DEGENERATE_RATIO` times the largest marks a combination of
parameters the data cannot constrain, and the parameters taking part in it are named.
Pairs with |correlation| above `CORRELATION_LIMIT`, parameters with a relative standard
error above `RELATIVE_ERROR_LIMIT`, and parameters at a bound are reported too. One
degeneracy is known exactly (a scaling symmetry of the Hertz law, checked by
tests/test_fit_identifiability.py): a uniform stiffness scale (C or mu*) together with a free striker velocity and free gains of all of a file's channels,
$F(t; \\lambda\\kappa, V_0) = \\lambda^{-2} F(t; \\kappa, \\lambda^2 V_0)$ for a
dissipationless chain; it is named whenever the chosen parameters contain it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from hertzchain.covariance import DEGENERATE_RATIO, PARTICIPATION, gauss_newton_covariance  # noqa: F401

CORRELATION_LIMIT = 0.99
RELATIVE_ERROR_LIMIT = 0.5
# Share by which chi^2/dof may differ from 1 (either way) before the residuals are taken to
# contradict the noise estimate (module docstring); and the width of the chi^2 distribution
# added on each side, in its standard deviations sqrt(2/dof).
MODEL_ERROR_ALLOWANCE = 0.25
NOISE_BAND_SIGMA = 3.0
# Residuals correlated along a series (a curve over frequency or time) are taken as an AR(1)
# noise of lag-1 correlation rho in [0, AR1_LIMIT]: anticorrelated residuals are credited with
# no more information than white ones, and the inflation stays finite.
AR1_LIMIT = 0.999


def lag1_autocorrelation(residuals) -> float:
    """Pooled lag-1 autocorrelation of `residuals` along their first axis (each column one
    series, e.g. a lock-in curve over frequency)."""
    r = np.asarray(residuals)
    r = r - r.mean(axis=0)
    return float(np.sum(r[1:] * r[:-1]) / np.sum(r * r))


def ar1_correlation(residuals) -> float:
    """The lag-1 correlation of `residuals` (`lag1_autocorrelation`) as an AR(1) noise's,
    clipped to [0, AR1_LIMIT]."""
    return min(max(lag1_autocorrelation(residuals), 0.0), AR1_LIMIT)


def ar1_inflation(rho: float) -> float:
    """$(1 + \\rho)/(1 - \\rho)$, $\\rho$ clipped to [0, AR1_LIMIT]: the factor by which an AR(1)
    noise of lag-1 correlation $\\rho$ inflates the variance of a white-noise estimate (its
    $n$ points count as $n (1 - \\rho)/(1 + \\rho)$ independent ones)."""
    rho = min(max(float(rho), 0.0), AR1_LIMIT)
    return (1.0 + rho) / (1.0 - rho)


def noise_band(dof: int) -> tuple[float, float]:
    """The range of chi^2/dof consistent with the noise estimate (module docstring)."""
    width = NOISE_BAND_SIGMA * math.sqrt(2.0 / max(dof, 1))
    return 1.0 / (1.0 + MODEL_ERROR_ALLOWANCE) - width, 1.0 + MODEL_ERROR_ALLOWANCE + width


COVARIANCES = ("auto", "noise", "residual", "correlated")


def covariance_choice(requested: str, chi2: float, dof: int, correlated: str | None = None) -> tuple[str, str]:
    """(scale, reason): the covariance scale ("noise", "residual" or "correlated") for
    `requested` (one of `COVARIANCES`) at a fit's chi^2 and dof, and a sentence on why (and
    on whether the residuals contradict the noise estimate, whatever was requested).
    `correlated`: why the residuals are expected to be correlated (e.g. the channels recorded
    below half a converter step of noise), or None; "auto" then chooses "correlated"."""
    if requested not in COVARIANCES:
        raise ValueError(f"covariance must be one of {', '.join(COVARIANCES)}; got {requested!r}.")
    low, high = noise_band(dof)
    reduced = chi2 / dof if dof > 0 else math.nan
    inside = math.isfinite(reduced) and low <= reduced <= high
    if inside:
        verdict = f"chi^2/dof = {reduced:.4g} is within [{low:.3g}, {high:.3g}], consistent with the noise estimate"
    elif not math.isfinite(reduced):
        verdict = "chi^2/dof is not defined (no degrees of freedom)"
    else:
        side = "larger" if reduced > high else "smaller"
        verdict = (f"chi^2/dof = {reduced:.4g} is outside [{low:.3g}, {high:.3g}]: the residuals are "
                   f"{side} than the noise estimate says (sigma off by a factor {math.sqrt(reduced):.3g}"
                   + (", or the model misses something" if reduced > high else "") + ")")
    if requested == "auto":
        scale = "correlated" if correlated else "noise" if inside or not math.isfinite(reduced) else "residual"
    else:
        scale = requested
    how = {"noise": "standard errors from the stated noise",
           "residual": "standard errors scaled by sqrt(chi^2/dof), the noise re-estimated from the residuals",
           "correlated": "standard errors from the residuals' own sample-to-sample covariance (Newey-West)"
           + (f", because {correlated}" if correlated else "")}[scale]
    return scale, f"{verdict}; {how} ({'chosen automatically' if requested == 'auto' else 'as asked'})."


def correlated_score_covariance(jacobian, residuals, series) -> np.ndarray:
    """Newey-West estimate of the covariance of the score $J^T r$, (p, p).

    $B = \\sum_s \\sum_{|l| \\le L_s} (1 - |l|/(L_s+1)) \\sum_t g_t g_{t+l}^T$ with
    $g_t = r_t J_t$ over each series $s$ (one channel of one file: residuals correlated within
    it, independent between them). `series`: (indices into the residual vector in time order,
    lag L_s) pairs. For white residuals of unit variance $B \\to J^T J$."""
    jac = np.asarray(jacobian, dtype=float)
    r = np.asarray(residuals, dtype=float)
    meat = np.zeros((jac.shape[1], jac.shape[1]))
    for rows, lags in series:
        g = r[rows, None] * jac[rows]
        meat += g.T @ g
        for lag in range(1, min(int(lags), len(rows) - 1) + 1):
            cross = g[lag:].T @ g[:-lag]
            meat += (1.0 - lag / (lags + 1.0)) * (cross + cross.T)
    return meat


@dataclasses.dataclass(frozen=True)
class Covariance:
    """Covariance of the physical parameters, with what it was computed from.

    **Fields:** `covariance` (p, p) in SI units; `stderr` (p,); `correlation` (p, p);
    `scale` ("noise" or "residual"); `variance_factor` $s^2$; `singular_values` of the
    column-normalised Jacobian (descending); `weak_directions`: list of
    (relative singular value, {label: component}) for the degenerate directions.
    """

    covariance: np.ndarray
    stderr: np.ndarray
    correlation: np.ndarray
    scale: str
    variance_factor: float
    singular_values: np.ndarray
    weak_directions: list


def covariance_from_jacobian(jacobian, labels, *, chi2: float, dof: int, scale: str,
                             score_covariance=None) -> Covariance:
    """Gauss-Newton covariance from the whitened Jacobian (see the module docstring), by
    `hertzchain.covariance.gauss_newton_covariance`; `scale` "correlated" needs
    `score_covariance` (`correlated_score_covariance`)."""
    if scale not in ("noise", "residual", "correlated"):
        raise ValueError(f"covariance scale must be 'noise', 'residual' or 'correlated', got {scale!r}.")
    if scale == "correlated" and score_covariance is None:
        raise ValueError("the 'correlated' covariance needs the score's covariance (correlated_score_covariance).")
    factor = 1.0 if scale == "noise" else (chi2 / dof if dof > 0 else math.nan)
    if scale == "correlated":  # the sandwich (J^T J)^+ B (J^T J)^+, at least the residual scale
        unscaled = gauss_newton_covariance(jacobian)
        inverse = unscaled.covariance
        cov = inverse @ np.asarray(score_covariance, dtype=float) @ inverse
        factor = max(factor, 1.0) if math.isfinite(factor) else 1.0
        stderr = np.where(np.isinf(unscaled.stderr), np.inf, np.sqrt(np.clip(np.diag(cov), 0, None)))
        gauss_newton = unscaled
    else:
        gauss_newton = gauss_newton_covariance(jacobian, residual_std=math.sqrt(factor))
        cov, stderr = gauss_newton.covariance, gauss_newton.stderr
    singular, vt = gauss_newton.singular_values, gauss_newton.directions
    top = singular[0] if singular.size and singular[0] > 0 else 1.0
    weak = [(float(singular[k] / top),
             {labels[j]: float(vt[k, j]) for j in range(len(labels)) if abs(vt[k, j]) > PARTICIPATION})
            for k in np.nonzero(~gauss_newton.kept)[0]]
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = cov / np.outer(stderr, stderr)
    correlation = np.where(np.isfinite(correlation), correlation, np.nan)
    np.fill_diagonal(correlation, 1.0)
    return Covariance(cov, stderr, correlation, scale, float(factor), singular, weak)


def identifiability_warnings(instances, values, cov: Covariance, experiments) -> list[str]:
    """Human-readable warnings about parameters the data cannot determine."""
    labels = [inst.label for inst in instances]
    messages = []
    # the exact scaling symmetry of the module docstring
    names = {inst.name for inst in instances}
    if names & {"C", "mu_star"}:
        scale_name = "C" if "C" in names else "mu_star"
        for e, experiment in enumerate(experiments):
            has_velocity = any(
                inst.name == "striker_velocity" and inst.experiment == e for inst in instances
            )
            gains = {inst.channel for inst in instances if inst.name == "gain" and inst.experiment == e}
            if has_velocity and set(experiment.channels) <= gains:
                messages.append(
                    f"{scale_name} is not identifiable with striker_velocity[{experiment.label}] and "
                    f"the gains of all its channels free: a stiffness scale lambda maps exactly onto "
                    "V0 -> lambda^2 V0 and forces -> lambda^-2 forces without dissipation "
                    "(only dissipation breaks this, weakly). Fix the striker velocity or a gain."
                )
    for relative, components in cov.weak_directions:
        parts = ", ".join(f"{c:+.2f} {name}" for name, c in sorted(components.items(), key=lambda kv: -abs(kv[1])))
        messages.append(
            f"not identifiable from these data: the combination [{parts}] (normalised units) has "
            f"relative singular value {relative:.1e}; these parameters cannot be determined separately."
        )
    p = len(labels)
    for i in range(p):
        for j in range(i + 1, p):
            c = cov.correlation[i, j]
            if np.isfinite(c) and abs(c) > CORRELATION_LIMIT:
                messages.append(
                    f"{labels[i]} and {labels[j]} are strongly correlated (r = {c:+.4f}): the data "
                    "constrain mainly a combination of them."
                )
    for j, inst in enumerate(instances):
        value, error = float(values[j]), float(cov.stderr[j])
        spec = inst.spec
        if spec.space != "linear" and np.isfinite(error) and value > 0 and error / value > RELATIVE_ERROR_LIMIT:
            messages.append(
                f"{inst.label} is practically not identifiable from these data (relative standard "
                f"error {error / value:.0%})."
            )
        _, centre, half, _ = spec.transform_constants()
        position = (spec.to_s(value) - centre) / half  # -1 and +1 are the bounds
        near_lower = position < -0.999 and spec.space != "asinh"  # asinh: zero is a physical value
        if near_lower or position > 0.999:
            messages.append(
                f"{inst.label} = {value:.6g} sits at its bound ({spec.lower:g}, {spec.upper:g}); "
                "its standard error is not meaningful."
            )
    return messages


def profile_interval(grid, delta_chi2, variance_factor: float, level: float) -> tuple[float | None, float | None]:
    """Where the profile $\\Delta\\chi^2/s^2$ crosses `level` on each side of its minimum.

    Linear interpolation between grid points; None on a side where it does not cross
    inside the grid (the interval is open there).
    """
    grid = np.asarray(grid, dtype=float)
    y = np.asarray(delta_chi2, dtype=float) / variance_factor
    best = int(np.nanargmin(y))
    lower = upper = None
    for k in range(best, 0, -1):
        if y[k - 1] >= level > y[k] or (y[k - 1] >= level and y[k] <= level):
            t = (level - y[k]) / (y[k - 1] - y[k])
            lower = float(grid[k] + t * (grid[k - 1] - grid[k]))
            break
    for k in range(best, len(y) - 1):
        if y[k + 1] >= level and y[k] <= level:
            t = (level - y[k]) / (y[k + 1] - y[k])
            upper = float(grid[k] + t * (grid[k + 1] - grid[k]))
            break
    return lower, upper
