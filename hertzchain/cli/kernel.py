"""`hertzchain kernel`: build the fused C++ kernel for this machine now, and say whether it runs.

The kernel (`hertzchain.native`) is compiled on its first use, once per machine, source and
JAX version (under a minute on two cores). Run this after installing, so that the first fit or
sweep does not wait for it; it also says why the kernel cannot be used where it cannot
(no compiler, `HERTZCHAIN_NATIVE=0`), in which case every command runs the JAX kernel (exit
status 0 either way: the README's install command goes on). `--all` also builds the libraries
that are otherwise built on their first use, 14-20 s each on two cores: the dashpot's, the
compliant sensor beads' and those of the other contact laws, which diagnoses and
elastic-plastic or power-law runs call. `--prune` deletes the cached libraries that newer
builds have superseded (every update of hertzchain or JAX builds new ones; the cache keeps
the newest of each kind) and build folders left by killed builds.
"""

from __future__ import annotations

import argparse
import time

from .. import native


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="print nothing when the kernel is ready")
    parser.add_argument("--all", action="store_true",
                        help="also build the libraries built on first use (the dashpot's, the compliant sensors', "
                             "the other contact laws')")
    parser.add_argument("--prune", action="store_true",
                        help="delete the cached libraries that newer builds of the same kind superseded")


def run(args: argparse.Namespace) -> int:
    began = time.perf_counter()
    if args.prune:
        deleted, freed = native.prune_cache()
        print(f"hertzchain kernel: pruned {deleted} superseded files ({freed / 2**20:.1f} MiB) "
              f"from {native.cache_dir()}")
    reason = native.unavailable_reason()
    if reason == native.SWITCHED_OFF:
        print(f"hertzchain kernel: the fused C++ kernel cannot be used ({reason}); "
              "every command runs the JAX kernel instead.")
    elif reason is not None:
        # the build's failure was announced on stderr with its first line: here is all of it
        print(f"hertzchain kernel: why the fused C++ kernel could not be built, in full:\n{reason}")
    if reason is not None:
        return 0  # not an error: everything runs, on the JAX kernel
    if not args.quiet:
        print(f"hertzchain kernel: ready ({native.library_path()}; {time.perf_counter() - began:.1f} s)")
    if args.all:
        for name, path, seconds in native.load_on_demand_libraries():
            if not args.quiet:
                print(f"hertzchain kernel: {name} library ready ({path}; {seconds:.1f} s)", flush=True)
    return 0
