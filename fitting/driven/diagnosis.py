"""The diagnosis of a driven experiment: the candidate-law protocol run on an experiment file,
its result as a folder and in plain words.

`diagnose_experiment` runs `fitting.driven.candidates.diagnose_laws`, the one protocol: every
candidate law fitted on the file's bending run, judged by what it predicts for the
measurements it was not fitted on (the bending run's `held_out_levels` highest drive levels,
a tongue's tip, a loop's onset going up), named only when it beats the base there
(`fitting.driven.candidates.verdict`). A bending-only file (a `[sweep]` table) is read as an
experiment of one bending measurement, so that its held-out levels are the only measurement
the candidates predict; a file of `[[measurement]]` tables is taken as it is.

The cost knobs are the protocol's: `held_out_levels` (each candidate's bending fit leaves them
out and predicts them), `level_stride` (each bending fit uses every k-th of the remaining
levels; every level is reported) and `max_steps` (optimiser iterations per candidate). The
defaults (`DEFAULT_HELD_OUT_LEVELS`, `DEFAULT_LEVEL_STRIDE`, `DEFAULT_MAX_STEPS`) keep the
single bead's joint file (`examples/lydon2015/single_bead_joint.toml`: bending, tongue, loop;
the six default candidates) within 10 minutes on 2 cores: it took 350 s of process CPU (1278 s
wall on 2 cores shared with other work, load average about 10). The result's `run` records the
load average at the start and the end and the process's CPU seconds.

`converged` is False when a candidate's fit reached no optimum or stopped on a refusal of the
chain (`unconverged_fits` names each); the command then exits as an impact diagnosis does.
"""

from __future__ import annotations

import dataclasses
import math
import os
import resource
from pathlib import Path

import numpy as np

from hertzchain.driven.measurements import Bending
from hertzchain.io.atomic import json_ready, save_figure, write_json, write_text
from hertzchain.native import kernel_record

from .candidates import CANDIDATES, SLOW_CANDIDATES, TARGETS, diagnose_laws, scores
from .experiment import DrivenExperiment, Measurement

# Each candidate's bending fit leaves out the top this many drive levels and predicts them ...
DEFAULT_HELD_OUT_LEVELS = 4
# ... fits every this-many-th of the rest (the highest kept) ...
DEFAULT_LEVEL_STRIDE = 4
# ... in at most this many optimiser iterations.
DEFAULT_MAX_STEPS = 20
# How each target reads in words: (what is measured, how its value is written, the target).
_WORDS = {
    "bending_misfit_median": ("bending misfit (median over drive levels)",
                              lambda v: f"{100 * v:.2f} % of each curve's peak",
                              f"<= {100 * TARGETS['bending_misfit_median']:g} %"),
    "shift_points": ("resonance shift, model - data", lambda v: f"{100 * v:+.2f} points",
                     f"within {100 * TARGETS['shift_points']:g} points"),
    "peak_ratio": ("peak velocity per nm of drive, top over lowest", lambda v: f"{v:.3f}",
                   f"within {TARGETS['peak_ratio']:g} of the data's"),
    "tongue_tip_amplitude": ("tongue tip amplitude, model / data", lambda v: f"{v:.3f}",
                             f"within {100 * TARGETS['tongue_tip_amplitude']:g} %"),
    "tongue_tip_frequency": ("tongue tip frequency, model / data - 1", lambda v: f"{100 * v:+.2f} %",
                             f"within {100 * TARGETS['tongue_tip_frequency']:g} %"),
    "loop_onset_up": ("loop onset going up, model / data", lambda v: f"{v:.3f}",
                      f"within {100 * TARGETS['loop_onset_up']:g} %"),
    "held_out_bending_misfit": ("held-out drive levels' misfit (median, predicted)",
                                lambda v: f"{100 * v:.2f} % of each curve's peak",
                                f"<= {100 * TARGETS['held_out_bending_misfit']:g} %"),
}


def candidates_named(names) -> tuple:
    """The candidates `names` (of `CANDIDATES` and `SLOW_CANDIDATES`), the base first whether
    named or not; all of `CANDIDATES` when `names` is empty.
    **Raises:** `ValueError` naming an unknown candidate and the valid ones."""
    known = {c.name: c for c in CANDIDATES + SLOW_CANDIDATES}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"--candidates: {', '.join(unknown)} not driven candidate laws; valid: {', '.join(known)}.")
    if not names:
        return CANDIDATES
    return (CANDIDATES[0],) + tuple(known[n] for n in dict.fromkeys(names) if n != CANDIDATES[0].name)


def with_measurements(experiment: DrivenExperiment) -> DrivenExperiment:
    """`experiment` as one of `[[measurement]]`s: a bending-only file's sweep becomes its one
    bending measurement (its run named by the file's label); a file of measurements as it is."""
    if experiment.measurements:
        return experiment
    sweep = experiment.sweep
    bending = Measurement("bending", experiment.label, Bending(experiment.label, sweep), experiment.drive_m_per_v,
                          experiment.drive_uncertainty, experiment.fit_mask, (sweep.source,))
    return dataclasses.replace(experiment, measurements=(bending,))


def diagnose_experiment(experiment: DrivenExperiment, candidates=CANDIDATES, *,
                        held_out_levels: int = DEFAULT_HELD_OUT_LEVELS, level_stride: int = DEFAULT_LEVEL_STRIDE,
                        max_steps: int = DEFAULT_MAX_STEPS, progress: bool = True) -> dict:
    """The candidate protocol on `experiment` (see the module docstring).

    **Returns:** `diagnose_laws`'s dict with `converged`, `unconverged_fits`, `measurements`
    (the kinds the file holds), `settings` (the knobs), `conclusion` (plain words) and `run`
    (load averages, the process's CPU seconds) added. **Raises:** `ValueError` for an
    experiment without a bending measurement, or fewer than one held-out level."""
    if held_out_levels < 1:
        raise ValueError(f"--held-out-levels {held_out_levels}: give at least 1; the held-out drive levels are "
                         "the measurement every candidate predicts.")
    load = os.getloadavg()[0]
    experiment = with_measurements(experiment)
    if not any(m.kind == "bending" for m in experiment.measurements):
        raise ValueError(f"{experiment.path}: the driven diagnosis fits each candidate law on a bending measurement "
                         "and predicts the others; add a [[measurement]] of kind \"bending\" (a frequency sweep of "
                         "the same apparatus).")
    result = diagnose_laws(experiment, candidates, held_out_levels=held_out_levels, level_stride=level_stride,
                           max_steps=max_steps, progress=progress)
    result = finished(result, [m.kind for m in experiment.measurements],
                      {"held_out_levels": held_out_levels, "level_stride": level_stride, "max_steps": max_steps,
                       "candidates": [c.name for c in candidates]})
    usage = resource.getrusage(resource.RUSAGE_SELF)
    result["run"] = {"load_average_at_start": load, "load_average_at_end": os.getloadavg()[0],
                     "process_cpu_s": usage.ru_utime + usage.ru_stime, "cpu_count": os.cpu_count()}
    return result


def finished(result: dict, kinds, settings: dict) -> dict:
    """`diagnose_laws`'s `result` with `converged` (every candidate's fit reached an optimum, none
    stopped on a refusal), `unconverged_fits`, `measurements` (the experiment's `kinds`),
    `settings` and `conclusion` added."""
    unconverged = [f"the fit of {e['name']} ({e['steps']} steps)" for e in result["candidates"] if not e["converged"]]
    unconverged += [f"the fit of {f['name']} (stopped: {f['error']})" for f in result["failed"]]
    result = dict(result, converged=not unconverged, unconverged_fits=unconverged, measurements=sorted(set(kinds)),
                  settings=settings)
    result["conclusion"] = conclusion(result)
    return result


def _measured(entry: dict, key: str) -> bool:
    """Whether the experiment holds the measurement of target `key` (a tongue, a loop,
    held-out levels; the bending always)."""
    if key.startswith("tongue"):
        return "tongue" in entry
    if key == "loop_onset_up":
        return "loop" in entry
    if key == "held_out_bending_misfit":
        return bool(entry["bending"]["held_out_levels"])
    return True


def _phrase(key: str, value) -> str:
    what, written, target = _WORDS[key]
    if value is None:
        return f"{what}: none predicted (no period doubling up to the search's top; target {target})"
    return f"{what} {written(value)} (target {target})"


def candidate_lines(entry: dict) -> tuple[list[str], list[str]]:
    """(what `entry` explains, what it does not), each a phrase with its number and target;
    measurements the experiment does not hold are left out."""
    explains, misses = [], []
    for key, (value, met) in scores(entry).items():
        if _measured(entry, key):
            (explains if met else misses).append(_phrase(key, value))
    return explains, misses


def conclusion(result: dict) -> str:
    """The diagnosis in plain words: the verdict, then per candidate which measurements it
    explains and which not (in numbers, against the targets), the measurements predicted
    rather than fitted, and every fit that reached no optimum."""
    verdict = result["verdict"]
    held_out = result["settings"]["held_out_levels"]
    predicted = [f"the bending run's top {held_out} drive levels"] + [
        k for k in ("tongue", "loop") if k in result["measurements"]]
    lines = [(f"Each candidate law was fitted on the bending run and predicts what it was not fitted on: "
             f"{', '.join(predicted)}.")]
    if verdict["named"]:
        lines.append(f"Named: {', '.join(verdict['named'])} (closest to the data on the predicted measurements: "
                     f"{verdict['best']}); each improves on the base on a measurement it was not fitted on.")
    else:
        lines.append("No mechanism named: no candidate predicts a measurement it was not fitted on better than the "
                     "base (Hertz contacts, viscous drag) by the protocol's margin.")
    for entry in result["candidates"]:
        explains, misses = candidate_lines(entry)
        improves = verdict["per_candidate"][entry["name"]]["improves_unfitted_over_base"]
        status = (f"converged in {entry['steps']} steps" if entry["converged"]
                  else f"NOT CONVERGED after {entry['steps']} steps (the values are the last iterate's)")
        line = f"{entry['name']} ({entry['mechanism']}; {status}): explains {'; '.join(explains) or 'nothing'}. "
        line += f"Does not explain {'; '.join(misses) or 'nothing'}."
        if improves and entry is not result["candidates"][0]:
            line += f" Better than the base on: {', '.join(improves)}."
        lines.append(line)
    for failed in result["failed"]:
        lines.append(f"{failed['name']} ({failed['mechanism']}): its fit stopped: {failed['error']}")
    if not result["converged"]:
        lines.append(f"NOT CONVERGED: {'; '.join(result['unconverged_fits'])}.")
    return "\n".join(lines)


def write_driven_diagnosis(result: dict, out_dir) -> list[Path]:
    """`diagnosis.json` (the protocol's dict, the kernel that ran), `diagnosis.md` (the
    conclusion and a table of every candidate's numbers) and `diagnosis.png` in `out_dir`."""
    out = Path(out_dir)
    write_json(out / "diagnosis.json", json_ready({**result, "kernel": kernel_record()}))
    keys = list(_WORDS)
    text = [f"# Diagnosis: {result['experiment']}", "", result["conclusion"].replace("\n", "\n\n"), "",
            "| candidate | converged | " + " | ".join(_WORDS[k][0] for k in keys) + " |",
            "|---|---|" + "---|" * len(keys)]
    for entry in result["candidates"]:
        cells = []
        for key, (value, met) in scores(entry).items():
            cells.append("not measured" if not _measured(entry, key) else
                         "none" if value is None else _WORDS[key][1](value) + (" (met)" if met else ""))
        text.append(f"| {entry['name']} | {entry['converged']} | " + " | ".join(cells) + " |")
    write_text(out / "diagnosis.md", "\n".join(text) + "\n")
    _plot(result, out / "diagnosis.png")
    return [out / "diagnosis.json", out / "diagnosis.md", out / "diagnosis.png"]


def _plot(result: dict, path) -> None:
    """A grid of candidates (rows) by measurements (columns): green where a target is met, red
    where not, grey where nothing was predicted; each cell written with its value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    entries = result["candidates"]
    keys = [k for k in _WORDS if _measured(entries[0], k)]
    state = np.full((len(entries), len(keys)), np.nan)
    figure, ax = plt.subplots(figsize=(2.1 * len(keys) + 2.5, 0.55 * len(entries) + 1.8))
    for i, entry in enumerate(entries):
        s = scores(entry)
        for j, key in enumerate(keys):
            value, met = s[key]
            state[i, j] = math.nan if value is None else float(met)
            ax.text(j, i, "none" if value is None else _WORDS[key][1](value).split(" of ")[0], ha="center",
                    va="center", fontsize=7)
    colours = matplotlib.colors.ListedColormap(["#f4a6a6", "#a6dba0"])
    colours.set_bad("#dddddd")
    ax.imshow(np.ma.masked_invalid(state), cmap=colours, vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(keys)), [_WORDS[k][0].replace(", ", ",\n") for k in keys], fontsize=7)
    ax.set_yticks(range(len(entries)), [e["name"] + ("" if e["converged"] else " (not converged)")
                                        for e in entries], fontsize=8)
    named = ", ".join(result["verdict"]["named"]) or "none"
    ax.set_title(f"each law fitted on the bending run; green: target met, red: not, grey: none predicted. "
                 f"Named: {named}", fontsize=8)
    figure.tight_layout()
    save_figure(figure, path, dpi=110)
    plt.close(figure)
