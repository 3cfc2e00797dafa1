"""The result of a fit: values, standard errors, correlations, how it ended, and the
numbers derived from them (the speed constant, residual RMS by channel), with the residual
series the correlated covariance sums over."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from hertzchain import contact
from hertzchain.io.atomic import json_ready
from hertzchain.io.importer import DITHER_STEPS
from hertzchain.theory import DISCRETE_SPEED_FACTOR

from .model import Problem
from .parameters import CONTINUUM_SPEED_FACTOR, LabelledValues, bare_speed_constant, public_label
from .uncertainty import Covariance, noise_band


# --- results ---------------------------------------------------------------------------------------
@dataclasses.dataclass
class FitResult:
    """What a fit found.

    **Fields:**

    - `labels`: names of the fitted numbers, registry spelling (`eta`, `striker_velocity[run1]`,
      ...); `to_json` and the reports write each as a user names it
      (`fitting.parameters.public_label`: `eta_s`, `striker_velocity_m_s[run1]`).
    - `values`, `stderr`: label -> value / standard error in SI units (stderr inf when the
      data cannot determine it); read by either spelling (`values["eta_s"]` is
      `values["eta"]`: `fitting.parameters.LabelledValues`).
    - `units`: label -> SI unit.
    - `correlation`: (p, p) correlation matrix in `labels` order; `covariance` likewise.
    - `covariance_scale`: "noise" (sigma known), "residual" (scaled by chi^2/dof) or
      "correlated" (the residuals' own sample-to-sample covariance, Newey-West);
      `stderr_stated_noise`: label -> the standard error the stated noise alone gives (the
      "noise" scale), beside `stderr` for comparison; `residuals`: the whitened residual
      vector at the optimum (`Problem.residuals` layout);
      `covariance_reason`: why, and whether chi^2/dof agrees with the noise estimate
      (`fitting.uncertainty.covariance_choice`).
    - `chi2`, `dof`, `reduced_chi2`: of the whitened residuals.
    - `residual_rms`: file label -> channel -> RMS residual in N; `residual_rms_whitened`
      likewise in units of the channel's sigma.
    - `speed_constant`: C of the fitted chain (discrete solitary waves, with standard
      error), Eq. 3's continuum value C_t (1+mu*)^(1/3), and mu*.
    - `converged`, `message`, `n_steps`: optimiser status of the kept start.
    - `starts`: one dict per start (start and final values, chi^2, converged, steps).
    - `warnings`: identifiability, bounds, multistart disagreement, resolution.
    - `profiles`: label -> profile likelihood (when asked for).
    - `problem`, `x`: the problem and the fitted vector (for predictions and plots).
    - `elapsed_s`, `timings`: wall time in all and by phase (set-up; compilation with the
      start's evaluation, until the first iteration; iterations; the final Jacobian and test
      of an optimum; covariance and profiles), s.
    """

    labels: tuple
    values: dict
    stderr: dict
    units: dict
    correlation: np.ndarray
    covariance: np.ndarray
    covariance_scale: str
    covariance_reason: str
    chi2: float
    dof: int
    reduced_chi2: float
    residual_rms: dict
    residual_rms_whitened: dict
    speed_constant: dict
    converged: bool
    message: str
    n_steps: int
    starts: list
    warnings: list
    identifiability: dict
    profiles: dict
    problem: Problem
    x: np.ndarray
    elapsed_s: float
    timings: dict = dataclasses.field(default_factory=dict)
    stderr_stated_noise: dict = dataclasses.field(default_factory=dict)
    residuals: np.ndarray | None = None

    def __post_init__(self):
        for field in ("values", "stderr", "units", "stderr_stated_noise", "profiles"):
            if isinstance(getattr(self, field), dict):
                setattr(self, field, LabelledValues(getattr(self, field)))

    def predictions(self) -> list[dict]:
        """Fitted model of every channel on the data's time axis, per file (N).

        Where every sample entered the fit, it is the data plus sigma times the whitened
        residuals at the optimum (`residuals`: the model the fit last evaluated there, to
        round-off, without a further simulation); otherwise the model is evaluated again."""
        problem = self.problem
        sigma = problem.sigma_vector()
        if self.residuals is None or not np.all(np.isfinite(sigma)):
            return problem.predictions(self.x)
        model = problem.data_vector() + sigma * np.asarray(self.residuals)[:sigma.size]
        return [{name: model[part] for name, part in parts.items()} for parts in problem.residual_slices()]

    def to_json(self) -> dict:
        """A JSON-ready dict (SI units; non-finite numbers as null; parameters by their public
        names, `fitting.parameters.public_label`)."""
        params = {
            public_label(label): {"value": json_ready(self.values[label]), "stderr": json_ready(self.stderr[label]),
                    "stderr_stated_noise": json_ready(self.stderr_stated_noise.get(label, self.stderr[label])),
                    "unit": self.units[label]}
            for label in self.labels
        }
        for key in ("C",):
            if key not in params:
                params[key] = {"value": json_ready(self.speed_constant["C"]),
                               "stderr": json_ready(self.speed_constant["C_stderr"]),
                               "unit": "m/s N^-1/6", "fitted": False}
        return {
            "params": params,
            "correlation": {
                "names": [public_label(label) for label in self.labels],
                "matrix": [[json_ready(c) for c in row] for row in np.asarray(self.correlation)],
            },
            "covariance_scale": self.covariance_scale,
            "covariance_reason": self.covariance_reason,
            "noise_band_reduced_chi2": list(noise_band(self.dof)),
            "chi2": json_ready(self.chi2),
            "dof": int(self.dof),
            "reduced_chi2": json_ready(self.reduced_chi2),
            "residual_rms_n": {k: {c: json_ready(v) for c, v in d.items()} for k, d in self.residual_rms.items()},
            "residual_rms_whitened": {
                k: {c: json_ready(v) for c, v in d.items()} for k, d in self.residual_rms_whitened.items()
            },
            "speed_constant": {k: json_ready(v) for k, v in self.speed_constant.items()},
            "converged": bool(self.converged),
            "message": self.message,
            "n_steps": int(self.n_steps),
            "starts": [
                {
                    "start": {public_label(k): json_ready(v) for k, v in s["start"].items()},
                    "final": {public_label(k): json_ready(v) for k, v in s["final"].items()},
                    "chi2": json_ready(s["chi2"]),
                    "converged": bool(s["converged"]),
                    "steps": int(s["steps"]),
                    "agrees_with_best": bool(s["agrees_with_best"]),
                }
                for s in self.starts
            ],
            "warnings": list(self.warnings),
            "identifiability": {
                "singular_values": [json_ready(v) for v in self.identifiability["singular_values"]],
                "condition_number": json_ready(self.identifiability["condition_number"]),
            },
            "profiles": {
                public_label(label): {
                    "values": [json_ready(v) for v in p["values"]],
                    "delta_chi2": [json_ready(v) for v in p["delta_chi2"]],
                    "converged": [bool(v) for v in p["converged"]],
                    "all_converged": bool(np.all(p["converged"])),
                    "interval_68": [json_ready(v) for v in p["interval_68"]],
                    "interval_95": [json_ready(v) for v in p["interval_95"]],
                }
                for label, p in self.profiles.items()
            },
            "noise_std_n": {
                e.label: {"source": e.noise_source, **{c: json_ready(s) for c, s in e.noise_std_n.items()}}
                for e in self.problem.experiments
            },
            "files": [e.trace.path or e.label for e in self.problem.experiments],
            "elapsed_s": json_ready(self.elapsed_s),
            "timings_s": {k: json_ready(v) for k, v in self.timings.items()},
        }


def _speed_constant(problem: Problem, x, cov: Covariance) -> dict:
    setup = problem.setup_at(x, 0)
    mu_star = float(setup.mu_star)
    bare = float(bare_speed_constant(setup))
    c = bare * (1 + mu_star) ** (1 / 3)
    error = math.nan
    labels = list(problem.labels)
    if "C" in labels:
        error = float(cov.stderr[labels.index("C")])
    elif "mu_star" in labels:
        error = float(cov.stderr[labels.index("mu_star")]) * c / (3 * (1 + mu_star))
    ratio = CONTINUUM_SPEED_FACTOR / DISCRETE_SPEED_FACTOR
    return {
        "C": c,
        "C_stderr": error,
        "C_continuum": c * ratio,
        "C_continuum_stderr": error * ratio,
        "mu_star": mu_star,
        "C_bare": bare,
    }


def _residual_rms(problem: Problem, residuals) -> tuple[dict, dict]:
    rms, whitened = {}, {}
    for experiment, slices in zip(problem.experiments, problem.residual_slices()):
        rms[experiment.label], whitened[experiment.label] = {}, {}
        for channel, part in slices.items():
            w = float(np.sqrt(np.mean(residuals[part] ** 2)))
            whitened[experiment.label][channel] = w
            rms[experiment.label][channel] = w * experiment.noise_std_n[channel]
    return rms, whitened


def _correlated_series(problem: Problem) -> tuple[list, str | None]:
    """Each fitted channel's residual rows with the lag over which its residuals may be
    correlated: the striker's Hertz collision time with bead 1 in samples (the duration of
    the impact, over which the model's pulse shape, and with it a converter's error of the
    moving signal, changes); and why the residuals are expected to be correlated (the
    channels recorded with less than `DITHER_STEPS` of analogue noise), or None."""
    series, coarse = [], []
    for experiment, slices in zip(problem.experiments, problem.residual_slices()):
        setup = experiment.trace.setup()
        striker, bead = float(setup.striker_mass_kg), float(setup.bead_mass_kg[0])
        duration = float(contact.collision_time(striker * bead / (striker + bead), float(setup.contact_kappa()[0]),
                                                float(setup.striker_velocity_m_s)))
        lags = max(1, round(duration / float(experiment.time_s[1] - experiment.time_s[0])))
        for channel, rows in slices.items():
            used = np.arange(rows.start, rows.stop)[experiment.used(channel)]
            series.append((used, lags))
            steps = experiment.analogue_noise_steps(channel)
            if steps is not None and steps < DITHER_STEPS:
                coarse.append(f"{experiment.label}:{channel} ({steps:.2f} step)")
    if not coarse:
        return series, None
    shown = ", ".join(coarse[:4]) + (f" and {len(coarse) - 4} more" if len(coarse) > 4 else "")
    return series, (f"{shown} recorded with analogue noise below {DITHER_STEPS:g} of a converter step, "
                    "where the converter's error of a moving signal is correlated from sample to sample")
