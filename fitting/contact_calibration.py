"""Calibrate an elastic-plastic contact law on measured force-approach curves.

A curve is a contact's force against the approach of the two bodies (sphere-sphere or
sphere-flat), sampled in time, loading and unloading. The law
(`hertzchain.contact.jackson_green_contact`) is driven along each measured approach
history: at each sample the force at the current approach and the largest approach so
far. Its yield stress is the dynamic one, $\\sigma_Y(1 + C\\ln(\\dot\\varepsilon/10^{-3}\\,
\\mathrm{s}^{-1}))$ with one strain rate per curve, the mean approach speed to the peak force
divided by the sum of the bodies' radii (the convention of Burgoyne & Daraio, PRE 89,
032203, 2014).

`calibrate` reports, per curve, the prediction at the given constants and at constants
fitted per material across its curves (the yield stress, optionally the rate constant and
the law's hardness ratio $h = H/\\sigma_Y$ of its fully plastic branch, 2.84 by default),
through the project's least squares (`fitting.fit.least_squares`, optimistix
Levenberg-Marquardt). Each curve weighs the same in the fit: residuals are
$(F_{model} - F_{measured})/F_{peak}$ divided by the square root of the curve's sample count,
so the fit minimises the sum over curves of the squared RMS misfit relative to each peak.
Standard errors: the Gauss-Newton one from the residual variance, which treats thousands of
strongly correlated samples as independent and is far too small, and the scatter of the
yield stresses fitted to each curve alone (standard deviation / sqrt(curves); not where the
rate constant or the hardness ratio is fitted with it); the larger
is reported as `stderr`.

Two optional terms account for a measured force that peaks before the approach does, which
no rate-independent law follows, and a third for an approach record that drifts (all off by
default):

- `fit_damping`: a Kuwabara-Kono viscous force on top of the law, the project's one damping
  law (`hertzchain.contact.contact_force`): $F = \\max(F_{JG} + \\tfrac32\\eta\\kappa
  \\delta^{1/2}\\dot\\delta, 0)$ with one damping time $\\eta$ (s) per material, fitted with
  $\\sigma_Y$; $\\dot\\delta$ from the approach averaged over `PEAK_WINDOW_S`. Physical,
  differentiable and usable in a chain (`eta_s` of a chain's contacts).
- `fit_time_shift`: a time alignment between the force and the approach records of each curve,
  a nuisance of split-Hopkinson-bar processing (the two records come from gauges at different
  distances from the sample, moved to its faces with the bar's wave speed and a dispersion
  correction): the law is driven with the approach at $t + \\tau$, $\\tau$ fitted per curve
  within $\\pm$`max_shift_s` (`bounded_shift_s`; positive: the force leads the approach). Its standard error is the
  Gauss-Newton one with each curve's residuals weighted by their own variance, inflated for
  their correlation along time (lag-1 autocorrelation $\\rho$ of the curve's residuals: factor
  $\\sqrt{(1+\\rho)/(1-\\rho)}$, an AR(1) noise), marginal over the material's constants
  fitted with it.
- `fit_approach_drift`: a linear drift of the approach record, fitted per curve: the law is
  driven with $\\delta(t) - b\\,(t - t_0)$ and its rate with $\\dot\\delta - b$ ($b$ in m/s,
  $t_0$ the first sample; positive: the record's approach grows faster than the contact's).
  The approach of a bar test is the difference of the two bar ends' displacements, each a
  time integral of gauge strains ($u = c_0\\int(\\varepsilon_i - \\varepsilon_r)\\,dt$ on the
  incident side), so a gain or dispersion mismatch $e$ between the incident and reflected
  pulses, or a strain baseline error, integrates to a velocity error $b \\approx e\\,c_0
  \\varepsilon_i$ that accumulates over the record, while the force (one gauge's strain)
  carries none. Its standard error is found as the shift's. The strain rate of the rate
  hardening stays the record's.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from hertzchain import contact
from hertzchain.covariance import gauss_newton_covariance
from hertzchain.materials import Material
from hertzchain.units import counted

from .contact_report import median_secant_ratio, summary_table, write_outputs  # noqa: F401
from .fit import least_squares
from .uncertainty import ar1_correlation, ar1_inflation, covariance_from_jacobian

GEOMETRIES = ("sphere-sphere", "sphere-flat")
OFFSETS = ("first-sample", "none")
# Window of the moving mean that gives a measured peak force (the data's ringing), s.
PEAK_WINDOW_S = 1e-6
# Largest deviation of a sampling interval from the median, as a fraction of it, that the terms
# read on a uniform grid (damping, time shift, approach drift) accept.
UNIFORM_SAMPLING = 0.01
# Unloading secant stiffness between these fractions of the peak force.
SECANT_FRACTIONS = (0.9, 0.5)
# Default bound of the fitted time alignment of the force and approach records, s: ten times
# what a 1 % error in the bar's wave speed moves the 132 us wave travel time of the Caltech
# bar's incident gauge (25.375 in at 4865.5 m/s); a shift at this bound is no alignment error
# of the processing but a misfit of the law.
MAX_TIME_SHIFT_S = 13e-6
# A fitted shift beyond this fraction of its bound is reported without a standard error.
SHIFT_AT_BOUND = 0.99
# Parameters of the fit, in this order; per-curve time shifts, then per-curve approach drifts
# (m/s), follow them.
PARAMETERS = ("ln_yield_stress", "rate_constant", "eta_s", "ln_hardness_ratio")


@dataclasses.dataclass(frozen=True)
class ContactGeometry:
    """Two bodies in contact: `kind` "sphere-sphere" (radii `radius_m`, `radius_b_m`; None
    means equal) or "sphere-flat" (a sphere of `radius_m` on a flat of the same material)."""

    kind: str
    radius_m: float
    radius_b_m: float | None = None

    def __post_init__(self):
        if self.kind not in GEOMETRIES:
            raise ValueError(f"geometry must be one of {GEOMETRIES}, got {self.kind!r}.")
        for name in ("radius_m", "radius_b_m"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive and finite (m), got {value}.")
        if self.kind == "sphere-flat" and self.radius_b_m is not None:
            raise ValueError("radius_b_m is for sphere-sphere contacts; a flat has none.")

    @property
    def other_radius_m(self) -> float:
        """Radius of the second body, m (inf for a flat)."""
        if self.kind == "sphere-flat":
            return math.inf
        return self.radius_m if self.radius_b_m is None else self.radius_b_m

    @property
    def reduced_radius_m(self) -> float:
        return 1.0 / (1.0 / self.radius_m + 1.0 / self.other_radius_m)

    @property
    def strain_length_m(self) -> float:
        """Length that turns the approach speed into a strain rate: the sum of the radii, m."""
        return self.radius_m + (0.0 if self.kind == "sphere-flat" else self.other_radius_m)


@dataclasses.dataclass(frozen=True)
class ContactCurve:
    """A measured force-approach curve, SI: `time_s` (None where the file has no time),
    `approach_m` as stored, `force_n`; `name` (the file's stem), `material` (both bodies)."""

    name: str
    time_s: np.ndarray | None
    approach_m: np.ndarray
    force_n: np.ndarray
    material: Material


def _csv_columns(path: Path) -> dict:
    """A force-approach CSV file as name -> values; refuses, naming the line and the fix, text
    that is not UTF-8, a ';'-separated file, rows with more or fewer cells than the header and
    cells that are not numbers (a byte-order mark is ignored)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not UTF-8 text; save the CSV file as UTF-8.") from None
    lines = [(number, line) for number, line in enumerate(text.splitlines(), start=1) if line.strip()]
    if len(lines) < 2:
        raise ValueError(f"{path}: no data rows under a header (approach_m, force_n, optional time_s).")
    (first, header_line), rows = lines[0], lines[1:]
    if ";" in header_line and "," not in header_line:
        raise ValueError(f"{path}: line {first}: the columns are separated by ';'; separate them by ',' and write "
                         "decimals with '.' (approach_m,force_n,time_s).")
    names = [name.strip() for name in next(csv.reader([header_line]))]
    columns = {name: [] for name in names}
    for number, line in rows:
        cells = next(csv.reader([line]))
        if len(cells) != len(names):
            decimal = " (is ',' the decimal point? write decimals with '.')" if len(cells) > len(names) else ""
            raise ValueError(f"{path}: line {number} has {len(cells)} cells for the {len(names)} columns "
                             f"{','.join(names)}{decimal}.")
        for name, cell in zip(names, cells):
            try:
                columns[name].append(float(cell))
            except ValueError:
                raise ValueError(f"{path}: line {number}, column {name}: {cell.strip()!r} is not a number.") from None
    return columns


def _column(table, names, path, required=True):
    for name in names:
        if name in table:
            return np.asarray(table[name], dtype=float)
    if required:
        raise ValueError(f"{path}: no column {names[0]!r} (columns: {', '.join(table)}); "
                         f"give a header with {names[0]}.")
    return None


def read_curve(path, material: Material) -> ContactCurve:
    """Read a force-approach file as it is, SI units.

    - `.mat`: `Fexternal` (N x 3: time s, approach m, force N; Burgoyne & Daraio's curves) or
      `fdK`, `fd1`, `fd2`, ... (N x 2: approach m, force N; no time).
    - `.csv`: a header with `approach_m` and `force_n` (or `force_measured_n`), optionally
      `time_s`.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"force-approach file {path} not found.")
    if path.suffix.lower() == ".mat":
        import scipy.io

        try:
            content = scipy.io.loadmat(path)
        except (ValueError, TypeError, NotImplementedError, OSError) as error:
            raise ValueError(f"{path}: not a MATLAB file scipy.io can read ({error}); give a .mat file (v4-v7, "
                             "not v7.3) with Fexternal or fdK, or a .csv file.") from None
        variables = {k: v for k, v in content.items() if not k.startswith("__")}
        if "Fexternal" in variables:
            table = np.asarray(variables["Fexternal"], dtype=float)
            if table.ndim != 2 or table.shape[1] != 3:
                raise ValueError(f"{path}: Fexternal must be N x 3 (time s, approach m, force N), "
                                 f"got shape {table.shape}.")
            time, approach, force = table.T
        else:
            key = next((k for k in variables if k.startswith("fd")), None)
            if key is None:
                raise ValueError(f"{path}: no Fexternal or fd* (fdK, fd1, ...) variable (found: {', '.join(variables)}).")
            table = np.asarray(variables[key], dtype=float)
            if table.ndim != 2 or table.shape[1] != 2:
                raise ValueError(f"{path}: {key} must be N x 2 (approach m, force N), got shape {table.shape}.")
            time, (approach, force) = None, table.T
    elif path.suffix.lower() == ".csv":
        table = _csv_columns(path)
        approach = _column(table, ("approach_m",), path)
        force = _column(table, ("force_n", "force_measured_n"), path)
        time = _column(table, ("time_s",), path, required=False)
    else:
        raise ValueError(f"{path}: unknown file type {path.suffix!r}; give .mat (Fexternal, fdK) or .csv.")
    for label, values in (("approach", approach), ("force", force), ("time", time)):
        if values is not None and not np.all(np.isfinite(values)):
            raise ValueError(f"{path}: the {label} column holds non-finite values.")
    if approach.size < 10:
        raise ValueError(f"{path}: {approach.size} samples; a curve needs at least 10.")
    if time is not None and not np.all(np.diff(time) > 0):
        first = int(np.argmax(np.diff(time) <= 0))
        raise ValueError(f"{path}: the time column must increase from sample to sample; sample {first + 1} is at "
                         f"{time[first + 1]:.9g} s after {time[first]:.9g} s (sort the rows, drop repeated samples, "
                         "or leave the time column out).")
    return ContactCurve(path.stem, time, approach, force, material)


def shifted_approach(curve: ContactCurve, offset: str) -> np.ndarray:
    """The approach the law is driven with, m: `offset` "first-sample" subtracts the first
    sample's (the measured curves start at 5-60 um with no force), "none" keeps it."""
    if offset not in OFFSETS:
        raise ValueError(f"offset must be one of {OFFSETS}, got {offset!r}.")
    return curve.approach_m - curve.approach_m[0] if offset == "first-sample" else curve.approach_m


def _smoothed(curve: ContactCurve) -> np.ndarray:
    """Force averaged over `PEAK_WINDOW_S` (11 samples where there is no time), N."""
    if curve.time_s is None:
        width = 11
    else:
        width = max(1, int(round(PEAK_WINDOW_S / float(np.median(np.diff(curve.time_s))))))
    return np.convolve(curve.force_n, np.ones(width) / width, mode="same")


def strain_rate_s(curve: ContactCurve, geometry: ContactGeometry, given: float | None = None) -> float:
    """Strain rate of a curve, 1/s: approach at the peak force over the time to it, over the
    sum of the radii; `given` where the file has no time."""
    if curve.time_s is None:
        if given is None:
            raise ValueError(f"{curve.name}: the file has no time column; give the strain rate (strain_rate_s, "
                             "--strain-rate) or no rate hardening.")
        return float(given)
    peak = int(np.argmax(_smoothed(curve)))
    speed = (curve.approach_m[peak] - curve.approach_m[0]) / (curve.time_s[peak] - curve.time_s[0])
    return float(speed / geometry.strain_length_m)


def _kappa(material: Material, geometry: ContactGeometry) -> float:
    theta = contact.theta(material.youngs_pa, material.poisson)
    if geometry.kind == "sphere-flat":
        return float(contact.kappa_sphere_flat(geometry.radius_m, material.youngs_pa, material.poisson,
                                               material.youngs_pa, material.poisson))
    return float(1.0 / (2 * theta * math.sqrt(1.0 / geometry.radius_m + 1.0 / geometry.other_radius_m)))


def law_force(approach_m, kappa, geometry: ContactGeometry, yield_stress_pa, poisson,
              hardness_ratio=contact.JG_HARDNESS_RATIO):
    """`jackson_green_contact` along an approach history, N (`hardness_ratio`: its $H/\\sigma_Y$)."""
    peak = jax.lax.cummax(approach_m)
    return contact.jackson_green_contact(approach_m, peak, kappa, geometry.reduced_radius_m, yield_stress_pa,
                                         poisson, hardness_ratio=hardness_ratio)[0]


def time_shifted(values, time_step_s, shift_s):
    """A uniformly sampled history read at $t + $ `shift_s`, linearly interpolated,
    differentiable in the shift: constant before the first sample (no contact yet), continued
    along its last slope after the end."""
    values = jnp.asarray(values)
    n = values.shape[0]
    position = jnp.arange(n) + shift_s / time_step_s
    left = jnp.clip(jnp.floor(position), 0, n - 2).astype(int)
    fraction = jnp.maximum(position - left, 0.0)
    return values[left] + fraction * (values[left + 1] - values[left])


def approach_rate_m_s(curve: ContactCurve, approach_m) -> np.ndarray:
    """Approach speed, m/s: the gradient of the approach averaged over `PEAK_WINDOW_S`."""
    if curve.time_s is None:
        raise ValueError(f"{curve.name}: the file has no time column; contact damping, a time shift and an approach drift need one.")
    steps = np.diff(curve.time_s)
    step = float(np.median(steps))
    if np.max(np.abs(steps - step)) > UNIFORM_SAMPLING * step:
        raise ValueError(f"{curve.name}: the time column is not uniformly sampled (intervals {np.min(steps):.4g} to "
                         f"{np.max(steps):.4g} s); contact damping, a time shift and an approach drift read the "
                         "record on a uniform grid: resample it, or leave those options out.")
    width = max(1, int(round(PEAK_WINDOW_S / step)))
    padded = np.pad(np.asarray(approach_m, float), width // 2, mode="edge")
    smooth = np.convolve(padded, np.ones(width) / width, mode="valid")[: np.size(approach_m)]
    return np.gradient(smooth, step)


def bounded_shift_s(value, max_shift_s):
    """The time shift of the fitted coordinate `value`, s: $\\tau_{max}\\tanh(x/\\tau_{max})$, equal to
    it near 0 and within $\\pm\\tau_{max}$; smooth, so that a fit that overshoots the bound can
    come back (a clip would leave it on a flat stretch)."""
    return max_shift_s * jnp.tanh(value / max_shift_s)


def drift_corrected(approach_m, rate_m_s, time_step_s, drift_m_s):
    """(approach m, rate m/s) of a uniformly sampled record without a linear drift of `drift_m_s`
    (m/s) from its first sample: $\\delta - b\\,(t - t_0)$, $\\dot\\delta - b$."""
    approach_m, rate_m_s = jnp.asarray(approach_m), jnp.asarray(rate_m_s)
    elapsed = jnp.arange(approach_m.shape[0]) * time_step_s
    return approach_m - drift_m_s * elapsed, rate_m_s - drift_m_s


def aligned_record(approach_m, rate_m_s, time_step_s, drift_m_s, shift_s):
    """(approach m, rate m/s) the law is driven with: the record without its drift `drift_m_s`
    (m/s), read `shift_s` (s) later."""
    approach, rate = drift_corrected(approach_m, rate_m_s, time_step_s, drift_m_s)
    return time_shifted(approach, time_step_s, shift_s), time_shifted(rate, time_step_s, shift_s)


def model_force(approach_m, rate_m_s, time_step_s, kappa, geometry: ContactGeometry, yield_stress_pa, poisson,
                eta_s=0.0, shift_s=0.0, hardness_ratio=contact.JG_HARDNESS_RATIO, drift_m_s=0.0):
    """The law along a measured history with the optional terms, N: the approach (and its rate)
    without a linear drift `drift_m_s` (m/s; 0: none) and read `shift_s` later (s; 0: none), the
    Kuwabara-Kono damping time `eta_s` (s; 0: none), the law's hardness ratio $H/\\sigma_Y$."""
    approach, rate = aligned_record(approach_m, rate_m_s, time_step_s, drift_m_s, shift_s)
    elastic = law_force(approach, kappa, geometry, yield_stress_pa, poisson, hardness_ratio)
    return contact.contact_force(approach, rate, kappa, eta_s, elastic_n=elastic)[1]


def thornton_force(approach_m, material: Material, geometry: ContactGeometry, yield_stress_pa):
    """The earlier law, `thornton_contact` with `yield_force`, along an approach history, N."""
    theta = contact.theta(material.youngs_pa, material.poisson)
    yield_force = contact.yield_force(yield_stress_pa, geometry.radius_m, theta, geometry.other_radius_m, theta)
    return _compiled_thornton_along(jnp.asarray(approach_m), _kappa(material, geometry), yield_force)


# The law along a record as one compiled program per record length: run op by op, every
# primitive is compiled for every record's length, which took most of a calibration's time.
_compiled_model_force = jax.jit(model_force, static_argnames=("geometry",))
_compiled_thornton_along = jax.jit(lambda approach_m, kappa, yield_force_n: contact.thornton_contact(
    approach_m, jax.lax.cummax(approach_m), kappa, yield_force_n)[0])
_compiled_aligned_record = jax.jit(aligned_record)


def unloading_secant_n_m(approach_m, force_n) -> float | None:
    """Secant stiffness of the unloading branch from 90 % to 50 % of the peak force, N/m
    (None if the record does not unload to 50 %)."""
    peak = int(np.argmax(force_n))
    after = force_n[peak:]
    high, low = (np.nonzero(after < f * force_n[peak])[0] for f in SECANT_FRACTIONS)
    if high.size == 0 or low.size == 0:
        return None
    i, j = peak + high[0], peak + low[0]
    change = approach_m[i] - approach_m[j]
    return float((force_n[i] - force_n[j]) / change) if change > 0 else None


def _padded_length(n: int) -> int:
    """The record length a curve of `n` samples is padded to in a fit: the next power of two,
    so that fits of curves of about one length share their compiled programs."""
    return 1 << (n - 1).bit_length()


def _padded(values, length):
    """A record continued to `length` samples along its last segment (what `time_shifted` reads
    beyond the end)."""
    values = np.asarray(values, dtype=float)
    extra = np.arange(1, length - values.size + 1)
    return np.concatenate([values, values[-1] + extra * (values[-1] - values[-2])])


def _whitened_residuals(x, data, kappa, poisson, max_shift_s, geometry):
    """The whitened residuals of `data` (per curve: padded approach m, speed m/s, force N, the
    whitening factor of each sample (0 on the padding), time step s, strain rate 1/s) in `x`
    (`_Residuals`), padded."""
    first, n = len(PARAMETERS), len(data)
    out = []
    for k, (approach, speed, force, factor, step, rate) in enumerate(data):
        stress = contact.rate_hardened_yield_stress(jnp.exp(x[0]), x[1], rate)
        shift = bounded_shift_s(x[first + k], max_shift_s)
        model = model_force(approach, speed, step, kappa, geometry, stress, poisson, x[2], shift, jnp.exp(x[3]),
                            x[first + n + k])
        out.append((model - force) * factor)
    return jnp.concatenate(out)


_compiled_residuals = jax.jit(_whitened_residuals, static_argnames=("geometry",))
_compiled_jacobian = jax.jit(jax.jacfwd(_whitened_residuals), static_argnames=("geometry",))


class _Residuals:
    """The whitened residuals of one material's curves in x = (ln sigma_Y, C, eta_s, ln h, shift_1 ..
    shift_n, drift_1 .. drift_n), for `fitting.fit.least_squares`; the shifts enter through
    `bounded_shift_s`, the approach drifts (m/s) as they are.

    The curves are padded to `_padded_length` and their data passed to one compiled program per
    set of padded lengths and geometry (every per-curve fit of a calibration shares one); the
    padding's residuals are 0 and left out of what this returns."""

    def __init__(self, pieces, kappa, geometry, poisson, max_shift_s):
        data, keep = [], []
        for approach, speed, step, force, peak, rate in pieces:
            n = np.size(force)
            length = _padded_length(n)
            factor = np.where(np.arange(length) < n, 1.0 / (peak * math.sqrt(n)), 0.0)
            data.append((jnp.asarray(_padded(approach, length)), jnp.asarray(_padded(speed, length)),
                         jnp.asarray(np.pad(np.asarray(force, float), (0, length - n))), jnp.asarray(factor),
                         jnp.asarray(float(step)), jnp.asarray(float(rate))))
            keep.append(np.arange(length) < n)
        self._data, self._keep = tuple(data), np.concatenate(keep)
        self._arguments = (jnp.asarray(float(kappa)), jnp.asarray(float(poisson)), jnp.asarray(float(max_shift_s)))
        self._geometry = geometry
        self._size = len(PARAMETERS) + 2 * len(data)

    def _x(self, x):
        x = jnp.asarray(x, dtype=float)
        if x.shape != (self._size,):
            n = len(self._data)
            raise ValueError(f"x must hold {len(PARAMETERS)} constants, {n} shifts and {n} drifts, got shape {x.shape}.")
        return x

    def residuals(self, x):
        r = _compiled_residuals(self._x(x), self._data, *self._arguments, geometry=self._geometry)
        return np.asarray(r)[self._keep]

    def linearize(self, x, columns):
        x = self._x(x)
        r = _compiled_residuals(x, self._data, *self._arguments, geometry=self._geometry)
        jac = _compiled_jacobian(x, self._data, *self._arguments, geometry=self._geometry)
        return np.asarray(r)[self._keep], np.asarray(jac)[self._keep][:, list(columns)]


def _fit_material(pieces, material, kappa, geometry, options):
    """(values {yield_stress_pa, rate_constant, eta_s}, stderr {...}, converged (the joint fit's),
    per-curve sigma_Y and whether each of those fits converged, per-curve shifts (s) and
    approach drifts (m/s), each a list of (value, standard error))."""
    n = len(pieces)
    first = len(PARAMETERS)
    start = np.concatenate([[math.log(material.yield_stress_pa), material.yield_rate_constant or 0.0, 0.0,
                             math.log(contact.JG_HARDNESS_RATIO)], np.zeros(2 * n)])
    base = [0] + ([1] if options["fit_rate_constant"] else []) + ([2] if options["fit_damping"] else []) \
        + ([3] if options["fit_hardness_ratio"] else [])

    def solve(indices):
        problem = _Residuals([pieces[i] for i in indices], kappa, geometry, material.poisson, options["max_shift_s"])
        m = len(indices)
        free = base + ([first + k for k in range(m)] if options["fit_time_shift"] else []) \
            + ([first + m + k for k in range(m)] if options["fit_approach_drift"] else [])
        x0 = np.concatenate([start[:first], start[first:first + n][list(indices)],
                             start[first + n:][list(indices)]])
        return problem, least_squares(problem, x0, free, max_steps=60, tolerance=1e-8), free

    problem, result, free = solve(range(n))
    x = result.x.copy()
    r, jac = problem.linearize(x, free)
    labels = [PARAMETERS[c] if c < first else f"shift_{c - first}" if c < first + n else f"drift_{c - first - n}"
              for c in free]
    cov = covariance_from_jacobian(jac, labels, chi2=float(r @ r), dof=max(r.size - len(free), 1), scale="residual")
    stderr = dict(zip(free, cov.stderr))
    stress = math.exp(x[0])
    # sigma_Y alone per curve; not where it trades off against another constant fitted with it
    traded = options["fit_rate_constant"] or options["fit_hardness_ratio"]
    single_fits = [] if traded else [solve([i])[1] for i in range(n)]
    singles = [math.exp(fit.x[0]) for fit in single_fits]
    singles_converged = [bool(fit.converged) for fit in single_fits]
    scatter = float(np.std(singles, ddof=1) / math.sqrt(len(singles))) if len(singles) > 1 else math.nan
    gauss_newton = stress * float(stderr[0])
    values = {"yield_stress_pa": stress, "rate_constant": float(x[1]), "eta_s": float(x[2]),
              "hardness_ratio": math.exp(x[3])}
    errors = {"yield_stress_gauss_newton_pa": gauss_newton, "yield_stress_curve_scatter_pa": scatter,
              "yield_stress_pa": float(np.nanmax([gauss_newton, scatter])),
              "rate_constant": float(stderr[1]) if 1 in stderr else None,
              "eta_s": float(stderr[2]) if 2 in stderr else None,
              "hardness_ratio": math.exp(x[3]) * float(stderr[3]) if 3 in stderr else None}
    bound = options["max_shift_s"]
    sizes = np.cumsum([0] + [np.size(p[3]) for p in pieces])

    # Gauss-Newton covariance with each curve's rows weighted by its own residual variance
    # (whitened per curve: the sample count cancels), inflated for their correlation along time
    # (AR(1): (1 + rho) / (1 - rho)); a curve's own parameter's error is marginal over the
    # material's constants fitted with it
    weighted = jac.copy()
    for k in range(n):
        rows = slice(sizes[k], sizes[k + 1])
        variance = float(r[rows] @ r[rows]) / max(sizes[k + 1] - sizes[k] - 1, 1)
        weighted[rows] /= math.sqrt(variance * ar1_inflation(ar1_correlation(r[rows]))) if variance > 0 else 1.0
    used = np.abs(weighted).max(axis=0) > 0
    marginal = np.full(len(free), np.nan)
    marginal[used] = gauss_newton_covariance(weighted[:, used]).stderr ** 2

    def curve_stderr(k, index, slope=1.0):
        """The standard error of curve k's own parameter x[index] (`slope`: d value / d x)."""
        variance = marginal[free.index(index)]
        return None if not np.isfinite(variance) else abs(slope) * math.sqrt(variance)

    shifts = [(float(bounded_shift_s(v, bound)), None) for v in x[first:first + n]]
    if options["fit_time_shift"]:
        # d shift / d x = 1 - (shift / bound)^2; no error for a shift stopped at its bound
        shifts = [(s, None if abs(s) > SHIFT_AT_BOUND * bound else curve_stderr(k, first + k, 1.0 - (s / bound) ** 2))
                  for k, (s, _) in enumerate(shifts)]
    drifts = [(float(v), curve_stderr(k, first + n + k) if options["fit_approach_drift"] else None)
              for k, v in enumerate(x[first + n:])]
    return values, errors, bool(result.converged), singles, singles_converged, shifts, drifts


def _piece(curve, approach, peak, rate, timed):
    """(approach m, approach speed m/s, time step s, force N, peak N, strain rate 1/s) of a curve
    for the fit (`timed`: a term that needs the time is fitted); files without time have no
    speed (zeros) and a unit step (neither is used)."""
    if timed:
        speed, step = approach_rate_m_s(curve, approach), float(np.median(np.diff(curve.time_s)))
    else:
        speed, step = np.zeros_like(approach), 1.0
    return approach, speed, step, curve.force_n, peak, rate


def _curve_report(curve, piece, kappa, geometry, given, fitted, own_stress_pa=None, shift=(0.0, None),
                  drift=(0.0, None)):
    """Numbers of one curve at the given and the fitted constants (with the fitted damping time,
    time shift and approach drift, where fitted; `shift`, `drift`: (value, standard error), s
    and m/s)."""
    (shift_s, shift_stderr_s), (drift_m_s, drift_stderr_m_s) = shift, drift
    approach, speed, step, _, _, rate = piece
    smooth = _smoothed(curve)
    peak = float(np.max(smooth))

    def force(stress_pa, rate_constant, eta_s=0.0, shift=0.0, hardness_ratio=contact.JG_HARDNESS_RATIO, drift=0.0):
        stress = contact.rate_hardened_yield_stress(stress_pa, rate_constant, rate)
        return np.asarray(_compiled_model_force(jnp.asarray(approach), jnp.asarray(speed), step, kappa, geometry, stress,
                                      curve.material.poisson, eta_s, shift, hardness_ratio, drift))

    model = force(given["yield_stress_pa"], given["rate_constant"])
    fit = force(fitted["yield_stress_pa"], fitted["rate_constant"], fitted["eta_s"], shift_s, fitted["hardness_ratio"],
                drift_m_s)
    old = np.asarray(thornton_force(approach, curve.material, geometry, given["yield_stress_pa"]))
    # the measured force against the approach it is aligned with (without the fitted drift, at the
    # fitted shift; neither: as stored)
    aligned = approach if not (shift_s or drift_m_s) else np.asarray(
        _compiled_aligned_record(jnp.asarray(approach), jnp.asarray(speed), step, drift_m_s, shift_s)[0])
    data_secant = unloading_secant_n_m(aligned, smooth)
    secants = {"model": unloading_secant_n_m(approach, model), "fitted": unloading_secant_n_m(aligned, fit)}
    i_peak = int(np.argmax(smooth))
    loading, unloading = slice(0, i_peak + 1), slice(i_peak + 1, None)
    own = None if own_stress_pa is None else force(own_stress_pa, fitted["rate_constant"], fitted["eta_s"], shift_s,
                                                   fitted["hardness_ratio"], drift_m_s)
    modulus = 0.75 * kappa / math.sqrt(geometry.reduced_radius_m)
    fitted_stress = contact.rate_hardened_yield_stress(fitted["yield_stress_pa"], fitted["rate_constant"], rate)
    radius = float(contact.jackson_green_contact_radius(float(np.max(aligned)), kappa, geometry.reduced_radius_m,
                                                        fitted_stress, curve.material.poisson))
    return {
        "file": curve.name,
        "material": curve.material.name,
        "samples": int(curve.force_n.size),
        "approach_offset_m": float(curve.approach_m[0]),
        "strain_rate_s": rate,
        "time_shift_s": float(shift_s),
        "time_shift_stderr_s": shift_stderr_s,
        "approach_drift_m_s": float(drift_m_s),
        "approach_drift_stderr_m_s": drift_stderr_m_s,
        # what the drift adds to the record's approach over its span, m
        "approach_drift_over_record_m": float(drift_m_s) * step * (np.size(approach) - 1),
        "peak_force_measured_n": peak,
        "approach_at_peak_m": float(approach[i_peak]),
        "mean_pressure_truncated_area_over_yield_stress": peak / (
            2 * math.pi * geometry.reduced_radius_m * float(approach[i_peak])) / curve.material.yield_stress_pa,
        "peak_force_error_model": float(np.max(model)) / peak - 1.0,
        "peak_force_error_fitted": float(np.max(fit)) / peak - 1.0,
        "peak_force_error_thornton": float(np.max(old)) / peak - 1.0,
        "rms_over_peak_model": float(np.sqrt(np.mean((model - curve.force_n) ** 2))) / peak,
        "rms_over_peak_fitted": float(np.sqrt(np.mean((fit - curve.force_n) ** 2))) / peak,
        # sigma_Y fitted to this curve alone: what the law's shape leaves whatever the constant
        "yield_stress_own_fit_pa": own_stress_pa,
        "rms_over_peak_own_fit": None if own is None else float(np.sqrt(np.mean((own - curve.force_n) ** 2))) / peak,
        "rms_over_peak_fitted_loading": float(np.sqrt(np.mean((fit - curve.force_n)[loading] ** 2))) / peak,
        "rms_over_peak_fitted_unloading": float(np.sqrt(np.mean((fit - curve.force_n)[unloading] ** 2))) / peak
        if i_peak + 1 < curve.force_n.size else None,
        # the contact radius a Hertzian unloading (secant 90 -> 50 % = 1.76 E* a) needs to match the measured
        # secant, over the law's contact radius at the largest approach and over the reduced radius
        "unloading_radius_needed_over_law": None if data_secant is None else data_secant / (1.76 * modulus) / radius,
        "unloading_radius_needed_over_reduced_radius": None if data_secant is None
        else data_secant / (1.76 * modulus) / geometry.reduced_radius_m,
        "unloading_secant_measured_n_m": data_secant,
        "unloading_secant_ratio_model": None if data_secant is None or secants["model"] is None
        else secants["model"] / data_secant,
        "unloading_secant_ratio_fitted": None if data_secant is None or secants["fitted"] is None
        else secants["fitted"] / data_secant,
        "_series": {"approach_m": approach, "force_model_n": model, "force_fitted_n": fit, "force_thornton_n": old},
    }


def calibrate(curves, geometry: ContactGeometry, *, offset: str = "first-sample", fit_rate_constant: bool = False,
              fit_damping: bool = False, fit_time_shift: bool = False, fit_hardness_ratio: bool = False,
              fit_approach_drift: bool = False, max_shift_s: float = MAX_TIME_SHIFT_S,
              strain_rate_s_given: float | None = None, progress=None) -> dict:
    """Predict and calibrate the contact law on `curves` (`ContactCurve`, grouped by material).

    `fit_damping`: fit a Kuwabara-Kono damping time per material; `fit_time_shift`: fit a
    time alignment of the force and approach records per curve within +-`max_shift_s` (s);
    `fit_approach_drift`: a linear drift of the approach record per curve (m/s) (module
    docstring; all three need a time column); `fit_rate_constant`, `fit_hardness_ratio`:
    fit the rate constant C, the hardness ratio h (fitted as ln h) per material with sigma_Y.

    **Returns:** a dict: `materials` (per material: given and fitted constants with standard
    errors, per-curve yield stresses and whether each of those fits converged, `converged`:
    the joint fit and every per-curve fit reached an optimum, else `unconverged_fits` names
    them) and `curves` (per curve: strain rate,
    fitted time shift and approach drift with their standard errors, measured peak, peak-force errors at the given
    constants, the fitted ones and with the earlier Thornton law, RMS misfit over the peak,
    unloading secant stiffness 90 -> 50 % of the peak, measured and as ratios). `_series`
    entries hold the model forces for the per-file CSV and the figure.
    """
    if not curves:
        raise ValueError("no force-approach curves given.")
    if not (math.isfinite(max_shift_s) and max_shift_s > 0):
        raise ValueError(f"max_shift_s must be positive and finite (s), got {max_shift_s}.")
    groups: dict[str, list[int]] = {}
    for i, curve in enumerate(curves):
        if curve.material.yield_stress_pa is None:
            raise ValueError(f"{curve.name}: material {curve.material.name!r} has no yield stress; "
                             "give one (--yield-stress, Pa).")
        groups.setdefault(curve.material.name, []).append(i)
    options = {"fit_rate_constant": fit_rate_constant, "fit_damping": fit_damping, "fit_time_shift": fit_time_shift,
               "fit_hardness_ratio": fit_hardness_ratio, "fit_approach_drift": fit_approach_drift,
               "max_shift_s": max_shift_s}
    approaches = [shifted_approach(c, offset) for c in curves]
    rates = [strain_rate_s(c, geometry, strain_rate_s_given) if (c.material.yield_rate_constant or
             fit_rate_constant) else 1e-3 for c in curves]
    pieces = [_piece(c, a, float(np.max(_smoothed(c))), r, fit_damping or fit_time_shift or fit_approach_drift)
              for c, a, r in zip(curves, approaches, rates)]
    report = {"geometry": dataclasses.asdict(geometry), "reduced_radius_m": geometry.reduced_radius_m,
              "offset": offset, **options, "materials": {}, "curves": []}
    for name, members in groups.items():
        material = curves[members[0]].material
        kappa = _kappa(material, geometry)
        if progress:
            progress(f"fitting {name} on {counted(len(members), 'curve')}")
        values, errors, converged, singles, singles_converged, shifts, drifts = _fit_material(
            [pieces[i] for i in members], material, kappa, geometry, options)
        files = [curves[i].name for i in members]
        # the curves' scatter is an error reported (the larger of it and the joint fit's): a
        # per-curve fit without an optimum makes that error unfounded
        unconverged = ([] if converged else ["the joint fit"]) + [
            f"the fit of {name} alone" for name, ok in zip(files, singles_converged) if not ok]
        given = {"yield_stress_pa": material.yield_stress_pa, "rate_constant": material.yield_rate_constant or 0.0,
                 "eta_s": 0.0, "hardness_ratio": contact.JG_HARDNESS_RATIO}
        report["materials"][name] = {
            "youngs_pa": material.youngs_pa, "poisson": material.poisson, "given": given, "fitted": values,
            "stderr": errors, "converged": not unconverged, "joint_fit_converged": converged,
            "unconverged_fits": unconverged,
            "fitted_over_given_yield_stress": values["yield_stress_pa"] / material.yield_stress_pa,
            "yield_stress_per_curve_pa": dict(zip(files, singles)),
            "yield_stress_per_curve_converged": dict(zip(files, singles_converged)),
            "files": files,
        }
        for k, i in enumerate(members):
            report["curves"].append(_curve_report(curves[i], pieces[i], kappa, geometry, given, values,
                                                  singles[k] if singles else None, shifts[k], drifts[k]))
    return report
