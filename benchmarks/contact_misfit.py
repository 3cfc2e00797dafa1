"""What the contact law misses on Burgoyne & Daraio's curves once damping is fitted: where in
each record the misfit sits, what bounds it, and what fitting more of the law's constants does.

    python -m benchmarks.contact_misfit [--data PATH] [--out benchmarks/results/contact_burgoyne] [--reuse]

Starts from `damping/` of `contact_rate_terms.py` (sigma_Y and a Kuwabara-Kono damping time
fitted once per material, published rate constants, approach offset shifted out; run it
first). Per curve, with the model forces at that run's fitted constants:

- RMS / peak and the share of the squared misfit in five phases: `toe` (loading below 20 %
  of the peak force), `rise` (loading, 20-90 %), `top` (above 90 %, either side of the
  peak), `fall` (unloading, 20-90 %), `tail` (unloading below 20 %); loading = up to the
  peak of the force (1 us mean);
- the mean residual (bias) of loading and unloading, % of the peak;
- the ringing floor: RMS of the data about a quartic in time per branch (no smooth law can
  go below it);
- the monotone floor: on the samples where the approach is at its largest so far, a
  rate-independent law (whatever its shape) gives a force that never falls; the RMS of the
  data about their best non-decreasing fit in time (`scipy.optimize.isotonic_regression`)
  over all samples;
- residual overlap: the approach at which the unloading force first falls below 10 % of the
  peak, over the largest approach (None: not within the record); the force at the end of the
  record (last 1 us), data and model, % of the peak;
- the mean contact pressure the measured unloading implies: an elastic contact of radius a
  unloads at most as stiffly as a flat punch, 2E*a, so the measured secant stiffness S
  (90 -> 50 % of the peak) needs a >= S/(2E*), and the peak force on that area is at most
  F/(pi (S/2E*)^2); over the published sigma_Y, beside the loading's mean pressure on the
  truncated area (a plastically loaded contact carries about the hardness, 2.8-3 sigma_Y);
- the end of the record: how much the force falls in its last 5 us (% of the peak; the
  approach hardly moves there) and the RMS without those 5 us;
- the curve's own sigma_Y (fitted to it alone with the material's damping time) over the
  material's, its RMS so, sampling interval, approach offset, strain rate, mean contact
  pressure on the truncated area 2 pi R* delta at the peak over the published sigma_Y.

Runs, each into its own folder under --out (`calibrate` on the 15 curves with damping):

- `damping_rate_fitted/`: the rate constant C fitted per material as well (sigma_y(1 + C
  ln(rate / 1e-3 /s)), the published form);
- `damping_hardness_fitted/`: the hardness ratio h = H/sigma_Y of the law's fully plastic
  branch fitted per material as well (`--fit-hardness-ratio`);
- `damping_without_outliers/`: the damping fit without `force10b` and `force_alum` (the
  curves the analysis flags), to show what they move;
- `damping_end_trimmed/`: the damping fit on the records without their last 5 us (where the
  force falls faster than any elastic contact of these hemispheres can unload: the stiffness
  of that drop over 2E* is the radius of the flat punch it needs, reported per curve beside
  the hemisphere's radius).

Writes `misfit.json`, `misfit.md`, `misfit_time.png` and `misfit_approach.png` (residual
against time and against approach per curve, coloured by phase) into --out.
"""

from __future__ import annotations

import math
import sys

import jax.numpy as jnp
import numpy as np
from scipy.optimize import isotonic_regression

from benchmarks.contact_burgoyne import GEOMETRY, caltech_and_base, run_calibration
from fitting.contact_calibration import (ContactCurve, _kappa, _smoothed, approach_rate_m_s, model_force,
                                         shifted_approach)
from hertzchain import contact
from hertzchain.io import atomic

PHASES = ("toe", "rise", "top", "fall", "tail")
PHASE_COLOURS = {"toe": "tab:gray", "rise": "tab:blue", "top": "tab:red", "fall": "tab:orange", "tail": "tab:green"}
# Fraction of the peak force below which an unloading counts as ended (residual overlap).
RESIDUAL_FORCE_FRACTION = 0.1
# Length of the end of a record whose force drop is reported, us.
END_WINDOW_US = 5


def end_samples(step_s):
    """Samples in the last microsecond of a record."""
    return max(1, int(round(1e-6 / step_s)))


RUNS = {
    "damping_rate_fitted": {"fit_damping": True, "fit_rate_constant": True},
    "damping_hardness_fitted": {"fit_damping": True, "fit_hardness_ratio": True},
    "damping_without_outliers": {"fit_damping": True},
    "damping_end_trimmed": {"fit_damping": True},
}
OUTLIERS = ("force10b", "force_alum")


def phases(force_n, smooth_n):
    """Phase label of every sample (`PHASES`), from the force relative to its smoothed peak."""
    peak_index = int(np.argmax(smooth_n))
    fraction = smooth_n / smooth_n[peak_index]
    loading = np.arange(force_n.size) <= peak_index
    labels = np.where(fraction > 0.9, "top", np.where(loading, np.where(fraction < 0.2, "toe", "rise"),
                                                    np.where(fraction < 0.2, "tail", "fall")))
    return labels


def monotone_floor(approach_m, force_n, peak_n):
    """RMS / peak over all samples of the best a rate-independent law can do where the approach
    is at its largest so far (force non-decreasing in time there); other samples count as 0."""
    at_max = approach_m >= np.maximum.accumulate(approach_m)
    chosen = force_n[at_max]
    squared = np.sum((chosen - isotonic_regression(chosen).x) ** 2)
    return float(math.sqrt(squared / force_n.size) / peak_n)


def quartic_floor(time_s, force_n, peak_index, peak_n):
    """RMS / peak of the data about a quartic in time on each side of the force peak."""
    squared = 0.0
    for part in (slice(0, peak_index + 1), slice(peak_index + 1, None)):
        t, f = time_s[part], force_n[part]
        if t.size > 5:
            squared += float(np.sum((f - np.polyval(np.polyfit(t - t[0], f, 4), t - t[0])) ** 2))
    return float(math.sqrt(squared / force_n.size) / peak_n)


def residual_overlap_fraction(approach_m, force_n, peak_index, peak_n):
    """Approach at which the force first falls below 10 % of the peak after it, over the largest
    approach (None: not within the record)."""
    below = np.nonzero(force_n[peak_index:] < RESIDUAL_FORCE_FRACTION * peak_n)[0]
    return None if below.size == 0 else float(approach_m[peak_index + below[0]] / np.max(approach_m))


def trimmed(curve: ContactCurve, duration_s: float) -> ContactCurve:
    """The curve without its last `duration_s` of samples."""
    keep = curve.time_s <= curve.time_s[-1] - duration_s
    return ContactCurve(curve.name, curve.time_s[keep], curve.approach_m[keep], curve.force_n[keep], curve.material)


def fitted_force(curve: ContactCurve, entry, material_entry):
    """The law with the damping along a curve at a run's fitted constants (its `contact.json`
    entries of the curve and its material), N."""
    approach = shifted_approach(curve, "first-sample")
    fitted = material_entry["fitted"]
    stress = contact.rate_hardened_yield_stress(fitted["yield_stress_pa"], fitted["rate_constant"],
                                                entry["strain_rate_s"])
    return np.asarray(model_force(jnp.asarray(approach), jnp.asarray(approach_rate_m_s(curve, approach)),
                                  float(np.median(np.diff(curve.time_s))), _kappa(curve.material, GEOMETRY),
                                  GEOMETRY, stress, curve.material.poisson, fitted["eta_s"]))


def analyse_curve(curve, entry, material_entry):
    """The per-curve numbers of the module docstring from a run's report entry."""
    approach = shifted_approach(curve, "first-sample")
    smooth = _smoothed(curve)
    peak_index = int(np.argmax(smooth))
    peak = float(smooth[peak_index])
    model = entry["force_fitted_n"]
    residual = (model - curve.force_n) / peak
    labels = phases(curve.force_n, smooth)
    step = float(np.median(np.diff(curve.time_s)))
    tail, last = end_samples(step), END_WINDOW_US * end_samples(step)
    secant = entry["unloading_secant_measured_n_m"]
    modulus = material_entry["youngs_pa"] / (2 * (1 - material_entry["poisson"] ** 2))  # E* of like bodies
    total = float(np.sum(residual**2))
    loading = np.arange(residual.size) <= peak_index
    own = material_entry["yield_stress_per_curve_pa"][curve.name]
    sigma = material_entry["fitted"]["yield_stress_pa"]
    return {
        "file": curve.name, "material": curve.material.name,
        "rms_percent": 100 * math.sqrt(total / residual.size),
        "share_loading": float(np.sum(residual[loading] ** 2) / total),
        **{f"share_{p}": float(np.sum(residual[labels == p] ** 2) / total) for p in PHASES},
        "bias_loading_percent": 100 * float(np.mean(residual[loading])),
        "bias_unloading_percent": 100 * float(np.mean(residual[~loading])) if (~loading).any() else None,
        "ringing_floor_percent": 100 * quartic_floor(curve.time_s, curve.force_n, peak_index, peak),
        "monotone_floor_percent": 100 * monotone_floor(approach, curve.force_n, peak),
        "residual_overlap_fraction_data": residual_overlap_fraction(approach, smooth, peak_index, peak),
        "end_force_data_percent": 100 * float(np.mean(curve.force_n[-tail:]) / peak),
        "end_force_model_percent": 100 * float(np.mean(model[-tail:]) / peak),
        "force_at_largest_approach_percent": 100 * float(smooth[int(np.argmax(approach))] / peak),
        "own_yield_stress_over_material": own / sigma,
        "rms_own_fit_percent": 100 * entry["rms_over_peak_own_fit"],
        "sample_interval_ns": 1e9 * step,
        "approach_offset_um": 1e6 * float(curve.approach_m[0]),
        "strain_rate_s": entry["strain_rate_s"],
        "peak_force_kn": peak / 1e3,
        "approach_at_peak_mm": 1e3 * float(approach[peak_index]),
        "mean_pressure_over_published_yield_stress": entry["mean_pressure_truncated_area_over_yield_stress"],
        "unloading_pressure_bound_over_published_yield_stress": None if secant is None
        else peak / (math.pi * (secant / (2 * modulus)) ** 2) / curve.material.yield_stress_pa,
        "end_force_drop_percent": 100 * float(np.mean(curve.force_n[-last - tail:-last])
                                              - np.mean(curve.force_n[-tail:])) / peak,
        "end_approach_change_um": 1e6 * float(approach[-last - 1] - approach[-1]),
        # a flat punch of radius a unloads with 2E*a, the stiffest any elastic contact of radius a can
        "end_drop_flat_punch_radius_mm": 1e3 * float(np.mean(curve.force_n[-last - tail:-last])
                                                     - np.mean(curve.force_n[-tail:]))
        / max(float(approach[-last - 1] - approach[-1]), 1e-12) / (2 * modulus),
        "rms_without_end_percent": 100 * math.sqrt(float(np.mean(residual[:-last] ** 2))),
        "_residual": residual, "_labels": labels, "_approach": approach,
    }


def _figures(curves, rows, out):
    from hertzchain.plotting import plt

    for axis_name, filename in (("time", "misfit_time.png"), ("approach", "misfit_approach.png")):
        figure, axes = plt.subplots(3, 5, figsize=(18, 9), squeeze=False)
        for ax, curve, row in zip(axes.flat, curves, rows):
            x = (curve.time_s - curve.time_s[0]) * 1e6 if axis_name == "time" else row["_approach"] * 1e3
            for phase in PHASES:
                chosen = row["_labels"] == phase
                ax.plot(x[chosen], 100 * row["_residual"][chosen], ".", ms=1.5, color=PHASE_COLOURS[phase],
                        label=phase)
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_title(f"{curve.name}: RMS {row['rms_percent']:.1f} %", fontsize=9)
            ax.set_xlabel("time (us)" if axis_name == "time" else "approach (mm)", fontsize=8)
            ax.set_ylabel("(model - data) / peak (%)", fontsize=8)
        axes.flat[0].legend(fontsize=7, markerscale=5)
        figure.suptitle(f"residual of the law with damping (sigma_Y, eta fitted per material) against {axis_name}")
        atomic.finish_figure(figure, out / filename, dpi=80)


def main(argv=None) -> int:
    started = caltech_and_base(argv, __doc__, "damping", "contact_rate_terms.py")
    if started is None:
        return 1
    args, out, curves, damping = started
    rows = []
    for curve, entry in zip(curves, damping["curves"]):
        material = damping["materials"][curve.material.name]
        rows.append(analyse_curve(curve, {**entry, "force_fitted_n": fitted_force(curve, entry, material)},
                                  material))
    _figures(curves, rows, out)

    runs = {}
    for label, options in RUNS.items():
        chosen = [c for c in curves if label != "damping_without_outliers" or c.name not in OUTLIERS]
        if label == "damping_end_trimmed":
            chosen = [trimmed(c, END_WINDOW_US * 1e-6) for c in curves]
        print(f"{label} ...", file=sys.stderr, flush=True)
        runs[label] = run_calibration(chosen, out / label, label.replace("_", " "), args.reuse, **options)
    elapsed = {label: run.get("elapsed_s") for label, run in runs.items()}
    for row in rows:
        for label, run in runs.items():
            match = [c for c in run["curves"] if c["file"] == row["file"]]
            row[f"{label}_rms_percent"] = 100 * match[0]["rms_over_peak_fitted"] if match else None

    materials = {}
    for name, entry in damping["materials"].items():
        materials[name] = {"damping": _constants(entry),
                           **{label: _constants(run["materials"][name]) for label, run in runs.items()}}
    offsets = [r["approach_offset_um"] for r in rows]
    correlation = {key: float(np.corrcoef(offsets, [r[key] for r in rows])[0, 1])
                   for key in ("rms_percent", "share_toe", "bias_loading_percent")}
    summary = {"base_run": "damping/ (benchmarks/contact_rate_terms.py)", "phases": list(PHASES),
               "correlation_with_approach_offset": correlation, "approach_offset_range_um": [min(offsets), max(offsets)],
               "residual_force_fraction": RESIDUAL_FORCE_FRACTION, "outliers": list(OUTLIERS),
               "curves": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
               "materials": materials, "elapsed_s": elapsed,
               "elapsed_note": "timed on a shared 2-core machine under load"}
    atomic.write_json(out / "misfit.json", atomic.json_ready(summary))
    atomic.write_text(out / "misfit.md", _markdown(summary))
    print((out / "misfit.md").read_text())
    return 0


def _constants(entry):
    fitted, errors = entry["fitted"], entry["stderr"]
    return {"yield_stress_mpa": fitted["yield_stress_pa"] / 1e6,
            "yield_stress_stderr_mpa": errors["yield_stress_pa"] / 1e6,
            "fitted_over_published": entry["fitted_over_given_yield_stress"],
            "eta_us": 1e6 * fitted["eta_s"], "rate_constant": fitted["rate_constant"],
            "rate_constant_stderr": errors.get("rate_constant"),
            "hardness_ratio": fitted.get("hardness_ratio", 2.84), "hardness_ratio_stderr": errors.get("hardness_ratio")}


def _f(value, digits=1):
    return "-" if value is None else f"{value:.{digits}f}"


def _markdown(summary) -> str:
    rows = summary["curves"]
    lines = ["# Where the law with damping misses the 15 Caltech curves", "",
             "Base: `damping/` (σ_Y and η fitted once per material, published rate constants, approach offset "
             "shifted out). Residual = (model − data) / peak force. Shares of the squared misfit by phase: toe "
             "(loading < 20 % of the peak), rise (loading 20–90 %), top (> 90 %), fall (unloading 20–90 %), tail "
             "(unloading < 20 %). Floors: ringing = RMS about a quartic in time per branch; monotone = RMS about "
             "the best non-decreasing force where the approach is at its largest so far (what any "
             "rate-independent law must leave). Residual overlap: approach where the unloading force first "
             "falls below 10 % of the peak ÷ largest approach (`-`: not in the record); end force: the last 1 µs, "
             "% of the peak. p̄: mean contact pressure at the peak on the truncated area 2πR*δ (loading) and the "
             "most the measured unloading stiffness allows, F/(π(S/2E*)²) (flat-punch bound). Last 5 µs: the fall "
             "of the force (1 µs means) and of the approach, the flat-punch radius that drop needs (ΔF/Δδ ÷ 2E*; "
             "each hemisphere has R = 3.175 mm; `-`: the approach grows) and the RMS without those samples. "
             "Figures: "
             "[`misfit_time.png`](misfit_time.png), [`misfit_approach.png`](misfit_approach.png).", "",
             "| curve | dt (ns) | RMS (%) | loading share | toe | rise | top | fall | tail | bias load / unload (%) "
             "| ringing floor (%) | monotone floor (%) | residual overlap, data | end force data / model (%) "
             "| own σ_Y ÷ material | RMS own σ_Y (%) | p̄ ÷ σ_Y pub: loading / unloading bound "
             "| last 5 µs: force drop (%) / approach change (µm) / flat-punch radius it needs (mm) / RMS without (%) |",
             "|---" * 18 + "|"]
    for r in rows:
        lines.append(
            f"| {r['file']} | {r['sample_interval_ns']:.0f} | {r['rms_percent']:.1f} | {r['share_loading']:.2f} | "
            + " | ".join(f"{r[f'share_{p}']:.2f}" for p in summary["phases"])
            + f" | {_f(r['bias_loading_percent'])} / {_f(r['bias_unloading_percent'])} | "
            f"{r['ringing_floor_percent']:.1f} | {r['monotone_floor_percent']:.1f} | "
            f"{_f(r['residual_overlap_fraction_data'], 2)} | "
            f"{r['end_force_data_percent']:.0f} / {r['end_force_model_percent']:.0f} | "
            f"{r['own_yield_stress_over_material']:.2f} | {r['rms_own_fit_percent']:.1f} | "
            f"{r['mean_pressure_over_published_yield_stress']:.2f} / "
            f"{_f(r['unloading_pressure_bound_over_published_yield_stress'], 2)} | "
            f"{r['end_force_drop_percent']:.0f} / {r['end_approach_change_um']:.1f} / "
            f"{_f(r['end_drop_flat_punch_radius_mm'] if r['end_approach_change_um'] > 0 else None)} / "
            f"{r['rms_without_end_percent']:.1f} |")
    correlation = summary["correlation_with_approach_offset"]
    low, high = summary["approach_offset_range_um"]
    lines += ["", f"The approach offset at the first sample (shifted out; {low:.0f}–{high:.0f} µm) against the misfit "
              f"over the {len(rows)} curves: correlation with the RMS {correlation['rms_percent']:+.2f}, with the toe's share "
              f"{correlation['share_toe']:+.2f}, with the loading bias {correlation['bias_loading_percent']:+.2f}."]
    labels = [k[: -len("_rms_percent")] for k in rows[0] if k.endswith("_rms_percent") and k != "rms_percent"]
    lines += ["", "RMS ÷ peak (%) per curve with more constants fitted per material (all with damping):", "",
              "| curve | damping | " + " | ".join(labels) + " |", "|---" * (len(labels) + 2) + "|"]
    for r in rows:
        lines.append(f"| {r['file']} | {r['rms_percent']:.1f} | "
                     + " | ".join(_f(r[f"{label}_rms_percent"]) for label in labels) + " |")
    lines += ["", "Fitted constants per material (σ_Y ± σ; the σ of the runs that fit C or h with σ_Y is the "
              "Gauss-Newton one only, far too small for thousands of correlated samples):", "",
              "| run | material | σ_Y (MPa) | ÷ published | η (µs) | C | h |", "|---|---|---|---|---|---|---|"]
    for name, entry in summary["materials"].items():
        for label, c in entry.items():
            lines.append(f"| {label} | {name} | {c['yield_stress_mpa']:.0f} ± {c['yield_stress_stderr_mpa']:.0f} | "
                         f"{c['fitted_over_published']:.2f} | {c['eta_us']:.2f} | {c['rate_constant']:.4f} | "
                         f"{c['hardness_ratio']:.2f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
