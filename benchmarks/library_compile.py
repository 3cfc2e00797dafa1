"""The cold build of each host kernel library, one at a time: compile seconds and the template
instances each holds.

    python benchmarks/library_compile.py --out benchmarks/results/library_compile/latest.json
                                         [--only chain,dashpot] [--label TEXT]

Every library that `hertzchain kernel --all` builds on this machine (`native.library_table`:
the main library "chain", the rate-slot laws', the compliant sensors', each other contact law's
with and without sensors, the driven chains') is compiled by `native.build._build`
into an empty temporary folder, one after another in this process. Measured per library: the
wall time, and the CPU seconds of the compiler processes (user + system of the children,
`resource.RUSAGE_CHILDREN`; the main library's two parts run at once, so its wall time is about
the larger part's CPU time on two idle cores); CPU seconds depend much less than wall time on
other work on the machine. From the built library (`nm -C -S`): the number of instances of the
block runs (`RunFullBlock<lanes, viscous, friction, tangent, extras, dashpot, books, law,
sensors>` and the conservative `RunBlock<lanes, preload, springs, books>`), each with its code
size, and the library's size.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

_INSTANCE = re.compile(r"^[0-9a-f]+ ([0-9a-f]+) [tTwW] (?:void )?(?:\(anonymous namespace\)::|hertzchain::)?"
                       r"(?P<name>RunFullBlock|RunBlock)<(?P<args>[^>]*)>\(")


def libraries() -> dict:
    """The host libraries of this machine by name (`hertzchain kernel --all`'s): (`-D` defines, source)."""
    from hertzchain import native

    return native.library_table()


def instances(path: Path) -> list[dict]:
    """The block runs' template instances in the library `path`: name, arguments, code bytes
    (with the instance's split-off parts, `[clone .cold]` and the like)."""
    listing = subprocess.run(["nm", "-C", "-S", str(path)], capture_output=True, text=True, check=True).stdout
    found: dict[tuple[str, str], int] = {}
    for line in listing.splitlines():
        match = _INSTANCE.match(line)
        if match:
            key = (match["name"], match["args"].replace("(hertzchain::Law)", "law "))
            found[key] = found.get(key, 0) + int(match.group(1), 16)
    return [{"name": name, "args": args, "bytes": size} for (name, args), size in sorted(found.items())]


def build_one(defines: tuple[str, ...], source: Path, folder: Path) -> dict:
    """Compile one library into `folder`: wall and compiler CPU seconds, its instances."""
    from hertzchain.native import build

    os.environ["HERTZCHAIN_CACHE"] = str(folder)
    path = build._library_path(defines, source)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = os.getloadavg()[0]
    began = time.perf_counter()
    build._build(path, defines, source)
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    found = instances(path)
    return {"library": path.name, "defines": list(defines), "wall_s": wall,
            "compiler_cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "load_average_1min_before": load, "load_average_1min_after": os.getloadavg()[0],
            "bytes": path.stat().st_size, "instances": len(found),
            "instance_bytes": sum(item["bytes"] for item in found), "instance_list": found}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="JSON output")
    parser.add_argument("--only", default="", help="comma-separated library names (main, dashpot, sensors, "
                                                   "power_law, ..., driven) [all]")
    parser.add_argument("--label", default="", help="what the machine was doing (e.g. 'quiet', 'loaded')")
    args = parser.parse_args(argv)
    from hertzchain.io.atomic import write_json
    from hertzchain.native import build

    table = libraries()
    names = [n.strip() for n in args.only.split(",") if n.strip()] or list(table)
    unknown = sorted(set(names) - table.keys())
    if unknown:
        parser.error(f"--only: unknown libraries {unknown}; choose from {', '.join(table)}")
    compiler = subprocess.run([build._cxx(), "--version"], capture_output=True, text=True, check=False).stdout
    result = {"label": args.label, "cpus": os.cpu_count(), "compiler": compiler.splitlines()[0] if compiler else None,
              "flags": list(build._flags()), "libraries": {}}
    for name in names:
        folder = Path(tempfile.mkdtemp(prefix="hertzchain-compile-"))
        try:
            result["libraries"][name] = build_one(*table[name], folder)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        one = result["libraries"][name]
        print(f"{name}: {one['wall_s']:.1f} s wall, {one['compiler_cpu_s']:.1f} s compiler CPU, "
              f"{one['instances']} instances", flush=True)
        write_json(args.out, result)
    result["compiler_cpu_s_total"] = sum(one["compiler_cpu_s"] for one in result["libraries"].values())
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
