"""float64 in JAX, which the physics needs, switched on once and checked where work starts.

Energy is conserved to 1e-6 and gradients match finite differences to 1e-5 only in double
precision; in float32 the same code runs but its numbers are wrong. So hertzchain does not
run in float32: importing it switches `jax_enable_x64` on, refuses to import where the
environment switches it off (`JAX_ENABLE_X64=0`), and `require_float64` refuses to start a
computation after a program switched it off again.
"""

from __future__ import annotations

import os

import jax

_OFF = ("0", "false", "no", "off")


class Float64Error(RuntimeError):
    """hertzchain asked to compute with JAX's float64 switched off."""


def enable_float64() -> None:
    """Switch `jax_enable_x64` on; raise `Float64Error` where `JAX_ENABLE_X64` says off."""
    setting = os.environ.get("JAX_ENABLE_X64")
    if setting is not None and setting.strip().lower() in _OFF:
        raise Float64Error(
            f"hertzchain computes in float64, but the environment sets JAX_ENABLE_X64={setting}: "
            "unset it (or set JAX_ENABLE_X64=1) and run again."
        )
    jax.config.update("jax_enable_x64", True)


def require_float64(where: str) -> None:
    """Raise `Float64Error` naming `where` when `jax_enable_x64` is off."""
    if not jax.config.jax_enable_x64:
        raise Float64Error(
            f"{where}: JAX's float64 is switched off (jax_enable_x64 = False) and hertzchain would "
            "compute in float32; call jax.config.update('jax_enable_x64', True) before, or do not "
            "switch it off after importing hertzchain."
        )
