"""What a driven fit found, as files: `fit.json`, `curves.csv`, `fit.png` (`write_driven_report`),
and the measures of resonance bending both the report and the diagnosis quote (`bending`)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from hertzchain.io.atomic import json_ready, save_figure, write_csv, write_json
from hertzchain.peaks import frequency_response_peaks

from .lockin_fit import UNITS, DrivenFit, DrivenLayout, chain_at, nominal_modes_hz


def mode_windows(experiment, n_modes: int) -> list[np.ndarray]:
    """Boolean masks (F,) of the frequencies around each mode: split halfway between the
    lowest drive's peaks (one window = everything for one bead)."""
    f = experiment.sweep.frequencies_hz
    if n_modes == 1:
        return [np.ones(f.size, bool)]
    mask = experiment.fit_mask
    peaks = frequency_response_peaks(f[mask], experiment.sweep.rms_velocity_m_s[mask, 0], n_modes)
    edges = np.concatenate([[-np.inf], 0.5 * (peaks[1:] + peaks[:-1]), [np.inf]])
    return [(f > lo) & (f <= hi) for lo, hi in itertools.pairwise(edges)]


def bending(experiment, curves) -> list[dict]:
    """Per mode: the peak frequency of each curve (F, A) (m/s), its shift from the lowest to
    the highest drive, and the peak velocity per metre of drive at the top drive over the
    lowest's (1 for a linear chain)."""
    f = experiment.sweep.frequencies_hz
    drives = experiment.sweep.drive_amplitudes_m
    usable = experiment.fit_mask
    result = []
    for window in mode_windows(experiment, experiment.n_beads):
        part = np.where((window & usable)[:, None], curves, -np.inf)
        peak_hz = f[np.argmax(part, axis=0)]
        per_m = part.max(axis=0) / drives
        result.append({
            "peak_hz": peak_hz,
            "lowest_drive_peak_hz": float(peak_hz[0]),
            "highest_drive_peak_hz": float(peak_hz[-1]),
            "shift": float(peak_hz[-1] / peak_hz[0] - 1),
            "peak_velocity_per_m": per_m,
            "peak_per_drive_top_over_lowest": float(per_m[-1] / per_m[0]),
        })
    return result


def _params(result: DrivenFit) -> dict:
    layout = DrivenLayout.for_beads(result.experiment.n_beads)
    params = {}
    for name in dict.fromkeys(layout.names):
        idx = layout.index(name)
        value = [float(result.x[i]) for i in idx]
        error = [float(result.stderr[i]) for i in idx]
        params[name] = {
            "value": value if len(idx) > 1 else value[0],
            "stderr": error if len(idx) > 1 else error[0],
            "unit": UNITS[name],
            "fitted": any(i in result.free for i in idx),
        }
    return params


def report_data(result: DrivenFit, *, data_dir) -> dict:
    """The contents of `fit.json`."""
    e = result.experiment
    chain = chain_at(e, result.x)
    layout = DrivenLayout.for_beads(e.n_beads)
    gamma = float(result.x[layout.index("damping_rate_per_s")[0]])
    modes = result.x[layout.index("linear_resonance_hz")]
    scale = float(result.x[layout.index("drive_scale")[0]])
    measured = bending(e, e.sweep.rms_velocity_m_s)
    model = bending(e, result.model_curves)
    return {
        "experiment": str(e.path),
        "label": e.label,
        "data_dir": str(data_dir),
        "sweep_file": e.sweep.source,
        "params": _params(result),
        "derived": {
            "damping_ratio": gamma / (2 * 2 * np.pi * float(modes[0])),
            "contact_kappa_n_m1p5": np.asarray(chain.contact_kappa_n_m1p5),
            "static_overlap_m": np.asarray(chain.static_overlap_m()),
            "drive_m_per_v": scale * e.drive_m_per_v,
            "drive_scale_within_calibration_uncertainty": bool(abs(scale - 1) <= e.drive_uncertainty),
        },
        "nominal": {
            "linear_resonance_hz": nominal_modes_hz(e),
            "precompression_n": e.precompression_n,
            "contact_kappa_n_m1p5": e.contact_kappa_n_m1p5,
            "drive_m_per_v": e.drive_m_per_v,
            "drive_calibration_uncertainty": e.drive_uncertainty,
        },
        "uncertainty": {
            "method": "Gauss-Newton covariance x chi^2/(n - p) x (1 + rho)/(1 - rho): residuals (fractions of each "
                      "curve's peak) correlated along frequency as an AR(1) series of lag-1 autocorrelation rho, "
                      "i.e. n_effective = n (1 - rho)/(1 + rho) independent points",
            "lag1_autocorrelation": result.rho,
            "n_points": int(e.fit_mask.sum() * e.sweep.drive_amplitudes_m.size),
            "n_effective": result.n_effective,
            "correlation": {"labels": [layout.labels[c] for c in result.free], "matrix": result.correlation},
        },
        "misfit": {
            "definition": "RMS of (model - measured) over each curve's fitted frequencies / the curve's measured peak",
            "per_curve": result.misfit,
            "median": float(np.median(result.misfit)),
            "max": float(np.max(result.misfit)),
        },
        "bending": [
            {
                "mode": k + 1,
                "measured": {key: value for key, value in m.items() if key not in ("peak_hz", "peak_velocity_per_m")},
                "model": {key: value for key, value in s.items() if key not in ("peak_hz", "peak_velocity_per_m")},
            }
            for k, (m, s) in enumerate(zip(measured, model))
        ],
        "drive_amplitudes_m": e.sweep.drive_amplitudes_m,
        "excluded_hz": e.sweep.frequencies_hz[~e.fit_mask],
        "model_settings": e.model,
        "converged": result.converged,
        "message": result.message,
        "n_steps": result.steps,
        "chi2": result.chi2,
        "dof": result.dof,
        "reduced_chi2": result.reduced_chi2,
        "kernel": result.kernel,
        "elapsed_s": result.elapsed_s,
    }


def write_driven_report(result: DrivenFit, out_dir, *, data_dir, plots: bool = True) -> list[Path]:
    """Write `fit.json`, `curves.csv` (drive_level, frequency_hz, measured_m_s, model_m_s: every
    point of the sweep) and `fit.png` into `out_dir`; returns the paths."""
    out = Path(out_dir)
    e = result.experiment
    data = report_data(result, data_dir=data_dir)
    write_json(out / "fit.json", json_ready(data))
    f = e.sweep.frequencies_hz
    measured = e.sweep.rms_velocity_m_s
    rows = [
        [level + 1, f"{f[i]:.6g}", f"{measured[i, level]:.6e}", f"{result.model_curves[i, level]:.6e}"]
        for level in range(measured.shape[1]) for i in range(f.size)
    ]
    write_csv(out / "curves.csv", ["drive_level", "frequency_hz", "measured_m_s", "model_m_s"], rows)
    written = [out / "fit.json", out / "curves.csv"]
    if plots:
        written.append(plot_fit(result, out / "fit.png"))
    return written


def plot_fit(result: DrivenFit, path) -> Path:
    """Curves (every 7th drive level), misfit per curve, peak frequency and peak velocity per
    nm against drive: measured and model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    e = result.experiment
    f = e.sweep.frequencies_hz
    drives_nm = e.sweep.drive_amplitudes_m * 1e9
    measured = e.sweep.rms_velocity_m_s
    figure, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    ax = axes[0, 0]
    for k, level in enumerate(range(0, measured.shape[1], 7)):
        color = f"C{k}"
        ax.plot(f, measured[:, level] * 1e3, ".", ms=2, color=color)
        ax.plot(f, result.model_curves[:, level] * 1e3, "-", lw=1, color=color, label=f"{drives_nm[level]:.2f} nm")
    ax.set(xlabel="drive frequency (Hz)", ylabel="RMS velocity (mm/s)", title="measured (dots) and fitted model")
    ax.legend(fontsize=7)
    ax = axes[0, 1]
    ax.plot(drives_nm, 100 * result.misfit, "o-", ms=3)
    ax.set(xlabel="drive amplitude (nm, nominal)", ylabel="RMS misfit (% of curve peak)",
           title=f"misfit: median {100 * np.median(result.misfit):.2f} %, max {100 * result.misfit.max():.2f} %")
    measured_b, model_b = bending(e, measured), bending(e, result.model_curves)
    ax = axes[1, 0]
    for k, (m, s) in enumerate(zip(measured_b, model_b)):
        ax.plot(drives_nm, m["peak_hz"], "o", ms=3, color=f"C{k}", label=f"mode {k + 1} measured")
        ax.plot(drives_nm, s["peak_hz"], "-", color=f"C{k}", label=f"mode {k + 1} model")
    ax.set(xlabel="drive amplitude (nm, nominal)", ylabel="peak frequency (Hz)", title="resonance bending")
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    for k, (m, s) in enumerate(zip(measured_b, model_b)):
        ax.plot(drives_nm, m["peak_velocity_per_m"] / m["peak_velocity_per_m"][0], "o", ms=3, color=f"C{k}",
                label=f"mode {k + 1} measured")
        ax.plot(drives_nm, s["peak_velocity_per_m"] / s["peak_velocity_per_m"][0], "-", color=f"C{k}",
                label=f"mode {k + 1} model")
    ax.set(xlabel="drive amplitude (nm, nominal)", ylabel="peak velocity per nm / lowest drive's",
           title="amplitude-dependent loss")
    ax.legend(fontsize=7)
    figure.suptitle(e.label)
    figure.tight_layout()
    save_figure(figure, path, dpi=110)
    plt.close(figure)
    return Path(path)
