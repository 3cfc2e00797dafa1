"""The diagnosis's protocol in numbers: nuisances, shares, starts, noise bands; its error,
the model string and the variance a noise estimate adds."""

from __future__ import annotations

import numpy as np

from .. import effects as fx
from .locate import estimate_variance, noise_estimate_samples

NUISANCES = ("striker_velocity", "time_offset")
MIN_SHARE = 0.2
# Record fractions of the time-window continuation of per-bead refits (`_Search.refit`).
WINDOW_FRACTIONS = (0.45, 0.7)
# Each window's fit only has to bring the radii into the basin of the next: a few loose steps,
# ending (`fitting.fit`'s test of an optimum) when no step moves chi^2 by one s^2 (a move of one
# standard error); every other fit of a diagnosis ends by `fitting.fit`'s own tolerance.
WINDOW_MAX_STEPS = 8
WINDOW_TOLERANCE = 1.0
# Resonance frequencies of the starts of `sensor_dynamics` refits, Hz.
SENSOR_START_F0_HZ = (30e3, 45e3, 65e3, 90e3, 130e3, 190e3)
# Refits per candidate, from its best secant starts (default 1); candidates with variants
# (`_VARIANT`) first get the best start of each variant.
REFIT_STARTS = {"sensor_dynamics": 3, "precompression": 2, "plasticity": 2}
# The parameter (index among a candidate's strengths) whose start value is a variant of its law.
_VARIANT = {"sensor_dynamics": 2, "precompression": 1}
# Starts of threshold and singular candidates (see `_Search.start_for`): preloads as fractions
# of the smallest observed peak, yield forces as fractions of the largest observed force.
PRELOAD_START_FRACTIONS = (0.003, 0.01, 0.03, 0.1, 0.3)
YIELD_START_FRACTIONS = (1.0, 0.8, 0.65, 0.5, 0.35)
# Number of noise standard deviations of the chi^2 excess regarded as "at the noise level".
NOISE_BAND_SIGMA = 3.0
# The same for the largest excess of one channel x time-window cell (`fitting.diagnosis.locate`, files
# pooled): a global chi^2/dof at or below 1 (a noise estimate too large, or long quiet records)
# can hide a pulse window tens of sigma above the noise. The band's 3 plus the look-elsewhere
# allowance for the largest of K cells, sqrt(2 ln K) = 2.3-2.8 for the K = 15-50 cells of
# 3-10 channels x 5 windows: 5 noise units. Not fitted to any test case.
LOCAL_BAND_SIGMA = 5.0
# Parsimony for candidates with more than FEW_STRENGTHS strengths (per-bead radii): named only
# when the excess misfit before them is at least PRACTICAL_GAP per degree of freedom (the
# residual RMS 5 % above the noise: smaller gaps are what conventions of the model such as its
# time step leave behind), and when their held-out gain beats ln(n) per strength (the BIC
# penalty, on held-out data) instead of 1. A choice of practical significance, not fitted to
# any test case.
FEW_STRENGTHS = 3
PRACTICAL_GAP = 0.1


class DiagnosisError(ValueError):
    """Bad input to a diagnosis; the message names the fix."""


def parse_model(model: str, n_beads: int) -> list[str]:
    """`"base"` or `"base+viscous_damping+..."` -> the effects already in the model."""
    parts = [p.strip() for p in str(model).split("+") if p.strip()]
    if not parts or parts[0] != "base":
        raise DiagnosisError(
            f"model must be 'base' or 'base+EFFECT+...', got {model!r}; effects: {', '.join(fx.EFFECT_NAMES)}."
        )
    known = fx.library(n_beads)
    for name in parts[1:]:
        if name not in known:
            raise DiagnosisError(f"model: unknown effect {name!r}; effects: {', '.join(fx.EFFECT_NAMES)}.")
    return parts[1:]


def noise_estimate_variance(experiments) -> float:
    """The variance the noise levels' own estimates add to the chi^2 of a model that holds:
    a channel's n fitted samples, whitened by a sigma estimated from m samples (the importer's
    pre-trigger segment, `x_import_<channel>_noise_samples`), have their chi^2 scaled by
    sigma^2 / sigma_est^2 ~ chi^2(m - 1) / (m - 1), of relative variance 2 / (m - 1): each adds
    2 n^2 / (m - 1). Noise levels stated in a file (m = 0) add nothing."""
    return sum(estimate_variance(int(np.sum(e.used(name))), noise_estimate_samples(e, name))
               for e in experiments for name in e.channels)
