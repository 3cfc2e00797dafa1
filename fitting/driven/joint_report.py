"""What a joint driven fit found (`fitting.driven.joint`), as `fit.json`: the status, which
constants are shared and which per run with their values and standard errors, each run's chain,
and for every measurement the data beside the model (bending misfit and shift, the tongue's
onsets and tip, the loop's onset, the scope records' onset as a check)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hertzchain.driven.linear import normal_modes
from hertzchain.driven.measurements import loop_thresholds
from hertzchain.driven.thresholds import emulate_loop
from hertzchain.io.atomic import json_ready, write_json

from .joint import DRIVE_SCALE, JointFit, _leaf, _threshold_data, chain_fields
from .report import bending

# A constant whose log factor's standard error is above this is reported as not determined.
DETERMINED_LOG_STDERR = 0.5
_UNITS = (("_n_m1p5", "N/m^1.5"), ("_per_s", "1/s"), ("_kg", "kg"), ("_n", "N"), ("_s", "s"), ("_m", "m"))


def unit_of(name: str) -> str:
    """The SI unit a field's name ends in (`precompression_n` -> N), "1" for a drive scale."""
    return next((unit for suffix, unit in _UNITS if name.endswith(suffix)), "1")


def _value(values):
    values = np.atleast_1d(np.asarray(values, dtype=float))
    return float(values[0]) if values.size == 1 or np.all(values == values[0]) else values.tolist()


def _parameters(fit: JointFit) -> dict:
    model = fit.model
    out = {}
    for k, p in enumerate(model.parameters):
        factor, error = math.exp(fit.x[k]), math.exp(fit.x[k]) * fit.stderr[k]
        if p.name == DRIVE_SCALE:
            run = next(r for r in model.runs if r.run == p.run) if p.run else model.runs[0]
            start, value = run.start_scale, model.run_scale(run, fit.x)
        else:
            start = _value(_leaf(model.start_chain, p.name))
            value = _value(np.asarray(_leaf(model.start_chain, p.name)) * factor)
        scale = value / start if not isinstance(value, list) else factor
        out[p.label] = {
            "name": p.name, "shared": p.run is None, "run": p.run, "unit": unit_of(p.name),
            "value": value, "stderr": (np.asarray(value) * fit.stderr[k]).tolist() if isinstance(value, list)
            else float(value * fit.stderr[k]),
            "factor_on_start": float(scale), "factor_stderr": float(error),
            # the data fix the factor to better than x/ e^0.5 = 1.65, or they leave it open
            "determined": bool(fit.stderr[k] < DETERMINED_LOG_STDERR),
        }
        if p.name == DRIVE_SCALE:
            u = run.drive_uncertainty
            out[p.label]["stated_uncertainty"] = u
            out[p.label]["within_stated_uncertainty"] = bool(abs(math.log(value)) <= math.log1p(u)) if u > 0 else None
    return out


def _runs(fit: JointFit) -> dict:
    out = {}
    for run in fit.model.runs:
        chain = fit.model.run_chain(run, fit.x)
        out[run.run] = {
            "measurements": [m.kind for m in run.measurements],
            "precompression_n": float(chain.precompression_n),
            "contact_kappa_n_m1p5": np.asarray(chain.contact_kappa_n_m1p5).tolist(),
            "damping_rate_per_s": np.asarray(chain.damping_rate_per_s).tolist(),
            "static_overlap_m": np.asarray(chain.static_overlap_m()).tolist(),
            "linear_resonance_hz": np.asarray(normal_modes(chain)[0]).tolist(),
            "drive_scale": fit.model.run_scale(run, fit.x),
            "drive_m_per_v": run.measurements[0].drive_m_per_v * fit.model.run_scale(run, fit.x),
        }
    return out


def _bending(fit: JointFit, run, m) -> dict:
    experiment = fit.model.experiment.for_bending(m)
    rows = np.arange(m.data.sweep.frequencies_hz.size)
    curves = fit.model.bending_curves(run, m, fit.x, rows)
    measured = m.data.sweep.rms_velocity_m_s
    misfit = np.sqrt(np.mean((curves[m.fit_mask] - measured[m.fit_mask]) ** 2, axis=0)) / measured.max(axis=0)
    data, model = bending(experiment, measured)[0], bending(experiment, curves)[0]
    keep = ("lowest_drive_peak_hz", "highest_drive_peak_hz", "shift", "peak_per_drive_top_over_lowest")
    return {"kind": "bending", "run": m.run, "files": list(m.files),
            "misfit": {"median": float(np.median(misfit)), "max": float(misfit.max()), "per_level": misfit.tolist(),
                       "of": "RMS of (model - measured) over each curve's fitted frequencies / its peak"},
            "measured": {k: data[k] for k in keep}, "model": {k: model[k] for k in keep}}


def _thresholds(fit: JointFit, run) -> list[dict]:
    """The run's tongue and loop beside the fitted model, and beside what the bending run's own
    fit (the start: its constants, the run's nominal drive) predicts for them."""
    rows = _threshold_data(run)
    start = np.zeros_like(fit.x)
    _, predicted = fit.model.onsets(run, start)
    predicted_nominal = np.where(predicted.found, predicted.amplitude_m, np.nan) / fit.model.run_scale(run, start)
    _, found = fit.model.onsets(run, fit.x)
    scale = fit.model.run_scale(run, fit.x)
    model_nominal = np.where(found.found, found.amplitude_m, np.nan) / scale
    out = []
    for m in (m for m in run.measurements if m.kind in ("tongue", "loop")):
        picked = [i for i, row in enumerate(rows) if row[4] == m.kind]
        f = np.array([rows[i][0] for i in picked])
        data, model = np.array([rows[i][1] for i in picked]), model_nominal[picked]
        alone = predicted_nominal[picked]
        reasons = [found.reasons[i] for i in picked]
        if m.kind == "tongue":
            entry = {"kind": "tongue", "run": m.run, "files": list(m.files), "frequencies_hz": f.tolist(),
                     "measured_onset_m": data.tolist(), "model_onset_m": model.tolist(), "model_search": reasons,
                     "measured_tip": _tip(f, data), "model_tip": _tip(f, model),
                     "bending_alone_onset_m": alone.tolist(), "bending_alone_tip": _tip(f, alone)}
            if entry["model_tip"]["amplitude_m"] is not None:
                entry["tip_amplitude_model_over_measured"] = (entry["model_tip"]["amplitude_m"]
                                                              / entry["measured_tip"]["amplitude_m"])
        else:
            entry = {"kind": "loop", "run": m.run, "files": list(m.files), "frequency_hz": float(f[0]),
                     "measured_onset_up_m": float(data[0]), "model_onset_up_m": float(model[0]),
                     "model_search": reasons[0], "bending_alone_onset_up_m": float(alone[0]),
                     "measured_last_down_m": m.data.last_down_m, "measured_gone_down_m": m.data.gone_down_m,
                     "model_loop": _emulated(fit, run, m, fit.x),
                     "bending_alone_loop": _emulated(fit, run, m, start),
                     "loop_how": "the lab's loop on the model by time stepping (hertzchain.driven.thresholds."
                                 "emulate_loop: each step held 0.25 s, lock-in at f and f/2): reported, not fitted"}
            if math.isfinite(model[0]):
                entry["onset_model_over_measured"] = float(model[0] / data[0])
        entry["amplitudes"] = "nominal: the run's lock-in volts x its file calibration; the model's divided by the run's drive scale"
        out.append(entry)
    return out


def _emulated(fit: JointFit, run, m, x) -> dict:
    """The loop `m` run on the model at `x` (nominal amplitudes: the true ones / the run's scale)."""
    scale = fit.model.run_scale(run, x)
    loop = emulate_loop(fit.model.run_chain(run, x), m.data.frequency_hz, m.data.drive_amplitudes_m * scale,
                        bead=fit.model.experiment.sensor_bead, steps_per_period=int(fit.model.experiment.model[
                            "steps_per_period"]))
    return {"onset_up_m": loop.onset_up_m / scale, "last_down_m": loop.last_down_m / scale,
            "gone_down_m": loop.gone_down_m / scale, "periods_per_step": loop.periods_per_level,
            "subharmonic_over_fundamental": (loop.subharmonic_m_s / loop.fundamental_m_s).tolist()}


def _tip(frequencies, onsets) -> dict:
    if not np.isfinite(onsets).any():
        return {"amplitude_m": None, "frequency_hz": None}
    i = int(np.nanargmin(onsets))
    return {"amplitude_m": float(onsets[i]), "frequency_hz": float(frequencies[i])}


def _scope(m) -> dict:
    present = np.asarray(m.data.subharmonic_present)
    onset = loop_thresholds(m.data.drive_amplitudes_m, present)[0]
    return {"kind": "scope", "run": m.run, "files": list(m.files), "frequency_hz": m.data.frequency_hz,
            "onset_up_m": onset if np.isfinite(onset) else None,
            "records_with_subharmonic": int(present.sum()), "records": int(present.size),
            "fitted": False, "why": "a check: the records measure the same onset as the run's lock-in loop"}


def report_data(fit: JointFit, *, data_dir) -> dict:
    """The contents of `fit.json`."""
    model = fit.model
    measurements = []
    for run in model.runs:
        for m in run.measurements:
            if m.kind == "bending":
                measurements.append(_bending(fit, run, m))
            elif m.kind == "scope":
                measurements.append(_scope(m))
        if any(m.kind in ("tongue", "loop") for m in run.measurements):
            measurements.extend(_thresholds(fit, run))
    cov = fit.covariance
    return json_ready({
        "experiment": str(model.experiment.path), "label": model.experiment.label, "data_dir": str(data_dir),
        "kinds": [m.kind for m in model.experiment.measurements],
        "model": {"chain": type(model.start_chain).__name__, "fields": chain_fields(model.start_chain)},
        "status": {"converged": fit.converged, "message": fit.message, "steps": fit.steps, "chi2": fit.chi2,
                   "dof": fit.dof, "reduced_chi2": fit.chi2 / fit.dof},
        "shared": [p.name for p in model.parameters if p.run is None],
        "per_run": sorted({p.name for p in model.parameters if p.run is not None}),
        "params": _parameters(fit),
        "runs": _runs(fit),
        "measurements": measurements,
        "uncertainty": {
            "method": "Gauss-Newton covariance (fitting.uncertainty.covariance_from_jacobian) of the whitened "
                      "residuals, scaled by chi^2/(n_effective - p); stderr of the log factors, so relative",
            "run_to_run": "the per-run constants carry what differs between runs; the shared constants' errors "
                          "are scaled by the joint misfit, which holds how far the runs disagree under one set of "
                          "shared constants",
            "bending_weight": model.bending_weight, "bending_lag1_autocorrelation": fit.rho,
            "threshold_sigma_log": model.sigma,
            "weak_directions": [{"relative_singular_value": s, "components": c} for s, c in cov.weak_directions],
            "correlation": {"labels": list(fit.labels), "matrix": cov.correlation.tolist()},
        },
        "start": {"bending_alone": {label: float(v) for label, v in zip(fit.start.labels, fit.start.x)},
                  "converged": fit.start.converged, "bending_misfit_median": float(np.median(fit.start.misfit)),
                  "why": "the bending run fitted alone (fitting.driven.fit_driven): the joint fit's start, and what "
                         "its constants predict for the other runs (bending_alone_* in the threshold entries)"},
        "elapsed_s": fit.elapsed_s,
    })


def write_joint_report(fit: JointFit, out_dir, *, data_dir) -> list[Path]:
    """Write `fit.json` into `out_dir`. **Returns:** the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "fit.json"
    write_json(path, report_data(fit, data_dir=data_dir))
    return [path]
