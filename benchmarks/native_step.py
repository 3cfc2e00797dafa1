"""Instruction counts of the host kernels' step (`hertzchain/kernels/csrc/chain_kernel.cc`) under callgrind.

Wall-clock timings on a shared machine are noise; the instructions a fixed run executes are
not. `native_step_driver.cc` runs one block of 8 chains (20 bodies and a wall, 4000 steps,
two recorded contacts) through the conservative step, the full step (damped, with friction)
and the full step with its tangents along three directions (damping, friction, impact
speed: a fit iteration's value and jacfwd in one run). This script builds the driver against
the kernel sources in `--sources` (default: this tree's `hertzchain/`), counts each run's
instructions with `valgrind --tool=callgrind` (collected inside `main`) and stores them under
`--label` in `benchmarks/results/native_step/latest.json`, with the ratios of every label to
`--baseline` when both are there.

The driver is built for x86-64-v3 (AVX2 and FMA, without contraction as the library is
built): valgrind does not execute AVX-512, so these are the AVX2 build's counts.

    python benchmarks/native_step.py --sources /path/to/old/hertzchain --label before
    python benchmarks/native_step.py --label after
"""

import argparse
import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import jax

HERE = Path(__file__).resolve().parent
DRIVER = HERE / "native_step_driver.cc"
RESULT = HERE / "results" / "native_step" / "latest.json"
RUNS = ("conservative", "forward", "tangent")
FLAGS = ("-march=x86-64-v3", "-O3", "-ffp-contract=off", "-fno-math-errno", "-fno-trapping-math", "-std=c++17",
         "-pthread", "-DHC_PART=0")


def build(sources: Path, output: Path) -> None:
    """Compile the driver against the kernel sources in `sources` into `output`."""
    compiler = shutil.which("g++") or shutil.which("c++")
    if compiler is None:
        raise SystemExit("native_step: no C++ compiler (g++) on PATH")
    subprocess.run([compiler, *FLAGS, f"-I{jax.ffi.include_dir()}", f"-I{sources}", str(DRIVER), "-o", str(output)],
                   check=True)


def instructions(driver: Path, run: str, scratch: Path) -> tuple[int, str]:
    """The instructions `driver run` executes inside `main`, and what it printed (a checksum)."""
    out = scratch / f"callgrind.{run}"
    proc = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", "--toggle-collect=main",
                           str(driver), run], capture_output=True, text=True, check=True)
    collected = re.search(r"Collected : (\d+)", proc.stderr)
    if collected is None:
        raise SystemExit(f"native_step: no count in callgrind's output:\n{proc.stderr}")
    return int(collected.group(1)), proc.stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sources", type=Path, default=HERE.parent / "hertzchain" / "kernels" / "csrc",
                        help="folder holding chain_kernel.cc and its headers (default: this tree's hertzchain/kernels/csrc/)")
    parser.add_argument("--label", required=True, help="the key the counts are stored under (e.g. before, after)")
    parser.add_argument("--baseline", default="before", help="the label the ratios are taken against")
    args = parser.parse_args()
    if shutil.which("valgrind") is None:
        raise SystemExit("native_step: valgrind is not on PATH (apt-get install valgrind)")
    stored = json.loads(RESULT.read_text()) if RESULT.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        scratch = Path(tmp)
        driver = scratch / "native_step_driver"
        build(args.sources.resolve(), driver)
        counts = {}
        for run in RUNS:
            count, checksum = instructions(driver, run, scratch)
            counts[run] = {"instructions": count, "checksum": checksum}
            print(f"{args.label} {run}: {count} instructions (checksum {checksum})")
    stored.setdefault("labels", {})[args.label] = counts
    stored["flags"] = list(FLAGS)
    base = stored["labels"].get(args.baseline)
    if base:
        stored["ratios_to_" + args.baseline] = {
            label: {run: counts_[run]["instructions"] / base[run]["instructions"] for run in RUNS if run in counts_}
            for label, counts_ in stored["labels"].items()}
    RESULT.parent.mkdir(parents=True, exist_ok=True)
    RESULT.write_text(json.dumps(stored, indent=2) + "\n")


if __name__ == "__main__":
    main()
