"""Scope files from a second generator, imported and fitted with the commands a lab would use.

Two checks of the importer (noise, time zero, vendor layouts) on data the fit's own code did
not make: the chains are simulated by the diffrax reference solver (`hertzchain.reference`,
adaptive Dopri8; Coulomb friction as its tanh form), recorded by `hertzchain.acquisition`
(8 bits, AC-coupled piezo channels with DC offsets, a pre-trigger segment) and written as
text by this script, not by hertzchain's writers. Every command runs as a user runs it
(`python -m hertzchain ...` in a subprocess); its exit status is stored.

``--noise``: 15 brass beads of 5 mm struck by a 3 mm brass ball, six shots (0.05-1.0 m/s),
contact 5 and the wall, each channel in its own Tektronix TDS CSV file; analogue noise of a
quarter of a converter step (a resting record sits on one or two codes; `--noise-steps`
sets another). Per noise seed:
`hertzchain fit experiment.toml --params eta,mu,C`; stored: exit status, chi^2/dof, values,
standard errors, and over the seeds the ratio of the mean standard error to the spread of
the fitted values.

``--second-lab``: 16 brass beads of 4 mm, Rigol DS1000Z CSV files (``X,CH1,CH2,CH3,Start,
Increment,``) with contact 8 (CH1), the wall (CH2) and a light gate (CH3, TTL) that fires
40 us before the impact; `format = "auto"`, `time_zero = "channel:CH3>2.5V+40us"`. Stored:
the import's time-zero check with and without the delay, `hertzchain fit`, and `hertzchain
diagnose --free eta,mu,C` on the declared chain and on one whose true wall is softer
(20 GPa) than declared.

Run (each writes `benchmarks/results/scope_files/<case>/latest.json`, or with `--label`
`history/<label>.json` beside it; the timings in it are wall times of the whole commands)::

    python benchmarks/scope_files.py --noise --seeds 20
    python benchmarks/scope_files.py --second-lab
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import hertzchain as hc
from fitting.parameters import public_label
from hertzchain.acquisition import Acquisition, acquire
from hertzchain.io.atomic import json_ready, write_json
from hertzchain.materials import BEAD_STEEL, BRASS
from hertzchain.reference import simulate_reference

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
TRUTH = {"eta_s": 1.5e-6, "mu": 0.15}
SENSITIVITY_V_PER_N = {"contact": 0.01124, "wall": 0.1124}
INTERVAL_S = 1e-6
PRE_TRIGGER = 200
# TDS1000/2000: 25 codes per division, 8 bits; volts/div on the 1-2-5 sequence.
CODES_PER_DIVISION = 25


def brass_chain(n_beads, radius_m, velocity, wall_youngs_pa=BEAD_STEEL.youngs_pa, **extra):
    return hc.ChainSetup(n_beads, bead_radius_m=radius_m, bead_density_kg_m3=BRASS.density_kg_m3,
                         bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                         wall_youngs_pa=wall_youngs_pa, wall_poisson=BEAD_STEEL.poisson,
                         striker_velocity_m_s=velocity, **extra)


def volts_per_division(peak_v: float) -> float:
    """The 1-2-5 setting that shows `peak_v` within 3.5 divisions."""
    target = peak_v / 3.5
    decade = 10.0 ** math.floor(math.log10(target))
    return next(m * decade for m in (1.0, 2.0, 5.0, 10.0) if m * decade >= target)


def simulate(setup, contacts, t_end_s):
    run = simulate_reference(setup, t_end_s=t_end_s, sample_interval_s=0.1e-6, contacts=contacts, rtol=1e-9)
    forces = {f"contact_{k}": np.asarray(run.forces_n[f"contact_{k}"]) for k in contacts}
    forces["wall"] = np.asarray(run.forces_n["wall"])
    return np.asarray(run.time_s), forces


def record(time_s, forces, sources, *, noise_steps, seed, record_s, trigger_delay_s=0.0):
    """8-bit AC-coupled record of `forces` (name -> N): (time, volts per source, volts/div)."""
    rng = np.random.default_rng(seed)
    sensitivity = {s: SENSITIVITY_V_PER_N["wall" if n == "wall" else "contact"] for s, n in sources.items()}
    scale = {s: volts_per_division(float(np.max(forces[n])) * sensitivity[s]) for s, n in sources.items()}
    step = {s: scale[s] / CODES_PER_DIVISION for s in sources}
    setting = Acquisition(
        sample_interval_s=INTERVAL_S, record_length=PRE_TRIGGER + 1 + int(record_s / INTERVAL_S),
        pre_trigger_samples=PRE_TRIGGER, trigger_delay_s=trigger_delay_s,
        noise_std_n={s: noise_steps * step[s] / sensitivity[s] for s in sources}, bits=8, coupling="ac",
        full_scale_v={s: 128 * step[s] for s in sources}, sensitivity_v_per_n=sensitivity,
        dc_offset_v={s: float(rng.uniform(-0.4, 0.4)) * scale[s] for s in sources})
    recorded = acquire(time_s, {s: forces[n] for s, n in sources.items()}, setting, seed=seed)
    return recorded.time_s, recorded.volts, scale


def write_tds_csv(path: Path, time_s, volts, source: str, scale_v: float) -> None:
    """One channel in the TDS1000/2000 CSV layout (settings in columns 1-2, time and value in
    4-5), written line by line as text."""
    settings = [("Record Length", f"{len(time_s):.6e}"), ("Sample Interval", f"{INTERVAL_S:.6e}"),
                ("Trigger Point", f"{PRE_TRIGGER:.12e}"), ("", ""), ("", ""), ("", ""), ("Source", source),
                ("Vertical Units", "V"), ("Vertical Scale", f"{scale_v:.6e}"), ("Vertical Offset", "0.000000e+00"),
                ("Horizontal Units", "s"), ("Horizontal Scale", f"{100 * INTERVAL_S:.6e}"), ("Pt Fmt", "Y"),
                ("Yzero", "0.000000e+00"), ("Probe Atten", "1.000000e+00"), ("Model Number", "TDS2014C"),
                ("Serial Number", "C010101"), ("Firmware Version", "FV:v24.26")]
    lines = []
    for k, (t, v) in enumerate(zip(time_s, volts)):
        key, value = settings[k] if k < len(settings) else ("", "")
        lines.append(f"{key},{value},,{t:.9e},{v:.5e},")
    path.write_text("\r\n".join(lines) + "\r\n")


def write_rigol_csv(path: Path, time_s, volts: dict) -> None:
    """The DS1000Z CSV layout: 'X,CH1,...,Start,Increment,', a units row with the start and
    the interval, then sample index and volts per row, each ending with a comma."""
    names = list(volts)
    lines = [",".join(["X", *names, "Start", "Increment"]) + ",",
             ",".join(["Sequence", *["Volt"] * len(names), f"{time_s[0]:.6e}", f"{INTERVAL_S:.6e}"]) + ","]
    for k in range(len(time_s)):
        lines.append(",".join([str(k), *(f"{volts[n][k]:.6e}" for n in names)]) + ",")
    path.write_text("\n".join(lines) + "\n")


def chain_toml(n_beads, radius_m, striker_radius_m=None) -> str:
    text = (f"[chain]\nn_beads = {n_beads}\nbead_radius_m = {radius_m!r}\nbead_density_kg_m3 = {BRASS.density_kg_m3}\n"
            f"bead_youngs_pa = {BRASS.youngs_pa}\nbead_poisson = {BRASS.poisson}\n"
            f"wall_youngs_pa = {BEAD_STEEL.youngs_pa}\nwall_poisson = {BEAD_STEEL.poisson}\n")
    if striker_radius_m:
        text += f"striker_radius_m = {striker_radius_m!r}\n"
    return text


def channel_toml(source, measures) -> str:
    kind = "wall" if measures == "wall" else "contact"
    return (f'\n[[channel]]\nsource = "{source}"\nmeasures = "{measures}"\n'
            f'sensitivity_v_per_n = {SENSITIVITY_V_PER_N[kind]}\ncoupling = "ac"\n')


def hertzchain(*args, cwd) -> dict:
    """Run `python -m hertzchain ARGS` as a user would: exit status, wall time, the warnings
    it printed, output tail."""
    start = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "hertzchain", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, check=False)
    # (a command prints each warning as one line "hertzchain COMMAND: warning: TEXT")
    warned = [line.strip() for line in done.stderr.splitlines() if ": warning: " in line]
    return {"command": "hertzchain " + " ".join(args), "exit_status": done.returncode,
            "wall_s": time.perf_counter() - start, "warnings": warned,
            "output_tail": (done.stdout + done.stderr)[-1500:]}


# --- --noise --------------------------------------------------------------------------------

NOISE_SETUP = dict(n_beads=15, radius_m=5e-3, striker_radius_m=3e-3, contacts=(5,),
                   velocities_m_s=(0.05, 0.1, 0.2, 0.4, 0.7, 1.0), record_s=1.0e-3)


def noise_check(seeds: int, out: Path, noise_steps: float = 0.25) -> dict:
    spec = NOISE_SETUP
    runs = []
    for velocity in spec["velocities_m_s"]:
        truth = brass_chain(spec["n_beads"], spec["radius_m"], velocity, striker_radius_m=spec["striker_radius_m"],
                            **TRUTH)
        runs.append(simulate(truth, spec["contacts"], spec["record_s"] + 0.05e-3))
    sources = {"CH1": "contact_5", "CH2": "wall"}
    rows = []
    for seed in range(seeds):
        with tempfile.TemporaryDirectory() as folder:
            folder = Path(folder)
            text = chain_toml(spec["n_beads"], spec["radius_m"], spec["striker_radius_m"])
            text += '\n[scope]\nformat = "auto"\ntime_zero = "trigger"\n'
            text += "".join(channel_toml(s, n) for s, n in sources.items())
            for k, ((time_s, forces), velocity) in enumerate(zip(runs, spec["velocities_m_s"])):
                t, volts, scale = record(time_s, forces, sources, noise_steps=noise_steps, seed=1000 * seed + k,
                                         record_s=spec["record_s"])
                files = []
                for source in sources:
                    name = f"F{k:04d}{source}.CSV"
                    write_tds_csv(folder / name, t, volts[source], source, scale[source])
                    files.append(name)
                text += f"\n[[shot]]\nfiles = {json.dumps(files)}\nstriker_velocity_m_s = {velocity}\n"
            (folder / "experiment.toml").write_text(text)
            run = hertzchain("fit", "experiment.toml", "--params", "eta_s,mu,C", "--no-plots", "--quiet",
                             "--out", "fit", cwd=folder)
            fit = json.loads((folder / "fit" / "fit.json").read_text()) if (folder / "fit" / "fit.json").exists() else {}
        row = {"seed": seed, **run}
        if fit:
            row |= {"reduced_chi2": fit.get("reduced_chi2"), "covariance": fit.get("covariance_scale"),
                    "values": {p: fit["params"][public_label(p)]["value"] for p in ("eta", "mu", "C")},
                    "stderr": {p: fit["params"][public_label(p)]["stderr"] for p in ("eta", "mu", "C")},
                    "stderr_stated_noise": {p: fit["params"][public_label(p)].get("stderr_stated_noise") for p in ("eta", "mu", "C")}}
        rows.append(row)
        print(f"seed {seed}: exit {run['exit_status']}, chi2/dof {row.get('reduced_chi2')}, "
              f"{run['wall_s']:.0f} s", flush=True)
        summary = _noise_summary(rows)
        write_json(out, json_ready({"setup": spec | {"truth": TRUTH, "noise_steps": noise_steps, "bits": 8,
                                                      "coupling": "ac", "generator": "diffrax reference"},
                                    "seeds": rows, "summary": summary}))
    return summary


def _noise_summary(rows) -> dict:
    fitted = [r for r in rows if "values" in r]
    summary = {"n_seeds": len(rows), "exit_0": sum(r["exit_status"] == 0 for r in rows),
               "reduced_chi2": [r["reduced_chi2"] for r in fitted]}
    if len(fitted) >= 3:
        for p in ("eta", "mu", "C"):
            values = np.array([r["values"][p] for r in fitted])
            errors = np.array([r["stderr"][p] for r in fitted])
            spread = float(np.std(values, ddof=1))
            summary[p] = {"mean": float(values.mean()), "spread": spread, "mean_stderr": float(errors.mean()),
                          "stderr_over_spread": float(errors.mean() / spread) if spread > 0 else None}
            stated = [r.get("stderr_stated_noise", {}).get(p) for r in fitted]
            if spread > 0 and all(v is not None for v in stated):  # the white-noise errors, for comparison
                summary[p]["stated_noise_stderr_over_spread"] = float(np.mean(stated) / spread)
            summary[p]["covariances"] = sorted({r.get("covariance") for r in fitted})
    return summary


# --- --second-lab ----------------------------------------------------------------------------

LAB_SETUP = dict(n_beads=16, radius_m=4e-3, contacts=(8,), velocities_m_s=(0.05, 0.1, 0.25, 0.5, 1.0),
                 record_s=0.9e-3, gate_s=40e-6)


def second_lab(out: Path) -> dict:
    spec = LAB_SETUP
    result = {"setup": spec | {"truth": TRUTH, "generator": "diffrax reference", "format": "rigol-csv"}}
    for case, wall in (("declared_wall", BEAD_STEEL.youngs_pa), ("softer_wall", 20e9)):
        with tempfile.TemporaryDirectory() as folder:
            folder = Path(folder)
            shots = ""
            for k, velocity in enumerate(spec["velocities_m_s"]):
                truth = brass_chain(spec["n_beads"], spec["radius_m"], velocity, wall_youngs_pa=wall, **TRUTH)
                time_s, forces = simulate(truth, spec["contacts"], spec["record_s"] + 0.05e-3)
                t, volts, _ = record(time_s, forces, {"CH1": "contact_8", "CH2": "wall"}, noise_steps=0.5,
                                     seed=77 + k, record_s=spec["record_s"], trigger_delay_s=-spec["gate_s"])
                # the scope triggers on the light gate's rising edge (TTL 0 -> 5 V, 0.1 us edge)
                # at record time 0, 40 us before the impact; its own 8-bit steps of 40 mV
                rng = np.random.default_rng(k)
                edge = 5.0 / (1.0 + np.exp(-np.clip(t / 0.1e-6, -50, 50)))
                gate = np.round((edge + 0.01 * rng.standard_normal(t.size)) / 0.04) * 0.04
                name = f"RigolDS{k}.csv"
                write_rigol_csv(folder / name, t, {"CH1": volts["CH1"], "CH2": volts["CH2"], "CH3": gate})
                shots += f'\n[[shot]]\nfiles = ["{name}"]\nstriker_velocity_m_s = {velocity}\n'
            head = chain_toml(spec["n_beads"], spec["radius_m"]) + '\n[scope]\nformat = "auto"\n'
            channels = channel_toml("CH1", "contact_8") + channel_toml("CH2", "wall")
            (folder / "no_delay.toml").write_text(head + 'time_zero = "channel:CH3>2.5V"\n' + channels + shots)
            (folder / "experiment.toml").write_text(head + 'time_zero = "channel:CH3>2.5V+40us"\n' + channels + shots)
            entry = {"import_without_delay": hertzchain("import", "no_delay.toml", "--out", "i0", "--no-plots",
                                                        cwd=folder),
                     "import": hertzchain("import", "experiment.toml", "--out", "i1", "--no-plots", cwd=folder)}
            imported = sorted((folder / "i1").glob("*.csv"))
            entry["time_zero_check"] = [_header_value(p, "x_import_time_zero_check") for p in imported]
            entry["fit"] = hertzchain("fit", "experiment.toml", "--params", "eta_s,mu,C", "--no-plots", "--quiet",
                                      "--out", "fit", cwd=folder)
            if (folder / "fit" / "fit.json").exists():
                fit = json.loads((folder / "fit" / "fit.json").read_text())
                entry["fit"] |= {"reduced_chi2": fit.get("reduced_chi2"),
                                 "params": {p: {k: fit["params"][public_label(p)][k] for k in ("value", "stderr")}
                                            for p in ("eta", "mu", "C")}}
            entry["diagnose"] = hertzchain("diagnose", "experiment.toml", "--free", "eta,mu,C", "--quiet",
                                           "--out", "diagnosis", cwd=folder)
            found = folder / "diagnosis" / "diagnosis.json"
            if found.exists():
                diagnosis = json.loads(found.read_text())
                entry["diagnose"]["missing_effects"] = diagnosis["missing_effects"]
        result[case] = entry
        print(f"{case}: fit exit {entry['fit']['exit_status']}, diagnose exit {entry['diagnose']['exit_status']}",
              flush=True)
        write_json(out, json_ready(result))
    return result


def _header_value(path: Path, key: str) -> str | None:
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            return None
        name, _, value = line[1:].partition("=")
        if name.strip() == key:
            return value.strip()
    return None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--noise", action="store_true", help="8-bit AC-coupled Tektronix files, several seeds")
    parser.add_argument("--second-lab", action="store_true", help="Rigol CSV files with a light gate")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--noise-steps", type=float, default=0.25,
                        help="--noise: analogue noise in converter steps [0.25: a resting record on 1-2 codes]")
    parser.add_argument("--label", default="", help="store as history/LABEL.json (e.g. the machine) instead of latest.json")
    args = parser.parse_args(argv)
    def result_file(case):
        folder = RESULTS / "scope_files" / case
        return folder / "history" / f"{args.label}.json" if args.label else folder / "latest.json"

    if args.noise:
        case = "noise" if args.noise_steps == 0.25 else f"noise_{args.noise_steps:g}steps"
        print(json.dumps(noise_check(args.seeds, result_file(case), args.noise_steps), indent=1))
    if args.second_lab:
        second_lab(result_file("second_lab"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
