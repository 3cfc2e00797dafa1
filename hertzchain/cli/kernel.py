"""`hertzchain kernel`: build the fused C++ kernels for this machine now, and say whether they run.

The kernels (`hertzchain.native`) are compiled once per machine, source and JAX version,
and kept in the library cache (`$HERTZCHAIN_CACHE`, else `~/.cache/hertzchain`). Run this
after installing: it builds every library a first fit or diagnosis needs
(`native.FIRST_USE_LIBRARIES`: the main one, the dashpot's, the compliant sensors', the
Jackson-Green and power-law contacts', Jackson-Green with compliant sensors, the driven
chains'), several at once over the CPU's cores, with a line as each is ready
(`[3/7] dashpot (61 s)`); `--all` builds every library (the Thornton law's, velocity-squared
dissipation's and the other laws' compliant sensors too). A cached library that does not match its build record
(truncated, emptied, changed) is said to be so and built again.

Exit status: 0 when every library asked for is built and loads, and when the kernels are
switched off on purpose (`HERTZCHAIN_NATIVE=0`: every command runs the JAX kernel);
`BUILD_FAILED` (4) when any of them could not be built or loaded (no compiler, a compiler
error): each failure is named with its whole message, and the runs it serves take the JAX
kernel, several times slower. `--prune` deletes the cached libraries that newer builds have
superseded (every update of hertzchain or JAX builds new ones; the cache keeps the newest of
each kind) and build folders left by killed builds.
"""

from __future__ import annotations

import argparse
import time

from .. import native
from ..units import counted

# The exit status where a library asked for could not be built or loaded.
BUILD_FAILED = 4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="print nothing but failures")
    parser.add_argument("--all", action="store_true",
                        help="build every library, not only those a first fit or diagnosis needs")
    parser.add_argument("--jobs", type=int, default=None,
                        help="libraries built at once (default: the CPU cores this process may use)")
    parser.add_argument("--prune", action="store_true",
                        help="delete the cached libraries that newer builds of the same kind superseded")


def run(args: argparse.Namespace) -> int:
    began = time.perf_counter()
    if args.prune:
        deleted, freed = native.prune_cache()
        print(f"hertzchain kernel: pruned {counted(deleted, 'superseded file')} ({freed / 2**20:.1f} MiB) "
              f"from {native.cache_dir()}")
    if native.registry.switched_off():
        print(f"hertzchain kernel: the fused C++ kernel cannot be used ({native.SWITCHED_OFF}); "
              "every command runs the JAX kernel instead.")
        return 0
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs must be a positive number of builds, got {args.jobs}.")
    names = tuple(native.library_table()) if args.all else native.FIRST_USE_LIBRARIES
    if native.build._cxx() is None:
        print("hertzchain kernel: no C++ compiler found (set CXX, or install g++): the fused kernels cannot be "
              "built, and every command runs the JAX kernel instead, several times slower.")
        return BUILD_FAILED
    if not args.quiet:
        print(f"hertzchain kernel: checking {counted(len(names), 'library', 'libraries')} in {native.cache_dir()} and building "
              f"those not there ({native.BUILD_TIME_NOTE} each, several at once)", flush=True)
    failed = []
    for done, (name, path, seconds, why) in enumerate(native.build_libraries(names, args.jobs), start=1):
        if why is not None:
            failed.append(name)
            print(f"hertzchain kernel: [{done}/{len(names)}] {name} FAILED ({seconds:.0f} s): {path} could not be "
                  f"built or loaded; those runs take the JAX kernel, several times slower. Why, in full:\n{why}",
                  flush=True)
        elif not args.quiet:
            print(f"hertzchain kernel: [{done}/{len(names)}] {name} ({seconds:.0f} s) {path}", flush=True)
    if failed:
        print(f"hertzchain kernel: {len(failed)} of {len(names)} libraries failed ({', '.join(failed)})",
              flush=True)
        return BUILD_FAILED
    if not args.quiet:
        print(f"hertzchain kernel: ready, {counted(len(names), 'library', 'libraries')} ({time.perf_counter() - began:.0f} s)")
    return 0
