"""The one table from law types to the native kernels.

Each contact law maps to its `batched.KernelFlags.law` name (the native library it selects,
`native.LAW_DEFINES`); each dissipation law to the `KernelFlags` field that compiles it in.
None: no native kernel has the law, and the JAX kernels run it (`BatchedTraces.kernel`
says which kernel ran).
"""

from __future__ import annotations

from .contact_law import AbstractContactLaw
from .dissipation import AbstractDissipation, Dashpot, VelocitySquared, Viscoelastic
from .elastic import Hertz, PowerLaw
from .plastic import JacksonGreen, Thornton

NATIVE_NAMES: dict[type, str | None] = {
    Hertz: "hertz",
    PowerLaw: "power_law",
    Thornton: "thornton",
    JacksonGreen: "jackson_green",
    Viscoelastic: "viscous",
    Dashpot: "dashpot",
    VelocitySquared: None,
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
