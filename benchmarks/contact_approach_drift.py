"""A drifting approach record: the law with a linear drift of each curve's approach fitted, on
Burgoyne & Daraio's 15 Caltech curves, and the drift two processings of one shot measure.

    python -m benchmarks.contact_approach_drift [--data PATH] [--out benchmarks/results/contact_burgoyne] [--reuse]

The approach of a split-Hopkinson-bar test is the difference of the two bar ends'
displacements, each the time integral of gauge strains, so a gain or dispersion mismatch
between the incident and reflected pulses, or a strain baseline error, makes it drift, while
the force (the transmitted strain) carries none (`fitting.contact_calibration`, option
`fit_approach_drift`). Runs (`calibrate`, published rate constants, approach offset at the
first sample shifted out, sigma_Y fitted once per material), each into its own folder under
--out:

- `approach_drift/`: the law with a drift b (m/s) per curve;
- `damping_and_drift/`: the same with the Kuwabara-Kono damping time per material.

Against `damping/` of `contact_rate_terms.py` (the damping without a drift; run it first).
Per curve: RMS / peak, the drift with its sigma, what it adds over the record against the
largest approach, the unloading secant ratio (law / data, the data read against the approach
without the drift).

The check the files allow: `force_alum` and `al_12` are two processings of one shot (the
May/June record 5-22 `fd4`: `processing.md` of `contact_processing.py`). Their forces agree
once aligned in time; the difference of their approaches, fitted with a line in time over
the overlap, is a drift that the processing alone made. It is set beside the difference of
the two curves' fitted drifts.

Writes `approach_drift.json` and `approach_drift.md` into --out.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from benchmarks.contact_burgoyne import calibration_runs, caltech_and_base
from benchmarks.contact_processing import best_alignment
from benchmarks.contact_rate_terms import _span, material_table
from fitting.contact_calibration import shifted_approach
from hertzchain.io import atomic

RUNS = {
    "approach_drift": {"fit_approach_drift": True},
    "damping_and_drift": {"fit_damping": True, "fit_approach_drift": True},
}
# Two processings of one shot (processing.md): the second's force is the first's shot
SAME_SHOT = ("al_12", "force_alum")
# The misfit target of the curves, RMS / peak
TARGET = 0.08


def processing_drift(first, second):
    """(slope m/s, RMS about the line m, overlap s, force deviation / peak, lag samples) of the
    approach of `second` minus that of `first` (`ContactCurve`s with equal sampling), aligned
    by their forces, each approach from its first aligned sample."""
    deviation, _, lag = best_alignment(first.force_n, second.force_n)
    start, other = max(0, -lag), max(0, lag)
    size = min(first.force_n.size - start, second.force_n.size - other)
    time = first.time_s[start:start + size] - first.time_s[start]
    a = first.approach_m[start:start + size]
    b = second.approach_m[other:other + size]
    difference = (b - b[0]) - (a - a[0])
    line = np.polyfit(time, difference, 1)
    rms = float(np.sqrt(np.mean((difference - np.polyval(line, time)) ** 2)))
    return float(line[0]), rms, float(time[-1]), float(deviation), int(lag)


def main(argv=None) -> int:
    started = caltech_and_base(argv, __doc__, "damping", "contact_rate_terms.py")
    if started is None:
        return 1
    args, out, curves, base = started
    runs = {"damping": base, **calibration_runs(curves, out, RUNS, args.reuse)}

    rows = []
    for k, curve in enumerate(curves):
        largest = float(np.max(shifted_approach(curve, "first-sample")))
        row = {"file": curve.name, "material": curve.material.name, "largest_approach_m": largest}
        for label, run in runs.items():
            entry = run["curves"][k]
            row[f"{label}_rms"] = entry["rms_over_peak_fitted"]
            row[f"{label}_secant_ratio"] = entry["unloading_secant_ratio_fitted"]
            if label in RUNS:
                row[f"{label}_drift_m_s"] = entry["approach_drift_m_s"]
                row[f"{label}_drift_stderr_m_s"] = entry["approach_drift_stderr_m_s"]
                row[f"{label}_drift_over_record_m"] = entry["approach_drift_over_record_m"]
        rows.append(row)

    by_name = {c.name: c for c in curves}
    index = {c.name: k for k, c in enumerate(curves)}
    slope, rms, overlap, deviation, lag = processing_drift(*(by_name[n] for n in SAME_SHOT))
    same_shot = {"curves": list(SAME_SHOT), "approach_drift_between_processings_m_s": slope,
                 "rms_about_the_line_m": rms, "overlap_s": overlap, "force_deviation_over_peak": deviation,
                 "lag_samples": lag}
    for label in RUNS:
        first, second = (rows[index[n]] for n in SAME_SHOT)
        errors = [r[f"{label}_drift_stderr_m_s"] for r in (first, second)]
        same_shot[label] = {
            "fitted_drift_difference_m_s": second[f"{label}_drift_m_s"] - first[f"{label}_drift_m_s"],
            "stderr_m_s": None if None in errors else math.hypot(*errors)}

    summary = {"data": "Burgoyne & Daraio 2014 (CC-BY 4.0), ExperimentalData: 15 Caltech curves",
               "curves": rows, "same_shot": same_shot, "target_rms_over_peak": TARGET,
               "elapsed_s": {label: runs[label].get("elapsed_s") for label in RUNS},
               "elapsed_note": "timed on a shared 2-core machine", "materials": {}, "median_secant_ratio": {},
               "curves_within_target": {}}
    for label, run in runs.items():
        summary["median_secant_ratio"][label] = run["median_unloading_secant_ratio_fitted"]
        summary["curves_within_target"][label] = sum(r[f"{label}_rms"] <= TARGET for r in rows)
    for name in runs["damping"]["materials"]:
        summary["materials"][name] = {label: {
            "yield_stress_mpa": run["materials"][name]["fitted"]["yield_stress_pa"] / 1e6,
            "yield_stress_stderr_mpa": run["materials"][name]["stderr"]["yield_stress_pa"] / 1e6,
            "fitted_over_published": run["materials"][name]["fitted_over_given_yield_stress"],
            "eta_us": 1e6 * run["materials"][name]["fitted"]["eta_s"],
            "converged": run["materials"][name]["converged"]} for label, run in runs.items()}
    atomic.write_json(out / "approach_drift.json", atomic.json_ready(summary))
    atomic.write_text(out / "approach_drift.md", _markdown(summary, list(runs)))
    print((out / "approach_drift.md").read_text())
    return 0


def _markdown(summary, labels) -> str:
    rows, materials = summary["curves"], list(summary["materials"])
    lines = ["# A drifting approach record (15 Caltech curves)", "",
             "σ_Y fitted once per material; published rate constants; approach offset shifted out. "
             "`damping`: the Kuwabara-Kono damping time per material without a drift "
             "(`contact_rate_terms.py`); the drift b (m/s) is fitted per curve, the law driven with "
             "δ(t) − b (t − t₀).", ""]
    add = material_table(lines, materials)
    for label in labels:
        add(f"{label}: RMS ÷ peak (%)", lambda m: _span([100 * r[f"{label}_rms"] for r in rows
                                                         if r["material"] == m]))
        add(f"{label}: fitted σ_Y (MPa) ± σ, ÷ published", lambda m: "{:.0f} ± {:.0f}, {:.2f}".format(
            summary["materials"][m][label]["yield_stress_mpa"], summary["materials"][m][label]["yield_stress_stderr_mpa"],
            summary["materials"][m][label]["fitted_over_published"]))
        add(f"{label}: η (µs)", lambda m: f"{summary['materials'][m][label]['eta_us']:.2f}")
        add(f"{label}: unloading secant law ÷ data", lambda m: _span([r[f"{label}_secant_ratio"] for r in rows
                                                                      if r["material"] == m], 2))
        if label in RUNS:
            add(f"{label}: drift (m/s)", lambda m: _span([r[f"{label}_drift_m_s"] for r in rows
                                                          if r["material"] == m], 3))
            add(f"{label}: drift over the record ÷ largest approach", lambda m: _span(
                [r[f"{label}_drift_over_record_m"] / r["largest_approach_m"] for r in rows if r["material"] == m], 2))
    lines += ["", "Curves within {:.0f} % RMS of their peak: ".format(100 * summary["target_rms_over_peak"]) + ", ".join(
        f"{label} {count} of {len(rows)}" for label, count in summary["curves_within_target"].items()) + ".",
        "Median unloading secant ratio law ÷ data: " + ", ".join(
            f"{label} {value:.2f}" for label, value in summary["median_secant_ratio"].items() if value is not None) + ".",
        ""]
    same = summary["same_shot"]
    first, second = same["curves"]
    lines.append(
        f"Two processings of one shot: `{second}` against `{first}`, forces aligned ({same['lag_samples']} samples, "
        f"force deviation {100 * same['force_deviation_over_peak']:.1f} % of the peak): their approaches differ by "
        f"a drift of {same['approach_drift_between_processings_m_s']:.3f} m/s over {1e6 * same['overlap_s']:.0f} µs "
        f"({1e6 * same['rms_about_the_line_m']:.1f} µm RMS about the line). Fitted drifts, `{second}` − `{first}`: "
        + ", ".join(f"{label} {same[label]['fitted_drift_difference_m_s']:.3f}"
                    + (f" ± {same[label]['stderr_m_s']:.3f}" if same[label]["stderr_m_s"] is not None else "")
                    + " m/s" for label in RUNS) + ".")
    lines += ["", "Per curve (RMS ÷ peak %; drift ± σ, m/s):", "",
              "| curve | " + " | ".join(f"{l} RMS" for l in labels)
              + " | drift | drift with damping | drift with damping over the record ÷ largest approach |",
              "|---" * (len(labels) + 4) + "|"]
    for r in rows:
        def drift(label):
            error = r[f"{label}_drift_stderr_m_s"]
            return f"{r[f'{label}_drift_m_s']:+.3f}" + (f" ± {error:.3f}" if error is not None else "")
        lines.append(f"| {r['file']} | " + " | ".join(f"{100 * r[f'{l}_rms']:.1f}" for l in labels)
                     + f" | {drift('approach_drift')} | {drift('damping_and_drift')} | "
                     f"{r['damping_and_drift_drift_over_record_m'] / r['largest_approach_m']:.2f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
