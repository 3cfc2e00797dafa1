"""`hertzchain kernel`: build the fused C++ kernel for this machine now, and say whether it runs.

The kernel (`hertzchain.native`) is compiled on its first use, once per machine, source and
JAX version (under a minute on two cores). Run this after installing, so that the first fit or
sweep does not wait for it; it also says why the kernel cannot be used where it cannot
(no compiler, `HERTZCHAIN_NATIVE=0`), in which case every command runs the JAX kernel (exit
status 0 either way: the README's install command goes on).
"""

from __future__ import annotations

import argparse
import time

from .. import native


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="print nothing when the kernel is ready")


def run(args: argparse.Namespace) -> int:
    began = time.perf_counter()
    reason = native.unavailable_reason()
    if reason is not None:
        print(f"hertzchain kernel: the fused C++ kernel cannot be used ({reason}); "
              "every command runs the JAX kernel instead.")
        return 0  # not an error: everything runs, on the JAX kernel
    if not args.quiet:
        print(f"hertzchain kernel: ready ({native.library_path()}; {time.perf_counter() - began:.1f} s)")
    return 0
