"""The contact calibration's outputs: the per-material summary of its per-curve numbers, and
the files it writes (`contact.json`, a CSV per curve, `contact.png`, `residuals.png`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hertzchain.native import kernel_record


def summary_table(report: dict) -> list[dict]:
    """Per material: ranges of the per-curve numbers (for the JSON and the console)."""
    rows = []
    for name, entry in report["materials"].items():
        mine = [c for c in report["curves"] if c["material"] == name]

        def span(key):
            values = [c[key] for c in mine if c[key] is not None]
            return [min(values), max(values)] if values else None

        rows.append({"material": name, "curves": len(mine), "peak_force_error_model": span("peak_force_error_model"),
                     "peak_force_error_thornton": span("peak_force_error_thornton"),
                     "rms_over_peak_fitted": span("rms_over_peak_fitted"),
                     "fitted_over_given_yield_stress": entry["fitted_over_given_yield_stress"],
                     "unloading_secant_ratio_fitted": span("unloading_secant_ratio_fitted")})
    return rows


def median_secant_ratio(report: dict, key: str = "unloading_secant_ratio_fitted") -> float | None:
    values = [c[key] for c in report["curves"] if c[key] is not None]
    return float(np.median(values)) if values else None


def write_outputs(report: dict, curves, out_dir, *, title: str = "") -> dict:
    """Write `contact.json`, one `<stem>.csv` per curve (time_s, approach_m, force_measured_n,
    force_model_n, force_fitted_n), `contact.png` (data and laws) and `residuals.png`.
    Returns the JSON written (without the series)."""
    from hertzchain.io import atomic
    from hertzchain.plotting import plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for curve, entry in zip(curves, report["curves"]):
        series = entry["_series"]
        time = curve.time_s if curve.time_s is not None else np.full(curve.force_n.size, np.nan)
        rows = [[f"{t:.9g}" if np.isfinite(t) else "", f"{a:.9g}", f"{m:.9g}", f"{p:.9g}", f"{f:.9g}"]
                for t, a, m, p, f in zip(time, series["approach_m"], curve.force_n, series["force_model_n"],
                                         series["force_fitted_n"])]
        atomic.write_csv(out / f"{curve.name}.csv",
                         ["time_s", "approach_m", "force_measured_n", "force_model_n", "force_fitted_n"], rows)
    columns = min(5, len(curves))
    lines = -(-len(curves) // columns)
    laws, axes = plt.subplots(lines, columns, figsize=(3.6 * columns, 3.0 * lines), squeeze=False)
    residual_figure, residual_axes = plt.subplots(lines, columns, figsize=(3.6 * columns, 2.4 * lines), squeeze=False)
    for k, (curve, entry) in enumerate(zip(curves, report["curves"])):
        series = entry["_series"]
        approach_mm = series["approach_m"] * 1e3
        ax = axes.flat[k]
        ax.plot(approach_mm, curve.force_n * 1e-3, color="0.4", lw=0.8, label="measured")
        ax.plot(approach_mm, series["force_model_n"] * 1e-3, "b--", lw=1.2, label="given constants")
        ax.plot(approach_mm, series["force_fitted_n"] * 1e-3, "r-", lw=1.2, label="fitted sigma_Y")
        ax.plot(approach_mm, series["force_thornton_n"] * 1e-3, "g:", lw=1.2, label="Thornton (given)")
        ax.set_title(f"{curve.name} ({curve.material.name})", fontsize=9)
        ax.set_xlabel("approach (mm)", fontsize=8)
        ax.set_ylabel("force (kN)", fontsize=8)
        x = np.arange(curve.force_n.size) if curve.time_s is None else (curve.time_s - curve.time_s[0]) * 1e6
        rax = residual_axes.flat[k]
        rax.plot(x, (series["force_model_n"] - curve.force_n) / entry["peak_force_measured_n"], "b--", lw=0.8)
        rax.plot(x, (series["force_fitted_n"] - curve.force_n) / entry["peak_force_measured_n"], "r-", lw=0.8)
        rax.axhline(0.0, color="k", lw=0.5)
        rax.set_title(curve.name, fontsize=9)
        rax.set_xlabel("time (us)" if curve.time_s is not None else "sample", fontsize=8)
        rax.set_ylabel("(model - data) / peak", fontsize=8)
    for ax in list(axes.flat[len(curves):]) + list(residual_axes.flat[len(curves):]):
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    laws.suptitle(title or "force-approach: data and contact laws")
    residual_figure.suptitle("residuals: given constants (blue dashed), fitted (red)")
    for figure, name in ((laws, "contact.png"), (residual_figure, "residuals.png")):
        atomic.finish_figure(figure, out / name, dpi=90)
    data = {key: value for key, value in report.items() if key != "curves"}
    data["curves"] = [{k: v for k, v in entry.items() if k != "_series"} for entry in report["curves"]]
    data["summary"] = summary_table(report)
    data["median_unloading_secant_ratio_fitted"] = median_secant_ratio(report)
    data["median_unloading_secant_ratio_model"] = median_secant_ratio(report, "unloading_secant_ratio_model")
    data = atomic.json_ready({**data, "kernel": kernel_record()})
    atomic.write_json(out / "contact.json", data)
    return data
