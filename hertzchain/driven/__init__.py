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
from .drive import ActuatorMode as ActuatorMode
from .drive import RayleighStroke as RayleighStroke
from .floquet import Floquet as Floquet
from .floquet import floquet_multipliers as floquet_multipliers
from .floquet import period_doubling_threshold as period_doubling_threshold
from .grid import LockinGrid as LockinGrid
from .grid import lockin_grid as lockin_grid
from .grid import settle_periods as settle_periods
from .grid_sweep import LockinSweepResult as LockinSweepResult
from .grid_sweep import read_lockin_sweep as read_lockin_sweep
from .grid_sweep import run_lockin_sweep as run_lockin_sweep
from .lockin import LockIn as LockIn
from .lockin import lockin as lockin
from .schedule import DrivenTraces as DrivenTraces
from .schedule import HarmonicSchedule as HarmonicSchedule
from .schedule import ScheduleLockin as ScheduleLockin
from .schedule import chirp as chirp
from .schedule import lockin_schedule as lockin_schedule
from .schedule import record_sampled as record_sampled
from .schedule import record_schedule as record_schedule
from .steady import SteadyLockin as SteadyLockin
from .steady import lockin_until_steady as lockin_until_steady

__all__ = [
    "ActuatorMode",
    "DrivenChain",
    "DrivenTraces",
    "Floquet",
    "HarmonicSchedule",
    "LockIn",
    "LockinGrid",
    "LockinSweepResult",
    "RayleighStroke",
    "ScheduleLockin",
    "SteadyLockin",
    "chirp",
    "floquet_multipliers",
    "lockin",
    "lockin_grid",
    "lockin_schedule",
    "lockin_until_steady",
    "period_doubling_threshold",
    "read_lockin_sweep",
    "record_sampled",
    "record_schedule",
    "run_lockin_sweep",
    "settle_periods",
]
