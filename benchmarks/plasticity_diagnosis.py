"""The diagnosis on held-out plasticity data: the paper's chain with beads of 1.8 GPa
integrated by the independent integrator of `tests/test_contact_plasticity_diagnosis.py`
(only the two fastest of four shots cross the yield force), over several noise draws of the
same shots: the fitted yield stress, its z-score (fitted - true) / sigma, and the time.

    python benchmarks/plasticity_diagnosis.py [--draws 0 1 2 3] [--add] [--out benchmarks/results/plasticity_diagnosis]

Writes `diagnosis.json` (per draw: named effects, fitted yield stress with its standard
error, z-score, time and the machine's 1-minute load average over it: min, mean, max; the mean z-score and its standard error over the draws: a bias shows as
a mean z several of its standard errors from 0). The file is rewritten after every draw;
`--add` keeps the draws an earlier run stored there (and their times) and adds these.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

from fitting.diagnosis import diagnose
from hertzchain import atomic

TEST = Path(__file__).resolve().parents[1] / "tests" / "test_contact_plasticity_diagnosis.py"
# Interval of the load-average samples stored with each draw's time, s.
LOAD_INTERVAL_S = 10.0


class _LoadSampler:
    """The machine's 1-minute load average every `LOAD_INTERVAL_S` while a draw runs."""

    def __init__(self):
        self.samples, self._done = [os.getloadavg()[0]], threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._done.wait(LOAD_INTERVAL_S):
            self.samples.append(os.getloadavg()[0])

    def stop(self) -> dict:
        self._done.set()
        self._thread.join()
        self.samples.append(os.getloadavg()[0])
        return {"load_average_1min_min": min(self.samples), "load_average_1min_mean": float(np.mean(self.samples)),
                "load_average_1min_max": max(self.samples), "load_average_samples": len(self.samples)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, nargs="+", default=[0, 1, 2, 3],
                        help="noise draws (seeds 4 draw + shot)")
    parser.add_argument("--add", action="store_true", help="keep the draws already stored in --out")
    parser.add_argument("--out", default="benchmarks/results/plasticity_diagnosis")
    parser.add_argument("--load-label", default="shared 2-core machine under load",
                        help="how loaded the machine was (stored with the times)")
    args = parser.parse_args(argv)
    spec = importlib.util.spec_from_file_location("held_out", TEST)
    held_out = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(held_out)
    began = time.perf_counter()
    runs = held_out.held_out_runs()
    result = {"true_yield_stress_pa": held_out.TRUE_YIELD_STRESS_PA, "velocities_m_s": held_out.VELOCITIES_M_S,
              "generation_s": time.perf_counter() - began, "timing_note": args.load_label, "draws": []}
    stored = Path(args.out) / "diagnosis.json"
    if args.add and stored.is_file():
        result["draws"] = [d for d in json.loads(stored.read_text()).get("draws", []) if d["draw"] not in args.draws]
    for draw in args.draws:
        print(f"draw {draw} ...", file=sys.stderr, flush=True)
        began, load = time.perf_counter(), _LoadSampler()
        diagnosis = diagnose(held_out.held_out_records(draw, runs), progress=True)
        entry = {"draw": draw, "missing_effects": diagnosis.missing_effects, "conclusion": diagnosis.conclusion,
                 "diagnosis_s": time.perf_counter() - began, "cpu_count": os.cpu_count(), **load.stop()}
        if diagnosis.steps and diagnosis.steps[0].effect == "plasticity":
            step = diagnosis.steps[0]
            y, dy = step.values["yield_softening"], step.stderr["yield_softening"]
            entry["fitted_yield_stress_pa"] = 2e9 / y
            entry["fitted_yield_stress_stderr_pa"] = 2e9 * dy / y**2
            entry["z_score"] = (entry["fitted_yield_stress_pa"] - held_out.TRUE_YIELD_STRESS_PA) / \
                entry["fitted_yield_stress_stderr_pa"]
        entry["timing_note"] = args.load_label
        result["draws"].append(entry)
        result["draws"].sort(key=lambda d: d["draw"])
        z = [d["z_score"] for d in result["draws"] if "z_score" in d]
        if z:
            result["mean_z_score"] = float(np.mean(z))
            result["mean_z_score_stderr"] = 1.0 / math.sqrt(len(z))  # z of an unbiased fit: unit variance
        atomic.write_json(Path(args.out) / "diagnosis.json", atomic.json_ready(result))
        print(entry, file=sys.stderr, flush=True)
    print(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
