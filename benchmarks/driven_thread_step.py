"""Instruction counts of the driven lock-in kernel and of the thread kernel's host emulation under callgrind.

Wall-clock timings on a shared machine are noise; the instructions a fixed run executes are
not. `driven_thread_step_driver.cc` runs one block of 16 driven lock-in runs
(`hertzchain/kernels/csrc/driven_kernel.cc`: two damped beads, 1000 steps, two harmonics;
the tangent along four directions) and 8 chains of the one-thread-per-chain kernel's host
emulation (`chain_kernel_thread.cu` built with HC_HOST_EMULATION, HC_ROWS=12: damped, with
friction, 4000 steps; the tangent along three directions), each forward and with its
tangents. This script builds the driver against the kernel sources in `--sources`
(default: this tree's), counts each run's instructions with `valgrind --tool=callgrind`
(collected inside `main`) and stores them under `--label` in
`benchmarks/results/native_step/driven_and_thread.json`, with every label's ratio to
`--baseline`.

The driven kernel is built as its library is, for x86-64-v3 (valgrind does not execute
AVX-512); the emulation with the emulated library's flags (-O1).

    python benchmarks/driven_thread_step.py --sources /path/to/old/csrc --label before
    python benchmarks/driven_thread_step.py --label after
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
DRIVER = HERE / "driven_thread_step_driver.cc"
RESULT = HERE / "results" / "native_step" / "driven_and_thread.json"
RUNS = ("forward", "tangent")
FLAGS = {
    "driven": (
        "-march=x86-64-v3",
        "-O3",
        "-ffp-contract=off",
        "-fno-math-errno",
        "-fno-trapping-math",
        "-std=c++17",
        "-pthread",
        "-DHC_DRIVEN_RUN",
    ),
    "thread": (
        "-x",
        "c++",
        "-DHC_HOST_EMULATION",
        "-DHC_ROWS=12",
        "-O1",
        "-ffp-contract=off",
        "-fno-math-errno",
        "-std=c++17",
        "-DHC_THREAD_RUN",
    ),
}


def build(kernel: str, sources: Path, output: Path) -> None:
    """Compile the driver of `kernel` ("driven" or "thread") against `sources` into `output`."""
    compiler = shutil.which("g++") or shutil.which("c++")
    if compiler is None:
        raise SystemExit("driven_thread_step: no C++ compiler (g++) on PATH")
    subprocess.run(
        [
            compiler,
            *FLAGS[kernel],
            f"-I{jax.ffi.include_dir()}",
            f"-I{sources}",
            str(DRIVER),
            "-o",
            str(output),
        ],
        check=True,
    )


def instructions(driver: Path, run: str, scratch: Path) -> tuple[int, str]:
    """The instructions `driver run` executes inside `main`, and what it printed (a checksum)."""
    out = scratch / f"callgrind.{driver.name}.{run}"
    proc = subprocess.run(
        [
            "valgrind",
            "--tool=callgrind",
            f"--callgrind-out-file={out}",
            "--toggle-collect=main",
            str(driver),
            run,
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    collected = re.search(r"Collected : (\d+)", proc.stderr)
    if collected is None:
        raise SystemExit(f"driven_thread_step: no count in callgrind's output:\n{proc.stderr}")
    return int(collected.group(1)), proc.stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--sources",
        type=Path,
        default=HERE.parent / "hertzchain" / "kernels" / "csrc",
        help="folder holding driven_kernel.cc, chain_kernel_thread.cu and their headers",
    )
    parser.add_argument(
        "--label", required=True, help="the key the counts are stored under (e.g. before, after)"
    )
    parser.add_argument(
        "--baseline", default="before", help="the label the ratios are taken against"
    )
    args = parser.parse_args()
    if shutil.which("valgrind") is None:
        raise SystemExit("driven_thread_step: valgrind is not on PATH (apt-get install valgrind)")
    stored = json.loads(RESULT.read_text()) if RESULT.exists() else {}
    counts = {}
    with tempfile.TemporaryDirectory() as tmp:
        scratch = Path(tmp)
        for kernel in FLAGS:
            driver = scratch / f"{kernel}_driver"
            build(kernel, args.sources.resolve(), driver)
            for run in RUNS:
                count, checksum = instructions(driver, run, scratch)
                counts[f"{kernel}_{run}"] = {"instructions": count, "checksum": checksum}
                print(f"{args.label} {kernel} {run}: {count} instructions (checksum {checksum})")
    stored.setdefault("labels", {})[args.label] = counts
    stored["flags"] = {kernel: list(flags) for kernel, flags in FLAGS.items()}
    base = stored["labels"].get(args.baseline)
    if base:
        stored["ratios_to_" + args.baseline] = {
            label: {
                run: c[run]["instructions"] / base[run]["instructions"] for run in c if run in base
            }
            for label, c in stored["labels"].items()
        }
    RESULT.parent.mkdir(parents=True, exist_ok=True)
    RESULT.write_text(json.dumps(stored, indent=2) + "\n")


if __name__ == "__main__":
    main()
