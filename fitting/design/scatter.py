"""A design checked against actual fits: the scatter of least-squares fits over noise seeds
against the predicted standard errors."""

from __future__ import annotations

import dataclasses

import numpy as np

from hertzchain.progress import Progress

from ..data import as_experiments
from ..fit import OPTIMUM_TOLERANCE, fit_datasets
from ..model import ForwardModel
from ..parameters import LabelledValues, public_label
from .plan import DesignError, DesignResult, _check_names, _Plan, _result_from_jacobian


@dataclasses.dataclass(frozen=True)
class FitScatter:
    """Scatter of actual least-squares fits over noise seeds, against the design's prediction.

    **Fields:** `params` (registry keys; the dicts read either spelling, `to_json` writes the
    public names); `truth` (name -> value); `estimates` (n_seeds, p) fitted values of
    the converged fits; `empirical_std`, `predicted_stderr`, `ratio` (empirical/predicted),
    `bias` (mean - truth) per parameter; `n_seeds`, `n_converged`; `design` (`DesignResult`).
    """

    params: tuple
    truth: dict
    estimates: np.ndarray
    empirical_std: dict
    predicted_stderr: dict
    ratio: dict
    bias: dict
    n_seeds: int
    n_converged: int
    design: DesignResult

    def to_json(self) -> dict:
        return {
            "method": "Levenberg-Marquardt fits (the residuals, parameter transforms and solver of "
            "fitting.fit) of the plan's noise-free model plus white Gaussian noise of the stated "
            "sigma, one fit per seed, started at the truth",
            "n_seeds": self.n_seeds,
            "n_converged": self.n_converged,
            "params": {
                public_label(p): {"truth": self.truth[p], "predicted_stderr": self.predicted_stderr[p],
                    "empirical_std": self.empirical_std[p], "ratio": self.ratio[p],
                    "bias": self.bias[p]}
                for p in self.params
            },
        }


def fit_scatter(plan, params=("eta_s", "mu", "C"), *, values=None, nuisances=(), n_seeds: int = 50,
                seed: int = 0, chunk_size: int = 25, max_steps: int = 100, tolerance: float = OPTIMUM_TOLERANCE,
                forward: ForwardModel | None = None, progress: bool = True) -> FitScatter:
    """Fit `n_seeds` noisy copies of a plan's data and compare the scatter with `design`.

    The data of every seed is the fit model at the given values plus white Gaussian noise of
    each channel's sigma (N); each copy is fitted by `fitting.fit.fit_datasets`, i.e. with
    `fitting.fit`'s residuals, bounded parameter transforms, Levenberg-Marquardt solver,
    `tolerance` (on chi^2, dimensionless) and convergence test, started at the truth; the
    seeds run as vmapped batches of `chunk_size` (one compilation for all). Free nuisances
    are fitted too.
    """
    params, nuisances = _check_names(params, nuisances)
    experiments = as_experiments(plan)
    plan_ = _Plan(experiments, params, nuisances, values, forward)
    predicted = _result_from_jacobian(plan_, plan_.jacobian(), experiments)
    problem = plan_.problem
    x = plan_.x
    truth = dict(zip(map(public_label, problem.labels), map(float, x)))
    clean = np.asarray(problem.model_vector(x))
    sigma = problem.sigma_vector()
    sigma = np.where(np.isfinite(sigma), sigma, 0.0)  # samples left out of the fit stay clean
    rng = np.random.default_rng(seed)
    noises = rng.standard_normal((n_seeds, clean.size))
    chunk = max(1, min(chunk_size, n_seeds))
    meter = Progress(n_seeds, "fits over noise seeds") if progress else None
    estimates, converged = [], []
    for start in range(0, n_seeds, chunk):
        part = noises[start:start + chunk]
        count = part.shape[0]
        if count < chunk:  # the last batch padded to the same size: no second compilation
            part = np.concatenate([part, np.repeat(part[-1:], chunk - count, axis=0)])
        fits = fit_datasets(problem, clean + sigma * part, start=truth, max_steps=max_steps,
                            tolerance=tolerance)
        estimates.append(fits["values"][:count])
        converged.append(fits["converged"][:count])
        if meter:
            meter.advance(count)
    estimates = np.concatenate(estimates)
    converged = np.concatenate(converged)
    fitted = estimates[converged][:, plan_.interest]
    if fitted.shape[0] < 2:
        raise DesignError(f"only {fitted.shape[0]} of {n_seeds} fits converged; the scatter is undefined.")
    names = predicted.params
    std = {n: float(np.std(fitted[:, k], ddof=1)) for k, n in enumerate(names)}
    return FitScatter(
        params=names,
        truth=LabelledValues(predicted.values),
        estimates=fitted,
        empirical_std=LabelledValues(std),
        predicted_stderr=LabelledValues(predicted.stderr),
        ratio=LabelledValues({n: std[n] / predicted.stderr[n] for n in names}),
        bias=LabelledValues({n: float(np.mean(fitted[:, k]) - predicted.values[n]) for k, n in enumerate(names)}),
        n_seeds=n_seeds,
        n_converged=int(converged.sum()),
        design=predicted,
    )


# --- plots ---------------------------------------------------------------------------------------
