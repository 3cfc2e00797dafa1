"""`hertzchain simulate`: run a chain (default: the paper's) and write traces, summary, plot."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .. import plotting
from ..atomic import save_figure, write_json
from ..native import kernel_record
from ..integrate import simulate
from ..summary import run_summary
from ..tracefile import TraceFile, setup_header, validate_header, write_trace
from .setup_options import add_run_arguments, add_setup_arguments, run_options, setup_from_args


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_setup_arguments(parser)
    add_run_arguments(parser)
    parser.add_argument(
        "--coupling", choices=("dc", "ac"), default="dc",
        help="channels of traces.csv: dc, the forces; ac, as piezo sensors read them, the change "
        "since before the impact (a static --precompression is not in them) [dc]",
    )
    parser.add_argument("--out", default="out/simulate", help="output folder [out/simulate]")


def run(args: argparse.Namespace) -> int:
    setup = setup_from_args(args)
    header = setup_header(setup)
    validate_header(header, "setup")
    options = run_options(args, setup.n_beads)
    print(
        f"simulating {setup.n_beads} beads, impact {float(setup.striker_velocity_m_s):g} m/s, "
        f"{options['t_end_s'] * 1e3:g} ms ...",
        flush=True,
    )
    traces = simulate(setup, record_all=True, progress=True, **options)
    out = Path(args.out)
    rest = float(setup.precompression_n) if args.coupling == "ac" else 0.0
    forces = {name: np.asarray(traces.forces_n[name]) - rest for name in traces.channel_names}
    if args.coupling == "ac":
        header["ac_channels"] = ",".join(forces)
    write_trace(
        out / "traces.csv",
        TraceFile(header=header, time_s=np.asarray(traces.time_s), channels=forces),
    )
    summary = run_summary(setup, traces, options)
    write_json(out / "summary.json", {**summary, "kernel": kernel_record()})
    save_figure(plotting.plot_run(traces), out / "simulation.png", dpi=120)
    print(f"wrote {out / 'traces.csv'}, {out / 'summary.json'}, {out / 'simulation.png'}")
    for name, peak in summary["peak_force_n"].items():
        print(f"  peak {name}: {peak:.4g} N")
    balance = summary["energy_balance"]["max_relative_error"]
    print(f"  energy books balance to {balance:.2e} of the impact energy")
    return 0
