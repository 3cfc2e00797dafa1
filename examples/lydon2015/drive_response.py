"""How hard the piezo really drove the single bead at the tongue's frequencies, measured from
the tongue run's own fundamental below every period-doubling threshold:

    python examples/lydon2015/drive_response.py --data-dir ../shared/data/real/lydon-2015
        [--out examples/lydon2015/results/single_bead_diagnosis_laws]

Far above its resonance a bead between two equal contacts moves, per metre of face motion, as
the linear chain says ($X/u = k_0/(k_0 + k_1 - m\\omega^2 + i\\omega m\\gamma)$,
`hertzchain.driven.linear.frequency_response`), whatever its precompression beyond what sets
$f_0$. So each run's lock-in at f at its lowest drive (15 nm nominal in the tongue and the loop,
below every onset) measures the drive's true amplitude over its calibration, frequency by
frequency: a drive scale of 0.22 at 7.2 kHz, or an actuator mode between 3.6 and 8 kHz, would
show in it. Fitted per run (a robust soft-L1 fit in log velocity): the drive scale s, and for
the bending run its linear resonance f0 (far above resonance s and f0 trade off, so the
tongue's and the loop's s is given at each of `TONGUE_RESONANCES_HZ`); the damping ratio is
held at the bending run's, which far from resonance barely matters. Writes
`drive_response.json` (per frequency the measured over the model velocity at the fit, and the
fit's constants), with the load average and the process CPU time.
"""

from __future__ import annotations

import argparse
import math
import tomllib
from pathlib import Path

import numpy as np
from run_record import started, write_stamped  # this folder's helper
from scipy.optimize import least_squares

from fitting.driven.experiment import load_driven_experiment
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import frequency_response

HERE = Path(__file__).resolve().parent
# the bending run fitted alone (`single_bead_joint/fit.json#start.bending_alone`): the damping
# ratio gamma / (2 omega0) every run here is held at
BENDING_RESONANCE_HZ = 3981.93
BENDING_DAMPING_PER_S = 1751.80
# The fits' robust scale (log units): the tongue run's fundamental has two narrow dip-and-peak
# features (6350-6400 and 7150-7200 Hz, factors 0.5 and 1.6 on the smooth response) that a
# plain least-squares fit of two constants would chase; soft-L1 beyond 10 % keeps them out.
ROBUST_SCALE = 0.1
# The tongue run's resonances tried: 2 x 3600 Hz is where its tongue sits, 3982 Hz the bending
# run's an hour later.
TONGUE_RESONANCES_HZ = (3400.0, 3600.0, 3800.0, BENDING_RESONANCE_HZ)


def linear_velocity_rms(frequencies_hz, resonance_hz, damping_per_s, mass_kg, amplitude_m):
    """RMS velocity (m/s) of a bead between two equal Hertz contacts, linear resonance
    `resonance_hz`, driven by a face amplitude `amplitude_m` (m)."""
    kappa = 1e10
    chain = DrivenChain([mass_kg], [kappa, kappa], 1.0, damping_per_s)
    # scale the static force so that the linear resonance is resonance_hz (f0 ~ F^(1/6))
    f_now = math.sqrt(2 * 1.5 * kappa ** (2 / 3) / mass_kg) / (2 * math.pi)
    chain = DrivenChain([mass_kg], [kappa, kappa], (resonance_hz / f_now) ** 6, damping_per_s)
    x, _ = frequency_response(chain, np.asarray(frequencies_hz, dtype=float))
    return np.abs(np.asarray(x[:, 0])) * 2 * np.pi * np.asarray(frequencies_hz) * amplitude_m / math.sqrt(2)


def fit_run(frequencies_hz, velocity_m_s, amplitude_m, mass_kg, zeta, fit_resonance=True,
            resonance_hz=BENDING_RESONANCE_HZ):
    """(drive scale, resonance Hz, measured / model per frequency) of one run's fundamental."""
    def model(p):
        f0 = math.exp(p[1]) if fit_resonance else resonance_hz
        return math.exp(p[0]) * linear_velocity_rms(frequencies_hz, f0, 2 * zeta * 2 * math.pi * f0, mass_kg,
                                                    amplitude_m)

    start = [0.0, math.log(resonance_hz)] if fit_resonance else [0.0]
    result = least_squares(lambda p: np.log(model(p) / velocity_m_s), start, loss="soft_l1", f_scale=ROBUST_SCALE)
    f0 = math.exp(result.x[1]) if fit_resonance else resonance_hz
    ratio = velocity_m_s / model(result.x)
    return math.exp(result.x[0]), f0, ratio, bool(result.success)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--out", default=str(HERE / "results" / "single_bead_diagnosis_laws"))
    args = parser.parse_args(argv)
    start = started()
    path = HERE / "single_bead_joint.toml"
    experiment = load_driven_experiment(path, args.data_dir)
    calibration = tomllib.loads(path.read_text())["sensor"]["calibration_m_s_per_v"]  # m/s per lock-in volt
    zeta = BENDING_DAMPING_PER_S / (2 * 2 * math.pi * BENDING_RESONANCE_HZ)
    mass = float(np.asarray(experiment.bead_mass_kg)[0])
    out = {"why": __doc__.splitlines()[0], "damping_ratio_held": zeta, "runs": {}}
    for m in experiment.measurements:
        if m.kind == "tongue":
            f, v, a = m.data.frequencies_hz, m.data.fundamental_v[0] * calibration, m.data.drive_amplitudes_m[0]
            below = np.nanmin(m.data.onset_m)
        elif m.kind == "bending":
            f, v = m.data.sweep.frequencies_hz, m.data.sweep.rms_velocity_m_s[:, 0]
            a, below = m.data.sweep.drive_amplitudes_m[0], None
        else:
            continue
        entry = {"run": m.run, "nominal_drive_m": float(a), "lowest_onset_m": None if below is None else float(below),
                 "frequencies_hz": [float(f.min()), float(f.max())], "points": int(f.size)}
        if m.kind == "bending":  # through its resonance: s and f0 both determined
            scale, f0, ratio, ok = fit_run(f, v, a, mass, zeta)
            entry.update({"converged": ok, "drive_scale": scale, "resonance_hz": f0,
                          "ratio_median": float(np.median(ratio)), "ratio_log_rms": float(np.sqrt(np.mean(np.log(ratio) ** 2)))})
        else:  # far above resonance s and f0 trade off (X/u ~ s f0^2 / (f^2 - f0^2)): s at each f0
            entry["by_resonance"] = []
            for f0 in TONGUE_RESONANCES_HZ:
                scale, _, ratio, ok = fit_run(f, v, a, mass, zeta, fit_resonance=False, resonance_hz=f0)
                entry["by_resonance"].append({
                    "resonance_hz": f0, "drive_scale": scale, "converged": ok, "ratio_median": float(np.median(ratio)),
                    "ratio_min": float(ratio.min()), "ratio_max": float(ratio.max()),
                    "ratio_log_rms": float(np.sqrt(np.mean(np.log(ratio) ** 2))),
                    "frequencies_and_ratio": np.c_[f, ratio].tolist()})
        out["runs"][m.kind] = entry
    for m in experiment.measurements:
        if m.kind == "loop":  # one frequency: the drive scale at each of the other runs' resonances
            v = m.data.fundamental_v[0] * calibration
            a = m.data.drive_amplitudes_m[0]
            out["runs"]["loop"] = {"run": m.run, "frequency_hz": m.data.frequency_hz, "nominal_drive_m": float(a),
                                   "by_resonance": [{"resonance_hz": f0, "drive_scale": float(v / linear_velocity_rms(
                                       [m.data.frequency_hz], f0, 2 * zeta * 2 * math.pi * f0, mass, a)[0])}
                                       for f0 in TONGUE_RESONANCES_HZ]}
    write_stamped(Path(args.out) / "drive_response.json", out, start)


if __name__ == "__main__":
    main()
