"""Inference for driven experiments (`kind = "driven"` experiment files): a module a concept.

- `experiment`: the experiment file and its measurements (bending sweeps, tongues, loops,
  scope records), read and checked;
- `lockin_fit`: the fit of a lock-in frequency × drive sweep (`fit_driven`, `DrivenFit`, ...;
  where this package was its module, `fitting.driven.fit_driven` still works, with a
  `DeprecationWarning`);
- `joint`, `joint_report`: joint fits of every measurement across runs, and their report;
- `candidates`, `diagnosis`: the candidate laws, each fitted and judged on what it was not
  fitted on, and the diagnosis of an experiment file;
- `report`: a sweep fit's files and the measures of resonance bending;
- `band`: the band edge of a measured frequency response (Lydon et al. 2014).
"""

import importlib
import warnings


def __getattr__(name: str):
    """The sweep fit's names, where this package was its module (`fitting.driven.fit_driven`):
    forwarded to `lockin_fit` for one release, with a `DeprecationWarning`."""
    lockin_fit = importlib.import_module(f"{__name__}.lockin_fit")
    if name.startswith("__") or not hasattr(lockin_fit, name):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"`fitting.driven.{name}` moved to `fitting.driven.lockin_fit.{name}`; import it from there "
                  "(the old path goes in the next release).", DeprecationWarning, stacklevel=2)
    return getattr(lockin_fit, name)
