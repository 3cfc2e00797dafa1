"""The contact law on the measured sphere-sphere curves of Burgoyne & Daraio (PRE 89, 032203,
2014): `hertzchain contact` on the 15 Caltech curves, and how the data's caveats move it.

    python benchmarks/contact_burgoyne.py [--data PATH] [--out benchmarks/results/contact_burgoyne] [--reuse]

Runs, each into its own folder under --out:

- `published/`: the 15 Caltech curves (`ExperimentalData`, loading and unloading; the
  paper's Fig. 4), approach offset at the first sample shifted out, published constants
  with published rate constants, sigma_Y fitted per material. These are the curves the
  paper's constants were fitted to; `force_alum` has no unloading branch (its force falls
  while the approach still grows) and is reported but has no secant stiffness.
- `offset_kept/`: the same with the stored approach offset (5-60 um) kept.
- `rate_fitted/`: the rate constant fitted with sigma_Y.
- `processing_high/`, `processing_low/`: the 440C records in the two processings of the
  raw bar records, which differ ~2x in force (`fd_s440-1..6`: the July reprocessing,
  which the raw records' conversion reproduces; 5-22 `fd2, fd3` and 6-6 `fd1..3`: the
  May/June one). They have no time column: the strain rate is the median of the six 440C
  Caltech curves.

Writes `summary.json` and `summary.md` (the acceptance numbers) into --out.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from fitting.contact_calibration import ContactGeometry, calibrate, read_curve, write_outputs
from hertzchain.io import atomic
from hertzchain.materials import ALUMINIUM_2017, STEEL_302, STEEL_440C

DATA = Path(__file__).resolve().parents[2] / "shared/data/real/burgoyne-2014"
CALTECH = {
    STEEL_440C: ("force7_5", "force10", "force10b", "force12_5", "force15", "force17_5"),
    STEEL_302: ("s302_10", "s302_12", "s302_15", "s302_17"),
    ALUMINIUM_2017: ("al_12", "al_12b", "al_15", "al_17", "force_alum"),
}
GEOMETRY = ContactGeometry("sphere-sphere", 3.175e-3)  # two hemispheres of 1/8 in


def run_calibration(curves, out, title, reuse=False, curve_fields=None, **options):
    """`calibrate` on `curves` with `options`, written into `out` (its `contact.json` with the
    elapsed time); `reuse`: read an existing `contact.json` instead. `curve_fields(curve,
    entry)`: further fields of each curve's entry in `contact.json`, from the curve and its
    entry in the calibration's report (which still holds its `_series`)."""
    if reuse and (out / "contact.json").is_file():
        return json.loads((out / "contact.json").read_text())
    start = time.perf_counter()
    report = calibrate(curves, GEOMETRY, progress=lambda text: print(f"  {text}", file=sys.stderr), **options)
    extra = [curve_fields(c, entry) for c, entry in zip(curves, report["curves"])] if curve_fields else None
    data = write_outputs(report, curves, out, title=title)
    for entry, fields in zip(data["curves"], extra or ()):
        entry.update(fields)
    data["elapsed_s"] = time.perf_counter() - start
    atomic.write_json(out / "contact.json", atomic.json_ready(data))
    return data


def calibration_runs(curves, out, runs, reuse=False, curve_fields=None):
    """`run_calibration` of `curves` for each entry of `runs` (label -> `calibrate` options),
    each into `out / label`, titled by its label: label -> its `contact.json` data."""
    done = {}
    for label, options in runs.items():
        print(f"{label} ...", file=sys.stderr, flush=True)
        done[label] = run_calibration(curves, out / label, label.replace("_", " "), reuse, curve_fields, **options)
    return done


def _span(data, key, material):
    values = [c[key] for c in data["curves"] if c["material"] == material and c[key] is not None]
    return [min(values), max(values)] if values else None


def _shift(base, other, material):
    """Range over a material's curves of the change of the peak-force error between two runs."""
    changes = [o["peak_force_error_model"] - b["peak_force_error_model"]
               for b, o in zip(base["curves"], other["curves"]) if b["material"] == material]
    return [min(changes), max(changes)]


def stored_report(out, label, script):
    """The `contact.json` of the run `label` under `out`, or None (with a message naming the
    `script` that writes it) where it is missing."""
    path = out / label / "contact.json"
    if not path.is_file():
        print(f"{path} missing: run python -m benchmarks.{Path(script).stem} first", file=sys.stderr)
        return None
    return json.loads(path.read_text())


def caltech_arguments(argv, description):
    """(arguments, data folder, output folder, the 15 Caltech curves) of a benchmark on these
    data (`--data`, `--out`, `--reuse`); the curves are None where the data are missing."""
    parser = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=str(DATA))
    parser.add_argument("--out", default="benchmarks/results/contact_burgoyne")
    parser.add_argument("--reuse", action="store_true", help="read runs whose contact.json exists instead of rerunning")
    args = parser.parse_args(argv)
    data_dir, out = Path(args.data), Path(args.out)
    if not (data_dir / "ExperimentalData").is_dir():
        print(f"no data at {data_dir}: nothing to do", file=sys.stderr)
        return args, data_dir, out, None
    return args, data_dir, out, [read_curve(data_dir / "ExperimentalData" / f"{name}.mat", m)
                                 for m, names in CALTECH.items() for name in names]


def caltech_and_base(argv, description, label, script):
    """(arguments, output folder, the 15 Caltech curves, the stored run `label`) of a benchmark
    that starts from another one's run (`script` writes it); None where the data or that run
    are missing (said on stderr)."""
    args, _, out, curves = caltech_arguments(argv, description)
    if curves is None:
        return None
    base = stored_report(out, label, script)
    return None if base is None else (args, out, curves, base)


def main(argv=None) -> int:
    args, data_dir, out, caltech = caltech_arguments(argv, __doc__)
    if caltech is None:
        return 1
    runs = {}
    for label, title, options in (
        ("published", "published constants, offset shifted out", {}),
        ("offset_kept", "published constants, approach offset kept", {"offset": "none"}),
        ("rate_fitted", "sigma_Y and rate constant fitted", {"fit_rate_constant": True}),
    ):
        print(f"{label} ...", file=sys.stderr)
        runs[label] = run_calibration(caltech, out / label, title, args.reuse, **options)
    rate_440c = float(np.median([c["strain_rate_s"] for c in runs["published"]["curves"]
                                 if c["material"] == STEEL_440C.name]))
    processings = {
        "processing_high": [data_dir / "hopkinson_tests_5-22" / f"fd_s440-{k}.mat" for k in (1, 2, 3)]
        + [data_dir / "hopkinson_tests_6-6" / f"fd_s440-{k}.mat" for k in (4, 5, 6)],
        "processing_low": [data_dir / "hopkinson_tests_5-22" / f"fd{k}.mat" for k in (2, 3)]
        + [data_dir / "hopkinson_tests_6-6" / f"fd{k}.mat" for k in (1, 2, 3)],
    }
    for label, paths in processings.items():
        print(f"{label} ...", file=sys.stderr)
        curves = [read_curve(p, STEEL_440C) for p in paths]
        curves = [c.__class__(f"{p.parent.name[-4:]}_{c.name}", c.time_s, c.approach_m, c.force_n, c.material)
                  for c, p in zip(curves, paths)]
        runs[label] = run_calibration(curves, out / label, f"440C, {label.replace('_', ' ')}", args.reuse,
                           strain_rate_s_given=rate_440c)

    published = runs["published"]
    summary = {"data": "Burgoyne & Daraio 2014 (CC-BY 4.0), ExperimentalData: 15 Caltech curves",
               "strain_rate_for_fd_files_s": rate_440c, "materials": {}, "runs": {}}
    for name, entry in published["materials"].items():
        summary["materials"][name] = {
            "peak_force_error_published": _span(published, "peak_force_error_model", name),
            "peak_force_error_thornton_published": _span(published, "peak_force_error_thornton", name),
            "fitted_yield_stress_mpa": entry["fitted"]["yield_stress_pa"] / 1e6,
            "fitted_yield_stress_stderr_mpa": entry["stderr"]["yield_stress_pa"] / 1e6,
            "fitted_over_published": entry["fitted_over_given_yield_stress"],
            "rms_over_peak_fitted": _span(published, "rms_over_peak_fitted", name),
            "rms_over_peak_fitted_loading": _span(published, "rms_over_peak_fitted_loading", name),
            "rms_over_peak_own_fit": _span(published, "rms_over_peak_own_fit", name),
            "rms_over_peak_fitted_unloading": _span(published, "rms_over_peak_fitted_unloading", name),
            "unloading_secant_ratio_fitted": _span(published, "unloading_secant_ratio_fitted", name),
            "unloading_radius_needed_over_law": _span(published, "unloading_radius_needed_over_law", name),
            "unloading_radius_needed_over_reduced_radius": _span(
                published, "unloading_radius_needed_over_reduced_radius", name),
            "offset_kept_peak_force_error_published": _span(runs["offset_kept"], "peak_force_error_model", name),
            "offset_kept_peak_error_shift": _shift(published, runs["offset_kept"], name),
            "approach_offset_um": [1e6 * v for v in _span(published, "approach_offset_m", name)],
            "offset_kept_fitted_yield_stress_mpa":
                runs["offset_kept"]["materials"][name]["fitted"]["yield_stress_pa"] / 1e6,
            "rate_fitted": runs["rate_fitted"]["materials"][name]["fitted"],
            "rate_fitted_stderr": runs["rate_fitted"]["materials"][name]["stderr"],
            "rate_fitted_rms_over_peak": _span(runs["rate_fitted"], "rms_over_peak_fitted", name),
        }
    summary["median_unloading_secant_ratio_fitted"] = published["median_unloading_secant_ratio_fitted"]
    summary["median_unloading_secant_ratio_published"] = published["median_unloading_secant_ratio_model"]
    for label in processings:
        entry = runs[label]["materials"][STEEL_440C.name]
        summary["runs"][label] = {
            "fitted_yield_stress_mpa": entry["fitted"]["yield_stress_pa"] / 1e6,
            "peak_force_error_published": _span(runs[label], "peak_force_error_model", STEEL_440C.name),
            "rms_over_peak_fitted": _span(runs[label], "rms_over_peak_fitted", STEEL_440C.name),
            "peak_force_measured_kn": [c["peak_force_measured_n"] / 1e3 for c in runs[label]["curves"]],
        }
    summary["elapsed_s"] = {label: run.get("elapsed_s") for label, run in runs.items()}
    summary["elapsed_note"] = "timed on a shared 2-core machine under load"
    atomic.write_json(out / "summary.json", atomic.json_ready(summary))
    atomic.write_text(out / "summary.md", _markdown(summary))
    print((out / "summary.md").read_text())
    return 0


def _pct(span):
    return "-" if span is None else f"{100 * span[0]:+.1f} … {100 * span[1]:+.1f} %"


def _plain(span, digits=2):
    return "-" if span is None else f"{span[0]:.{digits}f} … {span[1]:.{digits}f}"


def _markdown(summary) -> str:
    lines = ["# Contact law on Burgoyne & Daraio (2014): 15 Caltech curves", "",
             "| | " + " | ".join(summary["materials"]) + " |", "|---|" + "---|" * len(summary["materials"])]
    rows = (
        ("peak force error, published constants + rate", lambda m: _pct(m["peak_force_error_published"])),
        ("same, Thornton law (earlier)", lambda m: _pct(m["peak_force_error_thornton_published"])),
        ("fitted σ_Y (MPa) ± σ", lambda m: f"{m['fitted_yield_stress_mpa']:.0f} ± "
                                           f"{m['fitted_yield_stress_stderr_mpa']:.0f}"),
        ("fitted ÷ published σ_Y", lambda m: f"{m['fitted_over_published']:.2f}"),
        ("RMS ÷ peak, fitted, whole curve", lambda m: _pct(m["rms_over_peak_fitted"])),
        ("RMS ÷ peak, fitted, loading", lambda m: _pct(m["rms_over_peak_fitted_loading"])),
        ("RMS ÷ peak, σ_Y fitted to each curve alone", lambda m: _pct(m["rms_over_peak_own_fit"])),
        ("RMS ÷ peak, fitted, unloading", lambda m: _pct(m["rms_over_peak_fitted_unloading"])),
        ("unloading secant 90→50 %, law ÷ data", lambda m: _plain(m["unloading_secant_ratio_fitted"])),
        ("contact radius the data's unloading needs ÷ law's", lambda m: _plain(m["unloading_radius_needed_over_law"])),
        ("same ÷ R*", lambda m: _plain(m["unloading_radius_needed_over_reduced_radius"])),
        ("offset kept: peak force error, published", lambda m: _pct(m["offset_kept_peak_force_error_published"])),
        ("offset kept: change of the peak error (points)", lambda m: _pct(m["offset_kept_peak_error_shift"])),
        ("approach offset at the first sample (µm)", lambda m: _plain(m["approach_offset_um"], 0)),
        ("offset kept: fitted σ_Y (MPa)", lambda m: f"{m['offset_kept_fitted_yield_stress_mpa']:.0f}"),
        ("σ_Y and C fitted: σ_Y (MPa), C", lambda m: f"{m['rate_fitted']['yield_stress_pa'] / 1e6:.0f}, "
                                                     f"{m['rate_fitted']['rate_constant']:.3f}"),
        ("σ_Y and C fitted: RMS ÷ peak", lambda m: _pct(m["rate_fitted_rms_over_peak"])),
    )
    for label, cell in rows:
        lines.append(f"| {label} | " + " | ".join(cell(m) for m in summary["materials"].values()) + " |")
    lines += ["", f"Median unloading secant ratio (fitted σ_Y): {summary['median_unloading_secant_ratio_fitted']:.2f}; "
              f"at published constants: {summary['median_unloading_secant_ratio_published']:.2f}.", "",
              "440C in the two processings of the raw bar records (strain rate "
              f"{summary['strain_rate_for_fd_files_s']:.0f} /s, no time column):", "",
              "| processing | peak forces (kN) | peak error, published | fitted σ_Y (MPa) | RMS ÷ peak, fitted |",
              "|---|---|---|---|---|"]
    for label, entry in summary["runs"].items():
        peaks = ", ".join(f"{p:.1f}" for p in entry["peak_force_measured_kn"])
        lines.append(f"| {label} | {peaks} | {_pct(entry['peak_force_error_published'])} | "
                     f"{entry['fitted_yield_stress_mpa']:.0f} | {_pct(entry['rms_over_peak_fitted'])} |")
    lines += ["", "The same curves with a Kuwabara-Kono damping time per material (`--damping`) or a time shift "
              "of the records per curve (`--time-shift`): [`rate_terms.md`](rate_terms.md) "
              "(`python -m benchmarks.contact_rate_terms`). What the damped law still misses, curve by curve: "
              "[`misfit.md`](misfit.md) (`python -m benchmarks.contact_misfit`); which stored record and "
              "processing each curve is: [`processing.md`](processing.md) (`python -m benchmarks.contact_processing`); "
              "with a linear drift of each curve's approach record fitted as well (`--approach-drift`): "
              "[`approach_drift.md`](approach_drift.md) (`python -m benchmarks.contact_approach_drift`)."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
