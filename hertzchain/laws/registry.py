"""The one table from law types to the native kernels.

Each contact law maps to its `batched.KernelFlags.law` name (the native library it selects,
`native.HOST_LIBRARIES`); each dissipation law to the kernels' name for it: Kuwabara-Kono
damping's is the `KernelFlags` field that compiles it in ("viscous"), the rate slot's laws'
are `KernelFlags.rate_law`'s values (`native.RATE_LAW_DEFINES`).
None: no native kernel has the law, and the JAX kernels run it (`BatchedTraces.kernel`
says which kernel ran).
"""

from __future__ import annotations

import jax
import numpy as np

from ..validation import as_float64
from .contact_law import AbstractContactLaw
from .dissipation import AbstractDissipation, Dashpot, HuntCrossley, VelocitySquared, Viscoelastic
from .elastic import Hertz, PowerLaw
from .plastic import JacksonGreen, Thornton
from .rough import RoughContact
from .series import SeriesCompliance

NATIVE_NAMES: dict[type, str | None] = {
    Hertz: "hertz",
    PowerLaw: "power_law",
    Thornton: "thornton",
    JacksonGreen: "jackson_green",
    Viscoelastic: "viscous",
    Dashpot: "dashpot",
    VelocitySquared: "velocity_squared",
    HuntCrossley: None,
    SeriesCompliance: None,
    RoughContact: None,
}


def native_name(law: AbstractContactLaw | AbstractDissipation) -> str | None:
    """The native name of `law` (a law instance), or None where only the JAX kernels run it."""
    try:
        return NATIVE_NAMES[type(law)]
    except KeyError:
        raise ValueError(f"{type(law).__name__} is not in hertzchain.laws.registry.NATIVE_NAMES; add it there "
                         "(None where no native kernel runs it).") from None


def contact_law_named(name: str) -> type[AbstractContactLaw]:
    """The contact-law class whose native name is `name` (a `KernelFlags.law`)."""
    for law, native in NATIVE_NAMES.items():
        if native == name and issubclass(law, AbstractContactLaw):
            return law
    known = sorted(n for law, n in NATIVE_NAMES.items() if n and issubclass(law, AbstractContactLaw))
    raise ValueError(f"no contact law is named {name!r}; known: {known}.")


def runs_natively(contact_law: AbstractContactLaw, dissipation=()) -> bool:
    """Whether the native kernels have every law of a chain."""
    return all(native_name(law) is not None for law in (contact_law, *dissipation))


# The elastic-plastic laws by the names the command line and experiment files give them.
PLASTIC_LAW_NAMES = ("thornton", "jackson_green")


def contact_law_from_keywords(*, plasticity: bool = False, plastic_law: str = "thornton", power_law=None,
                              contact_exponent=1.5, exponent_reference_overlap_m=1e-5) -> AbstractContactLaw:
    """The contact law that the keyword spelling of the command line and of setup files
    describes: elastic-plastic (`plasticity`, `plastic_law` one of `PLASTIC_LAW_NAMES`), a
    power law of exponent `contact_exponent` equal to Hertz's at `exponent_reference_overlap_m`
    (m; `power_law` None: wherever the exponent is not 1.5), else Hertz's."""
    if plastic_law not in PLASTIC_LAW_NAMES:
        raise ValueError(f"plastic_law must be one of {PLASTIC_LAW_NAMES}, got {plastic_law!r}.")
    exponent = as_float64(contact_exponent, "contact_exponent")
    reference = as_float64(exponent_reference_overlap_m, "exponent_reference_overlap_m")
    if power_law is None:
        power_law = not isinstance(exponent, jax.core.Tracer) and bool(np.any(np.asarray(exponent) != 1.5))
    if power_law and plasticity:
        raise ValueError("contact_exponent != 1.5 (power_law) and plasticity=True cannot be combined: "
                         "the elastic-plastic law is built on Hertz contacts.")
    if plasticity:
        return contact_law_named(plastic_law)()
    if power_law:
        return PowerLaw(exponent, reference)
    return Hertz()


