"""`hertzchain import experiment.toml --out DIR`: a lab's scope files as trace files.

Reads the experiment file (`hertzchain.io.importer`: chain, scope settings, channels with
their sensitivities and coupling, shots and their files), conditions every shot (offset,
volts to newtons, noise, time zero, clipping, each step recorded as `x_import_*` header
keys) and writes `DIR/<shot>.csv` per shot, a plot of each, and `import.json` listing the
files with each channel's offset, noise and clipped samples, and each shot's time zero with
its check against the pulse's arrivals (`importer.check_time_zero`). Nothing is written unless
every shot imports; the folder is written as a whole and replaces the previous run's
(`hertzchain.io.atomic.output_folder`). `fit`, `diagnose`, `analyze` and `design` also take the
experiment file directly (imported in memory).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.atomic import file_stem, finish_figure, output_folder, write_json  # noqa: E402
from ..io.importer import import_experiment  # noqa: E402
from ..io.tracefile import write_trace  # noqa: E402
from ..units import counted


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("experiment", metavar="EXPERIMENT", help="experiment file (.toml)")
    parser.add_argument("--out", default="out/import", help="output folder [out/import]")
    parser.add_argument("--no-plots", action="store_true", help="write trace files and JSON only")


def _plot(trace, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(8, 4))
    for name, values in trace.channels.items():
        line, = axes.plot(trace.time_s * 1e3, values, lw=0.8, label=name.replace("_", " "))
        clipped = trace.clipped(name)
        if clipped.any():
            axes.plot(trace.time_s[clipped] * 1e3, np.asarray(values)[clipped], "x",
                      color=line.get_color(), label=f"{name} clipped")
    axes.axvline(0.0, color="0.5", lw=0.6, ls=":")
    axes.set_xlabel("time since impact (ms)")
    axes.set_ylabel("force (N)")
    axes.set_title(f"shot {trace.header['x_shot']}")
    axes.legend(fontsize=8)
    finish_figure(figure, path)


def run(args: argparse.Namespace) -> int:
    if not Path(args.experiment).is_file():
        raise FileNotFoundError(f"no such experiment file: {args.experiment}")
    with output_folder(args.out, "import", "import.json") as out:
        traces = import_experiment(args.experiment)
        listing = _write(traces, out, args)
    print(f"wrote {counted(len(listing), 'trace file')} and import.json to {args.out}")
    return 0


def _write(traces, out: Path, args) -> list:
    """Each shot's trace file (and plot) and `import.json` in `out`; returns the listing."""
    listing = []
    for trace in traces:
        label = trace.header["x_shot"]
        path = out / f"{file_stem(label)}.csv"
        write_trace(path, trace)
        if not args.no_plots:
            _plot(trace, path.with_suffix(".png"))
        channels = {}
        for name in trace.channels:
            clipped = int(trace.clipped(name).sum())
            channels[name] = {
                "source": trace.header[f"x_import_{name}_source"],
                "offset_v": float(trace.header[f"x_import_{name}_offset_v"]),
                "noise_std_n": float(trace.header[f"noise_std_n_{name}"]),
                "noise_source": trace.header[f"x_import_{name}_noise_source"],
                "reads_change_since_rest": name in trace.ac_channels,
                "clipped_samples": clipped,
            }
            if clipped:
                print(f"warning: shot {label}, channel {name}: {counted(clipped, 'sample')} at the scope's range "
                      "limit (clipped); fits leave them out.", file=sys.stderr)
            note = trace.header.get(f"x_import_{name}_noise_note")
            if note:
                channels[name]["noise_note"] = note
                print(f"note: shot {label}, channel {name}: {note}.", file=sys.stderr)
        listing.append({
            "shot": label, "file": path.name, "samples": int(len(trace.time_s)),
            "pre_trigger_samples": int(np.sum(trace.time_s < 0)),
            "sample_interval_s": trace.sample_interval_s,
            "striker_velocity_m_s": trace.striker_velocity_m_s, "channels": channels,
            "time_zero_s": float(trace.header["x_import_time_zero_s"]),
            "time_zero_check": trace.header["x_import_time_zero_check"],
        })
        print(f"{label}: {counted(len(trace.time_s), 'sample')} ({listing[-1]['pre_trigger_samples']} before the "
              f"impact), channels {', '.join(trace.channels)} -> {Path(args.out) / path.name}")
    write_json(out / "import.json", {"experiment": str(args.experiment), "shots": listing})
    return listing
