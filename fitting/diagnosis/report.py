"""A diagnosis written out: `diagnosis.json`, `diagnosis.md`, per-step overlays and gap plots.

- `diagnosis.json`: `Diagnosis.to_json()` (`missing_effects`, `steps` with `gap_before` /
  `gap_after` and the residual breakdown before and after, the candidates' scores and
  refits, the final misfit and the misspecification alarm).
- `diagnosis.md`: the same in words and tables.
- `gap.png`: $\\chi^2/n$ per channel and time window, before and after each step.
- `overlay_step<k>_<effect>.png`: data, old model and new model of every file and channel
  (`overlay_base.png` when nothing was named).
- `gaps.csv`: channel, window, stage, n, chi2_per_sample, excess_sigma.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from hertzchain.io.atomic import save_figure, write_csv, write_json, write_text
from hertzchain.native import kernel_record
from hertzchain.units import counted, display_unit, format_measured

from ..effects import PREFIX, fitted_wall_youngs_pa, nominal_yield_stress_pa
from ..parameters import REGISTRY
from .locate import WINDOWS
from .results import Diagnosis


def _fmt(value, digits=4) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "-"
        return f"{value:.{digits}g}"
    return str(value)


def physical_reading(name: str, value: float, stderr, setup) -> str:
    """A fitted effect strength as the quantity it stands for, in human units with its σ
    (`wall_softening` -> the wall's modulus in GPa, `yield_softening` -> the yield stress in
    MPa, `eta_s` -> η in µs, `mu` -> the track's friction coefficient); "" for a strength without such a reading. `setup`: the
    diagnosed files' nominal chain (the first file's)."""
    stderr = None if stderr is None or not math.isfinite(stderr) else float(stderr)

    def error(scale):  # the standard error of a quantity whose derivative is `scale`
        return None if stderr is None else abs(scale) * stderr

    short = name.removeprefix(PREFIX)
    if short == "wall_softening":
        youngs = fitted_wall_youngs_pa(setup, value)
        return "wall Young's modulus " + format_measured(youngs, error(youngs), "Pa")
    if short == "yield_softening":
        if value <= 0:
            return "no yield (elastic contacts)"
        stress = float(nominal_yield_stress_pa(setup)) / value
        return "yield stress " + format_measured(stress, error(stress / value), "Pa")
    if short == "sensor_rate" and value > 0:
        f0 = 1e5 / math.sqrt(value)
        return "sensor resonance f0 " + format_measured(f0, error(0.5 * f0 / value), "Hz")
    if short in ("eta_s", "preload_n", "dashpot_n_s_m", "mu", "mu_star"):
        quantity = {"eta_s": "η", "preload_n": "preload", "dashpot_n_s_m": "dashpot", "mu": "track friction μ",
                    "mu_star": "contact-stiffness scale μ*"}[short]
        unit = {"eta_s": "s", "preload_n": "N", "dashpot_n_s_m": "N s/m", "mu": "", "mu_star": ""}[short]
        return f"{quantity} " + format_measured(value, stderr, unit)
    return ""


def readings(diagnosis: Diagnosis) -> list[str]:
    """One line per named effect's strength that stands for a quantity (`physical_reading`):
    `"wall_compliance: wall Young's modulus 20.3 ± 1.2 GPa"`, at the final fit (every named
    effect in the model), with its error there; a strength the final fit does not hold is
    read at the step that added it."""
    setup = diagnosis.problem.base_setups[0]
    final_values = diagnosis.final.get("values", {})
    final_stderr = diagnosis.final.get("stderr", {})
    lines = []
    for step in diagnosis.steps:
        if step.effect not in diagnosis.missing_effects:
            continue
        for name, value in step.values.items():
            if name in final_values:
                value, stderr = final_values[name], final_stderr.get(name)
            else:
                stderr = step.stderr.get(name)
            reading = physical_reading(name, value, stderr, setup)
            if reading:
                lines.append(f"{step.effect}: {reading}")
    return lines


def _unit(label: str) -> str:
    """The SI unit of a fitted label (`name`, `name[file]`, an effect's strength with or
    without its `PREFIX`), "" if not registered."""
    name = label.split("[", 1)[0]
    for key in (name, PREFIX + name):
        if key in REGISTRY:
            return REGISTRY[key].unit
    return ""


def _stages(diagnosis: Diagnosis):
    stages = [("base", diagnosis.base_fit["location"])]
    for step in diagnosis.steps:
        stages.append((f"+{step.effect}" + (f"-{step.replaces}" if step.replaces else ""), step.location_after))
    return stages


def _gap_table(diagnosis: Diagnosis) -> list[str]:
    stages = _stages(diagnosis)
    header = "| channel | window | " + " | ".join(name for name, _ in stages) + " |"
    lines = [header, "|" + "---|" * (len(stages) + 2)]
    first = stages[0][1]["by_channel_window"]
    for channel, windows in first.items():
        for window in WINDOWS:
            if not windows.get(window, {}).get("n"):
                continue
            cells = [_fmt(loc["by_channel_window"][channel][window]["chi2_per_sample"], 3) for _, loc in stages]
            lines.append(f"| {channel} | {window} | " + " | ".join(cells) + " |")
    return lines


def markdown(diagnosis: Diagnosis) -> str:
    """The report in Markdown."""
    d = diagnosis
    setup = d.problem.base_setups[0]
    out = io.StringIO()
    w = out.write
    w("# Diagnosis\n\n")
    w(f"Files: {', '.join(e.label for e in d.problem.experiments)}; model `{d.settings['model']}`; "
      f"nuisances {', '.join(d.settings['nuisances'])}"
      + (f"; free {', '.join(d.settings['free'])}" if d.settings["free"] else "") + ".\n\n")
    w(f"**Missing effects (in the order found):** {', '.join(d.missing_effects) or 'none'}\n\n")
    w(d.conclusion + "\n\n")
    for line in readings(d):
        w(f"- {line}\n")
    if readings(d):
        w("\n")
    w("## Gap before and after each step\n\n")
    w("Gap = reduced chi^2 of the whitened residuals (1 = noise level).\n\n")
    w("| step | effect | gap before | gap after | excess before (sigma) | excess after (sigma) |\n")
    w("|---|---|---|---|---|---|\n")
    w(f"| 0 | base fit | - | {_fmt(d.base_fit['gap'])} | - | {_fmt(d.base_fit['excess_sigma'], 3)} |\n")
    for k, s in enumerate(d.steps, 1):
        eb = (s.chi2_before - s.dof_before) / math.sqrt(2 * s.dof_before)
        ea = (s.chi2_after - s.dof_after) / math.sqrt(2 * s.dof_after)
        w(f"| {k} | {s.effect} | {_fmt(s.gap_before)} | {_fmt(s.gap_after)} | {_fmt(eb, 3)} | {_fmt(ea, 3)} |\n")
    w("\nchi^2 per sample by channel and time window:\n\n")
    w("\n".join(_gap_table(d)) + "\n\n")
    for k, s in enumerate(d.steps, 1):
        w(f"## Step {k}: {s.effect}" + (f" (in place of {s.replaces})" if s.replaces else "") + "\n\n")
        w("Fitted strengths (0 = effect off) and what they stand for:\n\n"
          "| parameter | value ± σ | unit | reading |\n|---|---|---|---|\n")
        for name, value in s.values.items():
            unit = _unit(name)
            w(f"| {name} | {format_measured(value, s.stderr.get(name))} | {display_unit(unit)} | "
              f"{physical_reading(name, value, s.stderr.get(name), setup)} |\n")
        w("\nCandidates at this step:\n\n")
        w(_candidate_table(s.candidates))
        w(f"\n![overlay](overlay_step{k}_{s.effect}.png)\n\n")
    if d.last_candidates:
        w("## Last round (nothing named)\n\n")
        w(_candidate_table(d.last_candidates) + "\n")
    w("## Final residual\n\n")
    for line in d.final["where"]:
        w(f"- {line}\n")
    if d.indistinguishable:
        w("\nCandidate pairs these data cannot tell apart (|cos| of projected sensitivities > 0.95): "
          + "; ".join(f"{p['effects'][0]} / {p['effects'][1]} ({p['abs_cos']:.3f})" for p in d.indistinguishable)
          + "\n")
    if d.dropped_in_backward_check:
        w(f"\nDropped by the backward check (redundant once the others were in): "
          f"{', '.join(d.dropped_in_backward_check)}\n")
    for swap in d.exchanged:
        w(f"\nExchanged (the misfit was above the noise): {swap['in']} in place of {swap['out']}, chi^2 "
          f"{swap['chi2_before']:.6g} -> {swap['chi2_after']:.6g}, BIC gain {swap['bic_gain']:.4g}"
          + ("" if swap["converged"] else f" (its refit did not converge within {swap['steps']} steps)") + "\n")
    w("\n![gap](gap.png)\n")
    w(f"\nRun time {d.elapsed_s:.1f} s, {counted(d.evaluations, 'model evaluation')}.\n")
    return out.getvalue()


def _candidate_table(candidates) -> str:
    lines = ["| candidate | k | score | delta chi^2 | BIC gain | share of excess | held-out gain | passed | why |",
             "|---|---|---|---|---|---|---|---|---|"]
    for c in sorted(candidates, key=lambda c: -c.delta_chi2):
        lines.append(
            f"| {c.effect} | {c.n_parameters} | {_fmt(c.score_chi2, 3)} | {_fmt(c.delta_chi2, 4)} | "
            f"{_fmt(c.bic_gain, 4)} | {_fmt(c.share_of_excess, 3)} | {_fmt(c.heldout_gain, 4)} | "
            f"{'yes' if c.passed else 'no'} | {c.reason} |"
        )
    return "\n".join(lines) + "\n"


def _overlay(diagnosis: Diagnosis, x_old, x_new, title: str):
    problem = diagnosis.problem
    old = diagnosis.predictions(x_old)
    new = diagnosis.predictions(x_new) if x_new is not None else None
    experiments = problem.experiments
    n_channels = max(len(e.channels) for e in experiments)
    fig, axes = plt.subplots(len(experiments), n_channels, figsize=(4 * n_channels, 2.4 * len(experiments)),
                             squeeze=False)
    for row, experiment in enumerate(experiments):
        for col, name in enumerate(experiment.channels):
            ax = axes[row, col]
            t = experiment.time_s * 1e3
            ax.plot(t, experiment.data(name), color="0.6", lw=0.8, label="data")
            ax.plot(t, old[row][name], color="tab:blue", lw=0.9, ls="--", label="old model")
            if new is not None:
                ax.plot(t, new[row][name], color="tab:red", lw=0.9, label="new model")
            ax.set_title(f"{experiment.label}: {name}", fontsize=8)
            ax.set_xlabel("time (ms)")
            ax.set_ylabel("force (N)")
            ax.tick_params(labelsize=7)
        for col in range(len(experiment.channels), n_channels):
            axes[row, col].axis("off")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _gap_figure(diagnosis: Diagnosis):
    stages = _stages(diagnosis)
    first = stages[0][1]["by_channel_window"]
    labels, values = [], []
    for channel, windows in first.items():
        for window in WINDOWS:
            if windows.get(window, {}).get("n"):
                labels.append(f"{channel}\n{window}")
                values.append([loc["by_channel_window"][channel][window]["chi2_per_sample"] for _, loc in stages])
    values = np.asarray(values, dtype=float)
    fig, ax = plt.subplots(figsize=(max(6, 0.5 * len(labels) + 2), 4))
    width = 0.8 / max(len(stages), 1)
    positions = np.arange(len(labels))
    for k, (name, _) in enumerate(stages):
        ax.bar(positions + k * width, values[:, k], width, label=name)
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_xticks(positions + width * (len(stages) - 1) / 2)
    ax.set_xticklabels(labels, fontsize=6, rotation=90)
    ax.set_ylabel("chi^2 per sample (1 = noise)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


GAP_HEADER = ["stage", "channel", "window", "n", "chi2_per_sample", "excess_sigma"]


def _gap_rows(diagnosis: Diagnosis) -> list[list]:
    """Rows of `gaps.csv`: the misfit per channel and window at every stage."""
    return [[stage, channel, window, c["n"], float(c["chi2_per_sample"]), float(c["excess_sigma"])]
            for stage, location in _stages(diagnosis)
            for channel, windows in location["by_channel_window"].items()
            for window, c in windows.items()]


def write_diagnosis_report(diagnosis: Diagnosis, out_dir) -> dict:
    """Write the report files into `out_dir`; returns name -> path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "diagnosis.json", "markdown": out / "diagnosis.md", "gap_png": out / "gap.png",
             "gaps_csv": out / "gaps.csv"}
    write_json(paths["json"], {**diagnosis.to_json(), "kernel": kernel_record()})
    write_text(paths["markdown"], markdown(diagnosis))
    write_csv(paths["gaps_csv"], GAP_HEADER, _gap_rows(diagnosis))
    fig = _gap_figure(diagnosis)
    save_figure(fig, paths["gap_png"], dpi=110)
    plt.close(fig)
    if diagnosis.steps:
        for k, step in enumerate(diagnosis.steps, 1):
            fig = _overlay(diagnosis, step.x_before, step.x_after,
                           f"step {k}: +{step.effect} (gap {step.gap_before:.4g} -> {step.gap_after:.4g})")
            path = out / f"overlay_step{k}_{step.effect}.png"
            save_figure(fig, path, dpi=90)
            plt.close(fig)
            paths[f"overlay_{k}"] = path
    else:
        fig = _overlay(diagnosis, diagnosis.x_base, None, f"base fit (gap {diagnosis.base_fit['gap']:.4g})")
        path = out / "overlay_base.png"
        save_figure(fig, path, dpi=90)
        plt.close(fig)
        paths["overlay_base"] = path
    return paths
