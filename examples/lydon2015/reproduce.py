"""Every Lydon et al. result of the README, in one command:

    python examples/lydon2015/reproduce.py --data-root ../shared/data/real [--out examples/lydon2015/results]
        [--only NAME ...] [--dry-run]

runs `hertzchain fit` on the single- and two-bead bending files and on the joint file of the
single bead's bending, tongue and loop, `hertzchain diagnose` on the joint file and on the
two-bead bending file, and the lab's scripts (`SCRIPTS`: the 2014 band edge, the two beads'
end compliance, the tongue with the measured drive transfer and the micro-slip tongue by
Floquet multipliers, these two from the stored `results/single_bead_diagnosis_laws` inputs),
each into its own folder under `--out`, and writes `summary.json`: the acceptance numbers of each, the wall time of each command (with the
machine's load average at the start: timings from a loaded machine are marked so) and the
command lines. `--only` runs the named ones (`JOBS`, `SCRIPTS`) and keeps the other entries of
an existing `summary.json` as they are; `--dry-run` prints the command lines and runs nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from hertzchain.io.atomic import write_json

HERE = Path(__file__).resolve().parent


JOBS = {
    "single_bead_fit": ("fit", HERE / "single_bead_bending.toml"),
    "two_bead_fit": ("fit", HERE / "two_bead_bending.toml"),
    "single_bead_joint": ("fit", HERE / "single_bead_joint.toml"),
    "single_bead_joint_diagnosis": ("diagnose", HERE / "single_bead_joint.toml"),
    "two_bead_bending_diagnosis": ("diagnose", HERE / "two_bead_bending.toml"),
}


# The lab's scripts: name -> (script, its arguments from (data root, output folder)).
SCRIPTS = {
    "lydon2014_band_edge": ("lydon2014_band_edge.py",
                            lambda data, out: ["--data-dir", str(data / "lydon-2014"), "--out", str(out)]),
    "lydon2014_static_exponent": ("lydon2014_static_exponent.py",
                                  lambda data, out: ["--data-dir", str(data / "lydon-2014"), "--out", str(out)]),
    "two_bead_end_compliance": ("two_bead_end_compliance.py",
                                lambda data, out: ["--data-dir", str(data / "lydon-2015"), "--out", str(out)]),
    "tongue_drive_transfer": ("tongue_drive_transfer.py",
                              lambda data, out: ["--data-dir", str(data / "lydon-2015"), "--results",
                                                 str(HERE / "results" / "single_bead_diagnosis_laws"), "--out", str(out)]),
    "micro_slip_floquet_tongue": ("micro_slip_floquet_tongue.py",
                                  lambda data, out: ["--data-dir", str(data / "lydon-2015"), "--results",
                                                     str(HERE / "results" / "single_bead_diagnosis_laws"), "--out",
                                                     str(out)]),
}


def _run(command: list[str]) -> float:
    began = time.perf_counter()
    print("$ " + " ".join(command), flush=True)
    subprocess.run(command, check=True)
    return time.perf_counter() - began


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data-root", required=True, type=Path, help="folder holding lydon-2015/ and lydon-2014/")
    parser.add_argument("--out", type=Path, default=HERE / "results")
    parser.add_argument("--only", action="append", default=[], metavar="NAME",
                        help="run only this one (repeatable); the summary keeps the others' entries")
    parser.add_argument("--dry-run", action="store_true", help="print the command lines, run nothing")
    args = parser.parse_args(argv)
    python = sys.executable
    data_2015 = str(args.data_root / "lydon-2015")
    summary = {"cpu_count": os.cpu_count(), "load_average_at_start": os.getloadavg()[0], "runs": {}}
    names = list(JOBS) + list(SCRIPTS)
    unknown = sorted(set(args.only) - set(names))
    if unknown:
        parser.error(f"--only: unknown {', '.join(unknown)} (choose from {', '.join(names)})")
    chosen = args.only or names
    lines = {name: [python, "-m", "hertzchain", command, str(toml), "--data-dir", data_2015, "--out",
                    str(args.out / name)] for name, (command, toml) in JOBS.items()}
    lines.update({name: [python, str(HERE / script), *arguments(args.data_root, args.out / name)]
                  for name, (script, arguments) in SCRIPTS.items()})
    if args.dry_run:
        for name in names:
            if name in chosen:
                print("$ " + " ".join(lines[name]))
        return {"commands": {name: lines[name][1:] for name in names if name in chosen}}
    previous = args.out / "summary.json"
    if args.only and previous.exists():  # the other entries as they were
        summary["runs"] = {k: v for k, v in json.loads(previous.read_text())["runs"].items() if k not in chosen}
    for name in names:
        if name not in chosen:
            continue
        load = os.getloadavg()[0]
        seconds = _run(lines[name])
        summary["runs"][name] = {"command": " ".join(lines[name][1:]), "wall_s": seconds, "load_average": load}
    for name in ("single_bead_fit", "two_bead_fit"):
        if name not in chosen:
            continue
        fit = json.loads((args.out / name / "fit.json").read_text())
        summary["runs"][name]["result"] = {
            "linear_resonance_hz": fit["params"]["linear_resonance_hz"],
            "precompression_n": fit["params"]["precompression_n"],
            "drive_scale": fit["params"]["drive_scale"],
            "damping_rate_per_s": fit["params"]["damping_rate_per_s"],
            "misfit_median": fit["misfit"]["median"],
            "misfit_max": fit["misfit"]["max"],
            "bending": fit["bending"],
        }
    summary["loaded_machine"] = summary["load_average_at_start"] > 0.5 * (os.cpu_count() or 1)
    write_json(args.out / "summary.json", summary)
    print(f"wrote {args.out / 'summary.json'}")
    return summary


if __name__ == "__main__":
    main()
