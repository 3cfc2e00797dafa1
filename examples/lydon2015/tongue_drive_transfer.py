"""The single bead's period-doubling tongue with the drive the tongue run itself measured at each
frequency, not a smooth calibration:

    python examples/lydon2015/tongue_drive_transfer.py --data-dir ../shared/data/real/lydon-2015
        [--results examples/lydon2015/results/single_bead_diagnosis_laws] [--out FOLDER]

Below every onset, the tongue run's own fundamental is linear in the drive, so its ratio to a
linear bead's at one smooth drive scale (`drive_response.json#runs.tongue.by_resonance`) is the
actuator's true stroke over the smooth one at each frequency: about 1 over most of 6.3-8 kHz,
with two narrow dip-and-peak pairs (0.45 / 1.53 at 6350 / 6400 Hz, outside the tongue, and
0.49 / 1.52 at 7150 / 7200 Hz, where the measured tongue tips), which look like a fixture's
modes. The micro-slip model of the tongue run (`micro_slip_tongue_run_preload.json`, the lab's
upward sweeps stepped in time at the smooth scale) gives each onset as an actual stroke
divided by that smooth scale; with the measured transfer r(f) the same actual onset is reached
at the nominal amplitude onset / r(f). This script applies that division (no new simulation)
and compares the tongue with the measured onsets frequency by frequency.

Exact up to the drive grid: the model stepped the lab's nominal levels times the smooth scale,
so an onset it found is known to one level (2.25 nm nominal, 3-5 %); where it found none, the
measured transfer could move an onset into range only where r(f) > 1, and those cells are
reported as not computed. The loop (6850 Hz, the next day) has no transfer of its own: its row
borrows the tongue run's r(6850 Hz) and is marked so.

Writes `tongue_drive_transfer.json` and `.png` beside the inputs, or into `--out` (whole or not at all).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from run_record import started, write_stamped  # this folder's helper

from fitting.driven.experiment import load_driven_experiment

HERE = Path(__file__).resolve().parent
SOURCE = "micro_slip_tongue_run_preload.json"
TRANSFER = "drive_response.json"
# The frequencies the source's tongue run was stepped at (its `--tongue-hz`, as the driven
# how-to's command gives it); the source stores onsets at every measured frequency, None where
# it stepped none or found none.
STEPPED_HZ = (6600.0, 6750.0, 6900.0, 7050.0, 7200.0, 7350.0, 7500.0)
# The targets of a prediction (the tongue tip within 25 % in amplitude and 2 % in frequency).
TIP_AMPLITUDE_TOLERANCE = 0.25
TIP_FREQUENCY_TOLERANCE = 0.02


def transfer_at(by_resonance: list, resonance_hz: float) -> dict:
    """The measured over the smooth drive, frequency by frequency, for a chain of linear
    resonance `resonance_hz`: each tabulated resonance's ratios interpolated in log f0."""
    f0 = np.log([row["resonance_hz"] for row in by_resonance])
    frequencies = [f for f, _ in by_resonance[0]["frequencies_and_ratio"]]
    table = np.log([[q for _, q in row["frequencies_and_ratio"]] for row in by_resonance])  # (R, F)
    x = math.log(resonance_hz)
    return {f: float(np.exp(np.interp(x, f0, table[:, j]))) for j, f in enumerate(frequencies)}


def corrected_row(row: dict, transfer: dict, measured: dict) -> dict:
    """One preload's tongue and loop with the measured transfer."""
    tongue = row["tongue"]
    cells = []
    for f, onset in zip(tongue["frequencies_hz"], tongue["model_onset_m"], strict=True):
        if f not in measured["stepped_hz"]:
            continue
        r = transfer[f]
        cell = {"frequency_hz": f, "transfer": r, "measured_onset_m": measured["onset_m"].get(f),
                "smooth_onset_m": onset}
        if onset is not None:
            cell["onset_m"] = onset / r
        else:
            cell["onset_m"] = None
            cell["note"] = ("no onset up to the highest level at the smooth scale; not computed with the transfer"
                            if r > 1.0 else "no onset: the measured stroke here is below the smooth one")
        cells.append(cell)
    found = [c for c in cells if c["onset_m"] is not None]
    tip = min(found, key=lambda c: c["onset_m"]) if found else None
    out = {"tongue_run_precompression_n": row["tongue_run_precompression_n"], "resonance_hz": row["resonance_hz"],
           "smooth_drive_scale": row["drive_scale"], "cells": cells}
    if tip is not None:
        out["tip_m"], out["tip_hz"] = tip["onset_m"], tip["frequency_hz"]
        out["tip_amplitude_gap"] = tip["onset_m"] / measured["tip_m"] - 1.0
        out["tip_frequency_gap"] = tip["frequency_hz"] / measured["tip_hz"] - 1.0
        out["tip_meets_targets"] = bool(abs(out["tip_amplitude_gap"]) <= TIP_AMPLITUDE_TOLERANCE
                                        and abs(out["tip_frequency_gap"]) <= TIP_FREQUENCY_TOLERANCE)
    both = [c for c in cells if c["onset_m"] is not None and c["measured_onset_m"] is not None]
    out["onsets_compared"] = len(both)
    out["onset_log_rms"] = (float(np.sqrt(np.mean([math.log(c["onset_m"] / c["measured_onset_m"]) ** 2 for c in both])))
                            if both else None)
    out["measured_onsets_without_model_onset"] = [c["frequency_hz"] for c in cells
                                                  if c["onset_m"] is None and c["measured_onset_m"] is not None]
    loop = row["loop"]
    r_loop = transfer.get(loop["frequency_hz"])
    out["loop"] = {"frequency_hz": loop["frequency_hz"], "transfer_borrowed_from_tongue_run": r_loop,
                   "measured_onset_up_m": loop["measured_onset_up_m"],
                   "onset_up_m": None if loop["model_onset_up_m"] is None or r_loop is None
                   else loop["model_onset_up_m"] / r_loop}
    return out


def plot(rows: list, measured: dict, transfer: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True, height_ratios=(1, 2))
    freqs = sorted(transfer)
    top.plot(freqs, [transfer[f] for f in freqs], ".-", color="0.3")
    top.axhline(1.0, color="0.7", lw=0.8)
    top.set_ylabel("measured / smooth drive")
    f_meas = sorted(measured["all_onset_m"])
    bottom.plot(f_meas, [measured["all_onset_m"][f] * 1e9 for f in f_meas], "ks", label="measured onset (f/2)")
    for row in rows:
        cells = [c for c in row["cells"] if c["onset_m"] is not None]
        label = f"{row['tongue_run_precompression_n']:g} N"
        bottom.plot([c["frequency_hz"] for c in cells], [c["onset_m"] * 1e9 for c in cells], "o-",
                    label=f"model, measured drive, {label}")
        bottom.plot([c["frequency_hz"] for c in cells], [c["smooth_onset_m"] * 1e9 for c in cells], "o:",
                    alpha=0.4, label=f"model, smooth drive, {label}")
    finish_onset_figure(fig, bottom, path)


def finish_onset_figure(fig, ax, path: Path) -> None:
    """Label `ax` as onsets of f/2 (nm of nominal drive) against the drive frequency (Hz),
    add its legend and write `fig` to `path`."""
    from hertzchain.io.atomic import finish_figure

    ax.set_xlabel("drive frequency (Hz)")
    ax.set_ylabel("onset of f/2, nominal drive (nm)")
    ax.legend(fontsize=7)
    finish_figure(fig, path, dpi=120)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", required=True, help="the lydon-2015 data folder")
    parser.add_argument("--results", default=str(HERE / "results" / "single_bead_diagnosis_laws"),
                        help="the folder holding drive_response.json and micro_slip_tongue_run_preload.json")
    parser.add_argument("--out", default=None,
                        help="the folder to write tongue_drive_transfer.json and .png to (default: --results)")
    parser.add_argument("--stepped-hz", type=float, nargs="+", default=list(STEPPED_HZ),
                        help="the frequencies the source run stepped (its --tongue-hz)")
    args = parser.parse_args(argv)
    start = started()
    folder = Path(args.results)
    source = json.loads((folder / SOURCE).read_text())
    by_resonance = json.loads((folder / TRANSFER).read_text())["runs"]["tongue"]["by_resonance"]
    experiment = load_driven_experiment(HERE / "single_bead_joint.toml", args.data_dir)
    tongue = next(m for m in experiment.measurements if m.kind == "tongue").data
    onsets = {float(f): float(o) for f, o in zip(tongue.frequencies_hz, tongue.onset_m, strict=True) if np.isfinite(o)}
    stepped = set(args.stepped_hz)
    for row in source["tongue_run_rows"]:
        found = {f for f, onset in zip(row["tongue"]["frequencies_hz"], row["tongue"]["model_onset_m"], strict=True)
                 if onset is not None}
        if not found <= stepped:
            parser.error(f"--stepped-hz: the source has onsets at {sorted(found - stepped)} Hz too; give every "
                         "frequency its run stepped")
    j = int(np.nanargmin(tongue.onset_m))
    measured = {"tip_m": float(tongue.onset_m[j]), "tip_hz": float(tongue.frequencies_hz[j]),
                "onset_m": {f: onsets.get(f) for f in sorted(stepped)}, "stepped_hz": stepped, "all_onset_m": onsets}
    rows = [corrected_row(row, transfer_at(by_resonance, row["resonance_hz"]), measured)
            for row in source["tongue_run_rows"]]
    result = {
        "why": __doc__.split("\n\n")[1].replace("\n", " "),
        "sources": [f"{folder.name}/{SOURCE}#tongue_run_rows", f"{folder.name}/{TRANSFER}#runs.tongue.by_resonance"],
        "measured": {"run": tongue.run, "tip_m": measured["tip_m"], "tip_hz": measured["tip_hz"],
                     "onset_m": {str(f): o for f, o in sorted(onsets.items())}},
        "targets": {"tip_amplitude": TIP_AMPLITUDE_TOLERANCE, "tip_frequency": TIP_FREQUENCY_TOLERANCE},
        "rows": rows,
        "caveats": [("the drive calibration is uncertain by sqrt(2); the transfer is measured relative to a linear "
                     "bead at the smooth scale, at the tongue run's lowest drive levels only"),
                    "onsets known to one drive level (2.25 nm nominal)",
                    "the loop ran the next day: its transfer is the tongue run's, borrowed"],
    }
    for row in rows:
        print(f"{row['tongue_run_precompression_n']:g} N: tip {row.get('tip_m', float('nan')) * 1e9:.1f} nm at "
              f"{row.get('tip_hz')} Hz (measured {measured['tip_m'] * 1e9:.1f} nm at {measured['tip_hz']:.0f} Hz), "
              f"onsets log-rms {row['onset_log_rms']}, loop {row['loop']['onset_up_m']}")
    out = folder if args.out is None else Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot(rows, measured, transfer_at(by_resonance, rows[-1]["resonance_hz"]), out / "tongue_drive_transfer.png")
    write_stamped(out / "tongue_drive_transfer.json", result, start)


if __name__ == "__main__":
    main()
