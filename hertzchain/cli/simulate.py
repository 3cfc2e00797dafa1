"""`hertzchain simulate`: run a chain (default: the paper's) and write traces, summary, plot."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .. import plotting
from ..integrate import simulate
from ..io.atomic import save_figure, say_replaced, write_json
from ..io.summary import run_summary
from ..io.tracefile import TraceFile, setup_header, validate_header, write_trace
from ..native import kernel_record
from ..validation import check_simulation_size
from .setup_options import add_run_arguments, add_setup_arguments, chain_from_args, run_options

DESCRIPTION = (
    "Simulate a chain and write traces.csv, summary.json and simulation.png. Without options "
    "it is the paper's chain (21 steel beads of radius 13 mm, a striker like them at 0.3 m/s, a "
    "steel wall) with lossless contacts (eta = 0); the paper's fits use --eta 2us, as "
    "`hertzchain reproduce` does. Describe your own chain with materials by name "
    "(--bead-material brass --striker-material steel --wall-material Cu), values with units "
    "(--bead-radius 5mm --wall-youngs 5GPa) or a setup file (--config setup.toml)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = DESCRIPTION
    add_setup_arguments(parser)
    add_run_arguments(parser)
    parser.add_argument(
        "--coupling", choices=("dc", "ac"), default="dc",
        help="channels of traces.csv: dc, the forces; ac, as piezo sensors read them, the change "
        "since before the impact (a static --precompression is not in them) [dc]",
    )
    parser.add_argument("--out", default="out/simulate", help="output folder [out/simulate]")
    parser.add_argument("--yes", action="store_true",
                        help="run even when the run needs more memory than is available or more than 1e10 "
                        "bead-steps")


def run(args: argparse.Namespace) -> int:
    chain = chain_from_args(args)
    setup = chain.setup
    header = setup_header(setup)
    validate_header(header, "setup")
    options = run_options(args, setup.n_beads)
    if not args.yes:
        check_simulation_size(setup, options)
    print(
        f"simulating {setup.n_beads} beads, impact {float(setup.striker_velocity_m_s):g} m/s, "
        f"{options['t_end_s'] * 1e3:g} ms ...",
        flush=True,
    )
    for line in chain.describe():
        print(line, flush=True)
    traces = simulate(setup, record_all=True, progress=True, **options)
    out = Path(args.out)
    earlier = any((out / name).is_file() for name in ("traces.csv", "summary.json", "simulation.png"))
    rest = float(setup.precompression_n) if args.coupling == "ac" else 0.0
    forces = {name: np.asarray(traces.forces_n[name]) - rest for name in traces.channel_names}
    if args.coupling == "ac":
        header["ac_channels"] = ",".join(forces)
    write_trace(
        out / "traces.csv",
        TraceFile(header=header, time_s=np.asarray(traces.time_s), channels=forces),
    )
    summary = run_summary(setup, traces, options)
    summary["materials"] = chain.materials
    summary["setup_sources"] = chain.sources
    write_json(out / "summary.json", {**summary, "kernel": kernel_record()})
    save_figure(plotting.plot_run(traces), out / "simulation.png", dpi=120)
    print(f"wrote {out / 'traces.csv'}, {out / 'summary.json'}, {out / 'simulation.png'}")
    if earlier:
        say_replaced(out, "simulate")
    for name, peak in summary["peak_force_n"].items():
        print(f"  peak {name}: {peak:.4g} N")
    balance = summary["energy_balance"]["max_relative_error"]
    print(f"  energy books balance to {balance:.2e} of the impact energy")
    return 0
