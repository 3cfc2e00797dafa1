"""Wall time of the default test suite as CI runs it: `.ci/run` on a clean clone.

    python benchmarks/default_suite.py [--cold] [--label TEXT] [--out DIR]

Clones this checkout's HEAD into a scratch folder with `../shared` beside it (a link to this
checkout's), then runs `bash .ci/run` there with `CI=true`, timing the whole command and its
parts: the environment's install, the kernel libraries' builds before the tests (the line
"kernel libraries ready in N s" that `tests/conftest.py` prints), the tests (pytest's own
"N passed ... in T s") and the documentation build. `--cold`: `HERTZCHAIN_CACHE` a fresh
folder (every kernel library compiled, as on a fresh machine); otherwise the user's cache.
Writes `OUT/<label>.json` (default `benchmarks/results/default_suite/`), whole or not at all,
with the commit, the machine (cores, CPU model, load before) and the command's exit status.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results" / "default_suite"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def parse_log(text: str) -> dict:
    """The parts of a `.ci/run` log: the kernel libraries' time (s), pytest's counts and time (s)."""
    parts: dict = {}
    ready = re.search(r"kernel libraries ready in (\d+) s", text)
    parts["kernel_libraries_s"] = float(ready.group(1)) if ready else None
    # pytest's last line: "[N failed, ]N passed[, N skipped]... in T s"
    summary = [line for line in text.splitlines() if re.search(r"\d+ (passed|failed).* in [0-9.]+s", line)]
    if summary:
        line = summary[-1]
        for word in ("passed", "failed", "skipped"):
            count = re.search(rf"(\d+) {word}", line)
            parts[word] = int(count.group(1)) if count else 0
        parts["pytest_s"] = float(re.search(r" in ([0-9.]+)s", line).group(1))
    docs = re.search(r"Documentation built in ([0-9.]+) seconds", text)
    parts["docs_build_s"] = float(docs.group(1)) if docs else None
    return parts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cold", action="store_true", help="a fresh HERTZCHAIN_CACHE: every kernel library built")
    parser.add_argument("--label", default=None, help="result file name (default: cold or warm)")
    parser.add_argument("--out", type=Path, default=RESULTS, help=f"output folder (default {RESULTS})")
    args = parser.parse_args(argv)
    label = args.label or ("cold" if args.cold else "warm")
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                            check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="hertzchain-suite-") as scratch:
        scratch = Path(scratch)
        subprocess.run(["git", "clone", "-q", str(ROOT), str(scratch / "ci")], check=True)
        (scratch / "shared").symlink_to((ROOT.parent / "shared").resolve())
        env = dict(os.environ, CI="true")
        env.pop("PYTHONPATH", None)
        env.pop("VIRTUAL_ENV", None)
        if args.cold:
            env["HERTZCHAIN_CACHE"] = str(scratch / "cache")
        load_before = os.getloadavg()
        began = time.perf_counter()
        proc = subprocess.run(["bash", ".ci/run"], cwd=scratch / "ci", env=env, capture_output=True, text=True)
        wall = time.perf_counter() - began
        log = proc.stdout + proc.stderr
    parts = parse_log(log)
    build = parts.get("kernel_libraries_s") or 0.0
    result = {
        "commit": commit,
        "cache": "cold" if args.cold else "warm",
        "exit_status": proc.returncode,
        "ci_run_wall_s": round(wall, 1),
        "default_suite_s": round(build + parts["pytest_s"], 1) if "pytest_s" in parts else None,
        **parts,
        "machine": {"cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
                    "cpu": _cpu_model(), "load_before": [round(x, 2) for x in load_before]},
        "log_tail": log[-3000:],
    }
    args.out.mkdir(parents=True, exist_ok=True)
    target = args.out / f"{label}.json"
    partial = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    partial.write_text(json.dumps(result, indent=1))
    os.replace(partial, target)
    print(f"{target}: exit {proc.returncode}, .ci/run {wall:.0f} s, kernel libraries {parts.get('kernel_libraries_s')} s, "
          f"pytest {parts.get('pytest_s')} s ({parts.get('passed')} passed, {parts.get('failed')} failed)")
    return proc.returncode


if __name__ == "__main__":
    raise SystemExit(main())
