"""Build variants of the one-thread-per-chain CUDA kernel, timed side by side on one GPU.

    python benchmarks/gpu_variants.py --out gpu_variants.json [--size 100000]
        [--variant NAME=FLAGS ...] [--cache-root DIR [--build-only]]

Each variant is the kernel of `hertzchain/kernels/csrc/chain_kernel_thread.cu` built with extra flags
(`native.THREAD_FLAGS_VARIABLE`) into a cache of its own; the builds run in parallel, then
each variant runs in a child process of its own: `gpu_kernel.py`'s `item_kernel_alone` (the
kernel jitted alone on the bench case, N = 21, f64, 2500 steps, three forces every step),
conservative and damped (eta = 2 us, mu = 0.19), and the registers and local memory of its
functions (`cuobjdump --dump-resource-usage`). The plain one-thread-per-chain CUDA kernel of
`gpu_kernel.py` is timed in the same run, so every variant has its ratio to it. The JSON is
rewritten after each item. Default variants:

- `default`: the build `native` makes (the square root in contact only, no fused
  multiply-adds);
- `always_root`: the square root at every contact (`-DHC_ALWAYS_ROOT`, the build before);
- `registers_168`, `registers_128`: at least 3 or 4 blocks of 128 threads resident per
  multiprocessor (`__launch_bounds__`), which caps a thread's registers at 168 or 128
  (the default build's conservative kernel uses 210; capped, it spills to local memory);
- `threads_64`: 64 threads a block (128 by default);
- `fused_multiply_add`: contraction into fused multiply-adds allowed (nvcc's default; the
  numbers then differ from the JAX kernel's at round-off, so `native` does not build it).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT = Path(__file__).resolve().parent.parent
ROWS = 23  # the bench chain: 21 beads, the striker and the wall's row
VARIANTS = {
    "default": "",
    "always_root": "-DHC_ALWAYS_ROOT",
    "registers_168": "-DHC_MIN_BLOCKS_PER_SM=3",
    "registers_128": "-DHC_MIN_BLOCKS_PER_SM=4",
    "threads_64": "-DHC_THREADS_PER_BLOCK=64",
    "fused_multiply_add": "--fmad=true",
}

_BUILD = "from hertzchain import native; native._thread_library('cuda', {rows})"
_TIME = r"""
import json, sys
sys.path.insert(0, "benchmarks")
import jax
jax.config.update("jax_enable_x64", True)
from gpu_kernel import item_kernel_alone
row = {{kind: item_kernel_alone({size}, kind == "damped", {repeats}) for kind in ("conservative", "damped")}}
print("RESULT " + json.dumps(row))
"""


def _environment(flags: str, cache: Path) -> dict:
    from hertzchain import native

    return dict(os.environ, HERTZCHAIN_CACHE=str(cache), **{native.THREAD_FLAGS_VARIABLE: flags},
                PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _resource_usage(cache: Path) -> str:
    """Registers, stack and local memory of each function of the variant's library."""
    libraries = sorted(cache.glob(f"chain_thread-cuda-r{ROWS}-*.so"))
    if not libraries:
        return "no library built"
    try:
        proc = subprocess.run(["cuobjdump", "--dump-resource-usage", str(libraries[-1])], capture_output=True,
                              text=True)
    except FileNotFoundError:
        return "cuobjdump not found"
    lines = [line.strip() for line in (proc.stdout + proc.stderr).splitlines() if "REG" in line or "Function" in line]
    return "\n".join(lines)[-3000:]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", help="output JSON file (needed unless --build-only)")
    parser.add_argument("--size", type=int, default=100_000, help="chains [100000]")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--variant", action="append", default=[],
                        help="NAME=FLAGS (extra build flags), instead of the default variants")
    parser.add_argument("--cache-root", type=Path,
                        help="the variants' build caches go to CACHE_ROOT/NAME [a new temporary folder]")
    parser.add_argument("--build-only", action="store_true",
                        help="build the variants into --cache-root and stop (to build them beside other work)")
    args = parser.parse_args(argv)
    variants = dict(v.split("=", 1) for v in args.variant) if args.variant else VARIANTS
    if args.build_only and args.cache_root is None:
        parser.error("--build-only needs --cache-root")
    if not args.build_only and args.out is None:
        parser.error("--out is needed (the JSON file to write)")

    start = time.perf_counter()
    workdir = args.cache_root or Path(tempfile.mkdtemp(prefix="hc_variants_"))
    result = {"size": args.size, "variants": {}}
    caches = {name: workdir / name for name in variants}
    print(f"building {len(variants)} variants in parallel", flush=True)
    builds = {name: subprocess.Popen([sys.executable, "-c", _BUILD.format(rows=ROWS)], cwd=ROOT,
                                     env=_environment(flags, caches[name]), stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
              for name, flags in variants.items()}
    for name, proc in builds.items():
        output, _ = proc.communicate(timeout=600)
        result["variants"][name] = {"flags": variants[name], "build_ok": proc.returncode == 0,
                                    "build_output": output[-1500:], "resources": _resource_usage(caches[name])}
    result["build_s"] = time.perf_counter() - start
    print(f"built in {result['build_s']:.0f} s", flush=True)
    if args.build_only:
        return 0 if all(row["build_ok"] for row in result["variants"].values()) else 1

    import jax

    jax.config.update("jax_enable_x64", True)
    from gpu_kernel import item_cuda, save_result

    result["device"] = str(jax.devices()[0])
    for kind in ("conservative", "damped"):
        try:
            result[f"plain_cuda_{kind}"] = item_cuda(args.size, kind == "damped", args.repeats, None)
        except Exception as error:  # noqa: BLE001 - each item fails on its own
            result[f"plain_cuda_{kind}"] = {"error": f"{type(error).__name__}: {error}"}
        print(f"plain {kind}: {result[f'plain_cuda_{kind}'].get('bead_steps_per_s')}", flush=True)
    save_result(result, args.out, start)
    for name, flags in variants.items():
        row = result["variants"][name]
        if not row["build_ok"]:
            continue
        proc = subprocess.run([sys.executable, "-c", _TIME.format(size=args.size, repeats=args.repeats)], cwd=ROOT,
                              env=_environment(flags, caches[name]), capture_output=True, text=True, timeout=300)
        lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
        if proc.returncode != 0 or not lines:
            row["error"] = proc.stderr[-2000:]
        else:
            row.update(json.loads(lines[-1][len("RESULT "):]))
            for kind in ("conservative", "damped"):
                plain = result[f"plain_cuda_{kind}"].get("bead_steps_per_s")
                ours = row[kind].get("bead_steps_per_s")
                if plain and ours:
                    row[f"{kind}_over_plain_cuda"] = ours / plain
        print(f"{name}: " + ", ".join(f"{kind} {row.get(kind, {}).get('bead_steps_per_s', 'error')} "
                                       f"({row.get(f'{kind}_over_plain_cuda', float('nan')):.3f}x)"
                                       for kind in ("conservative", "damped")), flush=True)
        save_result(result, args.out, start)
    print(f"wrote {args.out} ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
