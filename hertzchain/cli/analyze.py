"""`hertzchain analyze FILE...`: fit every pulse of trace files; speed, velocity law, restitution.

For each file and channel the pulses are found and labelled (`pulses.find_pulses`:
incident, reflected, secondary_N; wall, wall_secondary_N) and each is fitted with
$F_m\\cos^6((t - t_0)/\\tau)$ (`pulses.fit_cos6`). Embedded-sensor channels are also
deconvolved (`sensor.deconvolve_sensor`, Eq. 4) into the force at contact K
(`sensor_K_deconvolved`). Per file, with two or more contacts: the incident wave's speed
(slope of $2R\\,K$ against parabolic peak times) and amplitude (mean parabolic peak), the
restitution between the measured contacts, the momentum check against the wall and the
wall-to-incident force ratio. Over all files: the velocity law $v = CF_m^{1/6}$ and the
restitution law $1 - \\epsilon = C_vF^{1/6} + C_s/F$.

Writes `pulses.csv` (one row per pulse), `analysis.json` (rows, per-file results, fits,
definitions) and PNGs: each file's traces with the fitted pulses, speed and duration
against amplitude with the theory, and restitution against force. The folder is written as a
whole and replaces the previous run's (`hertzchain.io.atomic.output_folder`).
"""

from __future__ import annotations

import argparse
import csv
import io
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .. import pulses, sensor, theory  # noqa: E402
from ..io.atomic import file_stem, finish_figure, json_ready, output_folder, write_json, write_text  # noqa: E402
from ..io.importer import expand_sources  # noqa: E402
from ..io.tracefile import TraceFile, read_trace  # noqa: E402
from ..units import counted

# Shots whose measured striker velocities differ by less than this fraction are repeats
# of one setting when no nominal velocity is given (a drop height is set to about 1 %).
REPEAT_TOLERANCE = 0.02
_REPEAT_QUANTITIES = ("amplitude_n", "speed_m_s", "velocity_constant", "restitution", "wall_force_ratio")

COLUMNS = (
    "file",
    "channel",
    "label",
    "peak_time_s",
    "peak_force_n",
    "fit_peak_force_n",
    "fit_peak_force_stderr_n",
    "center_s",
    "center_stderr_s",
    "tau_s",
    "tau_stderr_s",
    "duration_s",
    "residual_rms_n",
    "n_points",
    "converged",
)

DEFINITIONS = {
    "peak": "3-point parabola through the largest sample of the pulse and its neighbours",
    "fit": "F_m cos^6((t - t0)/tau) fitted to the pulse's main lobe at or above `threshold` "
    "of its peak; standard errors from the Jacobian and the residual variance; duration = 2 tau",
    "speed": "least-squares slope of contact position 2R K against the incident pulses' arrival "
    "times, the cos^6 fit centres (deconvolved sensors count as their front contact K)",
    "amplitude": "mean parabolic peak force (or cos^6 amplitude with --amplitude fit) of the "
    "incident pulses used for the speed",
    "restitution": "eps = (F_K2/F_K1)^(5/(6 (K2 - K1))) between consecutive measured contacts, "
    "at force F_K1 (incident pulse amplitudes)",
    "paper_conversions": "eta = 2 sqrt(10) R C_v/(5C) and mu = 4 C_s/(5 m g) are the paper's; "
    "they do not hold for the viscoelastic/Coulomb model (C_v is 3.0x, C_s 0.69x what they "
    "predict): "
    "fit eta and mu with the simulator",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE",
                        help="trace files (hertzchain-trace/1) or experiment files (.toml)")
    parser.add_argument("--out", default="out/analyze", help="output folder [out/analyze]")
    parser.add_argument(
        "--threshold",
        type=float,
        default=0.05,
        help="cos^6 fit uses the samples above this fraction of the peak [0.05]",
    )
    parser.add_argument(
        "--amplitude",
        choices=("peak", "fit"),
        default="peak",
        help="amplitude of a pulse for the speed law: parabolic peak (C = 201.37 on the "
        "paper's clean chain) or cos^6 fit amplitude (0.77 %% lower, C = 201.6) [peak]",
    )
    parser.add_argument(
        "--min-fraction",
        type=float,
        default=0.05,
        help="smallest pulse reported, as a fraction of the channel's maximum [0.05]",
    )


def _channel_noise(trace, name):
    value = trace.channel_noise_std_n(name)
    return None if value is None else float(value)


def _fit_pulses(file_name, time, name, force, noise, kind, args):
    rows, fits = [], []
    for pulse in pulses.find_pulses(
        time, force, channel=kind, min_fraction=args.min_fraction, noise_std_n=noise
    ):
        fit = pulses.fit_cos6(time, force, threshold=args.threshold, window_s=pulse.window_s)
        fits.append((pulse, fit))
        rows.append(
            {
                "file": file_name,
                "channel": name,
                "label": pulse.label,
                "peak_time_s": pulse.peak_time_s,
                "peak_force_n": pulse.peak_force_n,
                "fit_peak_force_n": float(fit.peak_force_n),
                "fit_peak_force_stderr_n": float(fit.peak_force_stderr_n),
                "center_s": float(fit.center_s),
                "center_stderr_s": float(fit.center_stderr_s),
                "tau_s": float(fit.tau_s),
                "tau_stderr_s": float(fit.tau_stderr_s),
                "duration_s": float(fit.duration_s),
                "residual_rms_n": float(fit.residual_rms_n),
                "n_points": int(fit.n_points),
                "converged": bool(fit.converged),
            }
        )
    return rows, fits


def _arrival(pulse_and_fit, args):
    """(arrival time, amplitude) of an incident pulse: the cos^6 centre (less sensitive to
    noise than the parabola; they agree to 2e-5 on clean data) and the parabolic peak or
    the fitted amplitude (`--amplitude`)."""
    pulse, fit = pulse_and_fit
    amplitude = pulse.peak_force_n if args.amplitude == "peak" else float(fit.peak_force_n)
    return float(fit.center_s), amplitude


def analyze_trace(trace, args):
    """Analyse one `TraceFile`: returns (pulse rows, per-file summary, channels to plot with
    their fits)."""
    name_of_file = trace.header.get("x_shot") or (Path(trace.path).name if trace.path else "<trace>")
    time = np.asarray(trace.time_s)
    radius = float(trace.header["bead_radius_m"])
    setup = trace.setup(**({} if trace.striker_velocity_m_s else {"striker_velocity_m_s": 0.3}))
    constants = theory.setup_constants(setup)
    c_n = float(constants["discrete_velocity_constant"])
    rows, plotted = [], {}
    incident = {}  # contact K -> (peak time, peak force) of the incident pulse
    for name, force in trace.channels.items():
        kind = "wall" if name == "wall" else "contact"
        force = np.asarray(force)
        channel_rows, fits = _fit_pulses(
            name_of_file, time, name, force, _channel_noise(trace, name), kind, args
        )
        rows += channel_rows
        plotted[name] = (force, fits)
        if name.startswith("contact_") and fits and fits[0][0].label == "incident":
            incident[int(name.split("_")[1])] = _arrival(fits[0], args)
    speed = None
    if len(incident) >= 2:
        ks = sorted(incident)
        speed = pulses.wave_speed([2 * radius * k for k in ks], [incident[k][0] for k in ks])
    for name in list(trace.channels):
        if not name.startswith("sensor_"):
            continue
        bead = int(name.split("_")[1])
        force = np.asarray(trace.channels[name])
        first = pulses.find_pulses(
            time, force, min_fraction=args.min_fraction, noise_std_n=_channel_noise(trace, name)
        )
        if not first:
            continue
        beta = float(trace.header["sensor_beta"])
        v = (
            speed.speed_m_s
            if speed
            else float(theory.solitary_speed_m_s(first[0].peak_force_n / (1 - beta), c_n))
        )
        recovered = np.asarray(
            sensor.deconvolve_sensor(
                time,
                force,
                beta=beta,
                f0_hz=float(trace.header["sensor_f0_hz"]),
                delay_s=float(sensor.sensor_delay_s(radius, v)),
                noise_std_n=_channel_noise(trace, name),
            )
        )
        label = f"{name}_deconvolved"
        channel_rows, fits = _fit_pulses(
            name_of_file, time, label, recovered, None, "contact", args
        )
        rows += channel_rows
        plotted[label] = (recovered, fits)
        if fits and fits[0][0].label == "incident" and bead not in incident:
            incident[bead] = _arrival(fits[0], args)
    if len(incident) >= 2:
        ks = sorted(incident)
        speed = pulses.wave_speed([2 * radius * k for k in ks], [incident[k][0] for k in ks])
    summary = {
        "file": name_of_file,
        "striker_velocity_m_s": trace.striker_velocity_m_s,
        "nominal_velocity_m_s": _nominal_velocity(trace),
        "noise_std_n": trace.noise_std_n,
        "incident_contacts": sorted(incident),
        "theory": {
            "long_wave_velocity_constant": float(constants["long_wave_velocity_constant"]),
            "discrete_velocity_constant": c_n,
            "wall_force_ratio_eq5": float(constants["wall_force_ratio"]),
        },
    }
    if incident:
        summary["amplitude_n"] = float(np.mean([incident[k][1] for k in incident]))
    if speed is not None:
        summary.update(
            speed_m_s=speed.speed_m_s,
            speed_stderr_m_s=speed.speed_stderr_m_s,
            velocity_constant=speed.speed_m_s / summary["amplitude_n"] ** (1 / 6),
        )
    else:
        summary["speed_not_measured"] = _why_no_speed(trace, incident)
    ks = sorted(incident)
    summary["restitution"] = [
        {
            "contact_from": a,
            "contact_to": b,
            "force_n": incident[a][1],
            "restitution": (incident[b][1] / incident[a][1]) ** (5.0 / (6.0 * (b - a))),
        }
        for a, b in zip(ks[:-1], ks[1:])
    ]
    if "wall" in plotted and plotted["wall"][1] and incident:
        wall_peak = plotted["wall"][1][0][0].peak_force_n
        amplitude = summary["amplitude_n"]
        summary["wall_force_ratio"] = wall_peak / amplitude
        summary["momentum_check"] = {}
        for name in trace.channels:
            if name.startswith("contact_"):
                check = pulses.momentum_check(
                    time,
                    trace.channels["wall"],
                    trace.channels[name],
                    noise_std_n=_channel_noise(trace, name),
                )
                summary["momentum_check"][name] = check._asdict()
    return rows, summary, plotted


def _why_no_speed(trace, incident) -> str:
    """Why a file gives no wave speed: a speed needs incident pulses at two contacts."""
    contacts = [n for n in trace.channels if n.startswith(("contact_", "sensor_"))]
    if not contacts:
        return "no contact or sensor channel (the wall alone gives no arrival times to time the wave)"
    if not incident:
        return (f"no incident pulse found on {', '.join(contacts)} (a speed needs the incident pulse's "
                "arrival at two contacts)")
    (k,) = incident
    return (f"the incident pulse is seen at one contact only (contact {k}); a speed needs its arrival "
            "at two or more contacts: record a second contact or sensor channel")


def _plot_file(time, plotted, title, path):
    figure, axes = plt.subplots(figsize=(9, 4.5))
    for name, (force, fits) in plotted.items():
        (line,) = axes.plot(time * 1e3, force, lw=0.8, alpha=0.7, label=name.replace("_", " "))
        for pulse, fit in fits:
            start, stop = pulse.window_s
            t = np.linspace(start, stop, 400)
            axes.plot(t * 1e3, np.asarray(fit.profile_n(t)), "--", color=line.get_color(), lw=1.2)
            axes.annotate(
                pulse.label,
                (pulse.peak_time_s * 1e3, pulse.peak_force_n),
                fontsize=7,
                ha="center",
                va="bottom",
            )
    axes.set_xlabel("time (ms)")
    axes.set_ylabel("force (N)")
    axes.set_title(f"{title}: traces (solid) and cos^6 fits (dashed)")
    axes.legend(fontsize=8)
    finish_figure(figure, path)


def _plot_speed_duration(summaries, rows, radius_m, path):
    with_speed = [s for s in summaries if "speed_m_s" in s]
    figure, (speed_axes, duration_axes) = plt.subplots(1, 2, figsize=(10, 4))
    c_t = with_speed[0]["theory"]["long_wave_velocity_constant"] if with_speed else None
    c_n = with_speed[0]["theory"]["discrete_velocity_constant"] if with_speed else None
    forces = np.array([s["amplitude_n"] for s in with_speed])
    if len(forces):
        speed_axes.errorbar(
            forces,
            [s["speed_m_s"] for s in with_speed],
            yerr=[s["speed_stderr_m_s"] or 0 for s in with_speed],
            fmt="o",
            label="measured",
        )
        grid = np.geomspace(forces.min() * 0.7, forces.max() * 1.4, 100)
        speed_axes.plot(grid, c_t * grid ** (1 / 6), "k-", lw=1, label=f"Eq. 3, C_t = {c_t:.1f}")
        speed_axes.plot(
            grid, c_n * grid ** (1 / 6), "k--", lw=1, label=f"discrete chain, C_n = {c_n:.1f}"
        )
        speed_axes.set_xscale("log")
        speed_axes.legend(fontsize=8)
    else:
        speed_axes.text(0.5, 0.5, "no speed: it needs two measured contacts per file",
                        ha="center", va="center", transform=speed_axes.transAxes)
    speed_axes.set_xlabel("amplitude F_m (N)")
    speed_axes.set_ylabel("speed v (m/s)")
    incident = [
        r
        for r in rows
        if r["label"] == "incident"
        and (r["channel"].startswith("contact_") or r["channel"].endswith("_deconvolved"))
    ]
    if incident:
        f = np.array([r["fit_peak_force_n"] for r in incident])
        duration_axes.errorbar(
            f,
            [r["duration_s"] * 1e6 for r in incident],
            yerr=[r["tau_stderr_s"] * 2e6 for r in incident],
            fmt="o",
            ms=3,
            label="cos^6 fits",
        )
        grid = np.geomspace(f.min() * 0.7, f.max() * 1.4, 100)
        c_t = summaries[0]["theory"]["long_wave_velocity_constant"]
        c_n = summaries[0]["theory"]["discrete_velocity_constant"]
        eq3 = 2 * radius_m * math.sqrt(10) / (c_t * grid ** (1 / 6)) * 1e6
        duration_axes.plot(grid, eq3, "k-", lw=1, label="2R sqrt(10)/v, Eq. 3")
        discrete = (theory.DISCRETE_DURATION_FACTOR * 2 * radius_m * math.sqrt(10)
                    / (c_n * grid ** (1 / 6)) * 1e6)
        duration_axes.plot(grid, discrete, "k--", lw=1, label="discrete chain, no dissipation")
    duration_axes.set_xscale("log")
    duration_axes.set_xlabel("amplitude F_m (N)")
    duration_axes.set_ylabel("duration 2 tau (us)")
    duration_axes.legend(fontsize=8)
    finish_figure(figure, path)


def _plot_restitution(points, law, path):
    figure, axes = plt.subplots(figsize=(6, 4))
    force = np.array([p["force_n"] for p in points])
    axes.plot(force, [p["restitution"] for p in points], "o", label="measured")
    if law is not None:
        grid = np.geomspace(force.min() * 0.8, force.max() * 1.25, 100)
        axes.plot(
            grid,
            np.asarray(theory.restitution_law(grid, law["c_v"], law["c_s"])),
            "k-",
            lw=1,
            label=f"1 - {law['c_v']:.3g} F^1/6 - {law['c_s']:.3g}/F",
        )
    axes.set_xscale("log")
    axes.set_xlabel("force F (N)")
    axes.set_ylabel("restitution (F_K2/F_K1)^(5/6 per contact)")
    axes.legend(fontsize=8)
    finish_figure(figure, path)


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.threshold < 1:
        raise ValueError(f"--threshold must be in [0, 1), got {args.threshold}.")
    with output_folder(args.out, "analyze", "analysis.json") as out:
        _analyze(args, out)
    print(f"wrote pulses.csv, analysis.json and plots to {args.out}")
    return 0


def _analyze(args: argparse.Namespace, out: Path) -> None:
    """The analysis of `args.files`, written into `out` (the temporary of `--out`)."""
    all_rows, summaries = [], []
    radius = None
    traces = [source if isinstance(source, TraceFile) else read_trace(source)
              for source in expand_sources(args.files)]
    for trace in traces:
        rows, summary, plotted = analyze_trace(trace, args)
        radius = float(trace.header["bead_radius_m"])
        all_rows += rows
        summaries.append(summary)
        _plot_file(
            np.asarray(trace.time_s),
            plotted,
            summary["file"],
            out / f"{file_stem(Path(summary['file']).stem)}_pulses.png",
        )
        print(f"{summary['file']}: {counted(len(rows), 'pulse')}" + _file_line(summary))
    result = {"definitions": DEFINITIONS, "files": summaries}
    with_speed = [s for s in summaries if "speed_m_s" in s]
    if with_speed:
        law = pulses.fit_velocity_law(
            [s["amplitude_n"] for s in with_speed], [s["speed_m_s"] for s in with_speed]
        )
        result["velocity_law"] = law._asdict()
        print(
            f"velocity law: C = {law.velocity_constant:.2f} ± {law.velocity_constant_stderr:.2g} "
            f"(m/s)/N^(1/6) from {counted(law.n_points, 'file')}"
        )
    points = [p for s in summaries for p in s["restitution"]]
    law_dict = None
    if len(points) >= 2:
        friction = len(points) >= 3
        setup = traces[0].setup(striker_velocity_m_s=0.3)
        c = result.get("velocity_law", {}).get("velocity_constant") or float(
            theory.setup_constants(setup)["discrete_velocity_constant"]
        )
        law = pulses.fit_restitution_law(
            [p["force_n"] for p in points],
            [p["restitution"] for p in points],
            friction=friction,
            velocity_constant=c,
            bead_radius_m=radius,
            bead_mass_kg=float(setup.bead_mass_kg[0]),
        )
        law_dict = law._asdict()
        result["restitution_law"] = law_dict | {"note": DEFINITIONS["paper_conversions"]}
        _plot_restitution(points, law_dict, out / "restitution.png")
    if any(r["label"] == "incident" for r in all_rows):
        _plot_speed_duration(summaries, all_rows, radius, out / "speed_duration.png")
    repeats = repeat_scatter(summaries)
    if repeats:
        result["repeats"] = repeats
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(repeats[0]))
        writer.writeheader()
        writer.writerows(repeats)
        write_text(out / "repeats.csv", buffer.getvalue())
        for row in repeats:
            print(_repeat_line(row))
    result["pulses"] = all_rows
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS)
    writer.writeheader()
    writer.writerows(all_rows)
    write_text(out / "pulses.csv", buffer.getvalue())
    write_json(out / "analysis.json", json_ready(result))


def _file_line(summary) -> str:
    """The per-file line's measured part: speed and amplitude, or what was measured and why
    the speed was not."""
    if "speed_m_s" in summary:
        return f", v = {summary['speed_m_s']:.2f} m/s at F_m = {summary['amplitude_n']:.4g} N"
    amplitude = f", F_m = {summary['amplitude_n']:.4g} N" if "amplitude_n" in summary else ""
    return f"{amplitude}; no speed: {summary['speed_not_measured']}"


def _nominal_velocity(trace):
    value = trace.header.get("x_import_nominal_velocity_m_s")
    return float(value) if value is not None else trace.striker_velocity_m_s


def _repeat_line(row) -> str:
    """One group of repeats: the amplitude's and the speed's mean and scatter, or why not."""
    parts = []
    for name, label, unit in (("amplitude_n", "amplitude", "N"), ("speed_m_s", "speed", "m/s")):
        if row[f"{name}_mean"] is None:
            parts.append(f"{label} not measured in these shots")
        elif row[f"{name}_sd"] is None:
            parts.append(f"{label} {row[f'{name}_mean']:.4g} {unit} (measured in one shot only)")
        else:
            parts.append(f"{label} {row[f'{name}_mean']:.4g} ± {row[f'{name}_sd']:.2g} {unit}")
    return f"{counted(row['n_shots'], 'shot')} at {row['velocity_m_s']:.4g} m/s: {', '.join(parts)} (shot-to-shot sd)"


def repeat_scatter(summaries) -> list[dict]:
    """Shot-to-shot scatter of repeated shots: per group of two or more shots at the same
    nominal velocity (or measured velocities within `REPEAT_TOLERANCE`), the mean and the
    sample standard deviation of amplitude, speed, velocity constant, restitution (mean
    over each shot's contact pairs) and wall force ratio; None where the shots do not
    measure a quantity (a speed needs two contacts) or, for the sd, measure it once."""
    groups: list[list[dict]] = []
    for summary in sorted((s for s in summaries if s["nominal_velocity_m_s"]),
                          key=lambda s: s["nominal_velocity_m_s"]):
        v = summary["nominal_velocity_m_s"]
        if groups and abs(v / groups[-1][0]["nominal_velocity_m_s"] - 1) <= REPEAT_TOLERANCE:
            groups[-1].append(summary)
        else:
            groups.append([summary])
    rows = []
    for group in groups:
        if len(group) < 2:
            continue
        row = {"velocity_m_s": float(np.mean([s["nominal_velocity_m_s"] for s in group])),
               "n_shots": len(group), "shots": " ".join(s["file"] for s in group)}
        for name in _REPEAT_QUANTITIES:
            values = [s.get(name) if name != "restitution" else
                      (float(np.mean([p["restitution"] for p in s["restitution"]])) if s["restitution"] else None)
                      for s in group]
            values = [v for v in values if v is not None]
            row[f"{name}_mean"] = float(np.mean(values)) if values else None
            row[f"{name}_sd"] = float(np.std(values, ddof=1)) if len(values) >= 2 else None
        rows.append(row)
    return rows

