"""Which stored bar record each of Burgoyne & Daraio's 15 Caltech curves comes from, and how
its force and approach compare with that record's other processing.

    python -m benchmarks.contact_processing [--data PATH] [--out benchmarks/results/contact_burgoyne]

The paper's curves (`ExperimentalData`, force and approach in time) and the processed records
of the two test days (`hopkinson_tests_5-22/`, `hopkinson_tests_6-6/`: `fd1..8` of May/June,
`fd_s440-1..6` of the July reprocessing; approach and force, no time) are all sampled at
100 ns (the three 50-ns curves are taken every second sample). For each curve and each
record, over every alignment that overlaps at least 90 % of the curve, the force is matched
as F_curve = k F_record (k least squares); the record and alignment with the smallest RMS
deviation (% of the curve's peak) are reported with k, the second-best record's deviation
(how distinct the match is), and at that alignment the approach as a linear map of the
record's, d_curve = s d_record + c, with its RMS deviation (um): a pure rescaling of the
same approach would leave a deviation at the noise level.

Where a curve is a stored record with force and approach rescaled by one factor (k and s
within `RESCALED_TOLERANCE` of each other and more than `RESCALED_MIN_CHANGE` from 1, approach
deviation below `RESCALED_APPROACH_UM`; `5-22/fd1` is the same file as `fd_s440-1`, the
July reprocessing), the law is fitted (sigma_Y and a damping time, `--damping`) on
those curves twice: as the paper stores them (`paper_scale/`) and divided back to the
July scale, force / k and approach / s (`july_scale/`), to show what the scale does to the
misfit: the law is not invariant under a common rescaling of force and approach (Hertz
and the elastic unloading are not linear in the approach).

Writes `processing.json` and `processing.md` into --out.
"""

from __future__ import annotations

import sys

import numpy as np

from benchmarks.contact_burgoyne import caltech_arguments, run_calibration
from fitting.contact_calibration import ContactCurve, read_curve
from hertzchain import atomic
from hertzchain.materials import STEEL_440C

# Sampling interval of the processed records, s (the raw records are at 10 MHz).
RECORD_STEP_S = 100e-9
# Fraction of a curve that an alignment must overlap.
MIN_OVERLAP = 0.9
# A curve counts as a rescaled July record where |k - s| < this and the approach deviates by
# less than RESCALED_APPROACH_UM (a pure rescaling leaves the approach at its noise level).
RESCALED_TOLERANCE = 0.02
RESCALED_APPROACH_UM = 5.0
# ... and the common factor differs from 1 by more than this (a record kept at its scale is
# not rescaled).
RESCALED_MIN_CHANGE = 0.1


def _records(data_dir):
    records = {}
    for day in ("hopkinson_tests_5-22", "hopkinson_tests_6-6"):
        for path in sorted((data_dir / day).glob("fd*.mat")):
            curve = read_curve(path, STEEL_440C)  # the material is not used
            records[f"{day.split('_')[-1]}/{path.stem}"] = (curve.approach_m, curve.force_n)
    return records


def best_alignment(force, record_force):
    """(RMS deviation / peak, scale k, lag) of the best F = k F_record over the alignments
    (record index = curve index + lag) that overlap at least `MIN_OVERLAP` of the curve."""
    n, peak, best = force.size, float(np.max(force)), (np.inf, np.nan, 0)
    for lag in range(-int((1 - MIN_OVERLAP) * n), record_force.size - int(MIN_OVERLAP * n) + 1):
        start, other = max(0, -lag), max(0, lag)
        size = min(n - start, record_force.size - other)
        if size < MIN_OVERLAP * n:
            continue
        x, y = force[start:start + size], record_force[other:other + size]
        scale = float(x @ y / (y @ y))
        deviation = float(np.sqrt(np.mean((x - scale * y) ** 2)) / peak)
        if deviation < best[0]:
            best = (deviation, scale, lag)
    return best


def main(argv=None) -> int:
    args, data_dir, out, curves = caltech_arguments(argv, __doc__)
    if curves is None:
        return 1
    records = _records(data_dir)
    rows = []
    for curve in curves:
        every = max(1, int(round(RECORD_STEP_S / float(np.median(np.diff(curve.time_s))))))
        force, approach = curve.force_n[::every], curve.approach_m[::every]
        matches = sorted((best_alignment(force, record_force), name)
                         for name, (_, record_force) in records.items())
        (deviation, scale, lag), name = matches[0]
        record_approach, _ = records[name]
        start, other = max(0, -lag), max(0, lag)
        size = min(force.size - start, record_approach.size - other)
        x, y = approach[start:start + size], record_approach[other:other + size]
        slope, intercept = np.polyfit(y, x, 1)
        rows.append({"file": curve.name, "material": curve.material.name, "decimation": every,
                     "record": name, "force_rms_deviation_percent": 100 * deviation, "force_scale": scale,
                     "lag_samples": lag, "second_record": matches[1][1],
                     "second_force_rms_deviation_percent": 100 * matches[1][0][0],
                     "approach_slope": float(slope), "approach_intercept_um": 1e6 * float(intercept),
                     "approach_rms_deviation_um": 1e6 * float(np.sqrt(np.mean((x - slope * y - intercept) ** 2)))})
        print(rows[-1], file=sys.stderr, flush=True)
    rescaled = [(curve, row) for curve, row in zip(curves, rows)
                if abs(row["force_scale"] - row["approach_slope"]) < RESCALED_TOLERANCE
                and abs(row["force_scale"] - 1.0) > RESCALED_MIN_CHANGE
                and row["approach_rms_deviation_um"] < RESCALED_APPROACH_UM]
    scales = {}
    if rescaled:
        paper = [curve for curve, _ in rescaled]
        july = [ContactCurve(c.name, c.time_s, c.approach_m / r["approach_slope"], c.force_n / r["force_scale"],
                             c.material) for c, r in rescaled]
        for label, chosen in (("paper_scale", paper), ("july_scale", july)):
            print(f"{label} ...", file=sys.stderr, flush=True)
            report = run_calibration(chosen, out / label, label.replace("_", " "), fit_damping=True)
            material = report["materials"][STEEL_440C.name]
            scales[label] = {"yield_stress_mpa": material["fitted"]["yield_stress_pa"] / 1e6,
                             "fitted_over_published": material["fitted_over_given_yield_stress"],
                             "eta_us": 1e6 * material["fitted"]["eta_s"],
                             "curves": {c["file"]: {"rms_percent": 100 * c["rms_over_peak_fitted"],
                                                    "peak_error_published_percent": 100 * c["peak_force_error_model"],
                                                    "secant_ratio": c["unloading_secant_ratio_fitted"],
                                                    "radius_needed_over_law": c["unloading_radius_needed_over_law"]}
                                        for c in report["curves"]},
                             "elapsed_s": report["elapsed_s"]}
    summary = {"record_step_s": RECORD_STEP_S, "min_overlap": MIN_OVERLAP, "curves": rows, "scales": scales}
    atomic.write_json(out / "processing.json", atomic.json_ready(summary))
    lines = ["# The 15 Caltech curves against the stored processed records", "",
             "Force matched as F_curve = k F_record over alignments overlapping ≥ 90 % of the curve (100 ns "
             "samples); approach at that alignment as d_curve = s d_record + c. Deviations: RMS, force in % of "
             "the curve's peak, approach in µm. `fd1..8`: May/June processing; `fd_s440-*`: July reprocessing "
             "(`python -m benchmarks.contact_processing`).", "",
             "| curve | record | force deviation (%) | k | next record (deviation %) | s | c (µm) | approach deviation (µm) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['file']} | {r['record']} | {r['force_rms_deviation_percent']:.1f} | {r['force_scale']:.3f} | "
                     f"{r['second_record']} ({r['second_force_rms_deviation_percent']:.1f}) | {r['approach_slope']:.3f} | "
                     f"{r['approach_intercept_um']:.1f} | {r['approach_rms_deviation_um']:.1f} |")
    if scales:
        lines += ["", "Curves that are a stored record rescaled by one factor, fitted with `--damping` at the paper's scale and at the July scale "
                  "(force / k, approach / s; σ_Y and η fitted on these curves alone):", "",
                  "| scale | σ_Y (MPa) | ÷ published | η (µs) | curve: RMS ÷ peak (%), peak error at published (%), "
                  "unloading secant law ÷ data, radius the unloading needs ÷ law's |", "|---|---|---|---|---|"]
        for label, entry in scales.items():
            cells = "; ".join(f"{name}: {c['rms_percent']:.1f}, {c['peak_error_published_percent']:+.1f}, "
                              f"{c['secant_ratio']:.2f}, {c['radius_needed_over_law']:.2f}"
                              for name, c in entry["curves"].items())
            lines.append(f"| {label} | {entry['yield_stress_mpa']:.0f} | {entry['fitted_over_published']:.2f} | "
                         f"{entry['eta_us']:.2f} | {cells} |")
    atomic.write_text(out / "processing.md", "\n".join(lines) + "\n")
    print((out / "processing.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
