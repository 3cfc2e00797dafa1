"""`hertzchain sweep`: a grid of setups, streamed to disk in chunks, resumable, on all devices.

Example::

    hertzchain sweep --grid striker_velocity_m_s=0.1:1:10:log \\
        --grid wall_youngs_pa=3GPa,45GPa,203GPa --grid eta_s=0,2us --out out/sweep

Run the same command again after an interruption: finished chunks are kept.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..sweep import SweepSpec, nonfinite_runs, parse_grid, run_sweep, table_yield_notice
from ..units import counted, parse_quantity
from ..validation import check_plausible
from .setup_options import add_run_arguments, add_setup_arguments, chain_from_args


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_setup_arguments(parser)
    add_run_arguments(parser)
    parser.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="FIELD=VALUES",
        help="a swept ChainSetup field and its values, in the unit the field's name carries or with "
        "a suffix: a comma list (wall_youngs_pa=3GPa,45GPa), start:stop:count (eta_s=0:3us:4) or "
        "start:stop:count:log; repeat for an outer product",
    )
    parser.add_argument("--out", default="out/sweep", help="output folder [out/sweep]")
    parser.add_argument("--chunk-size", type=int, help="runs per chunk [sized to ~256 MB of samples]")
    parser.add_argument("--max-chunks", type=int, help="compute at most this many chunks now, resume later")
    parser.add_argument(
        "--distributed",
        action="store_true",
        help="one of several processes/hosts sharing the chunks (jax.distributed); process 0 writes "
        "the table. On SLURM, Open MPI or Kubernetes the cluster is detected; elsewhere give the "
        "three options below",
    )
    parser.add_argument("--coordinator", metavar="HOST:PORT",
                        help="with --distributed: address of process 0's coordinator service")
    parser.add_argument("--num-processes", type=int, help="with --distributed: number of processes P")
    parser.add_argument("--process-id", type=int, help="with --distributed: this process's index, 0..P-1")
    parser.add_argument("--no-plots", action="store_true", help="do not draw the summary plots")
    parser.add_argument("--yes", action="store_true",
                        help="run even when the sweep needs more memory than is available or more than 1e10 "
                        "bead-steps")


def start_distributed(args: argparse.Namespace) -> None:
    """Join the cluster: `jax.distributed.initialize` with the options given (None = detect)."""
    given = {"--coordinator": args.coordinator, "--num-processes": args.num_processes,
             "--process-id": args.process_id}
    if not args.distributed:
        named = [flag for flag, value in given.items() if value is not None]
        if named:
            raise ValueError(f"{', '.join(named)}: only for a --distributed sweep; add --distributed or drop them.")
        return
    if args.num_processes is not None and args.num_processes < 1:
        raise ValueError(f"--num-processes must be at least 1, got {args.num_processes}.")
    if args.process_id is not None and args.num_processes is not None and not (
        0 <= args.process_id < args.num_processes
    ):
        raise ValueError(f"--process-id must be in 0..{args.num_processes - 1}, got {args.process_id}.")
    import jax

    jax.distributed.initialize(
        coordinator_address=args.coordinator, num_processes=args.num_processes, process_id=args.process_id
    )


def jax_process_index() -> int:
    import jax

    return jax.process_index()


def run(args: argparse.Namespace) -> int:
    start_distributed(args)
    if not args.grid:
        raise ValueError("give at least one --grid FIELD=VALUES, e.g. --grid striker_velocity_m_s=0.1:1:10:log")
    chain = chain_from_args(args)
    setup = chain.setup
    grid = dict(parse_grid(text) for text in args.grid)
    for name, values in grid.items():
        check_plausible(name, values, where="--grid")
    spec = SweepSpec(
        setup=setup,
        grid=grid,
        t_end_s=parse_quantity(args.t_end, "s", name="--t-end"),
        sample_interval_s=parse_quantity(args.sample_interval, "s", name="--sample-interval"),
        dt_s=None if args.dt is None else parse_quantity(args.dt, "s", name="--dt"),
        contacts=tuple(args.contacts or ()),
    )
    print(f"sweep of {counted(spec.n_runs, 'run')} over {', '.join(grid)} into {args.out}", flush=True)
    for line in chain.describe(swept=grid):
        print(line, flush=True)
    result = run_sweep(
        spec,
        Path(args.out),
        chunk_size=args.chunk_size,
        max_chunks=args.max_chunks,
        distributed=args.distributed,
        plots=not args.no_plots,
        check_size=not args.yes,
    )
    if args.distributed and jax_process_index() != 0:
        print(f"process {jax_process_index()}: computed {counted(result.computed, 'chunk')}; process 0 writes the table.",
              flush=True)
        return 0
    if not result.complete:
        print(
            f"{result.chunks_done}/{result.n_chunks} chunks done; run the same command again to resume.",
            flush=True,
        )
        return 0
    print(f"wrote {result.folder / 'sweep.csv'} and {result.folder / 'sweep.parquet'} "
          f"({counted(len(result.table['run']), 'run')}, {counted(result.computed, 'chunk')} computed now)")
    notice = table_yield_notice(result.table, setup)
    if notice:
        print(f"hertzchain sweep: warning: {notice}", file=sys.stderr)
    failed = nonfinite_runs(result.table)
    if failed.size:
        shown = ", ".join(str(run) for run in failed[:10]) + (" ..." if failed.size > 10 else "")
        print(f"hertzchain sweep: error: {failed.size} of {len(result.table['run'])} runs gave non-finite forces "
              f"or energies (runs {shown}; result_finite = 0 in sweep.csv): not results; narrow the grid or "
              "give a smaller --dt.", file=sys.stderr)
        return 3
    return 0
