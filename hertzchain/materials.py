"""Elastic materials of beads and walls, with their sources.

All values are SI: Young's modulus in Pa, density in kg/m^3, yield stress in Pa.
The catalogue holds the paper's bead steel and the wall samples of its Fig. 3
(plexiglass, Mg, Cu, Si, Fe, W and the 5 GPa sample), plus a few common bead
materials for other setups.
"""

from __future__ import annotations

import dataclasses
import math


@dataclasses.dataclass(frozen=True)
class Material:
    """An isotropic linear-elastic material.

    **Arguments:**

    - `name`: short name used in tables and files.
    - `youngs_pa`: Young's modulus $Y$, Pa.
    - `poisson`: Poisson ratio $\\nu$, in (-1, 0.5).
    - `density_kg_m3`: density, kg/m^3 (None for a wall-only sample whose
      density does not enter the dynamics).
    - `yield_stress_pa`: compressive yield stress $\\sigma_Y$, Pa (None if unknown).
    - `source`: where the numbers come from.
    - `yield_rate_constant`: C of the rate hardening $\\sigma_Y(1 + C\\ln(\\dot\\varepsilon/10^{-3}\\,
      \\mathrm{s}^{-1}))$ (`contact.rate_hardened_yield_stress`); None if unknown.
    """

    name: str
    youngs_pa: float
    poisson: float
    density_kg_m3: float | None = None
    yield_stress_pa: float | None = None
    source: str = ""
    yield_rate_constant: float | None = None

    def __post_init__(self):
        if not (math.isfinite(self.youngs_pa) or self.youngs_pa == math.inf) or self.youngs_pa <= 0:
            raise ValueError(f"Material {self.name!r}: youngs_pa must be > 0 Pa, got {self.youngs_pa}.")
        if not -1.0 < self.poisson < 0.5:
            raise ValueError(f"Material {self.name!r}: poisson must lie in (-1, 0.5), got {self.poisson}.")
        if self.density_kg_m3 is not None and not self.density_kg_m3 > 0:
            raise ValueError(
                f"Material {self.name!r}: density_kg_m3 must be > 0, got {self.density_kg_m3}."
            )

    @property
    def theta_per_pa(self) -> float:
        """Elastic constant $\\theta = 3(1-\\nu^2)/(4Y)$ of the paper, 1/Pa."""
        return 3.0 * (1.0 - self.poisson**2) / (4.0 * self.youngs_pa)


_HANDBOOK = "room-temperature handbook value (CRC Handbook of Chemistry and Physics)"

BEAD_STEEL = Material(
    "bead_steel",
    youngs_pa=203e9,
    poisson=0.3,
    density_kg_m3=7780.0,
    yield_stress_pa=2e9,
    source="Job et al., PRL 94, 178002 (2005): AISI 52100 (JIS SUJ2) beads, "
    "Y = 203 +/- 4 GPa, nu = 0.3 assumed, rho = 7780 kg/m^3, sigma_Y = 2 GPa",
)

PLEXIGLASS = Material(
    "plexiglass", 3.0e9, 0.35, 1190.0, source="PMMA, " + _HANDBOOK + "; range 2.4-3.3 GPa"
)
MAGNESIUM = Material("Mg", 45e9, 0.29, 1738.0, source=_HANDBOOK)
COPPER = Material("Cu", 130e9, 0.34, 8960.0, source=_HANDBOOK)
SILICON = Material(
    "Si", 160e9, 0.22, 2329.0, source="polycrystalline average; single crystal 130-188 GPa by orientation"
)
IRON = Material("Fe", 211e9, 0.29, 7874.0, source=_HANDBOOK)
TUNGSTEN = Material("W", 411e9, 0.28, 19250.0, source=_HANDBOOK)
SOFT_5GPA = Material(
    "soft_5GPa", 5e9, 0.3, None, source="the 5 GPa sample of the paper's Fig. 3b/c; nu = 0.3 assumed"
)
PTFE = Material("PTFE", 1.46e9, 0.46, 2200.0, source="Daraio et al., PRE 72, 016603 (2005)")
BRASS = Material("brass", 110e9, 0.34, 8500.0, source=_HANDBOOK)
GLASS = Material("glass", 63e9, 0.22, 2500.0, source="soda-lime glass, " + _HANDBOOK)
_BURGOYNE = ("Burgoyne & Daraio, PRE 89, 032203 (2014), Table I and Fig. 4 (the constants of their "
             "contact model; rate constant of Al 2017 from Fig. 4c)")
STEEL_440C = Material("steel_440C", 200e9, 0.3, 7650.0, 1896e6, _BURGOYNE, yield_rate_constant=0.035)
STEEL_302 = Material("steel_302", 200e9, 0.3, 7900.0, 600e6, _BURGOYNE, yield_rate_constant=0.025)
ALUMINIUM_2017 = Material("Al_2017", 76e9, 0.3, 2700.0, 276e6, _BURGOYNE, yield_rate_constant=0.003)

MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        BEAD_STEEL,
        PLEXIGLASS,
        MAGNESIUM,
        COPPER,
        SILICON,
        IRON,
        TUNGSTEN,
        SOFT_5GPA,
        PTFE,
        BRASS,
        GLASS,
        STEEL_440C,
        STEEL_302,
        ALUMINIUM_2017,
    )
}

# The wall samples of the paper's Fig. 3a, in the paper's order and spelling.
PAPER_WALL_MATERIALS: tuple[str, ...] = ("plexiglass", "Mg", "Cu", "Si", "Fe", "W")


# Common names of catalogue materials: the same material, not another one.
ALIASES: dict[str, str] = {
    "steel": "bead_steel",  # the bearing steel (AISI 52100) of most granular-chain beads
    "PMMA": "plexiglass",
    "magnesium": "Mg",
    "copper": "Cu",
    "silicon": "Si",
    "iron": "Fe",
    "tungsten": "W",
    "teflon": "PTFE",
}


def material(name: str) -> Material:
    """Look a material up by name or alias (`ALIASES`), case-insensitive; raises
    `ValueError` with the known names."""
    wanted = name.strip().lower()
    for alias, key in ALIASES.items():
        if alias.lower() == wanted:
            wanted = key.lower()
    for key, value in MATERIALS.items():
        if key.lower() == wanted:
            return value
    aliases = ", ".join(f"{alias} = {key}" for alias, key in ALIASES.items())
    raise ValueError(f"Unknown material {name!r}; known materials: {', '.join(MATERIALS)} (also {aliases}).")


def sphere_volume_m3(radius_m):
    """Volume of a sphere of radius `radius_m` (m; a float or an array), m^3."""
    return 4.0 / 3.0 * math.pi * radius_m**3


def sphere_mass_kg(radius_m, density_kg_m3):
    """Mass of a solid sphere of radius `radius_m` (m) and density `density_kg_m3` (kg/m^3),
    kg (floats or arrays)."""
    return 4.0 / 3.0 * math.pi * density_kg_m3 * radius_m**3
