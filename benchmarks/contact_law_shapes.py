"""Which law shape the Caltech curves of Burgoyne & Daraio (PRE 89, 032203, 2014) allow:
`jackson_green_contact` against the fully plastic limit of a truncated sphere, and what
bounds the misfit of any elastic unloading.

    python -m benchmarks.contact_law_shapes [--data PATH] [--out benchmarks/results/contact_burgoyne]

Candidates, sigma_Y fitted once per material (`fitting.fit.least_squares`, published rate
constants, approach offset at the first sample shifted out, as `contact_burgoyne.py`):

- `jackson_green`: the law (`hertzchain.contact.jackson_green_contact`);
- `truncation`: Hertz up to the overlap where its slope reaches the truncated sphere's,
  $\\delta_t = (\\pi H/E^*)^2R^*$, then the tangent line $F = 2\\pi R^*H(\\delta - \\delta_t/3)$
  (contact area $2\\pi R^*\\delta$ of a sphere cut flat, Abbott & Firestone; $H = 2.84\\sigma_Y$),
  unloading Hertz-like (as the law) from the truncation radius $a_m^2 = 2R^*\\delta_m$.
  A measurement candidate, kept here and not in the library because it does not fit better.

Per curve, law-free: the smallest contact radius that can give the measured unloading secant
stiffness S (90 -> 50 % of the peak) elastically, $a \\ge S/(2E^*)$ (an axisymmetric elastic
contact unloads at most as stiffly as a flat punch of its radius, $2E^*a$), over the
truncation radius $\\sqrt{2R^*\\delta_m}$ (its inverse over all curves: the largest median secant
ratio law/data that any elastic unloading from that radius can reach); the force where the
approach is largest (a rate-independent law starts to unload only there) and how long after
the peak force; the RMS about a quartic fitted to each branch
(the floor a smooth curve reaches); and the median loading residual at the fitted sigma_Y.

Writes `law_shapes.json` and `law_shapes.md` into --out.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.contact_burgoyne import CALTECH, DATA, GEOMETRY
from fitting.contact_calibration import (_kappa, _smoothed, law_force, read_curve, shifted_approach, strain_rate_s,
                                         unloading_secant_n_m)
from fitting.fit import least_squares
from hertzchain import atomic, contact

HARDNESS_RATIO = contact.JG_HARDNESS_RATIO


def truncation_force(approach_m, kappa, geometry, yield_stress_pa, poisson):
    """The `truncation` candidate along an approach history, N (`poisson` unused: same call as `law_force`)."""
    radius = geometry.reduced_radius_m
    modulus = 0.75 * kappa / math.sqrt(radius)
    hardness = HARDNESS_RATIO * yield_stress_pa
    tangent = (jnp.pi * hardness / modulus) ** 2 * radius
    peak = jax.lax.cummax(approach_m)
    plastic = peak > tangent
    max_force = jnp.where(plastic, 2 * jnp.pi * radius * hardness * (peak - tangent / 3),
                          contact.hertz_force(peak, kappa))
    radius_sq = jnp.where(plastic, 2 * radius * peak, radius * peak)
    span = 0.75 * max_force / (modulus * jnp.sqrt(jnp.maximum(radius_sq, 1e-30)))
    unloading_kappa = max_force / jnp.maximum(span, 1e-30) ** 1.5
    return contact.hertz_force(approach_m - (peak - span), unloading_kappa)


LAWS = {"jackson_green": law_force, "truncation": truncation_force}


class _Problem:
    """Whitened residuals of one material's curves in x = (ln sigma_Y,) for `least_squares`."""

    def __init__(self, law, pieces, kappa, poisson):
        def residuals(x):
            return jnp.concatenate([
                (law(a, kappa, GEOMETRY, jnp.exp(x[0]) * factor, poisson) - f) / (peak * math.sqrt(f.size))
                for a, f, peak, factor in pieces])

        self._residuals, self._jacobian = jax.jit(residuals), jax.jit(jax.jacfwd(residuals))

    def residuals(self, x):
        return np.asarray(self._residuals(jnp.asarray(x, dtype=float)))

    def linearize(self, x, columns):
        x = jnp.asarray(x, dtype=float)
        return np.asarray(self._residuals(x)), np.asarray(self._jacobian(x))[:, list(columns)]


def _rms(r):
    return float(100 * np.sqrt(np.mean(r**2)))


def _quartic_floor(approach, force, peak_index, peak):
    pieces = [force[s] - np.polyval(np.polyfit(approach[s], force[s], 4), approach[s])
              for s in (slice(0, peak_index), slice(peak_index, None))]
    return _rms(np.concatenate(pieces) / peak)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=str(DATA))
    parser.add_argument("--out", default="benchmarks/results/contact_burgoyne")
    args = parser.parse_args(argv)
    data_dir, out = Path(args.data), Path(args.out)
    if not (data_dir / "ExperimentalData").is_dir():
        print(f"no data at {data_dir}: nothing to do", file=sys.stderr)
        return 1
    report = {"hardness_ratio": HARDNESS_RATIO, "materials": {}}
    for material, names in CALTECH.items():
        kappa = _kappa(material, GEOMETRY)
        modulus = 0.75 * kappa / math.sqrt(GEOMETRY.reduced_radius_m)
        curves = [read_curve(data_dir / "ExperimentalData" / f"{name}.mat", material) for name in names]
        pieces, extra = [], []
        for curve in curves:
            approach = shifted_approach(curve, "first-sample")
            smooth = _smoothed(curve)
            peak_index, peak = int(np.argmax(smooth)), float(np.max(smooth))
            factor = float(contact.rate_hardened_yield_stress(1.0, material.yield_rate_constant,
                                                              strain_rate_s(curve, GEOMETRY)))
            pieces.append((jnp.asarray(approach), jnp.asarray(curve.force_n), peak, factor))
            secant = unloading_secant_n_m(approach, smooth)
            truncation_radius = math.sqrt(2 * GEOMETRY.reduced_radius_m * approach[peak_index])
            extra.append({"curve": curve.name, "peak_index": peak_index,
                          "flat_punch_radius_over_truncation": None if secant is None
                          else secant / (2 * modulus) / truncation_radius,
                          "quartic_floor_rms_percent": _quartic_floor(approach, curve.force_n, peak_index, peak),
                          "force_at_largest_approach_percent": float(100 * smooth[np.argmax(approach)] / peak),
                          "largest_approach_after_peak_force_us": None if curve.time_s is None
                          else float(1e6 * (curve.time_s[np.argmax(approach)] - curve.time_s[peak_index]))})
        results = {}
        for name, law in LAWS.items():
            print(f"{material.name}: {name}", file=sys.stderr)
            problem = _Problem(law, pieces, kappa, material.poisson)
            fit = least_squares(problem, [math.log(material.yield_stress_pa)], [0], max_steps=60, tolerance=1e-8)
            stress = math.exp(fit.x[0])
            loading = np.concatenate([np.arange(np.size(f)) < info["peak_index"] for (_, f, _, _), info in zip(pieces, extra)])
            fit_loading = least_squares(problem, fit.x, [0], weights=loading.astype(float), max_steps=60, tolerance=1e-8)
            stress_loading = math.exp(fit_loading.x[0])
            rows = []
            for (a, f, peak, factor), info in zip(pieces, extra):
                f = np.asarray(f)
                fitted = np.asarray(law(a, kappa, GEOMETRY, stress * factor, material.poisson))
                published = np.asarray(law(a, kappa, GEOMETRY, material.yield_stress_pa * factor, material.poisson))
                on_loading = np.asarray(law(a, kappa, GEOMETRY, stress_loading * factor, material.poisson))
                r, p = (fitted - f) / peak, info["peak_index"]
                rows.append({**info, "rms_percent": _rms(r), "rms_loading_percent": _rms(r[:p]),
                             "rms_unloading_percent": _rms(r[p:]),
                             "rms_loading_percent_loading_fit": _rms((on_loading - f)[:p] / peak),
                             "rms_unloading_percent_loading_fit": _rms((on_loading - f)[p:] / peak),
                             "median_loading_residual_percent": float(100 * np.median(r[:p])),
                             "peak_error_published_percent": float(100 * (published.max() / peak - 1))})
            results[name] = {"yield_stress_fitted_pa": stress, "converged": bool(fit.converged),
                             "yield_stress_fitted_to_loading_pa": stress_loading,
                             "loading_fit_over_published": stress_loading / material.yield_stress_pa,
                             "fitted_over_published": stress / material.yield_stress_pa, "curves": rows}
        report["materials"][material.name] = results
    bounds = [1.0 / c["flat_punch_radius_over_truncation"] for v in report["materials"].values()
              for c in v["jackson_green"]["curves"] if c["flat_punch_radius_over_truncation"] is not None]
    report["flat_punch_secant_ratio_bound_median"] = float(np.median(bounds))
    atomic.write_json(out / "law_shapes.json", atomic.json_ready(report))
    atomic.write_text(out / "law_shapes.md", _markdown(report))
    print((out / "law_shapes.md").read_text())
    return 0


def _span(rows, key, digits=1):
    values = [r[key] for r in rows if r[key] is not None]
    return f"{min(values):+.{digits}f} … {max(values):+.{digits}f}" if values else "-"


def _markdown(report):
    materials = list(report["materials"])
    lines = ["# Law shapes on the 15 Caltech curves (sigma_Y fitted once per material)", "",
             "| | " + " | ".join(materials) + " |", "|---" * (len(materials) + 1) + "|"]
    for law in LAWS:
        def row(label, cell):
            lines.append(f"| {law}: {label} | " + " | ".join(cell(report["materials"][m][law]) for m in materials) + " |")
        row("fitted ÷ published σ_Y", lambda d: f"{d['fitted_over_published']:.2f}")
        row("peak error, published (%)", lambda d: _span(d["curves"], "peak_error_published_percent"))
        row("RMS ÷ peak, whole curve (%)", lambda d: _span(d["curves"], "rms_percent"))
        row("RMS ÷ peak, loading (%)", lambda d: _span(d["curves"], "rms_loading_percent"))
        row("RMS ÷ peak, unloading (%)", lambda d: _span(d["curves"], "rms_unloading_percent"))
        row("median loading residual (%)", lambda d: _span(d["curves"], "median_loading_residual_percent"))
        row("σ_Y fitted to loading only ÷ published", lambda d: f"{d['loading_fit_over_published']:.2f}")
        row("same: RMS ÷ peak, loading (%)", lambda d: _span(d["curves"], "rms_loading_percent_loading_fit"))
        row("same: RMS ÷ peak, unloading (%)", lambda d: _span(d["curves"], "rms_unloading_percent_loading_fit"))
    first = next(iter(LAWS))
    lines.append("| RMS ÷ peak about a quartic per branch (%) | " + " | ".join(
        _span(report["materials"][m][first]["curves"], "quartic_floor_rms_percent") for m in materials) + " |")
    lines.append("| S/(2E*) ÷ √(2R*δ_m), data | " + " | ".join(
        _span(report["materials"][m][first]["curves"], "flat_punch_radius_over_truncation", 2) for m in materials) + " |")
    for key, label in (("force_at_largest_approach_percent", "force at the largest approach ÷ peak (%)"),
                       ("largest_approach_after_peak_force_us", "largest approach after the peak force (µs)")):
        lines.append(f"| {label} | " + " | ".join(
            _span(report["materials"][m][first]["curves"], key) for m in materials) + " |")
    lines += ["", "Largest median unloading secant ratio law ÷ data for any elastic unloading from the "
              f"truncation radius (flat punch, {report['flat_punch_secant_ratio_bound_median']:.2f} over the curves "
              "that unload to 50 %)."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
