"""The band edge of a precompressed chain read from a measured frequency response (Lydon et al.
2014, `Band.mat`), against the linearised chain's (`hertzchain.driven.linear`).

A finite chain's response at a sensor has one peak per normal mode up to the top of the
acoustic band, and decays smoothly above it. `band_edge_hz` takes the highest peak that stands
`prominence_db` above its surroundings (scipy's peak prominence on the response in dB), above
`above_hz` (to skip the defect's own line); the prominence is the one free choice of the
criterion, and `lydon2014_band_edges` reports the edge for several.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from scipy.signal import find_peaks

from hertzchain.covariance import gauss_newton_covariance
from hertzchain.driven.sweeper_files import read_mat_variables

# Lydon 2014's static-force channel: F0 = (V - V_ref) x 4.09 N/V, V_ref the 17th of 81 steps
# (the actuator starts to compress at 1.6 V), from the authors' plotbanddata.m.
STATIC_FORCE_N_PER_V = 4.09
REFERENCE_STEP = 16
# The authors' theoretical band edge, Hz per N^(1/6).
PAPER_EDGE_HZ = 4.96e3


def band_edge_hz(frequencies_hz, amplitude, *, above_hz: float, prominence_db: float) -> float:
    """Frequency (Hz) of the highest peak of `amplitude` (any linear unit) above `above_hz`
    with a prominence of at least `prominence_db` dB; NaN when there is none."""
    frequencies_hz = np.asarray(frequencies_hz, dtype=float)
    level_db = 20 * np.log10(np.maximum(np.asarray(amplitude, dtype=float), 1e-300))
    peaks, _ = find_peaks(level_db, prominence=prominence_db)
    peaks = peaks[frequencies_hz[peaks] > above_hz]
    return float(frequencies_hz[peaks].max()) if peaks.size else float("nan")


@dataclasses.dataclass(frozen=True)
class BandEdges:
    """Near-sensor band edges of `Band.mat`: `precompression_n` (P,) from the static-force
    channel, `edges_hz` {prominence dB: (P,)}, `defect_hz` (P,) the strongest line in 6.0-6.3 kHz,
    all for the steps with precompression in `force_range_n`."""

    precompression_n: np.ndarray
    edges_hz: dict
    defect_hz: np.ndarray
    force_range_n: tuple


def lydon2014_band_edges(band_mat, *, force_range_n=(4.0, 9.0), prominences_db=(4.0, 6.0, 10.0),
                         above_hz: float = 6300.0) -> BandEdges:
    """Read `Band.mat` and extract the near sensor's band edge at each precompression step in
    `force_range_n` (N), for each prominence in `prominences_db`, above `above_hz`."""
    data = read_mat_variables(Path(band_mat), ["FrequencyHz", "DynForceAmpNear", "StaticForce"])
    force = (data["StaticForce"] - data["StaticForce"][REFERENCE_STEP]) * STATIC_FORCE_N_PER_V
    steps = np.nonzero((force >= force_range_n[0]) & (force <= force_range_n[1]))[0]
    freqs = data["FrequencyHz"]
    near = data["DynForceAmpNear"]
    edges = {
        p: np.array([band_edge_hz(freqs, near[:, j], above_hz=above_hz, prominence_db=p) for j in steps])
        for p in prominences_db
    }
    window = (freqs > 6000) & (freqs < 6300)
    defect = np.array([freqs[window][np.argmax(near[window, j])] for j in steps])
    return BandEdges(force[steps], edges, defect, tuple(force_range_n))


def power_law(force_n, edges_hz) -> dict:
    """Least-squares fits of log(edge) = log(a) + b log(F0): the free exponent (`prefactor_hz`,
    `exponent`, `exponent_stderr`) and b = 1/6 (`prefactor_sixth_hz`)."""
    x, y = np.log(np.asarray(force_n)), np.log(np.asarray(edges_hz))
    good = np.isfinite(y)
    x, y = x[good], y[good]
    design = np.column_stack([np.ones_like(x), x])
    coef, residual, *_ = np.linalg.lstsq(design, y, rcond=None)
    dof = max(x.size - 2, 1)
    sigma = math.sqrt(float(np.sum((y - design @ coef) ** 2)) / dof)
    return {
        "prefactor_hz": float(np.exp(coef[0])),
        "exponent": float(coef[1]),
        "exponent_stderr": float(gauss_newton_covariance(design, residual_std=sigma).stderr[1]),
        "prefactor_sixth_hz": float(np.exp(np.mean(y - x / 6))),
        "points": int(x.size),
    }
