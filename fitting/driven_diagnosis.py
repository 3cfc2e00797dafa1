"""What the nominal model of a driven experiment misses, named step by step.

`diagnose_driven(experiment)` starts from the nominal model: the file's contact constants
(Hertz from the materials), its precompression and drive calibration, with only the beads'
viscous damping fitted (the setup states no loss). Then, greedily, it adds the candidate
effect that lowers the misfit most, if it removes at least `min_share` of the remaining
chi^2, and repeats (at most `max_effects` times). Candidates, each a set of parameters of
`fitting.driven` freed together:

- `contact_stiffness_and_preload`: the contacts' linear stiffness (the modes' frequencies)
  and the effective static force, which together set the static overlap and so the bending;
- `drive_calibration`: the piezo's amplitude per volt (uncertain by sqrt(2) in the lab's own
  files);
- `amplitude_dependent_contact_loss`: Kuwabara-Kono damping at every contact (a loss that
  grows with the contacts' motion, `eta_s`).

A candidate tried on top of named effects, the precompression among its parameters, is fitted
from where the last round ended and from the data's own start with the precompression scan
(as `fit_driven` starts), the lower chi^2 kept: the contacts' fit of an earlier round can end
where a stiffness and a preload compensate the effect still missing.

Every fit's convergence (`fitting.fit`'s test of an optimum) is kept: a step whose fit
reached no optimum is judged at its last iterate (the fit only descends, so the share of
chi^2 it removes is a lower bound: an acceptance stands), and the conclusion and
`unconverged_fits` name it; `converged` is False when the nominal fit or a named step's
fit reached none.

Every step records the gap before and after (median over drive levels of the RMS misfit as a
fraction of each curve's peak), the resonance shift from the lowest to the highest drive, and
the peak velocity per metre of drive at the top drive over the lowest's (the amplitude-
dependent loss), measured and modelled. Fits run on every `level_stride`-th drive level (all
frequencies); the reported curves and measures use every level.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from hertzchain.atomic import json_ready, save_figure, write_csv, write_json, write_text
from hertzchain.native import kernel_record

from .driven import DrivenLayout, DrivenModel, chain_at, linear_start, nominal_modes_hz, scan_precompression
from .driven_report import bending
from .fit import least_squares

CANDIDATES = {
    "contact_stiffness_and_preload": ("linear_resonance_hz", "precompression_n"),
    "drive_calibration": ("drive_scale",),
    "amplitude_dependent_contact_loss": ("eta_s",),
}
# A model "explains" the amplitude dependence when its top-over-lowest peak velocity per
# metre of drive is within this of the measured one (a tenth of the measured 30 % drop).
LOSS_TOLERANCE = 0.03
# Kuwabara-Kono damping time at which its effect on the loss's amplitude dependence is shown, s.
ETA_PROBE_S = 1e-6
# A fitted constant this many times above or below the file's value (the nominal model's) is
# named with both values in the conclusion: an order of magnitude, a round figure, not one
# fitted to any data set (Lydon's single bead ends a factor 22 below the file's preload,
# the two beads' first step 8.7e5 above it).
FAR_FROM_FILE = 10.0


def _misfit(model: DrivenModel, curves) -> np.ndarray:
    measured = model.experiment.sweep.rms_velocity_m_s
    rows = model.experiment.fit_mask
    return np.sqrt(np.mean((curves[rows] - measured[rows]) ** 2, axis=0)) / measured.max(axis=0)


def _columns(layout: DrivenLayout, names) -> list[int]:
    return [i for i, n in enumerate(layout.names) if n in names]


def diagnose_driven(experiment, *, max_effects: int = 3, min_share: float = 0.2, level_stride: int = 5,
                    max_steps: int = 25, progress: bool = True) -> dict:
    """Name the effects the nominal model misses (see the module docstring). Returns a dict
    (`write_driven_diagnosis` writes it): `steps`, `missing_effects`, `conclusion`."""
    began = time.perf_counter()
    layout = DrivenLayout.for_beads(experiment.n_beads)
    levels = np.arange(0, experiment.sweep.drive_amplitudes_m.size, level_stride)
    model = DrivenModel(experiment, levels=levels)
    everything = DrivenModel(experiment, rows=np.arange(experiment.sweep.frequencies_hz.size))
    measured = bending(experiment, experiment.sweep.rms_velocity_m_s)

    def log(text):
        if progress:
            print(f"diagnose: {text} ({time.perf_counter() - began:.0f} s)", file=sys.stderr, flush=True)

    def state(x, chi2):
        curves = everything.curves(x)
        measures = bending(experiment, curves)
        misfit = _misfit(everything, curves)
        return {
            "x": dict(zip(layout.labels, map(float, x))),
            "chi2": chi2,
            "gap_median": float(np.median(misfit)),
            "gap_max": float(np.max(misfit)),
            "shift": [m["shift"] for m in measures],
            "peak_per_drive_top_over_lowest": [m["peak_per_drive_top_over_lowest"] for m in measures],
            "curves": curves,
        }

    def fit(x, names):
        result = least_squares(model, x, _columns(layout, names), max_steps=max_steps, extrapolate=True)
        return model.clip(result.x), result.chi2, result.converged

    # the nominal model: the file's constants, only the viscous damping fitted
    measured_start = linear_start(experiment)  # the resonance and damping of the lowest curve
    x = measured_start.copy()
    x[layout.index("linear_resonance_hz")] = nominal_modes_hz(experiment)
    x[layout.index("precompression_n")] = experiment.precompression_n
    x[layout.index("drive_scale")] = 1.0
    free = ["damping_rate_per_s"]
    x, chi2, nominal_ok = fit(x, free)
    current = state(x, chi2)
    log(f"nominal model (damping fitted): median misfit {100 * current['gap_median']:.1f} % of peak")
    nominal = current
    steps, named = [], []
    for _ in range(max_effects):
        trials = {}
        for name, params in CANDIDATES.items():
            if name in named:
                continue
            start = x.copy()
            if name == "contact_stiffness_and_preload":
                start[layout.index("linear_resonance_hz")] = measured_start[layout.index("linear_resonance_hz")]
                start = scan_precompression(experiment, start)
            trial = fit(start, free + list(params))
            if "precompression_n" in free + list(params) and name != "contact_stiffness_and_preload":
                # the contacts' fit of an earlier round can end in a valley where a stiffness and
                # a preload compensate the effect still missing: also from the data's own start
                # (`linear_start`: the resonance and damping of the lowest curve) and the best
                # of the precompression scan, as `fit_driven` starts; the lower of the two
                again = x.copy()
                for label in ("linear_resonance_hz", "damping_rate_per_s"):
                    again[layout.index(label)] = measured_start[layout.index(label)]
                trial = min(trial, fit(scan_precompression(experiment, again), free + list(params)),
                            key=lambda t: t[1])
            trial_x, trial_chi2, trial_ok = trial
            trials[name] = trial
            log(f"candidate {name}: chi^2 {current['chi2']:.5g} -> {trial_chi2:.5g}")
        if not trials:
            break
        best = min(trials, key=lambda n: trials[n][1])
        trial_x, trial_chi2, trial_ok = trials[best]
        share = (current["chi2"] - trial_chi2) / current["chi2"]
        after = state(trial_x, trial_chi2)
        step = {
            "effect": best,
            "parameters": list(CANDIDATES[best]),
            "accepted": bool(share >= min_share),
            "share_of_chi2_removed": share,
            "converged": bool(trial_ok),
            "gap_before": current["gap_median"],
            "gap_after": after["gap_median"],
            "candidates_chi2": {n: t[1] for n, t in trials.items()},
            "candidates_converged": {n: bool(t[2]) for n, t in trials.items()},
            "before": {k: v for k, v in current.items() if k != "curves"},
            "after": {k: v for k, v in after.items() if k != "curves"},
        }
        steps.append(step)
        if not step["accepted"]:
            log(f"best candidate {best} removes only {100 * share:.0f} % of chi^2 (< {100 * min_share:.0f} %): stop")
            break
        named.append(best)
        free += list(CANDIDATES[best])
        x, current = trial_x, after
        log(f"named {best}: median misfit {100 * step['gap_before']:.1f} % -> {100 * step['gap_after']:.1f} %")

    # the amplitude-dependent loss: also tried on top of the final model when not named, and
    # probed at a fixed eta_s (the other constants held) to show which way it moves the loss
    loss_check = None
    if "amplitude_dependent_contact_loss" not in named:
        trial_x, trial_chi2, _ = fit(x, free + ["eta_s"])
        loss_check = {k: v for k, v in state(trial_x, trial_chi2).items() if k != "curves"}
    probe = x.copy()
    probe[layout.index("eta_s")] = ETA_PROBE_S
    eta_probe = {k: v for k, v in state(probe, float("nan")).items() if k != "curves"}
    f = experiment.sweep.frequencies_hz
    top = experiment.sweep.rms_velocity_m_s[:, -1]
    contacts = {
        "static_overlap_m": float(chain_at(experiment, x).static_overlap_m()[0]),
        "bead_amplitude_at_top_drive_peak_m": float(np.sqrt(2) * top.max() / (2 * np.pi * f[np.argmax(top)])),
    }
    unconverged = ([] if nominal_ok else ["the nominal model's fit"]) + [
        f"the fit of {step['effect']}" for step in steps if step["accepted"] and not step["converged"]]
    result = {
        "experiment": str(experiment.path),
        "label": experiment.label,
        "fitted_levels": levels,
        "converged": not unconverged,
        "unconverged_fits": unconverged,
        "nominal": {k: v for k, v in nominal.items() if k != "curves"},
        "nominal_converged": bool(nominal_ok),
        "steps": steps,
        "missing_effects": named,
        "final": {k: v for k, v in current.items() if k != "curves"},
        "eta_on_final": loss_check,
        "eta_probe": eta_probe,
        "contact_opening": contacts,
        "measured": {
            "shift": [m["shift"] for m in measured],
            "peak_per_drive_top_over_lowest": [m["peak_per_drive_top_over_lowest"] for m in measured],
        },
        "loss_tolerance": LOSS_TOLERANCE,
        "elapsed_s": time.perf_counter() - began,
        "_curves": {"nominal": nominal["curves"], "final": current["curves"],
                    "measured": experiment.sweep.rms_velocity_m_s, "frequencies_hz": experiment.sweep.frequencies_hz},
    }
    result["conclusion"] = conclusion(result)
    return result


def _loss_explained(model_ratio, measured_ratio) -> bool:
    return abs(model_ratio - measured_ratio) <= LOSS_TOLERANCE


def _far_from_file(x: dict, nominal_x: dict, names) -> list[str]:
    """Each fitted constant of `names` that is `FAR_FROM_FILE` times or more above or below
    its value in the nominal model (the file's), with both values."""
    notes = []
    for label, value in x.items():
        file_value = nominal_x.get(label)
        if label.split("[")[0] not in names or not file_value or not np.isfinite(value):
            continue
        factor = value / file_value
        if factor < 0.0:
            notes.append(f"{label} = {value:.4g} has the other sign than the file's {file_value:.4g}")
        elif factor >= FAR_FROM_FILE or factor <= 1.0 / FAR_FROM_FILE:
            notes.append(f"{label} = {value:.4g} is {factor:.2g} times the file's {file_value:.4g}")
    return notes


def _direction(ratio: float) -> str:
    """How the peak velocity per metre of drive changes from the lowest drive to the top one."""
    if abs(ratio - 1.0) <= LOSS_TOLERANCE:
        return "stays"
    return "falls" if ratio < 1.0 else "grows"


def conclusion(result: dict) -> str:
    """The diagnosis in plain words, with its numbers: per step what it removes, its fitted
    constants (those an order of magnitude or more from the file's value named so, with both
    values), and whether it moves the amplitude dependence of the peak response away from
    the measured one; then that amplitude dependence in the final model against the data,
    in the data's own direction (a loss where the response per metre of drive falls at the
    top drive, a gain where it grows)."""
    nominal, final, measured = result["nominal"], result["final"], result["measured"]
    data_ratio = measured["peak_per_drive_top_over_lowest"][0]
    lines = [
        f"The nominal model (the file's Hertz contacts, precompression and drive calibration; viscous damping "
        f"fitted) misses the data by a median {100 * nominal['gap_median']:.1f} % of each curve's peak and bends "
        f"the resonance by {100 * nominal['shift'][0]:+.2f} % from the lowest to the highest drive "
        f"(measured {100 * measured['shift'][0]:+.2f} %)."
    ]
    for step in result["steps"]:
        verdict = "named" if step["accepted"] else "not named (too small a share)"
        if not step["converged"]:
            verdict += (" on a fit that reached no optimum within the step limit (judged at its last iterate: "
                        "the share removed is a lower bound, "
                        + ("the naming stands)" if step["accepted"] else "the rejection may not stand)"))
        after = step["after"]
        line = (
            f"{step['effect']} ({', '.join(step['parameters'])}): {verdict}; it removes "
            f"{100 * step['share_of_chi2_removed']:.0f} % of the remaining chi^2, the median misfit goes "
            f"{100 * step['gap_before']:.1f} % -> {100 * step['gap_after']:.1f} %, the resonance shift "
            f"{100 * after['shift'][0]:+.2f} %; fitted: "
            + ", ".join(f"{k} = {after['x'][k]:.4g}" for k in after["x"] if k.split('[')[0] in step["parameters"])
            + "."
        )
        far = _far_from_file(after["x"], nominal["x"], step["parameters"])
        if far:
            line += (f" Far from the file: {'; '.join(far)}; either the file is off by as much, or the "
                     f"value is an effective constant of this model rather than a measurement.")
        before_ratio = step["before"]["peak_per_drive_top_over_lowest"][0]
        after_ratio = after["peak_per_drive_top_over_lowest"][0]
        if abs(after_ratio - data_ratio) - abs(before_ratio - data_ratio) > LOSS_TOLERANCE:
            line += (f" It moves the peak velocity per nm of drive, top drive over lowest, from {before_ratio:.2f} "
                     f"to {after_ratio:.2f}, away from the measured {data_ratio:.2f}: "
                     f"{'named' if step['accepted'] else 'tried'} for the chi^2 it removes, "
                     f"not for the amplitude dependence.")
        lines.append(line)
    if not result["converged"]:
        lines.append(f"NOT CONVERGED: {'; '.join(result['unconverged_fits'])} reached no optimum; the values "
                     "reported are the last iterate's.")
    model_ratio = final["peak_per_drive_top_over_lowest"][0]
    dependence = (f"the peak velocity per nm of drive at the top drive over the lowest's is {model_ratio:.2f} in "
                  f"the final model (it {_direction(model_ratio)} with the drive) against {data_ratio:.2f} measured "
                  f"(it {_direction(data_ratio)})")
    if _loss_explained(model_ratio, data_ratio):
        lines.append(f"The amplitude dependence of the response is explained: {dependence}.")
    else:
        check, probe, opening = result.get("eta_on_final"), result["eta_probe"], result["contact_opening"]
        tried = ""
        if check is not None:
            tried = (f" Kuwabara-Kono damping at the contacts, fitted on top, ends at eta = {check['x']['eta_s']:.3g} s "
                     f"(ratio {check['peak_per_drive_top_over_lowest'][0]:.2f}, median misfit "
                     f"{100 * check['gap_median']:.1f} %).")
        probe_ratio = probe["peak_per_drive_top_over_lowest"][0]
        away = abs(probe_ratio - data_ratio) > abs(model_ratio - data_ratio)
        text = (f"The amplitude dependence of the response is not explained: {dependence}.{tried} "
                f"With eta = {probe['x']['eta_s']:.3g} s (the rest held) the ratio moves to {probe_ratio:.2f}, "
                f"{'away from' if away else 'towards'} the data.")
        amplitude, overlap = opening["bead_amplitude_at_top_drive_peak_m"], opening["static_overlap_m"]
        opens = (f" At the top drive the bead swings by {1e9 * amplitude:.0f} nm about the final model's static "
                 f"overlap of {1e9 * overlap:.1f} nm: its contacts open for part of each cycle")
        if amplitude > overlap and data_ratio < model_ratio and away:
            text += (f"{opens}, and a loss that acts only in contact falls, relative to the viscous one, as the "
                     f"amplitude grows. The measured loss needs another mechanism than the two (viscous, "
                     f"Kuwabara-Kono) the model has.")
        elif amplitude > overlap and data_ratio > model_ratio:
            text += f"{opens}, while the measured response per nm of drive {_direction(data_ratio)} with the drive."
        lines.append(text)
    return "\n".join(lines)


def write_driven_diagnosis(result: dict, out_dir) -> list[Path]:
    """`diagnosis.json`, `diagnosis.md`, `gaps.csv` and `diagnosis.png` in `out_dir`."""
    out = Path(out_dir)
    data = {k: v for k, v in result.items() if not k.startswith("_")}
    write_json(out / "diagnosis.json", json_ready({**data, "kernel": kernel_record()}))
    text = [f"# Diagnosis: {result['label']}", "", result["conclusion"].replace("\n", "\n\n"), "",
            "| step | effect | accepted | median misfit before | after | shift after | peak/nm top/lowest after |",
            "|---|---|---|---|---|---|---|"]
    for k, step in enumerate(result["steps"], 1):
        text.append(f"| {k} | {step['effect']} | {step['accepted']} | {100 * step['gap_before']:.2f} % | "
                    f"{100 * step['gap_after']:.2f} % | {100 * step['after']['shift'][0]:+.2f} % | "
                    f"{step['after']['peak_per_drive_top_over_lowest'][0]:.3f} |")
    write_text(out / "diagnosis.md", "\n".join(text) + "\n")
    rows = [["nominal", "", f"{result['nominal']['gap_median']:.6g}", f"{result['nominal']['chi2']:.6g}"]]
    rows += [[f"step {k}", s["effect"], f"{s['gap_after']:.6g}", f"{s['after']['chi2']:.6g}"]
             for k, s in enumerate(result["steps"], 1)]
    write_csv(out / "gaps.csv", ["model", "effect_added", "median_misfit_fraction_of_peak", "chi2"], rows)
    _plot(result, out / "diagnosis.png")
    return [out / "diagnosis.json", out / "diagnosis.md", out / "gaps.csv", out / "diagnosis.png"]


def _plot(result: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = result["_curves"]
    figure, axes = plt.subplots(1, 2, figsize=(11, 4))
    gaps = [result["nominal"]["gap_median"]] + [s["gap_after"] for s in result["steps"]]
    labels = ["nominal"] + [("+ " if s["accepted"] else "(tried) ") + s["effect"].replace("_", " ")
                            for s in result["steps"]]
    colors = ["C3"] + ["C0" if s["accepted"] else "C7" for s in result["steps"]]
    axes[0].barh(range(len(gaps)), [100 * g for g in gaps], color=colors)
    axes[0].set_yticks(range(len(gaps)), labels, fontsize=7)
    axes[0].invert_yaxis()
    axes[0].set_xlabel("median RMS misfit (% of each curve's peak)")
    axes[0].set_title("gap, step by step")
    f = curves["frequencies_hz"]
    for level, style in ((0, ":"), (curves["measured"].shape[1] - 1, "-")):
        axes[1].plot(f, curves["measured"][:, level] * 1e3, "k" + ("." if level else "x"), ms=2,
                     label=f"measured, drive level {level + 1}")
        axes[1].plot(f, curves["nominal"][:, level] * 1e3, "C3" + style, lw=1, label=f"nominal, level {level + 1}")
        axes[1].plot(f, curves["final"][:, level] * 1e3, "C0" + style, lw=1, label=f"final, level {level + 1}")
    axes[1].set_xlabel("drive frequency (Hz)")
    axes[1].set_ylabel("RMS velocity (mm/s)")
    axes[1].legend(fontsize=7)
    figure.tight_layout()
    save_figure(figure, path, dpi=110)
    plt.close(figure)
