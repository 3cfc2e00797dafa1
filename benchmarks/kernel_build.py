"""The cold first use of the fused kernels: how long until every library a first fit or
diagnosis needs is built, from an empty library cache.

    python -m benchmarks.kernel_build [--before TREE [--before-first-use]] [--out benchmarks/results/kernel_build]

"after": `hertzchain kernel` of this checkout, which builds those libraries
(`native.FIRST_USE_LIBRARIES`) several at once. "before" (with `--before`, a checkout of an
earlier version of hertzchain): its `hertzchain kernel`, which built the main library alone;
with `--before-first-use` also the rest one after another, as the first diagnosis met them
(that version's loaders, in one process). Each in a fresh process with `HERTZCHAIN_CACHE` pointed at an empty
temporary folder; wall-clock seconds of each step, the 1-minute load average before and
after each, the CPU count and the compiler. Writes `latest.json` into --out (after each step).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# The earlier version's loaders of the libraries after the main one, in the order a first
# diagnosis built them, and the driven chains' (a driven fit's).
_BEFORE_REST = r"""
import json, sys, time
from hertzchain import native
from hertzchain.driven import fused
steps = [("jackson_green compliant sensors", lambda: native._load_sensors("jackson_green")),
         ("dashpot", native._load_dashpot), ("compliant sensors", native._load_sensors),
         ("power_law", lambda: native._load_law("power_law")),
         ("jackson_green", lambda: native._load_law("jackson_green")), ("driven", fused._load)]
seconds = {}
for name, load in steps:
    began = time.perf_counter()
    load()
    seconds[name] = time.perf_counter() - began
print(json.dumps(seconds))
"""


def _load() -> float:
    return os.getloadavg()[0]


def _run(tree: Path, cache: Path, command: list[str]) -> dict:
    env = {**os.environ, "HERTZCHAIN_CACHE": str(cache), "PYTHONPATH": str(tree)}
    env.pop("HERTZCHAIN_NATIVE", None)
    load_before = _load()
    began = time.perf_counter()
    done = subprocess.run([sys.executable, *command], capture_output=True, text=True, env=env, cwd=tree)
    seconds = time.perf_counter() - began
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} in {tree} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    return {"wall_s": round(seconds, 1), "load_1min_before": round(load_before, 2),
            "load_1min_after": round(_load(), 2), "stdout": done.stdout, "stderr": done.stderr}


def _after(scratch: Path) -> dict:
    run = _run(ROOT, scratch / "after", ["-m", "hertzchain", "kernel"])
    libraries = {m["name"]: float(m["s"]) for m in re.finditer(r"\] (?P<name>[a-z_ ]+?) \((?P<s>\d+) s\)", run["stdout"])}
    return {"command": "hertzchain kernel", "wall_s": run["wall_s"], "load_1min_before": run["load_1min_before"],
            "load_1min_after": run["load_1min_after"], "library_ready_after_s": libraries,
            "libraries": len(libraries)}


def _before(tree: Path, scratch: Path, first_use: bool) -> dict:
    cache = scratch / "before"
    kernel = _run(tree, cache, ["-m", "hertzchain", "kernel"])
    result = {"command": "hertzchain kernel", "wall_s": kernel["wall_s"], "load_1min_before": kernel["load_1min_before"],
              "load_1min_after": kernel["load_1min_after"], "libraries": 1}
    if first_use:
        rest = _run(tree, cache, ["-c", _BEFORE_REST])
        seconds = json.loads(rest["stdout"].strip().splitlines()[-1])
        result |= {"then_one_after_another_s": {k: round(v, 1) for k, v in seconds.items()},
                   "then_load_1min": [rest["load_1min_before"], rest["load_1min_after"]],
                   "total_wall_s": round(kernel["wall_s"] + rest["wall_s"], 1), "libraries": 1 + len(seconds)}
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, help="a checkout of the earlier version to compare with")
    parser.add_argument("--before-first-use", action="store_true",
                        help="with --before: also build its other first-use libraries, one after another")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "kernel_build")
    args = parser.parse_args(argv)
    compiler = subprocess.run([os.environ.get("CXX") or "c++", "--version"], capture_output=True, text=True).stdout
    result = {"cpus": len(os.sched_getaffinity(0)), "machine": platform.machine(),
              "compiler": compiler.splitlines()[0] if compiler else None}
    args.out.mkdir(parents=True, exist_ok=True)

    def write():
        (args.out / "latest.json").write_text(json.dumps(result, indent=2) + "\n")

    with tempfile.TemporaryDirectory() as scratch:
        result["after"] = _after(Path(scratch))
        print(f"after: {result['after']['wall_s']} s", flush=True)
        write()
        if args.before is not None:
            result["before"] = _before(args.before.resolve(), Path(scratch), args.before_first_use)
            print(f"before: {result['before']['wall_s']} s", flush=True)
            write()
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
