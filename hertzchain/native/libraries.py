"""The host libraries of the fused chain kernel, one table (`HOST_LIBRARIES`): each library's
name, the physics it runs (its contacts' law, the rate-slot laws its runs take, compliant
sensors or not), the `-D` macros that compile it, the runs it holds and their FFI targets;
and `host_library_for`, the library that runs a chain's physics.

`chain_kernel.cc` is compiled into several libraries so that the one every run needs does
not wait for the code of laws few runs use (each is built on its first use). A law that the
native kernels run is its templated C++ function (`chain_laws.h`, selected by its macro),
its `laws.registry` name and its macro here: the libraries, their targets, their loading and
which runs they serve follow from this table.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

CSRC = Path(__file__).parent.parent / "kernels" / "csrc"  # the kernels' C++ and CUDA sources
SOURCE = CSRC / "chain_kernel.cc"
# The driven chains' lock-in kernel (`hertzchain.driven.fused`, which registers its targets).
DRIVEN_SOURCE = CSRC / "driven_kernel.cc"

# Each contact law other than Hertz's that the full kernel runs (`batched.KernelFlags.law`,
# `laws.registry.NATIVE_NAMES`): the macro that makes it the library's law (`chain_kernel.cc`'s
# `kLibraryLaw`): the power law (`contact.power_law_force`), Thornton's and Jackson-Green's
# elastic-plastic laws (`contact.thornton_contact`, `contact.jackson_green_contact`). Its
# library runs it with or without a dashpot.
CONTACT_LAW_DEFINES = {"power_law": "HC_POWER_LIBRARY", "thornton": "HC_THORNTON_LIBRARY",
                       "jackson_green": "HC_JACKSON_GREEN_LIBRARY"}

# Each law of the rate slot beside Kuwabara-Kono damping on Hertz contacts (`chain_laws.h`'s
# `RateSlotCoefficient`, with `viscous`): the macros of its library. A linear dashpot's terms
# cost every damped run ~17 % as a runtime term
# (`benchmarks/results/dashpot_kernel/history/dashpot_in_cpp_kernel_not_kept.md`) and the
# main library 36 s -> 50 s of build on 2 cores, so they are compiled in for its runs alone;
# velocity-squared dissipation (`laws.VelocitySquared`) is the dashpot library's code with
# its coefficient c |rate| in the dashpot's place.
RATE_LAW_DEFINES = {"dashpot": ("HC_DASHPOT_LIBRARY",),
                    "velocity_squared": ("HC_DASHPOT_LIBRARY", "HC_VELOCITY_SQUARED_LIBRARY")}

# Compliant sensor beads (`hertzchain.compliant_sensor`; with or without a dashpot, forward
# and tangent runs, no books): on Hertz contacts, or beside a law's macro on that law.
SENSOR_DEFINE = "HC_SENSOR_LIBRARY"

# The kinds of run, by the handler symbol of `chain_kernel.cc` that computes them: the
# conservative step (with or without its books), and the full step's forces, their
# forward-mode tangents, and its run with the books.
SYMBOLS = {"forward": "HertzChainForward", "full": "HertzChainFullForward",
           "tangent": "HertzChainFullTangent", "books": "HertzChainFullBooks"}


class HostLibrary(NamedTuple):
    """One host library of `chain_kernel.cc`: its `name` (as `hertzchain kernel` and
    `native.build_libraries` take it), its contacts' `law` ("hertz" or a
    `CONTACT_LAW_DEFINES` key), `rate`, the rate-slot law compiled in (a
    `RATE_LAW_DEFINES` key, or None), whether its runs carry compliant `sensors`, and the
    `kinds` of run it holds (`SYMBOLS` keys)."""

    name: str
    law: str = "hertz"
    rate: str | None = None
    sensors: bool = False
    kinds: tuple[str, ...] = ("full", "tangent", "books")

    @property
    def defines(self) -> tuple[str, ...]:
        """Its `-D` macros, as the compiler takes them."""
        macros = (CONTACT_LAW_DEFINES[self.law],) if self.law != "hertz" else ()
        macros += RATE_LAW_DEFINES[self.rate] if self.rate else ()
        return tuple(f"-D{m}" for m in macros + ((SENSOR_DEFINE,) if self.sensors else ()))

    @property
    def rates(self) -> tuple[str | None, ...]:
        """The rate-slot laws its runs take (None: none): its own where one is compiled in;
        the libraries of another law and the compliant sensors' run a dashpot as a runtime
        term too (`chain_kernel.cc`'s `RunFull`), the main library none."""
        if self.rate:
            return (self.rate,)
        return (None, "dashpot") if self.law != "hertz" or self.sensors else (None,)

    @property
    def runs_on_threads(self) -> bool:
        """Whether the GPU's thread kernels (`chain_kernel_thread.cu`) run its chains too:
        Hertz contacts with or without a dashpot (one thread library holds both), no
        compliant sensors."""
        return self.law == "hertz" and not self.sensors and set(self.rates) <= {None, "dashpot"}

    @property
    def what(self) -> str:
        """How messages name it."""
        if self.name == "chain":
            return "the fused C++ kernel"
        if self.sensors:
            return "the fused chain kernel's compliant sensors" + (f" on {self.law}" if self.law != "hertz" else "")
        return f"the fused chain kernel's {self.name.replace('_', '-')} runs"

    def target(self, kind: str) -> str:
        """The FFI target of its runs of `kind` ("forward": the main library only, "full",
        "tangent", "books")."""
        if kind not in self.kinds:
            raise ValueError(f"the {self.name} library holds no {kind!r} runs (it holds {self.kinds}).")
        if kind == "forward":
            return "hertzchain_chain_forward"
        suffix = f"_{self.law}" if self.law != "hertz" else f"_{self.rate}" if self.rate else ""
        return f"hertzchain_chain_full_{'forward' if kind == 'full' else kind}{suffix}" + (
            "_sensors" if self.sensors else "")

    @property
    def targets(self) -> tuple[tuple[str, str], ...]:
        """Its (FFI target, handler symbol) pairs."""
        return tuple((self.target(kind), SYMBOLS[kind]) for kind in self.kinds)


_SENSOR_KINDS = ("full", "tangent")  # the compliant sensors' libraries keep no books

# Every host library of `chain_kernel.cc`, by name, in the order `hertzchain kernel --all`
# starts their builds: the main library every run needs, the rate-slot laws', the compliant
# sensors', then each other contact law's and its compliant sensors'.
HOST_LIBRARIES: dict[str, HostLibrary] = {
    library.name: library for library in (
        HostLibrary("chain", kinds=("forward", "full", "tangent", "books")),
        *(HostLibrary(rate, rate=rate) for rate in RATE_LAW_DEFINES),
        HostLibrary("compliant sensors", sensors=True, kinds=_SENSOR_KINDS),
        *(HostLibrary(law, law=law) for law in CONTACT_LAW_DEFINES),
        *(HostLibrary(f"{law} compliant sensors", law=law, sensors=True, kinds=_SENSOR_KINDS)
          for law in CONTACT_LAW_DEFINES),
    )
}

# The contact laws the full kernel runs.
CONTACT_LAWS = ("hertz",) + tuple(CONTACT_LAW_DEFINES)


def host_library_for(law: str = "hertz", rate: str | None = None, sensors: bool = False) -> HostLibrary | None:
    """The host library whose runs take contacts of `law` (a `CONTACT_LAWS` name), the
    rate-slot law `rate` (a `RATE_LAW_DEFINES` key, or None) and, where `sensors`, compliant
    sensors; None where no library runs them together (the JAX kernel does)."""
    if law not in CONTACT_LAWS:
        raise ValueError(f"law must be one of {CONTACT_LAWS}, got {law!r}.")
    if rate is not None and rate not in RATE_LAW_DEFINES:
        raise ValueError(f"rate must be None or one of {tuple(RATE_LAW_DEFINES)}, got {rate!r}.")
    for library in HOST_LIBRARIES.values():  # (at most one runs each combination: tests/test_native_libraries.py)
        if library.law == law and library.sensors == bool(sensors) and rate in library.rates:
            return library
    return None
