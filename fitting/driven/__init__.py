"""Inference for driven experiments (`kind = "driven"` experiment files): a module a concept.

- `experiment`: the experiment file and its measurements (bending sweeps, tongues, loops,
  scope records), read and checked;
- `lockin_fit`: the fit of a lock-in frequency × drive sweep (its names are this package's
  too: `fitting.driven.fit_driven`, `DrivenFit`, ...);
- `joint`, `joint_report`: joint fits of every measurement across runs, and their report;
- `candidates`, `diagnosis`: the candidate laws, each fitted and judged on what it was not
  fitted on, and the diagnosis of an experiment file;
- `report`: a sweep fit's files and the measures of resonance bending;
- `band`: the band edge of a measured frequency response (Lydon et al. 2014).
"""

from .lockin_fit import (
    COARSE_LEVEL_STRIDE,
    COARSE_ROW_STRIDE,
    NOMINAL_SCALE,
    PARAMETERS,
    UNITS,
    DrivenFit,
    DrivenLayout,
    DrivenModel,
    chain_at,
    check_layout,
    finish_fit,
    fit_driven,
    linear_start,
    lockin_settings,
    nominal_modes_hz,
    scan_precompression,
)

__all__ = [
    "COARSE_LEVEL_STRIDE", "COARSE_ROW_STRIDE", "NOMINAL_SCALE", "PARAMETERS", "UNITS", "DrivenFit",
    "DrivenLayout", "DrivenModel", "chain_at", "check_layout", "finish_fit", "fit_driven",
    "linear_start", "lockin_settings", "nominal_modes_hz", "scan_precompression",
]
