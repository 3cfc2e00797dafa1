"""The diagnosis on held-out plasticity data: the paper's chain with beads of 1.8 GPa
integrated by the independent integrator of `tests/test_contact_plasticity_diagnosis.py`
(only the two fastest of four shots cross the yield force); the result and its time.

    python benchmarks/plasticity_diagnosis.py [--out benchmarks/results/plasticity_diagnosis]

Writes `diagnosis.json` (named effects, fitted yield stress with its standard error, time).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

from fitting.diagnosis import diagnose
from hertzchain import atomic

TEST = Path(__file__).resolve().parents[1] / "tests" / "test_contact_plasticity_diagnosis.py"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="benchmarks/results/plasticity_diagnosis")
    args = parser.parse_args(argv)
    spec = importlib.util.spec_from_file_location("held_out", TEST)
    held_out = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(held_out)
    began = time.perf_counter()
    files = held_out.held_out_records()
    generated = time.perf_counter() - began
    diagnosis = diagnose(files, progress=True)
    elapsed = time.perf_counter() - began - generated
    result = {"true_yield_stress_pa": held_out.TRUE_YIELD_STRESS_PA, "velocities_m_s": held_out.VELOCITIES_M_S,
              "missing_effects": diagnosis.missing_effects, "conclusion": diagnosis.conclusion,
              "diagnosis_s": elapsed, "generation_s": generated,
              "timing_note": "shared 2-core machine under load"}
    if diagnosis.steps and diagnosis.steps[0].effect == "plasticity":
        step = diagnosis.steps[0]
        y, dy = step.values["yield_softening"], step.stderr["yield_softening"]
        result["fitted_yield_stress_pa"] = 2e9 / y
        result["fitted_yield_stress_stderr_pa"] = 2e9 * dy / y**2
    atomic.write_json(Path(args.out) / "diagnosis.json", atomic.json_ready(result))
    print(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
