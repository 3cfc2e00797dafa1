"""Fit reports: JSON, CSV and PNG files of a `FitResult`.

`write_report(result, out_dir)` writes (all atomically, through `hertzchain.io.atomic`):

- `fit.json`: everything in `FitResult.to_json()` (SI units).
- `params.csv`: label, value, standard error, relative error, unit.

Parameters are named as a user names them (`fitting.parameters.public_label`: `eta_s`,
`wall_youngs_pa`, `striker_velocity_m_s[run1]`) in every file and figure.
- `correlation.csv`: the correlation matrix (and `correlation.png` with `per_trace=True`).
- `rms.csv`: residual RMS per file and channel (N and in units of the noise sigma).
- `starts.csv`: every start of the multistart batch: chi^2, converged, steps, values.
- `residuals_<file>.csv`: time (s), data, model and residual (N) of every channel.
- `fit_summary.png`: every file's channels, data and fitted model, and the whitened residuals
  (one figure, drawn from at most `SUMMARY_POINTS` points per curve: about a second), with
  the fitted values and their standard errors (`fitted_lines`) beneath.
- with `per_trace=True`: `overlay_<file>.png` (fitted model over the data) and
  `residuals_<file>.png` at full resolution (about 1.5 s per file), and `correlation.png`.
- `profile_<parameter>.png` and `profile_<parameter>.csv` for each profile.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from hertzchain.io.atomic import file_stem, finish_figure, save_figure, write_csv, write_json
from hertzchain.native import kernel_record
from hertzchain.units import column_name, display_unit, format_measured

from .parameters import public_label

# Points per curve of the summary figure (min-max thinned, so peaks stay).
SUMMARY_POINTS = 1500


def _cell(value) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value)).lower()
    if value is None:
        return ""
    value = float(value)
    return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "nan" if math.isnan(value) else "-inf")


def write_report(result, out_dir, *, plots: bool = True, per_trace: bool = False) -> list[Path]:
    """Write the fit's JSON, CSV and PNG files into `out_dir`; returns the paths written.
    `plots`: the summary and profile figures; `per_trace`: also two figures per file at full
    resolution and the correlation matrix's."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    shown = [public_label(label) for label in result.labels]

    def table(name, header, rows):
        write_csv(out / name, header, ([_cell(v) for v in row] for row in rows))
        written.append(out / name)

    write_json(out / "fit.json", {**result.to_json(), "kernel": kernel_record()})
    written.append(out / "fit.json")
    table(
        "params.csv",
        ["parameter", "value", "stderr", "relative_stderr", "unit"],
        [
            [public_label(label), result.values[label], result.stderr[label],
             result.stderr[label] / abs(result.values[label]) if result.values[label] else math.nan,
             result.units[label]]
            for label in result.labels
        ] + [
            ["C (speed constant)", result.speed_constant["C"], result.speed_constant["C_stderr"],
             math.nan, "m/s N^-1/6"],
            ["C_t (1+mu*)^(1/3) (continuum)", result.speed_constant["C_continuum"],
             result.speed_constant["C_continuum_stderr"], math.nan, "m/s N^-1/6"],
        ],
    )
    table(
        "correlation.csv",
        ["parameter"] + shown,
        [[label] + list(row) for label, row in zip(shown, np.asarray(result.correlation))],
    )
    rows = []
    for experiment in result.problem.experiments:
        for channel in experiment.channels:
            rows.append([
                experiment.label, channel, result.residual_rms[experiment.label][channel],
                result.residual_rms_whitened[experiment.label][channel],
                experiment.noise_std_n[channel], experiment.noise_source,
            ])
    table("rms.csv", ["file", "channel", "rms_n", "rms_over_sigma", "noise_std_n", "noise_source"], rows)
    table(
        "starts.csv",
        ["start", "chi2", "converged", "steps", "agrees_with_best"]
        + [f"start_{label}" for label in shown] + [f"final_{label}" for label in shown],
        [
            [k, s["chi2"], s["converged"], s["steps"], s["agrees_with_best"]]
            + [s["start"][label] for label in result.labels]
            + [s["final"][label] for label in result.labels]
            for k, s in enumerate(result.starts)
        ],
    )
    predictions = result.predictions()
    for experiment, predicted in zip(result.problem.experiments, predictions):
        time = experiment.time_s
        columns, header = [time], ["time_s"]
        for channel in experiment.channels:
            data = experiment.data(channel)
            columns += [data, predicted[channel], data - predicted[channel]]
            header += [f"data_{channel}_n", f"model_{channel}_n", f"residual_{channel}_n"]
        path = out / f"residuals_{file_stem(experiment.label)}.csv"
        line = ",".join(["%.9g"] * len(columns))
        write_csv(path, header, ((line % tuple(row)).split(",") for row in np.column_stack(columns).tolist()))
        written.append(path)
    for label, profile in result.profiles.items():
        table(
            f"profile_{file_stem(public_label(label))}.csv",
            [column_name(public_label(label), result.units[label]), "delta_chi2", "converged"],
            zip(profile["values"], profile["delta_chi2"], profile["converged"]),
        )
    if plots:
        written += _plots(result, predictions, out, per_trace)
    return written


def _thinned(time, *curves, points: int = SUMMARY_POINTS):
    """`time` and `curves` cut to about `points` samples: each block's minimum and maximum of
    the first curve (the data), in time order, so that peaks survive the thinning."""
    n = len(time)
    if n <= points:
        return (time,) + curves
    block = math.ceil(2 * n / points)
    first = np.asarray(curves[0], dtype=float)
    rows = -(-n // block)
    # the last block is padded with its own last sample, which never displaces a true extreme
    padded = np.concatenate([first, np.full(rows * block - n, first[-1])]).reshape(rows, block)
    base = np.arange(rows) * block
    low = np.minimum(base + np.argmin(padded, axis=1), n - 1)
    high = np.minimum(base + np.argmax(padded, axis=1), n - 1)
    picks = np.unique(np.concatenate([low, high]))
    return (time[picks],) + tuple(c[picks] for c in curves)


def _summary_figure(result, predictions, out: Path) -> Path:
    """One figure of the whole fit: per file, data and model of every channel (left) and the
    residuals in units of each channel's sigma (right)."""
    experiments = result.problem.experiments
    values = fitted_lines(result)
    columns = 3
    text_rows = -(-len(values) // columns)
    text_height = 0.16 * text_rows + 0.1
    figure, axes = plt.subplots(len(experiments), 2, figsize=(11, 1.6 * len(experiments) + 0.8 + text_height),
                                sharex=True, squeeze=False)
    for row, (experiment, predicted) in enumerate(zip(experiments, predictions)):
        time_us = experiment.time_s * 1e6
        for k, channel in enumerate(experiment.channels):
            data, model = experiment.data(channel), predicted[channel]
            sigma = experiment.noise_std_n[channel]
            t, d, m = _thinned(time_us, data, model)
            axes[row, 0].plot(t, d, ".", ms=1.0, color=f"C{k}", alpha=0.5)
            axes[row, 0].plot(t, m, "-", lw=0.8, color=f"C{k}", label=channel)
            t, w = _thinned(time_us, (data - model) / sigma)
            axes[row, 1].plot(t, w, "-", lw=0.5, color=f"C{k}")
        axes[row, 0].set_ylabel(f"{experiment.label}\nforce (N)", fontsize=7)
        axes[row, 0].legend(fontsize=6, loc="upper right")
        axes[row, 1].axhspan(-2, 2, color="0.8", alpha=0.5)
        axes[row, 1].set_ylabel("residual (σ)", fontsize=7)
    axes[-1, 0].set_xlabel("time after impact (µs)")
    axes[-1, 1].set_xlabel("time after impact (µs)")
    figure.suptitle(f"fit: χ²/dof = {result.reduced_chi2:.4g}; data (dots) and model (lines); "
                    "residuals with the ±2σ band", fontsize=9)
    height = figure.get_figheight()
    for k, line in enumerate(values):
        figure.text(0.02 + (k % columns) / columns, (text_height - 0.05 - 0.16 * (k // columns)) / height,
                    line.strip(), fontsize=7, va="top", family="monospace")
    # fixed margins: `tight_layout` would draw the 2 x files panels once more only to measure them
    figure.subplots_adjust(left=0.08, right=0.99, bottom=(0.45 + text_height) / height,
                           top=1.0 - 0.6 / height, wspace=0.18, hspace=0.12)
    path = out / "fit_summary.png"
    save_figure(figure, path, dpi=100)
    plt.close(figure)
    return path


def _correlation_figure(result, out: Path) -> Path:
    """The fitted parameters' correlation matrix as an image."""
    p = len(result.labels)
    shown = [public_label(label) for label in result.labels]
    figure, ax = plt.subplots(figsize=(1.2 + 0.5 * p, 1.0 + 0.5 * p))
    image = ax.imshow(np.asarray(result.correlation, dtype=float), vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(p), shown, rotation=90, fontsize=7)
    ax.set_yticks(range(p), shown, fontsize=7)
    figure.colorbar(image, ax=ax, label="correlation (dimensionless)")
    ax.set_title("parameter correlation")
    path = out / "correlation.png"
    finish_figure(figure, path)
    return path


def _plots(result, predictions, out: Path, per_trace: bool) -> list[Path]:
    written = [_summary_figure(result, predictions, out)]
    for experiment, predicted in zip(result.problem.experiments, predictions if per_trace else ()):
        time_us = experiment.time_s * 1e6
        n = len(experiment.channels)
        for kind in ("overlay", "residuals"):
            figure, axes = plt.subplots(n, 1, figsize=(8, 2.4 * n + 0.6), sharex=True, squeeze=False)
            for ax, channel in zip(axes[:, 0], experiment.channels):
                data = experiment.data(channel)
                if kind == "overlay":
                    ax.plot(time_us, data, ".", ms=1.5, color="0.5", label="measured")
                    ax.plot(time_us, predicted[channel], "-", lw=1.0, color="C3", label="fitted model")
                    ax.set_ylabel(f"{channel} (N)")
                else:
                    sigma = experiment.noise_std_n[channel]
                    ax.plot(time_us, data - predicted[channel], "-", lw=0.6, color="C0")
                    ax.axhspan(-2 * sigma, 2 * sigma, color="C2", alpha=0.15, label="±2σ noise")
                    rms = result.residual_rms[experiment.label][channel]
                    ax.set_ylabel(f"{channel}\nresidual (N)")
                    ax.set_title(f"RMS {rms:.3g} N ({rms / sigma:.2f} σ)", fontsize=8, loc="right")
                ax.legend(fontsize=7, loc="upper right")
            axes[-1, 0].set_xlabel("time after impact (µs)")
            figure.suptitle(f"{experiment.label}: {'fit' if kind == 'overlay' else 'residuals'}")
            path = out / f"{kind}_{file_stem(experiment.label)}.png"
            finish_figure(figure, path)
            written.append(path)
    if per_trace:
        written.append(_correlation_figure(result, out))
    for label, profile in result.profiles.items():
        figure, ax = plt.subplots(figsize=(5, 3.5))
        scale = result.problem.instances[result.labels.index(label)].spec.unit
        y = np.asarray(profile["delta_chi2"]) / max(result_variance(result), 1e-300)
        ax.plot(profile["values"], y, "o-")
        for level, name in ((1.0, "68 %"), (3.84, "95 %")):
            ax.axhline(level, ls="--", lw=0.8, color="0.4")
            ax.text(profile["values"][0], level, name, fontsize=7, va="bottom")
        ax.set_xlabel(f"{public_label(label)} ({display_unit(scale)})")
        ax.set_ylabel("Δχ² / s² (dimensionless)")
        ax.set_title(f"profile likelihood of {public_label(label)}")
        path = out / f"profile_{file_stem(public_label(label))}.png"
        finish_figure(figure, path)
        written.append(path)
    return written


def result_variance(result) -> float:
    """The covariance's variance factor s^2 (1 for known noise, chi^2/dof otherwise)."""
    return 1.0 if result.covariance_scale == "noise" else result.reduced_chi2


def _why_undetermined(result, label) -> str:
    return ("the data do not determine it" if math.isinf(result.stderr[label])
            else "the covariance is not finite at this optimum")


def fitted_lines(result) -> list[str]:
    """One line per fitted value, `name = value ± σ unit` to the digits σ allows (human units:
    GPa, µs, MPa), then the speed constant C of the fitted chain where C is not fitted itself."""
    lines = [
        f"  {public_label(label)} = " + format_measured(result.values[label], result.stderr[label], result.units[label],
                                          why=_why_undetermined(result, label))
        for label in result.labels
    ]
    c = result.speed_constant
    if "C" not in result.labels:
        lines.append(f"  C (discrete solitary wave) = {format_measured(c['C'], c['C_stderr'], 'm/s N^-1/6')}")
    return lines


def summary_text(result) -> str:
    """A short plain-text table of the fitted values (for the terminal)."""
    lines = [(f"fit {'converged' if result.converged else 'did NOT converge'} in {result.n_steps} "
             f"iterations; χ²/dof = {result.reduced_chi2:.4g} (covariance: {result.covariance_scale})")]
    lines += fitted_lines(result)
    c = result.speed_constant
    lines.append(f"  continuum C_t (1+mu*)^(1/3) = {c['C_continuum']:.4g} {display_unit('m/s N^-1/6')}; "
                 f"mu* = {c['mu_star']:.4g}")
    for text in result.warnings:
        lines.append(f"  warning: {text}")
    return "\n".join(lines)
