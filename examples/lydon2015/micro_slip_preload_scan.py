"""Micro-slip at the supports with the contacts' static force scanned: the bending fit leaves
it undetermined, the tongue does not.

    python examples/lydon2015/micro_slip_preload_scan.py --data-dir ../shared/data/real/lydon-2015
        [--out examples/lydon2015/results/single_bead_diagnosis_laws] [--preloads 0.5 1 2 4.6]

With micro-slip doing the bending, the contacts' own softening matters little at any static
force above ~1 N, so the bending run's fit (`micro_slip_free_preload.json`) stays near where it
started. The tongue, however, needs a stiffness modulation at f of depth 4 zeta, which only the
contacts make, over a scale set by their static overlap (`stiffness_modulation.py`). So at each
static force of `--preloads` (N; the rest of the stated 4.5 N carried by the fixture in
parallel), with the bending fit's supports, damping and drive scale and the Hertz constant
rescaled so that the linear resonance stays the fitted one, this measures the bending (every
7th drive level, every frequency) and predicts the tongue and the loop by stepping the lab's
upward sweeps in time (`stepped_onsets`, `hertzchain.driven.thresholds.emulate_loop`, at the
calibration; `micro_slip_floquet_tongue.py` gives the same chains' Floquet thresholds). With
`--tongue-run-preloads` it also predicts the tongue and the loop for a tongue run of the same
apparatus (the Hertz constant of the first of `--preloads`, the bending run's) at its own
static force: the lab set the precompression anew for each run. Writes `NAME.json`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from run_record import started, write_stamped  # this folder's helper

from fitting.driven.candidates import (
    BoundedJointModel,
    bending_summary,
    fitted_levels,
    predict_thresholds,
    scores,
)
from fitting.driven.experiment import load_driven_experiment
from fitting.driven.joint import DRIVE_SCALE, JointParameter
from hertzchain import laws
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import normal_modes
from hertzchain.driven.thresholds import emulate_loop

HERE = Path(__file__).resolve().parent
SOURCE = "micro_slip_free_preload.json"
# The tongue's frequencies stepped in time by default (of the measured ones).
TONGUE_HZ = (6900.0, 7050.0, 7200.0, 7350.0, 7500.0, 7800.0)


def stepped_onsets(tongue_hz):
    """`predict_thresholds`' `onsets`: each threshold entry's onset going up (NaN: none) by
    stepping the lab's upward sweeps in time (`emulate_loop`): the loop's own amplitudes, the
    tongue's upward amplitudes at `tongue_hz` only (its other frequencies NaN)."""

    def onsets(predict, run):
        experiment, chain = predict.experiment, predict.start_chain
        steps, found = int(experiment.model["steps_per_period"]), []
        for m in run.measurements:
            if m.kind == "tongue":
                sweeps = [(f, m.data.drive_amplitudes_m) for f in m.data.frequencies_hz]
            else:
                sweeps = [(m.data.frequency_hz, m.data.drive_amplitudes_m)]
            for f, amplitudes in sweeps:
                onset = None
                if m.kind == "loop" or f in tongue_hz:
                    onset = emulate_loop(chain, f, amplitudes, bead=experiment.sensor_bead,
                                         steps_per_period=steps).onset_up_m
                found.append(np.nan if onset is None else onset)
        how = f"the lab's upward sweeps stepped in time (emulate_loop; tongue at {tuple(tongue_hz)} Hz only)"
        return np.array(found, dtype=float), how

    return onsets


def chain_at(constants: dict, precompression_n: float) -> DrivenChain:
    """The fitted micro-slip chain at `precompression_n`, its Hertz constant rescaled so that the
    linear resonance (supports included) is the fitted one."""
    support = laws.IwanSupport(constants["support_friction.stiffness_n_m"],
                               constants["support_friction.slip_displacement_m"])
    fitted = DrivenChain([0.028], constants["contact_kappa_n_m1p5"], constants["precompression_n"],
                         constants["damping_rate_per_s"], support_friction=support)
    target = float(normal_modes(fitted)[0][0])
    chain = eqx.tree_at(lambda c: c.precompression_n, fitted, jnp.asarray(float(precompression_n)))
    for _ in range(8):  # f0^2 = (2 k_c + K_s) / m: scale the contacts' stiffness, k_c ~ kappa^(2/3)
        contacts = (0.028 * (2 * math.pi * target) ** 2 - float(support.stiffness_n_m)) / 2
        now = float(chain.contact_stiffness_n_m()[0])
        chain = eqx.tree_at(lambda c: c.contact_kappa_n_m1p5, chain, chain.contact_kappa_n_m1p5 * (contacts / now) ** 1.5)
    return chain


def measured_drive_scale(folder: Path, resonance_hz: float) -> float:
    """The tongue run's drive scale its sub-threshold fundamental gives for a linear resonance
    `resonance_hz` (`drive_response.json#runs.tongue.by_resonance`, interpolated in log f0)."""
    rows = json.loads((folder / "drive_response.json").read_text())["runs"]["tongue"]["by_resonance"]
    f0 = np.log([r["resonance_hz"] for r in rows])
    return float(np.exp(np.interp(math.log(resonance_hz), f0, np.log([r["drive_scale"] for r in rows]))))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--out", default=str(HERE / "results" / "single_bead_diagnosis_laws"))
    parser.add_argument("--preloads", type=float, nargs="+", default=[0.5, 1.0, 2.0, 4.6])
    parser.add_argument("--tongue-run-preloads", type=float, nargs="*", default=[],
                        help="N: predict the tongue and the loop with the Hertz constant of the chain at the first of "
                        "--preloads (the bending run's) and the tongue run's own static force, each of these")
    parser.add_argument("--tongue-hz", type=float, nargs="+", default=list(TONGUE_HZ),
                        help="the tongue's frequencies stepped in time (of the measured ones)")
    parser.add_argument("--measured-drive-scale", action="store_true",
                        help="predict the tongue run at the drive scale its own fundamental measures at the chain's "
                        "resonance (drive_response.json, interpolated in log f0) instead of the calibration")
    parser.add_argument("--name", default="micro_slip_preload_scan")
    args = parser.parse_args(argv)
    start = started()
    out_dir = Path(args.out)
    source = json.loads((out_dir / SOURCE).read_text())
    entry = next(c for c in source["candidates"] if c["name"] == "micro_slip_free_preload")
    constants = entry["constants"]
    experiment = load_driven_experiment(HERE / "single_bead_joint.toml", args.data_dir)
    bending_m = next(m for m in experiment.measurements if m.kind == "bending")
    shown = fitted_levels(bending_m, 0, 7)
    alone = dataclasses.replace(experiment, measurements=(shown,))
    rows = []
    for force in args.preloads:
        chain = chain_at(constants, force)
        model = BoundedJointModel(alone, chain, [JointParameter(DRIVE_SCALE, bending_m.run)],
                                  {bending_m.run: constants[DRIVE_SCALE]}, 1.0, bounds=(-np.inf, np.inf))
        row = {"name": f"micro_slip_preload_{force:g}N", "precompression_n": force,
               "contact_kappa_n_m1p5": float(chain.contact_kappa_n_m1p5[0]),
               "static_overlap_m": float(chain.static_overlap_m()[0]),
               "resonance_hz": float(normal_modes(chain)[0][0]),
               "bending": bending_summary(experiment, model, model.runs[0], shown, np.zeros(1), 0,
                                          int(shown.data.sweep.drive_amplitudes_m.size))}
        row.update(predict_thresholds(experiment, chain, False, onsets=stepped_onsets(tuple(args.tongue_hz))))
        row["scores"] = {k: v for k, (v, _) in scores(row).items()}
        rows.append(row)
        print(f"{force:g} N: bending {row['bending']['misfit_median']:.4f}, tip {row['tongue']['model_tip_m']}, "
              f"loop {row['loop']['model_onset_up_m']}", flush=True)
    tongue_rows = []
    bending_chain = chain_at(constants, args.preloads[0])
    for force in args.tongue_run_preloads:  # the same apparatus (Hertz constant, supports), its own static force
        chain = eqx.tree_at(lambda c: c.precompression_n, bending_chain, jnp.asarray(float(force)))
        f0 = float(normal_modes(chain)[0][0])
        scale = measured_drive_scale(out_dir, f0) if args.measured_drive_scale else 1.0
        row = {"tongue_run_precompression_n": force, "bending_run_precompression_n": args.preloads[0],
               "static_overlap_m": float(chain.static_overlap_m()[0]), "resonance_hz": f0, "drive_scale": scale}
        row.update(predict_thresholds(experiment, chain, False, scale, onsets=stepped_onsets(tuple(args.tongue_hz))))
        tongue_rows.append(row)
        print(f"tongue run at {force:g} N: f0 {row['resonance_hz']:.0f} Hz, tip {row['tongue']['model_tip_m']} "
              f"at {row['tongue']['model_tip_hz']}, loop {row['loop']['model_onset_up_m']}", flush=True)
    write_stamped(out_dir / f"{args.name}.json", {
        "why": __doc__.splitlines()[0], "source": f"{SOURCE}#candidates.1.constants", "rows": rows,
        "tongue_run_rows": tongue_rows, "bending_levels": "every 7th drive level (6), every frequency"}, start)


if __name__ == "__main__":
    main()
