"""Starting values from the data, following the paper's own estimates, so no guess is needed.

- **Peaks and arrival times** of the first pulse in each contact/sensor channel
  (the first run above 30 % of the channel's maximum; its top, above 80 % of the run's
  largest sample, fitted by a least-squares parabola, so noise does not stop the search
  on the leading edge).
- **C** from the velocity law $v = C F_m^{1/6}$ of the discrete chain with the header's
  materials, $C = 0.905516\\,2R\\kappa^{1/3}m^{-1/2}$ (`theory.DISCRETE_SPEED_FACTOR`; 201.385
  for the paper's beads; the paper's measured 201.5 agrees to 0.1 %). It is checked against
  the speed measured from arrival times, $v = 2R\\,\\Delta k/\\Delta t$ between the first and last recorded
  positions of a file (a sensor in bead K sits at position K - 1/2); the measured value
  replaces it only when they differ by more than 10 % (e.g. wrong materials in the header).
  The measured value is biased by dissipation (a few %), and a start a few % off in C puts
  the pulses a whole pulse width away from the data at the far end of the chain, where the
  fit would find a local minimum.
- **Restitution** per contact from peak ratios along the chain,
  $\\epsilon = (F_b/F_a)^{(5/6)/(k_b-k_a)}$, fitted over files as
  $1 - \\epsilon = C_v F^{1/6} + C_s/F$ (non-negative least squares), then converted with
  the paper's conversions corrected by the ratios simulated on the paper's chain
  (`theory.VISCOUS_CONVERSION_CORRECTION`, `theory.FRICTION_CONVERSION_CORRECTION`, re-measured
  by tests/test_reproduce.py): $C_v = 0.333 \\cdot 5C\\eta/(2\\sqrt{10}R)$ and
  $C_s = 0.687 \\cdot 5\\mu m g/4$.
- **Striker velocity** (when the header lacks it) from the amplitude law
  $F_m = 0.63955\\,\\kappa^{2/5} m^{3/5} V_0^{6/5}$ (identical striker,
  `theory.impact_velocity_m_s`); from the wall channel alone, the wall force divided by
  Eq. (5) times its simulated correction `theory.WALL_FORCE_CORRECTION` (1.116).
- Time offsets start at 0, gains at 1, everything else at the header's value.
"""

from __future__ import annotations

import math

import numpy as np

from hertzchain import theory
from hertzchain.io.tracefile import TraceFile
from hertzchain.peaks import measured_first_peak

from .parameters import bare_speed_constant

DEFAULT_ETA_S = 1e-6
DEFAULT_MU = 0.05


def _position(channel: str) -> float | None:
    kind, _, index = channel.partition("_")
    if kind == "contact":
        return float(index)
    if kind == "sensor":
        return float(index) - 0.5
    return None


def channel_peaks(trace: TraceFile) -> list[tuple[float, float, float]]:
    """(position in contact units, peak time s, peak force N) of each contact/sensor channel."""
    peaks = []
    for name, values in trace.channels.items():
        position = _position(name)
        if position is None:
            continue
        peak = measured_first_peak(trace.time_s, values)
        if peak is not None:
            peaks.append((position, peak[0], peak[1]))
    return sorted(peaks)


def estimate_striker_velocity(trace: TraceFile) -> float:
    """Impact velocity (m/s) from the incident amplitude, for a striker identical to the beads."""
    setup = trace.setup(striker_velocity_m_s=1.0)
    kappa = float(setup.contact_kappa()[min(1, setup.n_beads - 1)])
    mass = float(setup.bead_mass_kg[0])
    peaks = channel_peaks(trace)
    if peaks:
        force = peaks[0][2]
    else:
        wall = np.asarray(trace.channels["wall"], dtype=float)
        wall_kappa = float(setup.wall_kappa())
        ratio = theory.WALL_FORCE_CORRECTION * theory.wall_force_ratio(wall_kappa, kappa)
        force = float(np.max(wall)) / ratio
    return float(theory.impact_velocity_m_s(force, kappa, mass))


def estimate_speed_constant(traces, setups) -> float | None:
    """C from arrival times between the first and last recorded position of each file."""
    values = []
    for trace, setup in zip(traces, setups):
        peaks = channel_peaks(trace)
        if len(peaks) < 2 or peaks[-1][0] - peaks[0][0] < 1:
            continue
        (ka, ta, fa), (kb, tb, fb) = peaks[0], peaks[-1]
        if tb <= ta:
            continue
        radius = float(setup.bead_radius_m[0])
        speed = 2 * radius * (kb - ka) / (tb - ta)
        values.append(speed / math.sqrt(fa * fb) ** (1 / 6))
    return float(np.median(values)) if values else None


def _nonnegative_least_squares(rows, rhs) -> np.ndarray:
    """argmin |rows c - rhs| over c >= 0 for two columns, exactly: the optimum of this convex
    problem is the unconstrained one or lies on a face (one coefficient zero, or both), so
    the best feasible one of the four faces' minimisers is it. (A closed form where
    `scipy.optimize.nnls` would cost its import, a third of a second, on every fit.)"""
    rows, rhs = np.asarray(rows, dtype=float), np.asarray(rhs, dtype=float)
    candidates = [np.zeros(2)]
    both = np.linalg.lstsq(rows, rhs, rcond=None)[0]
    if np.all(both >= 0):
        candidates.append(both)
    for k in range(2):
        column = rows[:, k]
        norm = float(column @ column)
        if norm > 0:
            single = np.zeros(2)
            single[k] = max(float(column @ rhs) / norm, 0.0)
            candidates.append(single)
    return min(candidates, key=lambda c: float(np.sum((rows @ c - rhs) ** 2)))


def estimate_dissipation(traces, setups, speed_constant: float) -> tuple[float | None, float | None]:
    """(eta s, mu) from peak decay along the chain, or None where the data cannot say."""
    rows, rhs = [], []
    for trace, setup in zip(traces, setups):
        peaks = channel_peaks(trace)
        if len(peaks) < 2:
            continue
        (ka, _, fa), (kb, _, fb) = peaks[0], peaks[-1]
        if kb - ka < 1 or fa <= 0 or fb <= 0:
            continue
        epsilon = (fb / fa) ** (5 / 6 / (kb - ka))
        force = math.sqrt(fa * fb)
        rows.append([force ** (1 / 6), 1 / force])
        rhs.append(1 - epsilon)
    if not rows:
        return None, None
    rows, rhs = np.asarray(rows), np.asarray(rhs)
    if len(rows) == 1 or np.ptp(rows[:, 1]) < 0.2 * np.mean(rows[:, 1]):
        # one amplitude: the two laws cannot be told apart; give it all to viscosity
        coefficients = np.array([max(rhs.mean(), 0.0) / rows[:, 0].mean(), 0.0])
    else:
        coefficients = _nonnegative_least_squares(rows, rhs)
    setup = setups[0]
    radius = float(setup.bead_radius_m[0])
    mass = float(setup.bead_mass_kg[0])
    gravity = float(setup.gravity_m_s2)
    eta = coefficients[0] * 2 * math.sqrt(10) * radius / (5 * speed_constant * theory.VISCOUS_CONVERSION_CORRECTION)
    mu = coefficients[1] / (theory.FRICTION_CONVERSION_CORRECTION * 1.25 * mass * max(gravity, 1e-12))
    return (float(eta) if eta > 0 else None), (float(mu) if mu > 0 else None)


def data_estimates(traces, setups) -> dict:
    """Start values of the global parameters from the data: keys eta, mu, C (where known)."""
    nominal = float(bare_speed_constant(setups[0]) * (1 + setups[0].mu_star) ** (1 / 3))
    measured = estimate_speed_constant(traces, setups)
    speed = measured if measured is not None and abs(math.log(measured / nominal)) > math.log(1.1) else nominal
    eta, mu = estimate_dissipation(traces, setups, speed)
    return {
        "C": speed,
        "C_measured": measured,
        "eta": eta if eta is not None else DEFAULT_ETA_S,
        "mu": mu if mu is not None else DEFAULT_MU,
    }
