"""Driven chains: beads between a driven face and a wall, their steady response and lock-in.

A `DrivenChain` holds the physical constants (bead masses, each contact's Hertz stiffness,
the static precompression, viscous damping). `lockin_grid` runs a frequency × drive-
amplitude grid as one batch and returns the lock-in RMS and phase of a bead's velocity or
displacement at harmonics of the drive, differentiable in forward mode:

    chain = DrivenChain.from_materials(n_beads=1, bead_radius_m=9.525e-3, bead_mass_kg=0.028,
                                       bead_youngs_pa=193e9, bead_poisson=0.3,
                                       driver_youngs_pa=193e9, driver_poisson=0.3,
                                       wall_youngs_pa=193e9, wall_poisson=0.3,
                                       precompression_n=4.5, damping_rate_per_s=1800.0)
    grid = lockin_grid(chain, frequencies_hz, drive_amplitudes_m)   # .rms, .phase_rad: (2, F, A)
"""

from .chain import DrivenChain as DrivenChain
from .grid import LockinGrid as LockinGrid
from .grid import lockin_grid as lockin_grid
from .grid import settle_periods as settle_periods
from .lockin import LockIn as LockIn
from .lockin import lockin as lockin

__all__ = ["DrivenChain", "LockIn", "LockinGrid", "lockin", "lockin_grid", "settle_periods"]
