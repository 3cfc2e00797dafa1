"""Pulse analysis of force traces: cos^6 fits, speeds, the velocity law, restitution, momentum.

The pulses are found by `hertzchain.peaks` (one finder per job; its names stay importable
from here). The functions that measure one pulse (`fit_cos6`, `incident_wave`) are written
in `jax.numpy`: they take arrays, work under `jit` and `vmap` (batch of traces along
leading axes) and are differentiable in the force values; `momentum_check` works on
concrete NumPy arrays (it decides how many pulses there are).

Definitions (they move the numbers by more than the paper's error bars, so they are fixed
here and stated in each docstring; see also `hertzchain.theory`):

- peak force and time: 3-point parabola through the largest sample and its neighbours;
- speed: least-squares slope of contact position $2R\\,K$ against peak time;
- amplitude for the velocity law: the mean parabolic peak force over the contacts used;
- duration $2\\tau$: the cos^6 fit to the samples of the main lobe at or above
  `threshold` (default 5 %) of the peak.

With these, the paper's chain gives $C$ = 201.37 over contacts 8-15 (the paper: 201.5 +- 0.1,
whose definition it does not state) and $2\\tau/(2R\\sqrt{10}/v)$ = 0.962.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import theory
from .covariance import gauss_newton_covariance
from .peaks import (  # noqa: F401
    Pulse,
    estimate_noise_std_n,
    find_pulses,
    first_peak,
    first_peak_index,
    first_run,
    refine_peak,
)

# ----------------------------------------------------------------------------------------
# cos^6 fit


class Cos6Fit(eqx.Module):
    """Least-squares fit of $F(t) = F_m\\cos^6((t - t_0)/\\tau)$ to one pulse.

    **Fields** (arrays with the batch shape of the input): `peak_force_n` ($F_m$, N),
    `center_s` ($t_0$, s), `tau_s` ($\\tau$, s; the duration is $2\\tau$), their standard
    errors `peak_force_stderr_n`, `center_stderr_s`, `tau_stderr_s` (from the Jacobian at
    the optimum and the residual variance, or the given noise level), `residual_rms_n`
    (N), `n_points` (samples fitted) and `converged` (bool).
    """

    peak_force_n: jax.Array
    center_s: jax.Array
    tau_s: jax.Array
    peak_force_stderr_n: jax.Array
    center_stderr_s: jax.Array
    tau_stderr_s: jax.Array
    residual_rms_n: jax.Array
    n_points: jax.Array
    converged: jax.Array

    @property
    def duration_s(self) -> jax.Array:
        """The pulse duration $2\\tau$, s."""
        return 2.0 * self.tau_s

    @property
    def duration_stderr_s(self) -> jax.Array:
        return 2.0 * self.tau_stderr_s

    def profile_n(self, time_s) -> jax.Array:
        """The fitted pulse at `time_s`, N."""
        return theory.solitary_profile_n(time_s, self.peak_force_n, self.center_s, self.tau_s)


def _lobe_mask(time_s, force_n, threshold, window_s):
    """Samples of the main lobe: contiguous around the largest sample in the window, all at or
    above `threshold` times that sample."""
    n = force_n.shape[-1]
    inside = (time_s >= window_s[0]) & (time_s <= window_s[1])
    peak_index = jnp.argmax(jnp.where(inside, force_n, -jnp.inf))
    level = threshold * force_n[peak_index]
    low = (force_n < level) | ~inside
    samples = jnp.arange(n)
    first = jnp.max(jnp.where(low & (samples < peak_index), samples, -1)) + 1
    last = jnp.min(jnp.where(low & (samples > peak_index), samples, n)) - 1
    return (samples >= first) & (samples <= last), peak_index


def _lobe_extent(mask, peak_index):
    """First and last sample of the lobe `mask` with its peak (the peak counted even where it
    is not in the mask: a trace without a positive maximum)."""
    samples = jnp.arange(mask.shape[-1])
    first = jnp.min(jnp.where(mask, samples, mask.shape[-1]))
    last = jnp.max(jnp.where(mask, samples, -1))
    return jnp.minimum(first, peak_index), jnp.maximum(last, peak_index)


@eqx.filter_jit
def _lobe_spans(time_s, force_n, threshold, window_s):
    """Samples from the first to the last of every trace's lobe and peak, (...)."""
    def span(f):
        first, last = _lobe_extent(*_lobe_mask(time_s, f, threshold, window_s))
        return last - first + 1

    for _ in range(force_n.ndim - 1):
        span = jax.vmap(span)
    return span(force_n)


# Samples kept beyond a lobe on either side when the fit runs on a slice of the trace: the
# parabola of `refine_peak` reads the peak's neighbours.
_SLICE_MARGIN = 2
# Batches of at least this many samples are fitted on slices. Below it, the whole traces: the
# slice's own compilations (its length found first, then a fit per length) cost more than they
# save. Whole-trace fits ran at about 1.6 us per sample (1024 traces of 2500 samples, 4.2 s), so
# 2^19 samples take about a second (a speed threshold, not tuned to any test).
SLICE_MIN_SAMPLES = 1 << 19


def _slice_length(time_s, force_n, threshold, window_s) -> int | None:
    """The length of the slices a batch of fits can run on (every trace's lobe, its peak and
    `_SLICE_MARGIN` samples either side in one slice; a power of two, so that batches of
    similar pulses share a compiled fit), or None for the whole trace (traced values, or
    lobes as long as the trace)."""
    if isinstance(force_n, jax.core.Tracer) or force_n.size == 0:
        return None
    widest = int(np.max(np.asarray(_lobe_spans(time_s, force_n, threshold, window_s))))
    length = 1 << max(widest + 2 * _SLICE_MARGIN - 1, 1).bit_length()
    return length if length < force_n.shape[-1] else None


def _inverse3(m):
    """Inverse of a 3x3 matrix by its adjugate (compiles much faster than a LAPACK call)."""
    cof = jnp.stack(
        [
            jnp.cross(m[1], m[2]),
            jnp.cross(m[2], m[0]),
            jnp.cross(m[0], m[1]),
        ]
    )
    return cof.T / jnp.dot(m[0], cof[0])


# The cos^6 fit's optimiser: tolerances on the scaled amplitude, centre and width (all about 1
# at the start), far below the standard errors the convergence test compares the last step with.
_COS6_SOLVER = optx.LevenbergMarquardt(rtol=1e-9, atol=1e-12)


def _fit_one(time_s, force_n, threshold, window_s, noise_std_n, n_iterations, length):
    mask, peak_index = _lobe_mask(time_s, force_n, threshold, window_s)
    step = time_s[1] - time_s[0]
    largest = jnp.max(jnp.abs(force_n))
    if length is not None:
        # the fit reads the lobe's samples only (the weights are 0 elsewhere): run it on the
        # slice of `length` samples that holds the lobe, its peak and their neighbours
        first, _ = _lobe_extent(mask, peak_index)
        start = jnp.clip(first - _SLICE_MARGIN, 0, force_n.shape[-1] - length)
        time_s, force_n, mask = (jax.lax.dynamic_slice(a, (start,), (length,))
                                 for a in (time_s, force_n, mask))
        peak_index = peak_index - start
    t_guess, f_guess = refine_peak(time_s, force_n, peak_index)
    f_guess = jnp.where(f_guess > 0.0, f_guess, largest + 1e-300)
    above_half = jnp.sum(mask & (force_n >= 0.5 * f_guess))
    tau_guess = jnp.maximum(above_half, 2) * step / (2.0 * theory.COS6_HALF_WIDTH)
    weight = mask.astype(force_n.dtype)
    x = (time_s - t_guess) / tau_guess
    y = force_n / f_guess

    def model_and_jacobian(p):
        a, c, s = p
        z = (x - c) / s
        inside = jnp.abs(z) < 0.5 * jnp.pi
        zc = jnp.clip(z, -0.5 * jnp.pi, 0.5 * jnp.pi)
        cos5 = jnp.where(inside, jnp.cos(zc) ** 5, 0.0)
        shape = cos5 * jnp.cos(zc)
        slope = 6.0 * a * cos5 * jnp.sin(zc) / s  # d model / d c
        jac = jnp.stack([shape, slope, slope * z], axis=-1)
        return a * shape, jac

    def residuals(p):
        return weight * (y - model_and_jacobian(p)[0])

    def jacobian(p):
        return -weight[:, None] * model_and_jacobian(p)[1]

    # the fit: optimistix's Levenberg-Marquardt in the scaled variables, at most
    # `n_iterations` steps; tau's sign is the model's symmetry (cos^6 is even), kept positive
    # after the fit
    solution = optx.least_squares(lambda p, _: residuals(p), _COS6_SOLVER,
                                  jnp.array([1.0, 0.0, 1.0], dtype=force_n.dtype), max_steps=n_iterations,
                                  throw=False)
    p = solution.value.at[2].set(jnp.abs(solution.value[2]))
    r = residuals(p)
    j = jacobian(p)
    n_points = jnp.sum(weight)
    dof = jnp.maximum(n_points - 3.0, 1.0)
    variance = jnp.where(jnp.isnan(noise_std_n), jnp.sum(r**2) / dof, (noise_std_n / f_guess) ** 2)
    se = gauss_newton_covariance(j, residual_std=jnp.sqrt(variance)).stderr
    last_step = -_inverse3(j.T @ j + 1e-12 * jnp.eye(3)) @ (j.T @ r)
    converged = ((n_points >= 4) & (solution.result == optx.RESULTS.successful)
                 & jnp.all(jnp.abs(last_step) <= 1e-6 + 1e-3 * se))
    return Cos6Fit(
        peak_force_n=p[0] * f_guess,
        center_s=t_guess + p[1] * tau_guess,
        tau_s=p[2] * tau_guess,
        peak_force_stderr_n=se[0] * f_guess,
        center_stderr_s=se[1] * tau_guess,
        tau_stderr_s=se[2] * tau_guess,
        residual_rms_n=jnp.sqrt(jnp.sum(r**2) / jnp.maximum(n_points, 1.0)) * f_guess,
        n_points=n_points.astype(int),
        converged=converged,
    )


@eqx.filter_jit
def _fit_batch(time_s, force_n, threshold, window_s, noise_std_n, n_iterations, length):
    fit = lambda f, noise: _fit_one(time_s, f, threshold, window_s, noise, n_iterations, length)  # noqa: E731
    for _ in range(force_n.ndim - 1):
        fit = jax.vmap(fit)
    return fit(force_n, noise_std_n)


def fit_cos6(time_s, force_n, *, threshold=0.05, window_s=None, noise_std_n=None, n_iterations=40):
    """Fit $F_m\\cos^6((t - t_0)/\\tau)$ (Eq. 3 of Job et al.) to the main pulse of a trace.

    The fitted samples are the main lobe: the largest sample inside `window_s` and the
    contiguous samples around it that stay at or above `threshold` times it (the paper's
    Fig. 2 uses the whole pulse; 0.05 leaves out the discrete pulse's long tails, which a
    cos^6 of compact support cannot follow). Start: the parabolic peak and the half-width
    of the samples above half maximum; then optimistix's Levenberg-Marquardt in scaled
    variables ($\\tau$ reported positive: the model is even in it). `converged`: the
    optimiser succeeded, at least 4 samples were fitted and a last Gauss-Newton step would
    move no parameter by more than 1e-3 of its standard error.

    **Arguments:**

    - `time_s`: (n,) evenly spaced times, s.
    - `force_n`: (..., n) forces, N; leading axes are a batch (fitted with `vmap`).
    - `threshold`: lobe level as a fraction of the peak, in [0, 1).
    - `window_s`: `(start, stop)` times limiting the search, s (default: the whole trace);
      use it to pick the incident, reflected or a secondary pulse.
    - `noise_std_n`: known noise standard deviation, N (scalar or batch-shaped) for the
      standard errors; default: the residual variance (sum of squares / (n - 3)).
    - `n_iterations`: the most optimiser steps per pulse.

    **Returns:** `Cos6Fit`. Standard errors are the usual linearised ones,
    $\\sqrt{\\mathrm{diag}(s^2(J^TJ)^{-1})}$; they describe noise, not the model error of
    fitting a cos^6 to a discrete pulse (the maximum residual of that is 1.2 % of $F_m$).
    """
    if not 0.0 <= threshold < 1.0:
        raise ValueError(f"threshold must be a fraction of the peak in [0, 1), got {threshold!r}.")
    time_s = jnp.asarray(time_s, dtype=jnp.float64)
    force_n = jnp.asarray(force_n, dtype=jnp.float64)
    if time_s.ndim != 1 or force_n.shape[-1] != time_s.shape[0]:
        raise ValueError(
            f"fit_cos6: time_s must be (n,) and force_n (..., n); got {time_s.shape} and "
            f"{force_n.shape}."
        )
    if time_s.shape[0] < 5:
        raise ValueError(f"fit_cos6 needs at least 5 samples, got {time_s.shape[0]}.")
    window = (-jnp.inf, jnp.inf) if window_s is None else tuple(float(w) for w in window_s)
    noise = jnp.broadcast_to(
        jnp.asarray(jnp.nan if noise_std_n is None else noise_std_n, dtype=jnp.float64),
        force_n.shape[:-1],
    )
    window = jnp.asarray(window)
    length = None
    if force_n.size >= SLICE_MIN_SAMPLES:
        length = _slice_length(time_s, force_n, float(threshold), window)
    return _fit_batch(time_s, force_n, float(threshold), window, noise, int(n_iterations), length)


# ----------------------------------------------------------------------------------------
# Speed and the velocity law


class SpeedFit(NamedTuple):
    """Speed from arrival times: `speed_m_s`, `speed_stderr_m_s` (NaN when not estimable),
    `intercept_s` (the time at position 0, s), `n_points`."""

    speed_m_s: float
    speed_stderr_m_s: float
    intercept_s: float
    n_points: int


def wave_speed(positions_m, arrival_times_s, *, time_stderr_s=None) -> SpeedFit:
    """Speed as the least-squares slope of position against arrival time.

    Two points give the time-of-flight speed $\\Delta x/\\Delta t$. The standard error comes
    from `time_stderr_s` (each arrival time's uncertainty, s) when given, otherwise from the
    residuals (three points or more).

    **Arguments:** `positions_m` (n,), m (e.g. $2R\\,K$ for contact K); `arrival_times_s`
    (n,), s (e.g. parabolic peak times or cos^6 centres).
    """
    x = np.asarray(positions_m, dtype=float)
    t = np.asarray(arrival_times_s, dtype=float)
    if x.shape != t.shape or x.ndim != 1 or len(x) < 2:
        raise ValueError(
            "wave_speed needs two or more (position, arrival time) pairs of equal length."
        )
    if np.ptp(t) <= 0:
        raise ValueError("wave_speed: all arrival times are equal; the speed is undefined.")
    tc = t - t.mean()
    slope = float(np.sum(tc * (x - x.mean())) / np.sum(tc**2))
    intercept_x = x.mean() - slope * t.mean()
    if time_stderr_s is not None:
        # Errors in the times only: the inverse slope 1/v of t(x) has variance s_t^2/Sxx.
        xc = x - x.mean()
        stderr = slope**2 * float(time_stderr_s) / math.sqrt(float(np.sum(xc**2)))
    elif len(x) > 2:
        residual = x - (intercept_x + slope * t)
        line = np.column_stack([np.ones_like(t), t])
        stderr = float(gauss_newton_covariance(
            line, residual_std=math.sqrt(float(np.sum(residual**2)) / (len(x) - 2))).stderr[1])
    else:
        stderr = math.nan
    return SpeedFit(slope, stderr, float(-intercept_x / slope), len(x))


class IncidentWave(NamedTuple):
    """The incident solitary wave measured at several contacts (definition of
    `incident_wave`): `speed_m_s`, `speed_stderr_m_s`, `peak_force_n` (mean of the
    contacts' peaks), `peak_times_s` and `peak_forces_n` per contact."""

    speed_m_s: float
    speed_stderr_m_s: float
    peak_force_n: float
    peak_times_s: np.ndarray
    peak_forces_n: np.ndarray


def incident_wave(time_s, forces_n, contacts, bead_radius_m, *, rise_fraction=0.3) -> IncidentWave:
    """Speed and amplitude of the first pulse passing a set of contacts.

    Definition (the paper does not state its own; tests/test_pulses.py checks the result
    against an adaptive DOP853 solution): at each contact K the first pulse
    (`first_peak`) gives a parabolic peak time and force; the speed is the least-squares
    slope of $2R\\,K$ against the peak times and the amplitude is the mean peak force. On
    the paper's chain (identical striker, contacts 8-15) this gives $v/F_m^{1/6}$ = 201.37.

    **Arguments:** `time_s` (n,); `forces_n` (n_contacts, n) or a dict name -> (n,) in the
    order of `contacts`; `contacts` the contact numbers K; `bead_radius_m`, m.
    """
    if isinstance(forces_n, dict):
        forces_n = np.stack([np.asarray(f) for f in forces_n.values()])
    forces = jnp.asarray(forces_n, dtype=jnp.float64)
    if forces.shape[0] != len(contacts):
        raise ValueError(f"incident_wave: {forces.shape[0]} traces for {len(contacts)} contacts.")
    index = np.asarray(first_peak_index(forces, rise_fraction))
    late = [k for k, i in zip(contacts, index) if i >= forces.shape[-1] - 2]
    if late:
        raise ValueError(
            f"incident_wave: the first pulse at contacts {late} peaks at the end of the trace; "
            "record longer (t_end_s)."
        )
    times, peaks = first_peak(jnp.asarray(time_s), forces, rise_fraction=rise_fraction)
    times, peaks = np.asarray(times), np.asarray(peaks)
    positions = 2.0 * float(bead_radius_m) * np.asarray(contacts, dtype=float)
    speed = wave_speed(positions, times)
    return IncidentWave(
        speed.speed_m_s, speed.speed_stderr_m_s, float(np.mean(peaks)), times, peaks
    )


class VelocityLawFit(NamedTuple):
    """Fit of $v = C F_m^{1/6}$: `velocity_constant` ($C$, m s^-1 N^-1/6) and its
    `velocity_constant_stderr`; the free power law $v = A F_m^{p}$ with `exponent` and
    `exponent_stderr` (1/6 expected); `relative_rms` of $v/(CF_m^{1/6}) - 1$; `n_points`."""

    velocity_constant: float
    velocity_constant_stderr: float
    exponent: float
    exponent_stderr: float
    relative_rms: float
    n_points: int


def fit_velocity_law(peak_force_n, speed_m_s, *, speed_stderr_m_s=None) -> VelocityLawFit:
    """Least-squares fit of the velocity law $v = C F_m^{1/6}$ over a set of pulses.

    $C = \\sum w v x / \\sum w x^2$ with $x = F_m^{1/6}$ and weights $w = 1/\\sigma_v^2$ (1 when
    no `speed_stderr_m_s`). Its standard error is $(\\sum w x^2)^{-1/2}$ scaled by the
    residual standard deviation (weighted, n - 1 degrees of freedom); with a single pulse
    it is the propagated speed error (NaN without one). The free exponent comes from a
    straight-line fit of $\\ln v$ against $\\ln F_m$ (NaN for fewer than 3 pulses).

    What $F_m$ and $v$ mean is the caller's definition; with `incident_wave` over contacts
    8-15 of the paper's chain the result is $C$ = 201.37 (the paper: 201.5 +- 0.1).
    """
    force = np.asarray(peak_force_n, dtype=float).ravel()
    speed = np.asarray(speed_m_s, dtype=float).ravel()
    if force.shape != speed.shape or len(force) == 0:
        raise ValueError("fit_velocity_law needs equal numbers of peak forces and speeds.")
    if np.any(force <= 0):
        raise ValueError("fit_velocity_law: peak forces must be positive (N).")
    sigma = (
        np.ones_like(speed)
        if speed_stderr_m_s is None
        else np.broadcast_to(np.asarray(speed_stderr_m_s, dtype=float), speed.shape)
    )
    w = 1.0 / sigma**2
    x = force ** (1.0 / 6.0)
    sxx = float(np.sum(w * x**2))
    c = float(np.sum(w * speed * x) / sxx)
    residual = speed - c * x
    n = len(force)
    if n > 1:
        scale = float(np.sum(w * residual**2)) / (n - 1)
        if speed_stderr_m_s is not None:
            scale = max(scale, 1.0)
    else:
        scale = 1.0 if speed_stderr_m_s is not None else math.nan
    stderr = float(gauss_newton_covariance((np.sqrt(w) * x)[:, None], residual_std=math.sqrt(scale)).stderr[0])
    exponent, exponent_se = math.nan, math.nan
    if n > 2 and np.ptp(np.log(force)) > 0:
        design = np.column_stack([np.ones(n), np.log(force)])
        coef, *_ = np.linalg.lstsq(design, np.log(speed), rcond=None)
        res = np.log(speed) - design @ coef
        line = gauss_newton_covariance(design, residual_std=math.sqrt(float(np.sum(res**2)) / (n - 2)))
        exponent, exponent_se = float(coef[1]), float(line.stderr[1])
    relative_rms = float(np.sqrt(np.mean((speed / (c * x) - 1.0) ** 2)))
    return VelocityLawFit(c, stderr, exponent, exponent_se, relative_rms, n)


# ----------------------------------------------------------------------------------------
# Restitution


def restitution_coefficients(peak_forces_n, reference_peak_forces_n=None):
    """The paper's restitution $\\epsilon_k = (U_{k+1}/U_k)^{1/2} = (F_{k+1}/F_k)^{5/6}$.

    **Arguments:** `peak_forces_n` (..., n) peak forces of one pulse at consecutive contacts,
    N; `reference_peak_forces_n`: the same from a dissipationless run of the same chain
    (optional): each $\\epsilon_k$ is then divided by its dissipationless value, which removes
    the decay of a wave still forming near the striker (it alone gives $\\epsilon$ = 0.9976
    at contact 5 of the paper's chain).

    **Returns:** (..., n - 1) $\\epsilon_k$; plot them against `peak_forces_n[..., :-1]`.
    """
    forces = jnp.asarray(peak_forces_n)
    eps = (forces[..., 1:] / forces[..., :-1]) ** (5.0 / 6.0)
    if reference_peak_forces_n is not None:
        eps = eps / restitution_coefficients(reference_peak_forces_n)
    return eps


class RestitutionFit(NamedTuple):
    """Fit of $1 - \\epsilon = C_v F^{1/6} + C_s/F$: `c_v` (N^-1/6), `c_s` (N), standard
    errors `c_v_stderr`, `c_s_stderr` (NaN for a term left out), `residual_rms`,
    `n_points`; and the paper's conversions `eta_paper_s` = $2\\sqrt{10}RC_v/(5C)$ and
    `mu_paper` = $4C_s/(5mg)$ (NaN unless the constants were given). The conversions do
    not hold for this model (simulated $\\eta$ = 2 us gives a $C_v$ 3.0 times smaller than
    they predict, $\\mu$ = 0.19 a $C_s$ 0.69 times): fit $\\eta$, $\\mu$ with the simulator."""

    c_v: float
    c_s: float
    c_v_stderr: float
    c_s_stderr: float
    residual_rms: float
    n_points: int
    eta_paper_s: float
    mu_paper: float


def fit_restitution_law(
    force_n,
    restitution,
    *,
    viscous=True,
    friction=True,
    velocity_constant=None,
    bead_radius_m=None,
    bead_mass_kg=None,
    gravity_m_s2=9.81,
) -> RestitutionFit:
    """Linear least-squares fit of the paper's law $\\epsilon \\approx 1 - C_v F^{1/6} - C_s/F$.

    **Arguments:** `force_n` (n,) the force at which each $\\epsilon$ was measured, N (the
    incoming pulse's peak); `restitution` (n,) the $\\epsilon$ values; `viscous`, `friction`
    choose the terms; `velocity_constant` (m s^-1 N^-1/6), `bead_radius_m`, `bead_mass_kg`,
    `gravity_m_s2` enable the paper's conversions to $\\eta$ and $\\mu$ (see
    `RestitutionFit` for why they are only indicative).
    """
    force = np.asarray(force_n, dtype=float).ravel()
    loss = 1.0 - np.asarray(restitution, dtype=float).ravel()
    if force.shape != loss.shape:
        raise ValueError("fit_restitution_law: force_n and restitution must have the same length.")
    if not (viscous or friction):
        raise ValueError("fit_restitution_law: keep at least one of viscous, friction.")
    if np.any(force <= 0):
        raise ValueError("fit_restitution_law: forces must be positive (N).")
    columns = ([force ** (1.0 / 6.0)] if viscous else []) + ([1.0 / force] if friction else [])
    design = np.column_stack(columns)
    n, k = design.shape
    if n < k:
        raise ValueError(f"fit_restitution_law: {n} points cannot fix {k} constants.")
    coef, *_ = np.linalg.lstsq(design, loss, rcond=None)
    residual = loss - design @ coef
    if n > k:
        se = gauss_newton_covariance(design, residual_std=math.sqrt(float(np.sum(residual**2)) / (n - k))).stderr
    else:
        se = np.full(k, math.nan)
    values = dict(c_v=0.0, c_s=0.0, c_v_stderr=math.nan, c_s_stderr=math.nan)
    names = (["c_v"] if viscous else []) + (["c_s"] if friction else [])
    for i, name in enumerate(names):
        values[name] = float(coef[i])
        values[name + "_stderr"] = float(se[i])
    eta = math.nan
    if velocity_constant is not None and bead_radius_m is not None:
        eta = float(theory.eta_from_c_v(values["c_v"], velocity_constant, bead_radius_m))
    mu = math.nan
    if bead_mass_kg is not None:
        mu = float(theory.mu_from_c_s(values["c_s"], bead_mass_kg, gravity_m_s2))
    return RestitutionFit(
        values["c_v"],
        values["c_s"],
        values["c_v_stderr"],
        values["c_s_stderr"],
        float(np.sqrt(np.mean(residual**2))),
        n,
        eta,
        mu,
    )


def collision_restitution(time_s, force_n, *, reduced_mass_kg, impact_velocity_m_s):
    """Restitution of one binary collision from its contact-force trace (the DEM definition).

    The impulse of the collision is $J = \\int F\\,dt = m^*(1+\\epsilon)v_{in}$, so
    $\\epsilon = J/(m^* v_{in}) - 1$ equals the ratio of separation to approach speed.
    `reduced_mass_kg` is $m_1m_2/(m_1+m_2)$ ($m$ for a bead on a wall); the trace must
    cover the whole contact (trapezoid rule; the force is taken as 0 before the first
    sample, i.e. at the impact).
    """
    time = jnp.asarray(time_s)
    force = jnp.asarray(force_n)
    impulse = jnp.trapezoid(force, time, axis=-1) + 0.5 * force[..., 0] * time[0]
    return impulse / (reduced_mass_kg * impact_velocity_m_s) - 1.0


# ----------------------------------------------------------------------------------------
# Several pulses in one trace


class MomentumCheck(NamedTuple):
    """Areas under force pulses, N s: `wall_impulse_n_s`, `incident_impulse_n_s`,
    `reflected_impulse_n_s` (everything after the incident pulse) and
    `ratio` = wall / (incident + reflected) (the paper: "equal"; 1.015-1.02 for stiff walls,
    the last beads leave the wall with momentum that never passes the contact)."""

    wall_impulse_n_s: float
    incident_impulse_n_s: float
    reflected_impulse_n_s: float
    ratio: float


def momentum_check(time_s, wall_force_n, contact_force_n, *, noise_std_n=None) -> MomentumCheck:
    """The paper's momentum check: area under the wall pulse against the areas of the
    incident and reflected pulses at a contact.

    The incident area runs from the start of the trace to the minimum after the first
    pulse of the contact (`find_pulses`); the reflected area is the rest of the trace.
    """
    time = np.asarray(time_s, dtype=float)
    contact_force = np.asarray(contact_force_n, dtype=float)
    pulses = find_pulses(time, contact_force, noise_std_n=noise_std_n)
    if not pulses:
        raise ValueError("momentum_check: no pulse found in the contact trace.")
    split = pulses[0].stop
    incident = float(np.trapezoid(contact_force[: split + 1], time[: split + 1]))
    reflected = float(np.trapezoid(contact_force[split:], time[split:]))
    wall = float(np.trapezoid(np.asarray(wall_force_n, dtype=float), time))
    return MomentumCheck(wall, incident, reflected, wall / (incident + reflected))
