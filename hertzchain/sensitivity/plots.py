"""Figures of sensitivity results (matplotlib, Agg): each function takes a result and
returns a Figure."""

from __future__ import annotations

import numpy as np

from ..parameters import PARAMETERS, resolve_name
from .global_measures import GlobalSensitivity
from .result import SensitivityResult


def _plt():
    """pyplot on the Agg backend, imported on first use (importing `hertzchain.sensitivity`
    does not load matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_elasticities(result: SensitivityResult):
    """Bar chart of the elasticities of each scalar observable (one setup)."""
    plt = _plt()
    scalars = [o for o in result.observables if o not in result.trace_observables]
    labels = []
    for p in result.params:
        n = int(np.prod(result.param_values[p].shape))
        labels += [p] if n == 1 else [f"{p}[{i + 1}]" for i in range(n)]
    figure, ax = plt.subplots(figsize=(max(6, 0.5 * len(labels) * max(len(scalars), 1) ** 0.5 + 4), 4.5))
    width = 0.8 / max(len(scalars), 1)
    x = np.arange(len(labels))
    for i, o in enumerate(scalars):
        row = np.concatenate([np.ravel(result.elasticity[o][p]) for p in result.params])
        ax.bar(x + (i - (len(scalars) - 1) / 2) * width, np.nan_to_num(row), width, label=o)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks(x, labels, rotation=45 if len(labels) > 6 else 0, ha="right" if len(labels) > 6 else "center")
    ax.set_ylabel("elasticity  ∂ln O / ∂ln p  (dimensionless)")
    ax.set_title("local sensitivities")
    if scalars:
        ax.legend(fontsize=8)
    figure.tight_layout()
    return figure


def plot_trace_sensitivities(result: SensitivityResult):
    """Derivative traces p dF(t)/dp (N) of every trace observable, one panel each."""
    plt = _plt()
    traces = result.trace_observables
    figure, axes = plt.subplots(len(traces), 1, figsize=(8, 2.8 * len(traces)), squeeze=False)
    t_ms = result.time_s * 1e3
    for ax, o in zip(axes[:, 0], traces):
        for p in result.params:
            d = np.asarray(result.derivative[o][p])
            pv = np.asarray(result.param_values[p])
            if d.ndim > 1:
                continue
            ax.plot(t_ms, d * (pv if np.all(pv != 0) else 1.0), label=p + ("" if np.all(pv != 0) else " (per unit)"))
        ax.set_ylabel(f"p ∂F/∂p (N)\n{o}")
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time since impact (ms)")
    figure.tight_layout()
    return figure


def plot_sweep(result: SensitivityResult):
    """Heat maps (two swept parameters) or curves (one) of every elasticity of the sweep."""
    plt = _plt()
    axes_names = list(result.grid_axes)
    obs, params = result.observables, [p for p in result.params if result.param_values[p].ndim == len(axes_names)]
    figure, grid = plt.subplots(len(obs), len(params), figsize=(3.6 * len(params) + 1, 3.0 * len(obs)),
                                squeeze=False)
    for i, o in enumerate(obs):
        for j, p in enumerate(params):
            ax = grid[i, j]
            e = np.asarray(result.elasticity[o][p], dtype=float)
            if len(axes_names) == 1:
                x = result.grid_axes[axes_names[0]]
                ax.plot(x, e, "o-")
                ax.set_xscale("log" if np.all(x > 0) else "linear")
                ax.set_xlabel(_axis_label(result, axes_names[0]))
                ax.axhline(0, color="k", lw=0.6)
            elif len(axes_names) == 2:
                x, y = (result.grid_axes[a] for a in axes_names)
                limit = np.nanmax(np.abs(e)) if np.any(np.isfinite(e)) else 1.0
                mesh = ax.pcolormesh(np.arange(len(y) + 1), np.arange(len(x) + 1), e, cmap="RdBu_r",
                                     vmin=-limit, vmax=limit, shading="flat")
                ax.set_xticks(np.arange(len(y)) + 0.5, [f"{v:.3g}" for v in y], fontsize=7, rotation=45)
                ax.set_yticks(np.arange(len(x)) + 0.5, [f"{v:.3g}" for v in x], fontsize=7)
                ax.set_xlabel(_axis_label(result, axes_names[1]))
                ax.set_ylabel(_axis_label(result, axes_names[0]))
                figure.colorbar(mesh, ax=ax, label="∂ln O/∂ln p")
            ax.set_title(f"{o} vs {p}", fontsize=9)
    figure.tight_layout()
    return figure


def _axis_label(result, name):
    unit = result.units.get(name) or PARAMETERS[resolve_name(name)].unit
    return f"{name} ({unit})" if unit else name


def plot_global_ranking(result: GlobalSensitivity):
    """Ranking bars of the mean squared elasticities (log scale), one panel per observable."""
    plt = _plt()
    obs = list(result.mean_squared_elasticity)
    figure, axes = plt.subplots(1, len(obs), figsize=(4 * len(obs) + 1, 3.8), squeeze=False)
    for ax, o in zip(axes[0], obs):
        order = result.ranking[o]
        values = [result.mean_squared_elasticity[o][p] or 0.0 for p in order]
        ax.barh(np.arange(len(order))[::-1], np.maximum(values, 1e-30), color="tab:blue")
        ax.set_yticks(np.arange(len(order))[::-1], order)
        ax.set_xscale("log")
        ax.set_xlabel("E[(∂ln O/∂ln p)²] over the box")
        ax.set_title(o, fontsize=9)
    figure.tight_layout()
    return figure
