"""Posterior reports: JSON, InferenceData, CSV, Markdown and PNG files of a `PosteriorResult`.

`write_posterior_report(result, out_dir)` writes (each file whole or not at all):

- `posterior.json`: `PosteriorResult.to_json()`: `params.<label>.{mean, sd, q05, q50, q95,
  r_hat, ess, ess_tail, unit}` (SI, the labels of `fit.json`: `eta_s`,
  `striker_velocity_m_s[run1]`), the Laplace comparison, priors, divergences, timing and
  settings.
- `posterior.nc`: the draws and sampler statistics as an ArviZ `InferenceData` (netCDF).
- `draws.csv`: one row per draw: chain, draw, every parameter (SI, by the same labels).

Every file names a parameter as a user writes it (`fitting.parameters.public_label`).
- `posterior_summary.md`: the summary table with the Laplace comparison, and the warnings.
- `posterior_pairs.png`: pairs of the global parameters, draws over the Laplace 1- and
  2-sigma ellipses, marginals over the Laplace normal.
- `posterior_trace.png`: every chain's draws of the global parameters.
- `posterior_predictive_<file>.png`: the model's 90 % band over the data, per channel.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hertzchain.io.atomic import (  # noqa: E402
    atomic_path,
    file_stem,
    save_figure,
    write_csv,
    write_json,
    write_text,
)
from hertzchain.units import counted, format_measured  # noqa: E402

from .parameters import public_label
from .posterior import PosteriorResult, posterior_predictive  # noqa: E402

# pairs and traces show the global parameters (per-file nuisances would make a wall of panels)
_MAX_PLOTTED = 8


def _inference_data(result: PosteriorResult):
    import arviz as az

    names = {label: file_stem(public_label(label)) for label in result.labels}
    posterior = {names[label]: result.draws[..., i] for i, label in enumerate(result.labels)}
    stats = {
        "diverging": result.sample_stats["diverging"].astype(bool),
        "tree_size": result.sample_stats["num_steps"],
        "acceptance_rate": result.sample_stats["accept_prob"],
        "lp": -result.sample_stats["potential_energy"],
    }
    idata = az.from_dict(posterior=posterior, sample_stats=stats)
    for label, name in names.items():
        idata.posterior[name].attrs.update({"label": public_label(label), "unit": result.units[label]})
    return idata


def _markdown(result: PosteriorResult) -> str:
    lines = [
        "# Posterior",
        "",
        f"{counted(result.settings['chains'], 'chain')} x {counted(result.settings['draws'], 'draw')} after "
        f"{result.settings['warmup']} warmup; {counted(result.divergences, 'divergence')}; "
        f"{result.elapsed_s['total']:.1f} s in all, "
        f"{result.seconds_per_effective_sample:.3g} s per effective sample.",
        "",
        "| parameter | unit | mean | sd | 5 % | 50 % | 95 % | R-hat | ESS bulk | ESS tail "
        "| MAP | Laplace sd | sd ratio | Laplace holds |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, row in result.summary.items():
        lap = result.laplace[label]
        lines.append(
            f"| {public_label(label)} | {result.units[label]} | {row['mean']:.6g} | {row['sd']:.3g} | {row['q05']:.6g} "
            f"| {row['q50']:.6g} | {row['q95']:.6g} | {row['r_hat']:.4f} | {row['ess']:.0f} "
            f"| {row['ess_tail']:.0f} | {lap['map']:.6g} | {lap['laplace_sd']:.3g} "
            f"| {lap['sd_ratio']:.3f} | {'no' if lap['fails'] else 'yes'} |"
        )
    lines += ["", "Priors:", ""]
    for label, prior in result.priors.items():
        if prior["kind"] == "normal":
            lines.append(f"- {public_label(label)}: normal, {format_measured(prior['centre'], prior['sd'], prior['unit'])}")
        else:
            lines.append(f"- {public_label(label)}: flat on [{prior['low']:.6g}, {prior['high']:.6g}] {prior['unit']}")
    if result.warnings:
        lines += ["", "Warnings:", ""] + [f"- {text}" for text in result.warnings]
    return "\n".join(lines) + "\n"


def _plotted(result: PosteriorResult) -> list[int]:
    problem = result.problem
    chosen = [i for i, inst in enumerate(problem.instances) if inst.spec.scope in ("global", "sensor")]
    return chosen[:_MAX_PLOTTED]


def plot_pairs(result: PosteriorResult):
    """Corner plot of the global parameters: draws, Laplace ellipses, marginals."""
    index = _plotted(result)
    n = len(index)
    flat = result.flat_draws()
    cov = np.asarray(result.fit.covariance)
    x_hat = np.asarray(result.fit.x)
    fig, axes = plt.subplots(n, n, figsize=(2.2 * n + 1, 2.2 * n + 1), squeeze=False)
    angle = np.linspace(0, 2 * np.pi, 200)
    for row, i in enumerate(index):
        for col, j in enumerate(index):
            ax = axes[row, col]
            if col > row:
                ax.axis("off")
                continue
            if row == col:
                ax.hist(flat[:, i], bins=40, density=True, color="tab:blue", alpha=0.6)
                sd = np.sqrt(cov[i, i])
                if np.isfinite(sd) and sd > 0:
                    grid = np.linspace(*ax.get_xlim(), 200)
                    ax.plot(grid, np.exp(-0.5 * ((grid - x_hat[i]) / sd) ** 2) / (sd * np.sqrt(2 * np.pi)),
                            color="black", lw=1)
                ax.set_yticks([])
            else:
                ax.plot(flat[:, j], flat[:, i], ".", ms=1.5, alpha=0.4, color="tab:blue")
                block = cov[np.ix_([j, i], [j, i])]
                if np.all(np.isfinite(block)):
                    values, vectors = np.linalg.eigh(block)
                    circle = np.stack([np.cos(angle), np.sin(angle)])
                    for k in (1, 2):
                        shape = vectors @ (k * np.sqrt(np.maximum(values, 0))[:, None] * circle)
                        ax.plot(x_hat[j] + shape[0], x_hat[i] + shape[1], color="black", lw=0.8)
            if row == n - 1:
                ax.set_xlabel(public_label(result.labels[j]), fontsize=8)
            if col == 0 and row != col:
                ax.set_ylabel(public_label(result.labels[i]), fontsize=8)
            ax.tick_params(labelsize=6)
    fig.suptitle("posterior draws; black: Laplace approximation (1 and 2 sigma)", fontsize=9)
    fig.tight_layout()
    return fig


def plot_trace(result: PosteriorResult):
    """Every chain's draws of the global parameters."""
    index = _plotted(result)
    fig, axes = plt.subplots(len(index), 1, figsize=(8, 1.6 * len(index) + 0.6), squeeze=False, sharex=True)
    for row, i in enumerate(index):
        ax = axes[row, 0]
        for chain in range(result.draws.shape[0]):
            ax.plot(result.draws[chain, :, i], lw=0.6)
        ax.set_ylabel(public_label(result.labels[i]), fontsize=8)
        ax.tick_params(labelsize=7)
    axes[-1, 0].set_xlabel("draw")
    fig.tight_layout()
    return fig


def plot_predictive(result: PosteriorResult, experiment_index: int, bands: dict):
    """The data of one file with the model's 5-95 % band and median, per channel."""
    experiment = result.problem.experiments[experiment_index]
    channels = experiment.channels
    fig, axes = plt.subplots(len(channels), 1, figsize=(8, 2.2 * len(channels) + 0.6), squeeze=False,
                             sharex=True)
    time_ms = np.asarray(experiment.time_s) * 1e3
    for ax, name in zip(axes[:, 0], channels):
        ax.plot(time_ms, experiment.data(name), ".", ms=1.5, color="0.5", label="data")
        low, median, high = bands[name]
        ax.fill_between(time_ms, low, high, color="tab:orange", alpha=0.5, label="model 90 %")
        ax.plot(time_ms, median, color="tab:red", lw=0.8, label="model median")
        ax.set_ylabel(f"{name} (N)", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (ms)")
    fig.suptitle(f"{experiment.label}: posterior predictive (model spread)", fontsize=9)
    fig.tight_layout()
    return fig


def write_posterior_report(result: PosteriorResult, out_dir, *, plots: bool = True) -> list[Path]:
    """Write the posterior's files into `out_dir`; returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "posterior.json", out / "posterior.nc", out / "draws.csv", out / "posterior_summary.md"]
    write_json(written[0], result.to_json())
    idata = _inference_data(result)
    with atomic_path(written[1]) as tmp:
        idata.to_netcdf(str(tmp))
    chains, draws, _ = result.draws.shape
    rows = (
        [str(c), str(d)] + [repr(float(v)) for v in result.draws[c, d]]
        for c in range(chains) for d in range(draws)
    )
    write_csv(written[2], ["chain", "draw"] + [public_label(label) for label in result.labels], rows)
    write_text(written[3], _markdown(result))
    if plots:
        figures = [("posterior_pairs.png", plot_pairs(result)), ("posterior_trace.png", plot_trace(result))]
        for e, bands in enumerate(posterior_predictive(result)):
            label = result.problem.experiments[e].label
            figures.append((f"posterior_predictive_{file_stem(label)}.png", plot_predictive(result, e, bands)))
        for name, figure in figures:
            save_figure(figure, out / name)
            plt.close(figure)
            written.append(out / name)
    return written
