"""Whether the full kernel's tangent runs gain from blocks of 64 chains: the Jacobian of many
chains' recorded forces in 5 directions (eta, mu, striker speed, preload, Young's modulus) on
two source trees, alternately, each in a process of its own with its own kernel cache.

    python benchmarks/tangent_block_width.py --trees BEFORE AFTER --caches CACHE_B CACHE_A \
        [--chains 128,1024] [--repeats 7] [--out benchmarks/results/tangent_block_width]

Each process: `jax.jit(jax.jacfwd(...))` of `tests/helpers.recorded_forces` on a 21-bead chain
(striker speeds 0.1-1 m/s x walls of 3 and 400 GPa, 1 ms at 2 us), compiled and run once, then
timed `--repeats` times; the median and minimum per tree and batch. Also the compile time of
each tree's main library's tangent part (`chain_kernel.cc` with HC_PART=2, the build's flags,
one compiler alone, `--compile-defines` "" and HC_DASHPOT_LIBRARY). Writes `latest.json` whole.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

WORKER = r"""
import json, statistics, sys, time
import numpy as np, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, sys.argv[1] + "/tests")
import hertzchain as hc
from helpers import recorded_forces
speeds = list(np.linspace(0.1, 1.0, int(sys.argv[2]) // 2))
base, _ = hc.batch_setup(hc.ChainSetup(21), striker_velocity_m_s=speeds, wall_youngs_pa=[3e9, 4e11])
grid = hc.choose_time_grid(base, t_end_s=1.0e-3, sample_interval_s=2e-6)
q = jnp.asarray([2e-6, 0.19, 1.0, 1.0, 1.0])
f = jax.jit(jax.jacfwd(lambda q: recorded_forces(base, grid, q, "auto")))
jax.block_until_ready(f(q))
times = []
for _ in range(int(sys.argv[3])):
    began = time.perf_counter()
    jax.block_until_ready(f(q * 1.0001))
    times.append(time.perf_counter() - began)
print(json.dumps({"chains": int(base.eta_s.shape[0]), "times_s": times}))
"""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trees", nargs=2, required=True, metavar=("BEFORE", "AFTER"), help="two source trees")
    parser.add_argument("--caches", nargs=2, required=True, metavar=("CACHE_B", "CACHE_A"),
                        help="each tree's HERTZCHAIN_CACHE (its kernel libraries)")
    parser.add_argument("--chains", default="128,1024", help="batch sizes, comma-separated [128,1024]")
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per process [7]")
    parser.add_argument("--rounds", type=int, default=2, help="processes per tree and batch, alternating [2]")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/tangent_block_width"))
    args = parser.parse_args(argv)
    from hertzchain.io.atomic import write_json
    from hertzchain.native import build

    names = ("before", "after")
    results = {name: {} for name in names}
    compile_s = {name: {} for name in names}
    for name, tree in zip(names, args.trees):
        source = Path(tree).resolve() / "hertzchain" / "kernels" / "csrc" / "chain_kernel.cc"
        for library, defines in (("chain", ()), ("dashpot", ("-DHC_DASHPOT_LIBRARY",))):
            command = [build._cxx(), *build._flags(), *defines, f"-I{build.jax.ffi.include_dir()}", "-DHC_PART=2",
                       "-c", "-o", os.devnull, str(source)]
            began = time.perf_counter()
            subprocess.run(command, check=True, capture_output=True)
            compile_s[name][library] = time.perf_counter() - began
            print(name, library, f"tangent part compiled in {compile_s[name][library]:.1f} s", file=sys.stderr)
    for chains in (int(c) for c in args.chains.split(",")):
        for _ in range(args.rounds):
            for name, tree, cache in zip(names, args.trees, args.caches):
                env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()), HERTZCHAIN_CACHE=str(Path(cache).resolve()))
                done = subprocess.run([sys.executable, "-c", WORKER, str(Path(tree).resolve()), str(chains),
                                       str(args.repeats)], env=env, capture_output=True, text=True, check=True)
                record = json.loads(done.stdout.strip().splitlines()[-1])
                results[name].setdefault(str(record["chains"]), []).extend(record["times_s"])
                print(name, record["chains"], f"{statistics.median(record['times_s']):.4f} s", file=sys.stderr)
    summary = {n: {c: {"median_s": statistics.median(t), "min_s": min(t), "runs": len(t)} for c, t in r.items()}
               for n, r in results.items()}
    ratio = {c: summary["after"][c]["median_s"] / summary["before"][c]["median_s"] for c in summary["before"]}
    write_json(args.out / "latest.json", {
        "trees": {n: str(Path(t).resolve()) for n, t in zip(names, args.trees)},
        "what": "jit(jacfwd) of recorded forces, 21 beads, 1 ms at 2 us, 5 directions",
        "cpus": os.cpu_count(), "load_average_at_end": list(os.getloadavg()), "finished_at": time.time(),
        "summary": summary, "after_over_before_median": ratio, "times_s": results,
        "tangent_part_compile_s": compile_s})
    print(json.dumps(ratio))
    return 0


if __name__ == "__main__":
    sys.exit(main())
