"""Two beads (2013-07-05) with the single bead's micro-slip constants: the same apparatus, so
the same contacts, supports and damping; the run's own precompression and drive calibration.

    python examples/lydon2015/two_bead_prediction.py --data-dir ../shared/data/real/lydon-2015
        [--out examples/lydon2015/results/two_bead_micro_slip] [--level-stride 7] [--row-stride 3]

The face and wall contacts take the single bead's fitted Hertz constant (sphere on flat), the
bead-bead contact that over sqrt 2 (sphere on sphere, R* = R/2); each bead the fitted support
stiffness and slip displacement and viscous rate (`single_bead_diagnosis_laws/micro_slip.json`,
candidate `micro_slip_supports`). Fitted: only the run's precompression (started at the stated
3 N) and drive scale (calibration prior), on every `level-stride`-th drive level and every
`row-stride`-th frequency (affordable on 2 cores; the measures below use every frequency of the
fitted levels). Then predicted by stepping the lab's upward amplitude sweep in time
(`emulate_loop`, the tongue's 15-96 nm at its calibration): the period doubling near twice each
mode. Writes `prediction.json` with per mode the misfit, the shift and the peak per nm top over
lowest beside the data's, and the predicted onsets.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
from run_record import started, write_stamped  # this folder's helper

from fitting.driven.candidates import BoundedJointModel, fitted_levels
from fitting.driven.experiment import Measurement, load_driven_experiment
from fitting.driven.joint import DRIVE_SCALE, JointParameter
from fitting.driven.report import bending
from fitting.fit import least_squares
from hertzchain import laws
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import normal_modes
from hertzchain.driven.measurements import Bending
from hertzchain.driven.thresholds import emulate_loop

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "results" / "single_bead_diagnosis_laws" / "micro_slip.json"
TONGUE_AMPLITUDES_M = 7.517e-7 * np.arange(0.020, 0.1285, 0.003)  # the single bead's tongue sweep
FACTOR_BOUNDS = (math.log(0.05), math.log(20.0))


def single_bead_constants() -> dict:
    entry = next(c for c in json.loads(SOURCE.read_text())["candidates"] if c["name"] == "micro_slip_supports")
    return entry["constants"]


def two_bead_chain(constants: dict, precompression_n: float) -> DrivenChain:
    kappa = constants["contact_kappa_n_m1p5"][0]
    return DrivenChain([0.028, 0.028], [kappa, kappa / math.sqrt(2), kappa], precompression_n,
                       constants["damping_rate_per_s"][0],
                       support_friction=laws.IwanSupport(constants["support_friction.stiffness_n_m"],
                                                         constants["support_friction.slip_displacement_m"]))


def two_bead_fit_start(argv, description: str, out: str, level_stride: int, max_steps: int):
    """(arguments, `started()`, the two-bead bending experiment) of a script here that fits the
    two-bead bending sweep: `--data-dir` (required), `--out` (default `results/<out>`), the
    `--level-stride` and `--max-steps` given, `--row-stride` 3 (every third frequency)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--out", default=str(HERE / "results" / out))
    parser.add_argument("--level-stride", type=int, default=level_stride)
    parser.add_argument("--row-stride", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=max_steps)
    args = parser.parse_args(argv)
    start = started()
    return args, start, load_driven_experiment(HERE / "two_bead_bending.toml", args.data_dir)


def main(argv=None) -> None:
    args, start, experiment = two_bead_fit_start(argv, __doc__.splitlines()[0], "two_bead_micro_slip", 7, 15)
    run = "2013-07-05 11:24"
    rows = experiment.fit_mask & (np.arange(experiment.fit_mask.size) % args.row_stride == 0)
    full = Measurement("bending", run, Bending(run, experiment.sweep), experiment.drive_m_per_v,
                       experiment.drive_uncertainty, experiment.fit_mask, ())
    fitted = fitted_levels(dataclasses.replace(full, fit_mask=rows), 0, args.level_stride)
    joint = dataclasses.replace(experiment, measurements=(fitted,))
    constants = single_bead_constants()
    chain = two_bead_chain(constants, experiment.precompression_n)
    parameters = [JointParameter("precompression_n", None), JointParameter(DRIVE_SCALE, run)]
    bounds = (np.full(2, FACTOR_BOUNDS[0]), np.full(2, FACTOR_BOUNDS[1]))
    # the bending residuals' weight as the single bead's protocol (lag-1 correlation ~0.98)
    model = BoundedJointModel(joint, chain, parameters, {run: 1.0}, 0.1, True, bounds=bounds)
    result = least_squares(model, np.zeros(2), [0, 1], max_steps=args.max_steps, bounds=bounds)
    x = model.clip(result.x)
    fitted_chain = model.run_chain(model.runs[0], x)
    scale = model.run_scale(model.runs[0], x)
    shown = dataclasses.replace(fitted, fit_mask=experiment.fit_mask)
    curves = model.bending_curves(model.runs[0], shown, x, np.arange(experiment.fit_mask.size))
    data = shown.data.sweep.rms_velocity_m_s
    setting = experiment.for_bending(shown)
    modes, measured = bending(setting, curves), bending(setting, data)
    per_mode = []
    for k, (mine, theirs) in enumerate(zip(modes, measured)):
        per_mode.append({"mode": k + 1, "shift": mine["shift"], "measured_shift": theirs["shift"],
                         "shift_points": 100 * (mine["shift"] - theirs["shift"]),
                         "peak_ratio": mine["peak_per_drive_top_over_lowest"],
                         "measured_peak_ratio": theirs["peak_per_drive_top_over_lowest"],
                         "lowest_drive_peak_hz": mine["lowest_drive_peak_hz"],
                         "measured_lowest_drive_peak_hz": theirs["lowest_drive_peak_hz"]})
    mask = experiment.fit_mask
    misfit = np.sqrt(np.mean((curves[mask] - data[mask]) ** 2, axis=0)) / data.max(axis=0)
    linear = np.asarray(normal_modes(fitted_chain)[0])
    onsets = []
    for f in 2 * linear:
        loop = emulate_loop(fitted_chain, float(f), TONGUE_AMPLITUDES_M, bead=2,
                            steps_per_period=int(experiment.model["steps_per_period"]))
        onset = loop.onset_up_m
        onsets.append({"frequency_hz": float(f), "onset_up_m": onset if onset is not None and np.isfinite(onset) else None})
    out = {"why": __doc__.splitlines()[0], "source": "single_bead_diagnosis_laws/micro_slip.json#candidates.1.constants",
           "converged": bool(result.converged), "steps": int(result.steps),
           "precompression_n": float(fitted_chain.precompression_n), "drive_scale": scale,
           "linear_modes_hz": linear.tolist(), "fitted_levels": int(fitted.data.sweep.drive_amplitudes_m.size),
           "row_stride": args.row_stride, "misfit_median": float(np.median(misfit)), "misfit_max": float(misfit.max()),
           "modes": per_mode,
           "predicted_doubling": {"how": "emulate_loop at twice each linear mode, the single bead's tongue amplitudes "
                                  "(15-96 nm) at drive scale 1; None: no f/2 up to 96 nm", "onsets": onsets}}
    write_stamped(Path(args.out) / "prediction.json", out, start)


if __name__ == "__main__":
    main()
