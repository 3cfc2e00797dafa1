"""Lydon, Serra-Garcia & Daraio 2014: the contact exponent of the precompressed chain from its
static force against the actuator's displacement (`Modes_Fine.mat`), by `fitting.static_curve`.

    python examples/lydon2015/lydon2014_static_exponent.py --data-dir ../shared/data/real/lydon-2014 \
        [--out examples/lydon2015/results/lydon2014_static_exponent]

The authors' own fit of the same quantities (a comment in their `plotbanddata.m`, summarised in
the data's README): F = 2.138e9 delta^1.522, 95 % interval of n 1.504-1.539. Writes
`static_exponent.json` (the fit, the authors' numbers, the data's caveats), `static_curve.csv`
(one row per step: displacement, force, the fitted chain's force) and `static_curve.png`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.io  # noqa: E402

from fitting.static_curve import chain_force_n, fit_static_exponent  # noqa: E402
from hertzchain.io.atomic import save_figure, write_csv, write_json  # noqa: E402

# The authors' calibrations (`plotmode_fine.m`, the data's README): static force (V - V_ref)
# x 4.09 N/V, actuator displacement (V - V_ref) x 1.2564e-6 m/V from its strain gauge, V_ref
# the first step of Modes_Fine.mat.
FORCE_N_PER_V = 4.09
DISPLACEMENT_M_PER_V = 1.2564e-6
AUTHORS = {"exponent": 1.522, "exponent_95_low": 1.504, "exponent_95_high": 1.539, "prefactor": 2.138e9,
           "source": "comment in the authors' plotbanddata.m (Daraio-lab/Lydon_PRL_2014), F = A delta^n"}
CAVEATS = [
    "the authors' comment does not say which file, steps or zero they fitted; this fit takes every step of "
    "Modes_Fine.mat with positive force and displacement, both zeroed at its first step as their "
    "plotmode_fine.m does",
    "the displacement is the actuator's strain-gauge reading, not the chain's compression: the fitted "
    "one-contact stiffness is the chain's in series with the actuator and fixture, which a power law "
    "describes only if they are stiff or of the same exponent",
    "Band.mat's static-force channel is not monotonic in the actuator offset (it falls from 0.63 V at step "
    "25 to 0.40 V at step 31), so its curve is not fitted",
    "the standard error is scaled by the residuals' scatter and by their lag-1 correlation along the ramp",
]


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data-dir", required=True, type=Path, help="folder holding Modes_Fine.mat")
    parser.add_argument("--out", type=Path, default=Path("examples/lydon2015/results/lydon2014_static_exponent"))
    args = parser.parse_args(argv)
    path = args.data_dir / "Modes_Fine.mat"
    if not path.is_file():
        parser.error(f"--data-dir {args.data_dir}: no Modes_Fine.mat there (the lydon-2014 data folder holds it)")
    data = scipy.io.loadmat(path)
    static_v = np.asarray(data["StaticForce"], dtype=float).ravel()
    strain_v = np.asarray(data["ActuatorStrain"], dtype=float).ravel()
    force = (static_v - static_v[0]) * FORCE_N_PER_V
    displacement = (strain_v - strain_v[0]) * DISPLACEMENT_M_PER_V
    fit = fit_static_exponent(displacement, force)
    model = np.asarray(chain_force_n(np.clip(displacement, 0.0, None), fit.exponent, fit.kappa_eff_n_m1p5,
                                     fit.reference_overlap_m))
    within = AUTHORS["exponent_95_low"] <= fit.exponent <= AUTHORS["exponent_95_high"]
    authors_sigma = (AUTHORS["exponent_95_high"] - AUTHORS["exponent_95_low"]) / (2 * 1.96)
    result = {
        "file": "Modes_Fine.mat",
        "steps": int(force.size),
        "fit": fit.as_dict(),
        "authors": AUTHORS,
        "exponent_minus_authors": fit.exponent - AUTHORS["exponent"],
        # against the authors' interval (read as 1.96 sigma of independent residuals), with this
        # fit's error computed the same way and with the residuals' correlation along the ramp
        "exponent_difference_in_joint_sigma_white": (fit.exponent - AUTHORS["exponent"])
        / float(np.hypot(fit.exponent_stderr_white, authors_sigma)),
        "exponent_difference_in_joint_sigma": (fit.exponent - AUTHORS["exponent"])
        / float(np.hypot(fit.exponent_stderr, authors_sigma)),
        "within_authors_95_interval": bool(within),
        "force_range_n": [float(force[force > 0].min()), float(force.max())],
        "displacement_range_m": [float(displacement[displacement > 0].min()), float(displacement.max())],
        "caveats": CAVEATS,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "static_exponent.json", result)
    write_csv(args.out / "static_curve.csv", ["step", "displacement_m", "force_n", "model_force_n"],
              [[i, f"{x:.6e}", f"{f:.6f}", f"{m:.6f}"] for i, (x, f, m) in enumerate(zip(displacement, force, model))])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(displacement * 1e6, force, ".", ms=3, label="measured (Modes_Fine.mat)")
    order = np.argsort(displacement)
    ax.plot(displacement[order] * 1e6, model[order], "-",
            label=f"chain of power-law contacts: n = {fit.exponent:.3f} ± {fit.exponent_stderr_white:.3f} "
                  f"(± {fit.exponent_stderr:.2f} correlated)")
    authors_curve = AUTHORS["prefactor"] * np.clip(displacement[order], 0.0, None) ** AUTHORS["exponent"]
    ax.plot(displacement[order] * 1e6, authors_curve, "--", label="authors' fit: n = 1.522 (1.504-1.539)")
    ax.set_xlabel("actuator displacement (µm)")
    ax.set_ylabel("static force (N)")
    ax.set_title("Lydon 2014: static force against the actuator's stroke")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, args.out / "static_curve.png", dpi=120)
    plt.close(fig)
    print(f"n = {fit.exponent:.4f} ± {fit.exponent_stderr_white:.4f} independent residuals, ± "
          f"{fit.exponent_stderr:.3f} with their correlation (authors 1.522, 95 % 1.504-1.539); "
          f"converged: {fit.converged}; {args.out}")
    return result


if __name__ == "__main__":
    main()
