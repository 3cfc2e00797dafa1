"""The micro-slip single bead's period-doubling tongue by Floquet multipliers (the supports'
sliders as state), against the measured onsets and the onsets stepped in time:

    python examples/lydon2015/micro_slip_floquet_tongue.py --data-dir ../shared/data/real/lydon-2015
        [--results examples/lydon2015/results/single_bead_diagnosis_laws] [--out FOLDER]

Each tongue-run chain of `micro_slip_tongue_run_preload.json` (the bending fit's supports,
damping and Hertz constant, the tongue run's own static force: `micro_slip_preload_scan.py`)
gets its threshold at every measured tongue frequency by continuation in drive amplitude
(`hertzchain.driven.thresholds.period_doubling_onsets`: the orbit at each amplitude the Newton
polish of the one below, its stuck sliders where they were, as an upward sweep leaves them),
in the driver's stroke. As a nominal amplitude it is that stroke over the row's smooth drive
scale, and with the drive transfer the tongue run measured, r(f) (`tongue_drive_transfer.py`),
over the smooth scale times r(f) (`tip_m`: the lowest at any frequency; `tip_where_measured_m`:
the lowest where the lab measured an onset, r(f) peaking at 1.5 at 6400 Hz, outside the
measured tongue). The time-stepped onsets of the same chains
(`tongue_drive_transfer.json#rows`) show f/2 only once the multiplier's growth over a level
lifts rounding to the lab's rule, so they lie above the Floquet threshold. At the tongue's
tip frequency the multipliers of the orbits reached from rest at the lab's levels are stored
too: with micro-slip the period-1 orbit depends on where the sliders stuck, and there the
most negative multiplier hovers near -1 over a range of amplitudes.

Writes `micro_slip_floquet_tongue.json` and `.png` beside the inputs, or into `--out`.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from micro_slip_preload_scan import chain_at  # this folder's scripts
from run_record import started, write_stamped
from tongue_drive_transfer import finish_onset_figure, transfer_at

from fitting.driven.experiment import load_driven_experiment
from hertzchain.driven.floquet import floquet_multipliers
from hertzchain.driven.linear import normal_modes
from hertzchain.driven.thresholds import period_doubling_onsets

HERE = Path(__file__).resolve().parent

CONSTANTS = "micro_slip_free_preload.json"
ROWS = "micro_slip_tongue_run_preload.json"
TRANSFER = "drive_response.json"
STEPPED = "tongue_drive_transfer.json"
# The driver strokes the continuation searches, m (the lab's tongue tops out at 96 nm nominal).
LOWEST_STROKE_M, HIGHEST_STROKE_M = 20e-9, 250e-9
# The frequency at which the multipliers along the lab's levels are stored (the measured tip).
LEVELS_HZ = 7200.0


def tongue_chain(constants: dict, bending_n: float, tongue_n: float):
    """The micro-slip chain of the bending fit at `bending_n` (Hertz constant, supports), at
    the tongue run's static force `tongue_n` (as `micro_slip_preload_scan.py --tongue-run-preloads`)."""
    return eqx.tree_at(lambda c: c.precompression_n, chain_at(constants, bending_n), jnp.asarray(float(tongue_n)))


def plot(rows: list, measured: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    f_meas = sorted(measured)
    ax.plot(f_meas, [measured[f] * 1e9 for f in f_meas], "ks", label="measured onset (f/2)")
    for i, row in enumerate(rows):
        color = f"C{i}"
        label = f"{row['tongue_run_precompression_n']:g} N"
        cells = [c for c in row["cells"] if c["onset_m"] is not None]
        ax.plot([c["frequency_hz"] for c in cells], [c["onset_m"] * 1e9 for c in cells], "-", color=color,
                label=f"Floquet, measured drive, {label}")
        stepped = [c for c in row["stepped"] if c["onset_m"] is not None]
        ax.plot([c["frequency_hz"] for c in stepped], [c["onset_m"] * 1e9 for c in stepped], "o", color=color,
                mfc="none", label=f"stepped in time, measured drive, {label}")
    ax.set_ylim(0, 150)
    finish_onset_figure(fig, ax, path)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", required=True, help="the lydon-2015 data folder")
    parser.add_argument("--results", default=str(HERE / "results" / "single_bead_diagnosis_laws"),
                        help=f"the folder holding {CONSTANTS}, {ROWS}, {TRANSFER} and {STEPPED}")
    parser.add_argument("--out", default=None, help="the folder to write to (default: --results)")
    args = parser.parse_args(argv)
    start = started()
    folder = Path(args.results)
    source = json.loads((folder / CONSTANTS).read_text())
    constants = next(c for c in source["candidates"] if c["name"] == "micro_slip_free_preload")["constants"]
    tongue_rows = json.loads((folder / ROWS).read_text())["tongue_run_rows"]
    by_resonance = json.loads((folder / TRANSFER).read_text())["runs"]["tongue"]["by_resonance"]
    stepped_rows = json.loads((folder / STEPPED).read_text())["rows"]
    experiment = load_driven_experiment(HERE / "single_bead_joint.toml", args.data_dir)
    tongue = next(m for m in experiment.measurements if m.kind == "tongue").data
    steps = int(experiment.model["steps_per_period"])
    frequencies = np.asarray(tongue.frequencies_hz, dtype=float)
    measured = {float(f): float(o) for f, o in zip(frequencies, tongue.onset_m, strict=True) if np.isfinite(o)}
    j = int(np.nanargmin(tongue.onset_m))
    tip_m, tip_hz = float(tongue.onset_m[j]), float(frequencies[j])
    levels_m = np.asarray(tongue.drive_amplitudes_m, dtype=float)
    rows = []
    for source_row in tongue_rows:
        force, scale = source_row["tongue_run_precompression_n"], source_row["drive_scale"]
        chain = tongue_chain(constants, source_row["bending_run_precompression_n"], force)
        resonance = float(normal_modes(chain)[0][0])
        transfer = transfer_at(by_resonance, resonance)
        onsets = period_doubling_onsets(chain, frequencies, lowest_amplitude_m=LOWEST_STROKE_M,
                                        highest_amplitude_m=HIGHEST_STROKE_M, steps_per_period=steps)
        cells = []
        for f, stroke, reason in zip(frequencies, onsets.amplitude_m, onsets.reasons, strict=True):
            f = float(f)
            found = bool(np.isfinite(stroke))
            cells.append({"frequency_hz": f, "transfer": transfer[f], "measured_onset_m": measured.get(f),
                          "stroke_m": float(stroke) if found else None,
                          "smooth_onset_m": float(stroke) / scale if found else None,
                          "onset_m": float(stroke) / (scale * transfer[f]) if found else None, "reason": reason})
        found = [c for c in cells if c["onset_m"] is not None]
        tip = min(found, key=lambda c: c["onset_m"]) if found else None
        both = [c for c in found if c["measured_onset_m"] is not None]
        tip_measured = min(both, key=lambda c: c["onset_m"]) if both else None
        stepped = next(r for r in stepped_rows if r["tongue_run_precompression_n"] == force)
        levels = levels_m * scale
        floquet = floquet_multipliers(chain, LEVELS_HZ, levels, steps_per_period=steps)
        row = {"tongue_run_precompression_n": force, "resonance_hz": resonance, "smooth_drive_scale": scale,
               "cells": cells,
               "tip_m": None if tip is None else tip["onset_m"], "tip_hz": None if tip is None else tip["frequency_hz"],
               "tip_amplitude_gap": None if tip is None else tip["onset_m"] / tip_m - 1.0,
               "tip_where_measured_m": None if tip_measured is None else tip_measured["onset_m"],
               "tip_where_measured_hz": None if tip_measured is None else tip_measured["frequency_hz"],
               "onsets_compared": len(both),
               "onset_log_rms": (float(np.sqrt(np.mean([math.log(c["onset_m"] / c["measured_onset_m"]) ** 2
                                                        for c in both]))) if both else None),
               "stepped": [{"frequency_hz": c["frequency_hz"], "onset_m": c["onset_m"]} for c in stepped["cells"]],
               "stepped_tip_m": stepped.get("tip_m"), "stepped_tip_hz": stepped.get("tip_hz"),
               "levels_at_hz": LEVELS_HZ,
               "levels": {"stroke_m": levels.tolist(), "nominal_m": levels_m.tolist(),
                          "most_negative_multiplier": [None if not np.isfinite(m) else float(m)
                                                       for m in floquet.most_negative_real],
                          "stuck_sliders": floquet.stuck_sliders.sum(axis=(1, 2)).tolist(),
                          "orbit_residual_max": float(np.max(floquet.orbit_residual))}}
        rows.append(row)
        at = next(c for c in cells if c["frequency_hz"] == LEVELS_HZ)
        print(f"{force:g} N: Floquet tip {row['tip_m']} m at {row['tip_hz']} Hz; at {LEVELS_HZ:g} Hz {at['onset_m']} m "
              f"(stroke {at['stroke_m']} m); stepped tip {row['stepped_tip_m']} m; measured {tip_m:.4g} m at "
              f"{tip_hz:.0f} Hz", flush=True)
    result = {
        "why": __doc__.split("\n\n")[1].replace("\n", " "),
        "sources": [f"{folder.name}/{CONSTANTS}#candidates.1.constants", f"{folder.name}/{ROWS}#tongue_run_rows",
                    f"{folder.name}/{TRANSFER}#runs.tongue.by_resonance", f"{folder.name}/{STEPPED}#rows"],
        "measured": {"run": tongue.run, "tip_m": tip_m, "tip_hz": tip_hz,
                     "onset_m": {str(f): o for f, o in sorted(measured.items())}},
        "search": {"lowest_stroke_m": LOWEST_STROKE_M, "highest_stroke_m": HIGHEST_STROKE_M,
                   "steps_per_period": steps, "how": "period_doubling_onsets (continuation up in amplitude)"},
        "rows": rows,
        "caveats": [("the drive calibration is uncertain by sqrt(2); the transfer is measured relative to a linear "
                     "bead at the smooth scale, at the tongue run's lowest drive levels only"),
                    ("the map is piecewise smooth (slip pattern): its multipliers jump with amplitude, and the "
                     "period-1 orbit depends on where the sliders stuck (continuation versus a ramp from rest)"),
                    "the measured onsets are the lab's f/2 rule, reached past the Floquet threshold by a growth margin"],
    }
    out = folder if args.out is None else Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot(rows, measured, out / "micro_slip_floquet_tongue.png")
    write_stamped(out / "micro_slip_floquet_tongue.json", result, start)


if __name__ == "__main__":
    main()
