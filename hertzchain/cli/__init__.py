"""The `hertzchain` command line: one subcommand per module.

Each subcommand module defines `add_arguments(parser)` and `run(args) -> int`. The
commands of the `fitting` package (fit, diagnose, design) are listed here too: the command
line is the one place where the two packages meet; `hertzchain` itself never imports
`fitting`.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from .. import __version__
from .errors import EXIT_CODES, input_error_text
from .warning_format import command_warnings

COMMANDS = {
    "simulate": ("hertzchain.cli.simulate", "simulate a chain (default: the paper's) and plot it"),
    "analyze": ("hertzchain.cli.analyze", "fit every pulse of trace files (cos^6, speed, restitution)"),
    "synth": ("hertzchain.cli.synth", "write synthetic experiment trace files from any setup"),
    "import": ("hertzchain.cli.import_experiment", "condition a lab's scope files (experiment.toml) into trace files"),
    "fit": ("fitting.cli.fit", "fit eta, mu, C (and more) to trace files"),
    "diagnose": ("fitting.cli.diagnose", "find and name the effect a model is missing"),
    "reproduce": ("hertzchain.cli.reproduce", "regenerate the paper's figures and numbers"),
    "sweep": ("hertzchain.cli.sweep", "sweep a grid of setups, streamed to disk, resumable"),
    "sensitivity": ("hertzchain.cli.sensitivity", "exact sensitivities of observables to parameters"),
    "design": ("fitting.cli.design", "predicted uncertainties and optimal experiment plans"),
    "contact": ("fitting.cli.contact", "calibrate the elastic-plastic contact law on force-approach curves"),
    "kernel": ("hertzchain.cli.kernel", "build the fused C++ kernel for this machine (once) and check it"),
}


# Commands that run on every CPU core as a JAX device by default: `fit` (a posterior's
# chains run as one group per device). Sweeps keep the devices the user gives them: with
# the cores exposed in each process, the two-process distributed sweep's table differed in
# its last digits from the one-process table (tests/test_sweep.py).
CORES_AS_DEVICES = ("fit",)


def expose_cpu_cores() -> None:
    """Let JAX see every CPU core this process may use as a device (`jax_num_cpu_devices`),
    so that work split over devices (the posterior's chains) uses them all. Only before
    JAX's first computation, and not where the user chose a device count
    (`--xla_force_host_platform_device_count` in `XLA_FLAGS`, `JAX_NUM_CPU_DEVICES`);
    elsewhere nothing changes. GPU runs are not affected."""
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", "") or \
            "JAX_NUM_CPU_DEVICES" in os.environ:
        return
    import jax

    try:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        jax.config.update("jax_num_cpu_devices", cores or 1)
    except RuntimeError:  # JAX already started (the command run from Python): keep its devices
        pass


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in CORES_AS_DEVICES:
        expose_cpu_cores()
    parser = argparse.ArgumentParser(
        prog="hertzchain",
        description="Differentiable simulation and fitting of 1-D Hertzian bead chains "
        "(Job, Melo, Sokolow, Sen, PRL 94, 178002, 2005).",
        epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"hertzchain {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = argv[0] if argv and argv[0] in COMMANDS else None
    module = None
    for name, (module_name, help_text) in COMMANDS.items():
        sub = commands.add_parser(name, help=help_text, description=help_text, epilog=EXIT_CODES,
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
        if name == chosen:  # import only the command that runs: start-up stays fast
            module = importlib.import_module(module_name)
            module.add_arguments(sub)
    args = parser.parse_args(argv)
    try:
        with command_warnings(args.command):
            return int(module.run(args) or 0)
    except (ValueError, OSError) as error:  # every input error of the library, and of the file system
        print(f"hertzchain {args.command}: error: {input_error_text(error)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
