"""hertzchain: differentiable simulation of 1-D granular chains of beads in Hertzian contact.

Importing the package enables float64 in JAX (`jax_enable_x64`): the physics needs it
(energy is conserved to 1e-6 and gradients match finite differences to 1e-5 only in
double precision). It refuses to import where `JAX_ENABLE_X64=0` is set, and to simulate
after a program switched float64 off (`hertzchain.precision`). Everything is SI inside;
public arguments carry their unit in their name.

Reference: S. Job, F. Melo, A. Sokolow, S. Sen, "How Hertzian solitary waves interact with
boundaries in a 1-D granular medium", Phys. Rev. Lett. 94, 178002 (2005).
"""

from .precision import enable_float64

enable_float64()

from . import contact, laws, materials  # noqa: E402
from . import acquisition, pulses, sensor, theory  # noqa: E402
from .chain import ChainModel, ChainSetup, build_model  # noqa: E402
from .integrate import (  # noqa: E402
    Recording,
    YieldWarning,
    batch_setup,
    simulate,
    simulate_batch,
    solve,
)
from .materials import MATERIALS, Material, material  # noqa: E402
from .timegrid import TimeGrid, choose_time_grid, shortest_contact_time_s  # noqa: E402
from .traces import Traces  # noqa: E402

from ._version import installed_version  # noqa: E402

__version__ = installed_version()

__all__ = [
    "ChainModel",
    "ChainSetup",
    "MATERIALS",
    "Material",
    "Recording",
    "TimeGrid",
    "Traces",
    "YieldWarning",
    "acquisition",
    "batch_setup",
    "build_model",
    "choose_time_grid",
    "contact",
    "laws",
    "material",
    "materials",
    "pulses",
    "sensor",
    "shortest_contact_time_s",
    "simulate",
    "simulate_batch",
    "solve",
    "theory",
]
