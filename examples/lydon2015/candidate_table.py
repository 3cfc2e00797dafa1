"""Every candidate law of the single bead against every target, from the stored runs:

    python examples/lydon2015/candidate_table.py
        [--dir examples/lydon2015/results/single_bead_diagnosis_laws]

Reads each `diagnose_laws.py` result in the folder (`RESULTS`, in this order; a file not there
is skipped and said) and writes `table.json`: one row per candidate (the first time its name
appears), with where it is stored (`file#candidates.i`), what it was fitted on, its
precompression and drive scales, and per target of `fitting.driven.candidates.TARGETS` the
value and whether it is met (`scores`); a target it was fitted on is marked so. The
micro-slip scans of the contacts' static force (`SCANS`) add one row per static force.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fitting.driven.candidates import MEASURED_BY, TARGETS, scores
from hertzchain.io.atomic import json_ready, write_json

HERE = Path(__file__).resolve().parent
RESULTS = ("diagnosis.json", "micro_slip.json", "micro_slip_free_preload.json", "micro_slip_velocity_squared.json",
           "micro_slip_rayleigh_piezo.json", "micro_slip_actuator_mode.json", "micro_slip_segalman.json",
           "with_tongue.json")
# The micro-slip scans of the contacts' static force (`micro_slip_preload_scan.py`).
SCANS = ("micro_slip_preload_scan.json", "micro_slip_tongue_run_preload.json")


def rows(folder: Path) -> tuple[list, list]:
    table, missing, seen = [], [], set()
    for name in RESULTS:
        path = folder / name
        if not path.is_file():
            missing.append(name)
            continue
        for i, entry in enumerate(json.loads(path.read_text())["candidates"]):
            if entry["name"] in seen:
                continue
            seen.add(entry["name"])
            fitted_on = entry.get("fitted_on", ["bending"])
            values = {k: {"value": v, "met": met, "fitted": k not in MEASURED_BY or MEASURED_BY[k] in fitted_on}
                      for k, (v, met) in scores(entry).items()}
            tongue_run = entry.get("tongue_run", {})
            table.append({"name": entry["name"], "mechanism": entry["mechanism"], "stored": f"{name}#candidates.{i}",
                          "fitted_on": fitted_on, "converged": entry["converged"],
                          "precompression_n": entry["constants"]["precompression_n"],
                          "tongue_run_precompression_n": tongue_run.get("precompression_n"),
                          "drive_scale": entry["constants"]["drive_scale"],
                          "tongue_run_drive_scale": tongue_run.get("drive_scale"),
                          "targets": values, "met": sorted(k for k, v in values.items() if v["met"])})
    for name in SCANS:
        path = folder / name
        if not path.is_file():
            missing.append(name)
            continue
        scan = json.loads(path.read_text())
        for i, row in enumerate(scan["rows"]):
            table.append(_scan_row(row, f"{name}#rows.{i}", row["precompression_n"], None, row))
        for i, row in enumerate(scan.get("tongue_run_rows", [])):  # the bending run's row, this tongue run
            table.append(_scan_row({**scan["rows"][0], "tongue": row["tongue"], "loop": row["loop"]},
                                   f"{name}#tongue_run_rows.{i}", row["bending_run_precompression_n"],
                                   row["tongue_run_precompression_n"], row))
    return table, missing


def _scan_row(entry: dict, stored: str, precompression_n, tongue_run_precompression_n, row: dict) -> dict:
    """A table row of a micro-slip scan's entry (bending, tongue, loop; fitted on the bending)."""
    values = {k: {"value": v, "met": met, "fitted": k not in MEASURED_BY} for k, (v, met) in scores(entry).items()}
    return {"name": f"micro_slip_contacts_{precompression_n:g}N"
            + ("" if tongue_run_precompression_n is None else f"_tongue_run_{tongue_run_precompression_n:g}N"),
            "mechanism": "micro-slip supports, the contacts' static force set (the rest carried in parallel)",
            "stored": stored, "fitted_on": ["bending"], "converged": None, "precompression_n": precompression_n,
            "tongue_run_precompression_n": tongue_run_precompression_n, "drive_scale": None,
            "tongue_run_drive_scale": row.get("drive_scale"), "targets": values,
            "met": sorted(k for k, v in values.items() if v["met"])}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", default=str(HERE / "results" / "single_bead_diagnosis_laws"))
    args = parser.parse_args(argv)
    folder = Path(args.dir)
    table, missing = rows(folder)
    write_json(folder / "table.json", json_ready({"why": __doc__.splitlines()[0], "targets": TARGETS,
                                                  "candidates": table, "not_run": missing}))


if __name__ == "__main__":
    main()
