"""`hertzchain synth`: synthetic experiment files (one per impact velocity) from any setup.

Each velocity is simulated on a grid `--oversample` times finer than the recording, then
recorded as an oscilloscope would (`hertzchain.acquisition`: trigger, bandwidth, noise,
quantisation, the paper's sensor sensitivities, AC or DC coupling, a pre-trigger segment)
and written as a `hertzchain-trace/1` file in newtons. The true parameters are stored in the header as `x_true_*` keys, the
acquisition settings as `x_acq_*` keys. Also written: a PNG per file and `synth.json`
listing the files and their truth.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..acquisition import Acquisition, record_simulation  # noqa: E402
from ..integrate import simulate  # noqa: E402
from ..io.atomic import finish_figure, write_json  # noqa: E402
from ..io.tracefile import validate_header, write_trace  # noqa: E402
from ..progress import Progress  # noqa: E402
from ..units import counted, parse_quantity  # noqa: E402
from ..validation import check_batch_size  # noqa: E402
from .setup_options import add_run_arguments, add_setup_arguments, run_options, setup_from_args  # noqa: E402

TRUTH_FIELDS = (
    "striker_velocity_m_s",
    "eta_s",
    "mu",
    "mu_star",
    "wall_youngs_pa",
    "precompression_n",
)


def _float_list(text: str) -> tuple[float, ...]:
    try:
        values = tuple(
            parse_quantity(part, "m/s", name="--velocities")
            for part in text.split(",")
            if part.strip()
        )
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from error
    if not values:
        raise argparse.ArgumentTypeError("give at least one velocity, e.g. 0.1,0.3,1")
    return values


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_setup_arguments(parser)
    add_run_arguments(parser)
    parser.add_argument(
        "--velocities",
        type=_float_list,
        help="impact velocities, m/s, one file each, e.g. 0.1,0.3,1 [--striker-velocity]",
    )
    noise = parser.add_mutually_exclusive_group()
    noise.add_argument("--noise-std", help="additive noise, N, on every channel [0]")
    noise.add_argument(
        "--noise-fraction",
        type=float,
        help="additive noise as a fraction of each channel's peak force, e.g. 0.005",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of noise and jitter (file i uses seed+i) [0]"
    )
    parser.add_argument(
        "--oversample", type=int, default=10, help="simulation samples per recorded sample [10]"
    )
    parser.add_argument("--bits", type=int, help="converter resolution, bits [none]")
    parser.add_argument("--bandwidth", help="low-pass cut-off (Hz; e.g. 100kHz) [none]")
    parser.add_argument("--bandwidth-filter", choices=("bessel", "first_order"), default="bessel")
    parser.add_argument(
        "--trigger-delay", default="0", help="trigger time after the impact (s) [0]"
    )
    parser.add_argument(
        "--trigger-jitter", default="0", help="trigger jitter, standard deviation (s) [0]"
    )
    parser.add_argument(
        "--coupling", choices=("dc", "ac"), default="dc",
        help="dc: channels read the force; ac: piezo sensors reading its change since before the "
        "impact, so a static preload (--precompression) is not in them [dc]",
    )
    parser.add_argument(
        "--pre-trigger", type=int, default=0, help="samples recorded before the trigger [0]"
    )
    parser.add_argument("--out", default="out/synth", help="output folder [out/synth]")
    parser.add_argument("--yes", action="store_true",
                        help="run even when the shots need more memory than is available or more than 1e10 "
                        "bead-steps")


def _plot(trace, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(8, 4))
    for name, values in trace.channels.items():
        axes.plot(trace.time_s * 1e3, values, lw=1, label=name.replace("_", " "))
    axes.set_xlabel("time since trigger (ms)")
    axes.set_ylabel("force (N)")
    velocity = trace.header.get("striker_velocity_m_s")
    axes.set_title(
        f"synthetic record, impact {velocity:g} m/s, noise {trace.header['noise_std_n']:.3g} N"
    )
    axes.legend(fontsize=9)
    finish_figure(figure, path)


def run(args: argparse.Namespace) -> int:
    base = setup_from_args(args)
    options = run_options(args, base.n_beads)
    if args.oversample < 1:
        raise ValueError(f"--oversample must be >= 1, got {args.oversample}.")
    velocities = args.velocities or (float(base.striker_velocity_m_s),)
    interval = options["sample_interval_s"]
    delay = parse_quantity(args.trigger_delay, "s", name="--trigger-delay")
    jitter = parse_quantity(args.trigger_jitter, "s", name="--trigger-jitter")
    bandwidth = (
        None if args.bandwidth is None else parse_quantity(args.bandwidth, "Hz", name="--bandwidth")
    )
    if args.pre_trigger < 0:
        raise ValueError(f"--pre-trigger must be >= 0 samples, got {args.pre_trigger}.")
    record_length = int(round(options["t_end_s"] / interval)) + args.pre_trigger
    # Simulate past the record's end by the trigger offset (jitter up to 6 sigma).
    t_sim = options["t_end_s"] + max(delay, 0.0) + 6.0 * jitter + interval
    if not args.yes:
        check_batch_size(base, n_runs=len(velocities), n_runs_in_memory=1, n_channels=len(options["contacts"]) + 2,
                         t_end_s=t_sim, sample_interval_s=interval / args.oversample, dt_s=options["dt_s"])
    out = Path(args.out)
    progress = Progress(len(velocities), "synth (files)")
    listing = []
    for index, velocity in enumerate(velocities):
        setup = eqx.tree_at(lambda s: s.striker_velocity_m_s, base, jnp.asarray(float(velocity)))
        traces = simulate(
            setup,
            t_end_s=t_sim,
            sample_interval_s=interval / args.oversample,
            contacts=options["contacts"],
            dt_s=options["dt_s"],
            progress=True,
        )
        forces = {name: np.asarray(traces.forces_n[name]) for name in traces.channel_names}
        if args.noise_fraction is not None:
            noise = {
                name: args.noise_fraction * float(np.max(np.abs(f))) for name, f in forces.items()
            }
        else:
            noise = (
                0.0
                if args.noise_std is None
                else parse_quantity(args.noise_std, "N", name="--noise-std")
            )
        setting = Acquisition(
            sample_interval_s=interval,
            record_length=record_length,
            trigger_delay_s=delay,
            trigger_jitter_s=jitter,
            bandwidth_hz=bandwidth,
            bandwidth_filter=args.bandwidth_filter,
            noise_std_n=noise,
            bits=args.bits,
            pre_trigger_samples=args.pre_trigger,
            coupling=args.coupling,
        )
        truth = {name: float(getattr(setup, name)) for name in TRUTH_FIELDS}
        truth["sensor_beads"] = ",".join(str(b) for b in setup.sensor_beads) or "none"
        if args.noise_fraction is not None:
            truth["noise_fraction"] = args.noise_fraction
        trace = record_simulation(setup, traces, setting, seed=args.seed + index, truth=truth)
        validate_header(trace.header, "synth")
        path = out / f"synth_v{velocity:.4g}.csv"
        write_trace(path, trace)
        _plot(trace, path.with_suffix(".png"))
        listing.append(
            {
                "file": path.name,
                "striker_velocity_m_s": float(velocity),
                "seed": args.seed + index,
                "noise_std_n": trace.header["noise_std_n"],
                "channels": list(trace.channels),
                "truth": truth,
            }
        )
        progress.advance(1)
    write_json(out / "synth.json", {"files": listing})
    print(f"wrote {counted(len(listing), 'trace file')}, their plots and synth.json to {out}")
    return 0
