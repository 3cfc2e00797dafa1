"""The whole `hertzchain contact` command on Burgoyne & Daraio's 15 Caltech curves, as a user runs
it: cold (an empty compilation cache) and warm (the same command again).

    python -m benchmarks.contact_cli_time [--data PATH] [--out benchmarks/results/contact_burgoyne]

Runs `hertzchain contact` on the 15 curves with `--damping --approach-drift` in a fresh
process each time, with `HERTZCHAIN_CACHE` pointed at an empty temporary folder for the cold
run (nothing compiled is kept from earlier runs) and at the same folder for the warm one.
Wall-clock seconds of the whole process, the 1-minute load average before each run, and
whether the two runs wrote the same `contact.json` (elapsed times aside). Writes
`cli_time.json` into --out.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.contact_burgoyne import CALTECH, caltech_arguments
from hertzchain import atomic

FLAGS = ["--radius", "3.175mm", "--damping", "--approach-drift"]


def main(argv=None) -> int:
    _, data_dir, out, curves = caltech_arguments(argv, __doc__)
    if curves is None:
        return 1
    files = [str(data_dir / "ExperimentalData" / f"{c.name}.mat") for c in curves]
    materials = [arg for m, names in CALTECH.items() for _ in names for arg in ("--material", m.name)]
    runs, reports = {}, {}
    with tempfile.TemporaryDirectory() as scratch:
        env = {**os.environ, "HERTZCHAIN_CACHE": str(Path(scratch) / "cache")}
        env.pop("HERTZCHAIN_NO_COMPILE_CACHE", None)
        for label in ("cold", "warm"):
            folder = Path(scratch) / label
            command = [sys.executable, "-m", "hertzchain", "contact", *files, *materials, *FLAGS, "--out", str(folder)]
            load = os.getloadavg()[0]
            began = time.perf_counter()
            done = subprocess.run(command, capture_output=True, text=True, env=env)
            seconds = time.perf_counter() - began
            if done.returncode != 0:
                print(done.stdout + done.stderr, file=sys.stderr)
                return 1
            runs[label] = {"seconds": seconds, "load_average_1min_before": load}
            reports[label] = json.loads((folder / "contact.json").read_text())
            print(f"{label}: {seconds:.1f} s", file=sys.stderr)
    same = json.dumps(reports["cold"], sort_keys=True) == json.dumps(reports["warm"], sort_keys=True)
    result = {"command": "hertzchain contact <15 Caltech curves> " + " ".join(FLAGS), "curves": len(files),
              "runs": runs, "same_contact_json": same,
              "note": "wall clock of the whole process on this machine (2 cores); cold: empty HERTZCHAIN_CACHE"}
    atomic.write_json(out / "cli_time.json", atomic.json_ready(result))
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
