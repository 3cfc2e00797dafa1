"""Two beads (2013-07-05): end contacts with their own stiffness, read from the mode frequencies,
then fitted on the low drive levels and used to predict the high ones.

    python examples/lydon2015/two_bead_end_compliance.py --data-dir ../shared/data/real/lydon-2015
        [--out examples/lydon2015/results/two_bead_end_compliance] [--max-steps 10]

1. `stiffness.json`: the contact stiffnesses the measured linear modes require. Two equal beads
   between two equal end contacts (`linear.symmetric_pair_stiffness_n_m`): $m\\omega_1^2 = k_e + k_s$,
   $m\\omega_2^2 = k_e + 2k_m + k_s$; one bead between two: $m\\omega^2 = 2k_e + k_s$. Each without
   supports and with the single bead's micro-slip supports ($k_s$ of
   `single_bead_diagnosis_laws/micro_slip.json`), and one asymmetric case (the wall contact at
   Hertz, the face contact free). Beside them Hertz, $k = \\tfrac32\\kappa^{2/3}F_0^{1/3}$, of the
   README's constants (sphere-sphere 9.7576e9 N/m^{3/2}, sphere-flat that times sqrt 2) at the
   stated preloads, the preload at which Hertz would give each contact's stiffness, and the end
   contacts' series compliance beside Hertz at the preload the middle contact implies.
2. `fit.json`: three fits. The two-bead chain with the single bead's micro-slip supports
   (`with_supports`) and without (`bare`), each with the single bead's viscous rate to start.
   Free: the end contacts' and the bead-bead contact's Hertz constants (started at the linear
   stiffnesses of 1, same case), the precompression (started at the best of
   `START_PRELOADS_N`, the linear stiffnesses kept), the viscous rate and the drive scale
   (calibration prior), on the lowest `FITTED_LEVELS` drive levels (every `level-stride`-th,
   every `row-stride`-th frequency). Predicted, not fitted: the other levels, the peak
   velocity per nm top over lowest and the resonance shift per mode, and the period doubling
   near twice each mode (`emulate_loop`, the single bead's tongue amplitudes). Third
   (`hertz_series_ends`): every contact Hertz with the README's constants, the end contacts in
   series with a linear spring (`laws.SeriesCompliance`), its compliance, the precompression
   (started at the bead-bead contact's Hertz preload and the series compliance of 1), the
   viscous rate and the drive scale free, no supports. `fit.png`: measured and model curves.
Whole or nothing: the folder is written only when every part has run.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from run_record import write_stamped  # this folder's helper
from two_bead_prediction import TONGUE_AMPLITUDES_M, single_bead_constants, two_bead_fit_start

from fitting.driven.candidates import BoundedJointModel, fitted_levels
from fitting.driven.experiment import Measurement, load_driven_experiment
from fitting.driven.joint import DRIVE_SCALE, JointParameter, _leaf
from fitting.driven.report import bending
from fitting.fit import least_squares
from fitting.uncertainty import covariance_from_jacobian
from hertzchain import laws
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import normal_modes, symmetric_pair_stiffness_n_m
from hertzchain.driven.measurements import Bending
from hertzchain.driven.thresholds import emulate_loop
from hertzchain.io.atomic import output_folder

HERE = Path(__file__).resolve().parent
RUN = "2013-07-05 11:24"
BEAD_MASS_KG = 0.028
KAPPA_SPHERE_SPHERE = 9.7576e9  # N/m^1.5, the README (the two-bead scripts)
KAPPA_SPHERE_FLAT = KAPPA_SPHERE_SPHERE * math.sqrt(2.0)
TWO_BEAD_PRELOAD_N, SINGLE_BEAD_PRELOAD_N = 3.0, 4.5
FITTED_LEVELS = (
    18  # the lower half of the 36 drive levels (0.68-3.6 nm); the upper half is predicted
)
FACTOR_BOUNDS = (math.log(0.01), math.log(100.0))
START_PRELOADS_N = (3.0, 1.0, 0.3, 0.1)
SERIES_PATHS = ("contact_law.compliance_m_n", "precompression_n", "damping_rate_per_s")
PATHS = (
    "contact_kappa_n_m1p5[0,2]",
    "contact_kappa_n_m1p5[1]",
    "precompression_n",
    "damping_rate_per_s",
)


def hertz_stiffness_n_m(kappa_n_m1p5, force_n):
    """Hertz's linear stiffness at a static force, $\\tfrac32\\kappa^{2/3}F^{1/3}$, N/m: the
    law's own (`laws.Hertz.stiffness_at_force`)."""
    return float(laws.Hertz().stiffness_at_force(force_n, laws.ContactConstants(kappa_n_m1p5=kappa_n_m1p5)))


def hertz_force_n(kappa_n_m1p5, stiffness_n_m):
    """The preload at which a Hertz contact of `kappa_n_m1p5` has `stiffness_n_m`, N (the
    inverse of `hertz_stiffness_n_m`)."""
    return (stiffness_n_m / (1.5 * kappa_n_m1p5 ** (2.0 / 3.0))) ** 3


def hertz_kappa(stiffness_n_m, force_n):
    """The Hertz constant that has `stiffness_n_m` at `force_n`, N/m^{3/2}."""
    return (stiffness_n_m / (1.5 * force_n ** (1.0 / 3.0))) ** 1.5


def face_free_stiffness(frequencies_hz, wall_n_m, support_n_m):
    """(face, middle) stiffness (N/m) of two beads whose wall contact is `wall_n_m`: from the trace
    and determinant of $M^{-1}K$ (a quadratic in the middle stiffness); the root with positive
    stiffnesses, or None."""
    w2 = (2 * np.pi * np.asarray(frequencies_hz)) ** 2
    trace, det = BEAD_MASS_KG * w2.sum(), BEAD_MASS_KG**2 * w2.prod()
    # c = k1 + k2 + ks, a = trace - c, det = a c - k1^2  ->  (trace - c) c - (c - k2 - ks)^2 = det
    shift = wall_n_m + support_n_m
    roots = np.roots([-2.0, trace + 2 * shift, -(shift**2) - det])
    for c in sorted(np.real(roots[np.isreal(roots)])):
        middle, face = c - shift, trace - c - (c - shift) - support_n_m
        if middle > 0 and face > 0:
            return float(face), float(middle)
    return None


def stiffness_record(two_bead_hz, single_bead_hz, support_n_m) -> dict:
    hertz_end = hertz_stiffness_n_m(KAPPA_SPHERE_FLAT, TWO_BEAD_PRELOAD_N)
    hertz_middle = hertz_stiffness_n_m(KAPPA_SPHERE_SPHERE, TWO_BEAD_PRELOAD_N)
    cases = {}
    for name, ks in (("bare", 0.0), ("with_supports", support_n_m)):
        end, middle = (
            float(v) for v in symmetric_pair_stiffness_n_m(two_bead_hz, BEAD_MASS_KG, ks)
        )
        single_end = (BEAD_MASS_KG * (2 * np.pi * single_bead_hz) ** 2 - ks) / 2
        middle_force = hertz_force_n(KAPPA_SPHERE_SPHERE, middle)
        hertz_end_at_middle_force = hertz_stiffness_n_m(KAPPA_SPHERE_FLAT, middle_force)
        cases[name] = {
            "support_stiffness_n_m": ks,
            "two_bead_end_n_m": end,
            "two_bead_middle_n_m": middle,
            "middle_over_end": middle / end,
            "end_over_hertz_3n": end / hertz_end,
            "middle_over_hertz_3n": middle / hertz_middle,
            "end_hertz_preload_n": hertz_force_n(KAPPA_SPHERE_FLAT, end) if end > 0 else None,
            "middle_hertz_preload_n": middle_force,
            "end_series_compliance_m_n": (1 / end - 1 / hertz_end_at_middle_force)
            if end > 0
            else None,
            "single_bead_end_n_m": single_end,
            "single_bead_end_over_hertz_4p5n": single_end
            / hertz_stiffness_n_m(KAPPA_SPHERE_FLAT, SINGLE_BEAD_PRELOAD_N),
            "single_bead_end_hertz_preload_n": hertz_force_n(KAPPA_SPHERE_FLAT, single_end),
            "single_bead_end_scaled_to_3n_n_m": single_end
            * (TWO_BEAD_PRELOAD_N / SINGLE_BEAD_PRELOAD_N) ** (1 / 3),
        }
    wall_hertz = face_free_stiffness(two_bead_hz, hertz_end, 0.0)
    return {
        "measured_modes_hz": list(two_bead_hz),
        "single_bead_resonance_hz": single_bead_hz,
        "bead_mass_kg": BEAD_MASS_KG,
        "hertz": {
            "end_3n_n_m": hertz_end,
            "middle_3n_n_m": hertz_middle,
            "middle_over_end": hertz_middle / hertz_end,
            "end_4p5n_n_m": hertz_stiffness_n_m(KAPPA_SPHERE_FLAT, SINGLE_BEAD_PRELOAD_N),
            "kappa_sphere_sphere_n_m1p5": KAPPA_SPHERE_SPHERE,
            "kappa_sphere_flat_n_m1p5": KAPPA_SPHERE_FLAT,
        },
        "symmetric_ends": cases,
        "wall_at_hertz_face_free": None
        if wall_hertz is None
        else {
            "wall_n_m": hertz_end,
            "face_n_m": wall_hertz[0],
            "middle_n_m": wall_hertz[1],
            "face_over_hertz_3n": wall_hertz[0] / hertz_end,
            "middle_over_hertz_3n": wall_hertz[1] / hertz_middle,
        },
        "caveats": [
            (
                "mode frequencies are the lowest drive's peaks on the 5 Hz grid (the lowest level, 0.68 nm, "
                "is already slightly softened: the peaks move 5-6 % over the sweep)"
            ),
            (
                "the preloads (3 N, 4.5 N) are the scripts' numbers; how they were measured is not in the files "
                "(the two-bead Figures.m has 2.9 N)"
            ),
            "the single-bead run and the two-bead run are separate set-ups (days and hours apart)",
            (
                "symmetric ends assumed: two frequencies fix two stiffnesses; face and wall apart need a third "
                "datum (the asymmetric case shows one alternative)"
            ),
            "a third weak resonance near 2.2 kHz (the fixture) is not modelled",
        ],
    }


def two_bead_chain(
    constants: dict, end_n_m: float, middle_n_m: float, supports: bool, preload_n: float
) -> DrivenChain:
    """The two beads with end and middle contacts of these linear stiffnesses (N/m) at
    `preload_n` (N), the single bead's viscous rate and (`supports`) its micro-slip supports."""
    end, middle = hertz_kappa(end_n_m, preload_n), hertz_kappa(middle_n_m, preload_n)
    friction = (
        laws.IwanSupport(
            constants["support_friction.stiffness_n_m"],
            constants["support_friction.slip_displacement_m"],
        )
        if supports
        else None
    )
    return DrivenChain(
        [BEAD_MASS_KG, BEAD_MASS_KG],
        [end, middle, end],
        preload_n,
        constants["damping_rate_per_s"][0],
        support_friction=friction,
    )


def series_chain(constants: dict, compliance_m_n: float, preload_n: float) -> DrivenChain:
    """The two beads with the README's Hertz constants (sphere on flat at the ends, sphere on
    sphere between), the end contacts in series with a spring of `compliance_m_n` (m/N), at
    `preload_n` (N), the single bead's viscous rate, no supports."""
    return DrivenChain(
        [BEAD_MASS_KG, BEAD_MASS_KG],
        [KAPPA_SPHERE_FLAT, KAPPA_SPHERE_SPHERE, KAPPA_SPHERE_FLAT],
        preload_n,
        constants["damping_rate_per_s"][0],
        contact_law=laws.SeriesCompliance(laws.Hertz(), [compliance_m_n, 0.0, compliance_m_n]),
    )


def fit_record(args, experiment, starts: dict, paths: tuple, fixed: dict) -> tuple[dict, dict]:
    """Fit the factors on `paths` and the drive scale from the best of the `starts` ({preload
    (N): chain}, by chi^2 at the start); the record of the fit and its curves."""
    rows = experiment.fit_mask & (np.arange(experiment.fit_mask.size) % args.row_stride == 0)
    full = Measurement(
        "bending",
        RUN,
        Bending(RUN, experiment.sweep),
        experiment.drive_m_per_v,
        experiment.drive_uncertainty,
        experiment.fit_mask,
        (),
    )
    levels = experiment.sweep.drive_amplitudes_m.size
    fitted = fitted_levels(
        dataclasses.replace(full, fit_mask=rows), levels - FITTED_LEVELS, args.level_stride
    )
    joint = dataclasses.replace(experiment, measurements=(fitted,))
    parameters = [JointParameter(p, None) for p in paths] + [JointParameter(DRIVE_SCALE, RUN)]
    scan = {}
    for preload, trial in starts.items():
        unit = BoundedJointModel(
            joint, trial, parameters, {RUN: 1.0}, 0.1, False, bounds=(-np.inf, np.inf)
        )
        r = unit.residuals(np.zeros(len(parameters)))
        scan[preload] = float(r @ r)
    start_preload = min(scan, key=scan.get)
    chain = starts[start_preload]
    bounds = (
        np.full(len(parameters), FACTOR_BOUNDS[0]),
        np.full(len(parameters), FACTOR_BOUNDS[1]),
    )
    model = BoundedJointModel(joint, chain, parameters, {RUN: 1.0}, 0.1, True, bounds=bounds)
    columns = list(range(len(parameters)))
    result = least_squares(
        model, np.zeros(len(parameters)), columns, max_steps=args.max_steps, bounds=bounds
    )
    x = model.clip(result.x)
    r, jac = model.linearize(x, columns)
    n_points = int(fitted.fit_mask.sum()) * fitted.data.sweep.drive_amplitudes_m.size
    dof = max(round(n_points * model.bending_weight**2) + 1 - len(columns), 1)
    cov = covariance_from_jacobian(
        jac, [p.label for p in parameters], chi2=float(r @ r), dof=dof, scale="residual"
    )
    chain_fit = model.run_chain(model.runs[0], x)
    scale = model.run_scale(model.runs[0], x)
    shown = dataclasses.replace(full, fit_mask=experiment.fit_mask)
    curves = model.bending_curves(model.runs[0], shown, x, np.arange(experiment.fit_mask.size))
    data = experiment.sweep.rms_velocity_m_s
    setting = experiment.for_bending(shown)
    mine, theirs = bending(setting, curves), bending(setting, data)
    mask = experiment.fit_mask
    misfit = np.sqrt(np.mean((curves[mask] - data[mask]) ** 2, axis=0)) / data.max(axis=0)
    fitted_mask = np.isin(experiment.sweep.drive_amplitudes_m, fitted.data.sweep.drive_amplitudes_m)
    predicted_mask = np.arange(levels) >= FITTED_LEVELS
    linear = np.asarray(normal_modes(chain_fit)[0])
    kappa = np.asarray(chain_fit.contact_kappa_n_m1p5)
    stiffness = np.asarray(chain_fit.contact_stiffness_n_m())
    constants_out = {}
    for k, p in enumerate(parameters):
        value = scale if p.name == DRIVE_SCALE else np.asarray(_leaf(chain_fit, p.name)).ravel()[0]
        constants_out[p.label] = {"value": float(value), "relative_stderr": float(cov.stderr[k])}
    onsets = []
    for f in 2 * linear:
        loop = emulate_loop(
            chain_fit,
            float(f),
            TONGUE_AMPLITUDES_M,
            bead=2,
            steps_per_period=int(experiment.model["steps_per_period"]),
        )
        onset = loop.onset_up_m
        onsets.append(
            {
                "frequency_hz": float(f),
                "onset_up_m": onset if onset is not None and np.isfinite(onset) else None,
            }
        )
    per_mode = [
        {
            "mode": k + 1,
            "peak_ratio": a["peak_per_drive_top_over_lowest"],
            "measured_peak_ratio": b["peak_per_drive_top_over_lowest"],
            "shift": a["shift"],
            "measured_shift": b["shift"],
            "lowest_drive_peak_hz": a["lowest_drive_peak_hz"],
            "measured_lowest_drive_peak_hz": b["lowest_drive_peak_hz"],
            "highest_drive_peak_hz": a["highest_drive_peak_hz"],
            "measured_highest_drive_peak_hz": b["highest_drive_peak_hz"],
        }
        for k, (a, b) in enumerate(zip(mine, theirs))
    ]
    record = {
        "converged": bool(result.converged),
        "steps": int(result.steps),
        "chi2": float(r @ r),
        "dof": dof,
        "free": [p.label for p in parameters],
        "start_precompression_n": start_preload,
        "start_scan_chi2": {str(k): v for k, v in scan.items()},
        "precompression_n": float(chain_fit.precompression_n),
        "static_overlap_m": np.asarray(chain_fit.static_overlap_m()).tolist(),
        "fixed": fixed,
        "contact_law": type(chain_fit.contact_law).__name__,
        "end_series_compliance_m_n": (
            float(chain_fit.contact_law.compliance_m_n[0])
            if isinstance(chain_fit.contact_law, laws.SeriesCompliance)
            else None
        ),
        "fitted_levels_m": fitted.data.sweep.drive_amplitudes_m.tolist(),
        "row_stride": args.row_stride,
        "constants": constants_out,
        "contact_kappa_n_m1p5": kappa.tolist(),
        "contact_stiffness_n_m": stiffness.tolist(),
        "end_kappa_over_hertz_sphere_flat": float(kappa[0] / KAPPA_SPHERE_FLAT),
        "middle_kappa_over_hertz_sphere_sphere": float(kappa[1] / KAPPA_SPHERE_SPHERE),
        "linear_modes_hz": linear.tolist(),
        "misfit_median": float(np.median(misfit)),
        "misfit_max": float(misfit.max()),
        "misfit_fitted_levels_median": float(np.median(misfit[fitted_mask])),
        "misfit_predicted_levels_median": float(np.median(misfit[predicted_mask])),
        "misfit_predicted_levels_max": float(misfit[predicted_mask].max()),
        "modes": per_mode,
        "predicted_doubling": {
            "how": "emulate_loop at twice each linear mode, the single bead's tongue amplitudes "
            "(15-96 nm) at drive scale 1; None: no f/2 up to 96 nm",
            "onsets": onsets,
        },
    }
    return record, {"curves": curves, "data": data, "mask": mask}


def plot(path: Path, experiment, shown: dict) -> None:
    """Measured (solid) and model (dashed) curves at the lowest, the highest fitted and the top
    drive level, one panel per fit."""
    f = experiment.sweep.frequencies_hz
    drives = experiment.sweep.drive_amplitudes_m
    fig, axes = plt.subplots(len(shown), 1, figsize=(8, 3.2 * len(shown)), sharex=True)
    for ax, (name, curves) in zip(np.atleast_1d(axes), shown.items()):
        for k, level in enumerate((0, FITTED_LEVELS - 1, drives.size - 1)):
            colour = f"C{k}"
            ax.plot(
                f,
                1e3 * curves["data"][:, level],
                color=colour,
                lw=1.0,
                label=f"data {1e9 * drives[level]:.2f} nm",
            )
            ax.plot(
                f, 1e3 * curves["curves"][:, level], color=colour, lw=1.0, ls="--", label="model"
            )
        ax.set_ylabel("bead 2 RMS velocity (mm/s)")
        ax.set_title(
            f"end contacts free, {name.replace('_', ' ')}: fitted on levels 1-{FITTED_LEVELS}",
            fontsize=9,
        )
        ax.legend(fontsize=7, ncol=3)
    np.atleast_1d(axes)[-1].set_xlabel("drive frequency (Hz)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    args, start, experiment = two_bead_fit_start(argv, __doc__.splitlines()[0], "two_bead_end_compliance", 6, 20)
    single = load_driven_experiment(HERE / "single_bead_bending.toml", args.data_dir)
    two_hz = [
        m["lowest_drive_peak_hz"] for m in bending(experiment, experiment.sweep.rms_velocity_m_s)
    ]
    one_hz = bending(single, single.sweep.rms_velocity_m_s)[0]["lowest_drive_peak_hz"]
    constants = single_bead_constants()
    stiffness = stiffness_record(two_hz, one_hz, constants["support_friction.stiffness_n_m"])
    fits, shown = {}, {}
    supports_fixed = {
        key: constants[key]
        for key in ("support_friction.stiffness_n_m", "support_friction.slip_displacement_m")
    }
    for name, supports in (("with_supports", True), ("bare", False)):
        case = stiffness["symmetric_ends"][name]
        starts = {
            preload: two_bead_chain(
                constants, case["two_bead_end_n_m"], case["two_bead_middle_n_m"], supports, preload
            )
            for preload in START_PRELOADS_N
        }
        fixed = supports_fixed if supports else {"support_friction": None}
        fits[name], shown[name] = fit_record(args, experiment, starts, PATHS, fixed)
    # Hertz of the README at every contact, the ends in series with a spring: started where the
    # bead-bead contact's stiffness puts the preload, with the series compliance that leaves
    bare = stiffness["symmetric_ends"]["bare"]
    preload = bare["middle_hertz_preload_n"]
    starts = {preload: series_chain(constants, bare["end_series_compliance_m_n"], preload)}
    fixed = {"contact_kappa_n_m1p5": [KAPPA_SPHERE_FLAT, KAPPA_SPHERE_SPHERE, KAPPA_SPHERE_FLAT]}
    fits["hertz_series_ends"], shown["hertz_series_ends"] = fit_record(
        args, experiment, starts, SERIES_PATHS, fixed
    )
    with output_folder(args.out, "two_bead_end_compliance.py", "fit.json") as folder:
        write_stamped(
            folder / "stiffness.json",
            {
                "why": "the contact stiffnesses the measured mode frequencies "
                "require, beside Hertz",
                **stiffness,
            },
            start,
        )
        plot(folder / "fit.png", experiment, shown)
        write_stamped(folder / "fit.json", {"why": __doc__.splitlines()[0], "fits": fits}, start)


if __name__ == "__main__":
    main()
