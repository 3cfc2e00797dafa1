"""Why a law does or does not period-double the single bead: the stiffness modulation its
motion makes at the drive frequency, against the Mathieu threshold.

    python examples/lydon2015/stiffness_modulation.py
        [--out examples/lydon2015/results/single_bead_diagnosis_laws]

A drive at f = 2 f0 period-doubles a bead when the total stiffness it feels, modulated by its
own period-1 motion, carries a component at f (the parametric frequency) of relative depth
$\\varepsilon_1 = 2|c_1|/c_0 \\gtrsim 4\\zeta$ (Mathieu's first tongue with damping ratio
$\\zeta$; $c_k$ the Fourier coefficients of the tangent stiffness over one drive period). For
each chain the bead's motion at f is taken from its linear response (`frequency_response`),
the contacts' tangent stiffness from the contact law at the moving overlaps, and the supports'
from the `IwanSupport` law stepped through two steady cycles (an element counts while its
slider does not move). A symmetric hysteresis (Masing's rule: the same loop either way)
repeats every half period, so the supports add to $c_0$ and $c_2$ and nothing to $c_1$. Writes
`stiffness_modulation.json`: per chain, $\\varepsilon_1$ and $\\varepsilon_2$ of the contacts
and the supports at each drive amplitude, and the amplitude where $\\varepsilon_1 = 4\\zeta$
(the Mathieu estimate of the tongue's tip, true drive, m).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from run_record import started, write_stamped  # this folder's helper

from hertzchain import laws
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import frequency_response, normal_modes

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
DRIVE_HZ = 7200.0  # the measured tongue's tip
AMPLITUDES_M = np.geomspace(5e-9, 3e-7, 25)
SAMPLES = 512  # phases per drive period


def _chains() -> dict:
    """The chains compared: the stored fits' constants (file#key in `source`)."""
    slip = json.loads((RESULTS / "single_bead_diagnosis_laws" / "micro_slip.json").read_text())["candidates"]
    base, micro = slip[0]["constants"], slip[1]["constants"]
    alone = json.loads((RESULTS / "single_bead_joint" / "fit.json").read_text())["start"]["bending_alone"]
    low = DrivenChain([0.028], [1e10, 1e10], alone["precompression_n"], alone["damping_rate_per_s"])
    low = DrivenChain([0.028], low.contact_kappa_n_m1p5 * (alone["linear_resonance_hz"]
                                                          / float(normal_modes(low)[0][0])) ** 3,
                      alone["precompression_n"], alone["damping_rate_per_s"])
    return {
        "hertz_4p5N": (DrivenChain([0.028], base["contact_kappa_n_m1p5"], 4.5, base["damping_rate_per_s"]),
                       "single_bead_diagnosis_laws/micro_slip.json#candidates.0.constants"),
        "micro_slip_4p5N": (DrivenChain([0.028], micro["contact_kappa_n_m1p5"], 4.5, micro["damping_rate_per_s"],
                                        support_friction=laws.IwanSupport(
                                            micro["support_friction.stiffness_n_m"],
                                            micro["support_friction.slip_displacement_m"], elements=64)),
                            "single_bead_diagnosis_laws/micro_slip.json#candidates.1.constants"),
        "hertz_bending_alone": (low, "single_bead_joint/fit.json#start.bending_alone"),
    }


def _support_tangent(support: laws.IwanSupport, displacement_m: np.ndarray) -> np.ndarray:
    """The supports' tangent stiffness (N/m) along `displacement_m` (one steady period, sampled),
    stepping the law through a first cycle and counting the stuck elements in the second."""
    path = np.concatenate([displacement_m, displacement_m])
    slider = support.initial_state(jnp.asarray(0.0))
    stuck = []
    for k, x in enumerate(path):
        moved = support.update_state(slider, jnp.asarray(x))
        if k >= displacement_m.size:
            stuck.append(float(jnp.sum(jnp.abs(moved - slider) == 0.0)))
        slider = moved
    return np.asarray(stuck) * float(support.stiffness_n_m) / support.elements


def modulation(chain: DrivenChain, amplitude_m: float) -> dict:
    """$\\varepsilon_1$, $\\varepsilon_2$ of the contacts and the supports at a drive `amplitude_m` (m)."""
    theta = 2 * np.pi * np.arange(SAMPLES) / SAMPLES
    response = complex(np.asarray(frequency_response(chain, np.array([DRIVE_HZ]))[0])[0, 0])
    face = amplitude_m * np.cos(theta)
    bead = np.real(response * amplitude_m * np.exp(1j * theta))
    overlap = np.asarray(chain.static_overlap_m())[None, :] + np.stack([face - bead, bead], axis=1)
    contacts = np.asarray(chain.contact_law.tangent_stiffness(jnp.asarray(overlap), jnp.asarray(overlap),
                                                              chain.contact_constants())).sum(axis=1)
    supports = (np.zeros(SAMPLES) if chain.support_friction is None
                else _support_tangent(chain.support_friction, bead))
    total = contacts + supports
    c = np.fft.rfft(total) / SAMPLES
    cs = np.fft.rfft(supports) / SAMPLES
    return {"amplitude_m": amplitude_m, "bead_amplitude_m": abs(response) * amplitude_m,
            "epsilon_1": float(2 * abs(c[1]) / c[0].real), "epsilon_2": float(2 * abs(c[2]) / c[0].real),
            "supports_epsilon_1": float(2 * abs(cs[1]) / c[0].real),
            "supports_epsilon_2": float(2 * abs(cs[2]) / c[0].real)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(RESULTS / "single_bead_diagnosis_laws"))
    args = parser.parse_args(argv)
    start = started()
    out = {"why": __doc__.splitlines()[0], "drive_hz": DRIVE_HZ, "chains": {}}
    for name, (chain, source) in _chains().items():
        f0 = float(normal_modes(chain)[0][0])
        zeta = float(chain.damping_rate_per_s[0]) / (2 * 2 * math.pi * f0)
        rows = [modulation(chain, a) for a in AMPLITUDES_M]
        eps = np.array([r["epsilon_1"] for r in rows])
        above = np.nonzero(eps >= 4 * zeta)[0]
        tip = None
        if above.size and above[0] > 0:  # log-log interpolation between the bracketing amplitudes
            i = above[0]
            t = math.log(4 * zeta / eps[i - 1]) / math.log(eps[i] / eps[i - 1])
            tip = float(AMPLITUDES_M[i - 1] * (AMPLITUDES_M[i] / AMPLITUDES_M[i - 1]) ** t)
        out["chains"][name] = {"source": source, "resonance_hz": f0, "damping_ratio": zeta,
                               "mathieu_threshold_epsilon": 4 * zeta, "mathieu_tip_m": tip,
                               "static_overlap_m": float(np.asarray(chain.static_overlap_m())[0]),
                               "max_supports_epsilon_1": max(r["supports_epsilon_1"] for r in rows),
                               "rows": rows}
    write_stamped(Path(args.out) / "stiffness_modulation.json", out, start)


if __name__ == "__main__":
    main()
