"""For which impact speeds plasticity matters in the paper's chain (21 steel beads of 13 mm,
sigma_Y = 2 GPa, steel wall) with the elastic-plastic law of measured contacts
(`plastic_law="jackson_green"`).

    python benchmarks/plasticity_speeds.py [--out benchmarks/results/plasticity_speeds]

For each striker speed: the largest bead-bead and wall forces of the elastic chain, the
forces at which the law leaves Hertz there, and with the law: the energy dissipated
plastically and the wall's peak force relative to the elastic chain's. The onset speeds
follow from the elastic peak forces, which scale as v^(6/5) (Hertz), checked on the grid.
Writes `speeds.json` and `speeds.md`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import hertzchain as hc
from hertzchain import atomic

SPEEDS_M_S = (0.1, 0.3, 0.5, 0.8, 1.0, 1.5, 2.0, 3.0)
T_END_S = 1.6e-3


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="benchmarks/results/plasticity_speeds")
    args = parser.parse_args(argv)
    out = Path(args.out)
    plastic_setup = hc.ChainSetup(21, plasticity=True, plastic_law="jackson_green")
    yield_force = np.asarray(plastic_setup.contact_yield_force_n())
    rows = []
    for speed in SPEEDS_M_S:
        elastic = hc.simulate(hc.ChainSetup(21, striker_velocity_m_s=speed), t_end_s=T_END_S, on_yield="ignore")
        plastic = hc.simulate(hc.ChainSetup(21, striker_velocity_m_s=speed, plasticity=True,
                                            plastic_law="jackson_green"), t_end_s=T_END_S)
        peaks = np.asarray(elastic.max_force_n)
        rows.append({
            "striker_speed_m_s": speed,
            "elastic_peak_force_bead_contacts_n": float(peaks[:-1].max()),
            "elastic_peak_force_wall_n": float(peaks[-1]),
            "crosses_bead_yield": bool(np.any(peaks[:-1] > yield_force[:-1])),
            "crosses_wall_yield": bool(peaks[-1] > yield_force[-1]),
            "plastic_dissipation_over_impact_energy": float(plastic.dissipated_plastic_j[-1])
            / float(plastic.initial_energy_j),
            "wall_peak_plastic_over_elastic": float(np.asarray(plastic.max_force_n)[-1]) / float(peaks[-1]),
            "energy_error_over_impact_energy": float(np.max(np.abs(np.asarray(plastic.energy_error_j))))
            / float(plastic.initial_energy_j),
        })
        print(rows[-1], file=sys.stderr)
    # onset: elastic peak force ~ v^(6/5); fitted on the grid (exponent reported as a check)
    speeds = np.array(SPEEDS_M_S)
    result = {"chain": "paper's chain: 21 beads R = 13 mm, 7780 kg/m^3, 203 GPa, nu 0.3, steel wall, sigma_Y 2 GPa",
              "law": "contact.jackson_green_contact (plastic_law='jackson_green'), quasi-static sigma_Y",
              "yield_force_bead_contacts_n": float(yield_force[1]), "yield_force_wall_n": float(yield_force[-1]),
              "rows": rows}
    for label, key, force in (("bead", "elastic_peak_force_bead_contacts_n", yield_force[1]),
                              ("wall", "elastic_peak_force_wall_n", yield_force[-1])):
        peaks = np.array([row[key] for row in rows])
        slope, intercept = np.polyfit(np.log(speeds), np.log(peaks), 1)
        result[f"peak_force_speed_exponent_{label}"] = float(slope)
        result[f"onset_speed_{label}_m_s"] = float(np.exp((np.log(force) - intercept) / slope))
    atomic.write_json(out / "speeds.json", atomic.json_ready(result))
    lines = ["# Plasticity in the paper's chain (Jackson-Green contacts, sigma_Y = 2 GPa)", "",
             f"Contacts leave Hertz at {result['yield_force_bead_contacts_n']:.0f} N between beads and "
             f"{result['yield_force_wall_n']:.0f} N at the wall: striker speeds above "
             f"{result['onset_speed_bead_m_s']:.2f} m/s (beads) and {result['onset_speed_wall_m_s']:.2f} m/s (wall).",
             "", "| striker speed (m/s) | elastic peak, beads (N) | elastic peak, wall (N) | plastic dissipation / "
             "impact energy | wall peak, plastic / elastic |", "|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['striker_speed_m_s']:.2f} | {row['elastic_peak_force_bead_contacts_n']:.0f} | "
                     f"{row['elastic_peak_force_wall_n']:.0f} | {row['plastic_dissipation_over_impact_energy']:.3g} | "
                     f"{row['wall_peak_plastic_over_elastic']:.3f} |")
    atomic.write_text(out / "speeds.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
