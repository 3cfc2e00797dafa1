"""fitting: least-squares fits of hertzchain models to force traces, with uncertainties.

The public API:

- `fit(experiments, params=("eta_s", "mu", "C"), ...) -> FitResult`: Levenberg-Marquardt
  (optimistix) on whitened residuals, multistart, standard errors, correlations,
  identifiability warnings and profile likelihoods.
- `load_experiments(paths)`, `make_experiment(trace)`, `Experiment`: the data model.
- `make_problem(experiments, params)` -> `Problem`, and `residuals_and_jacobian(problem, x)`:
  the whitened residual vector and its Jacobian at given physical values.
- `REGISTRY`, `ParameterSpec`, `register_parameter`, `ForwardModel`: the parameter
  registry and the hook for model switches.
- `fit_datasets(problem, datasets)`: one compiled fit over many data sets (noise seeds).
- `sample_posterior(experiments, params, priors=[...]) -> PosteriorResult`: NUTS on the
  same likelihood with a lab's tolerances (`fitting.posterior`, `fitting.priors`);
  `fitting.posterior_report.write_posterior_report(result, out_dir)`: its files.
- `fitting.report.write_report(result, out_dir)`: fit.json, CSV and PNG files.
"""

import hertzchain  # noqa: F401  (enables float64)

from .data import Experiment, FitInputError, estimate_noise_std, load_experiments, make_experiment
from .fit import (
    FitError,
    FitResult,
    FitWarning,
    fit,
    fit_datasets,
    initial_values,
    make_problem,
    profile_likelihood,
)
from .model import ForwardModel, Problem, residuals_and_jacobian
from .parameters import REGISTRY, ParameterInstance, ParameterSpec, get_spec, register_parameter
from .posterior import PosteriorResult, PosteriorWarning, sample_posterior

__all__ = [
    "REGISTRY",
    "Experiment",
    "FitError",
    "FitInputError",
    "FitResult",
    "FitWarning",
    "ForwardModel",
    "ParameterInstance",
    "ParameterSpec",
    "PosteriorResult",
    "PosteriorWarning",
    "Problem",
    "estimate_noise_std",
    "fit",
    "fit_datasets",
    "get_spec",
    "initial_values",
    "load_experiments",
    "make_experiment",
    "make_problem",
    "profile_likelihood",
    "register_parameter",
    "residuals_and_jacobian",
    "sample_posterior",
]

# Diagnosis of missing effects (fitting.diagnosis, fitting.effects).
from .diagnosis import Diagnosis, DiagnosisError, diagnose  # noqa: E402
from .effects import EFFECT_NAMES  # noqa: E402

__all__ += ["Diagnosis", "DiagnosisError", "EFFECT_NAMES", "diagnose"]
