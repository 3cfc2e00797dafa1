"""Unit conversion at the edges (command line, files, reports): everything inside is SI.

`parse_quantity("13mm", "m")` -> 0.013. A bare number is taken as SI. Accepted suffixes
are SI prefixes on the expected unit (`13mm`, `5GPa`, `2us`, `85kHz`, `0.3m/s`), plus
`um`/`µm`/`us`/`µs` for micro, and for masses prefixes on the gram (`8.9g`, `880mg`).
`parse_field("wall_youngs_pa", "5GPa")` takes the unit from the field's name: SI field names
end in their unit (`unit_of_field`).
"""

from __future__ import annotations

import math
import re

_PREFIXES = {
    "": 1.0, "p": 1e-12, "n": 1e-9, "u": 1e-6, "µ": 1e-6, "m": 1e-3, "c": 1e-2,
    "k": 1e3, "M": 1e6, "G": 1e9, "T": 1e12,
}
_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?inf)\s*(.*?)\s*$")


def parse_quantity(text: str | float, unit: str, *, name: str = "value") -> float:
    """Parse `text` as a quantity in `unit` and return it in SI.

    **Raises:** `ValueError` naming `name` when the text is not a number, or carries a
    unit other than `unit` with an SI prefix.
    """
    if isinstance(text, (int, float)):
        return float(text)
    match = _NUMBER.match(str(text))
    if not match:
        raise ValueError(f"{name}: cannot read {text!r} as a number in {unit}.")
    number, suffix = float(match.group(1)), match.group(2)
    if not suffix or suffix == unit:
        return number
    if unit and suffix.endswith(unit):
        prefix = suffix[: -len(unit)]
        if prefix in _PREFIXES:
            return number * _PREFIXES[prefix]
    if unit == "kg" and suffix.endswith("g") and suffix[:-1] in _PREFIXES:  # grams: 880mg, 0.88g
        return number * _PREFIXES[suffix[:-1]] * 1e-3
    raise ValueError(
        f"{name}: unit {suffix!r} in {text!r} is not a prefixed {unit!r} "
        f"(e.g. 13mm, 5GPa, 2us); give the value in {unit or 'SI units'}."
    )


# The unit a field name's suffix stands for (`bead_radius_m`, `wall_youngs_pa`, `eta_s`);
# a name without one of these suffixes is dimensionless.
FIELD_UNITS = {
    "_m": "m", "_pa": "Pa", "_kg": "kg", "_s": "s", "_hz": "Hz", "_n": "N", "_v": "V",
    "_m_s": "m/s", "_kg_m3": "kg/m3", "_n_s_m": "Ns/m",
}


def column_name(name: str, unit: str) -> str:
    """A table column for `name` that states its unit: the unit's field suffix where it has
    one (`column_name("eta", "s")` -> `"eta_s"`, `"striker_velocity[shot1]"`, `"m/s"` ->
    `"striker_velocity_m_s[shot1]"`), else `"name (unit)"`; `name` alone when dimensionless."""
    if unit in ("", "1"):
        return name
    suffixes = {u: suffix for suffix, u in FIELD_UNITS.items()}
    suffixes["N s/m"] = "_n_s_m"
    if unit not in suffixes:
        return f"{name} ({unit})"
    base, bracket, rest = name.partition("[")  # a per-file label: striker_velocity_m_s[shot1]
    return base + suffixes[unit] + bracket + rest


def unit_of_field(name: str) -> str:
    """The unit of a field from its name's suffix (`"eta_s"` -> `"s"`; `""` if dimensionless)."""
    for suffix in sorted(FIELD_UNITS, key=len, reverse=True):
        if name.endswith(suffix):
            return FIELD_UNITS[suffix]
    return ""


def parse_field(name: str, text: str | float, *, where: str | None = None) -> float:
    """Parse the value of the field `name` in the unit its name carries, to SI
    (`parse_field("eta_s", "2us")` -> 2e-06); errors name `where` (default: the field)."""
    return parse_quantity(text, unit_of_field(name), name=where or name)


# Units shown with an SI prefix chosen for the value (20 GPa, 2 µs, 600 MPa); others as they are.
_PREFIXED_UNITS = ("Pa", "s", "m", "N", "Hz", "J", "V")
_DISPLAY_PREFIXES = (("T", 1e12), ("G", 1e9), ("M", 1e6), ("k", 1e3), ("", 1.0), ("m", 1e-3),
                     ("µ", 1e-6), ("n", 1e-9), ("p", 1e-12))


def display_unit(unit: str) -> str:
    """A unit as human text says it: `""` or `"1"` -> `"dimensionless"`, `"us"` -> `"µs"`."""
    if unit in ("", "1"):
        return "dimensionless"
    return re.sub(r"\bu(?=[a-zA-Z])", "µ", unit)


def _prefixed(magnitude: float, unit: str) -> tuple[str, float]:
    if unit not in _PREFIXED_UNITS or not math.isfinite(magnitude) or magnitude == 0:
        return unit, 1.0
    for prefix, factor in _DISPLAY_PREFIXES:
        if magnitude >= factor:
            return prefix + unit, factor
    return "p" + unit, 1e-12


def format_measured(value: float, sigma: float | None, unit: str = "", *, why: str = "") -> str:
    """A fitted value with its standard error in human units, to the digits the error allows:
    `format_measured(2.031e10, 1.2e9, "Pa")` -> `"20.3 ± 1.2 GPa"`. The error is given to two
    significant digits and the value to the same decimal place. Without a finite, positive
    error (None, nan, inf, 0) the value is given to four digits and the text says
    `"σ not determined"`, with `why` where given. A dimensionless value has no unit."""
    value = float(value)
    determined = sigma is not None and math.isfinite(float(sigma)) and float(sigma) > 0
    shown, factor = _prefixed(abs(value) if value else (float(sigma) if determined else 0.0), unit)
    suffix = f" {display_unit(shown)}" if unit not in ("", "1") else ""
    if not math.isfinite(value):
        return f"{value:g}{suffix}"
    if not determined:
        note = f"σ not determined: {why}" if why else "σ not determined"
        return f"{value / factor:.4g}{suffix} ({note})"
    scaled_sigma = float(sigma) / factor
    decimals = max(0, 1 - math.floor(math.log10(scaled_sigma)))
    return f"{value / factor:.{decimals}f} ± {scaled_sigma:.{decimals}f}{suffix}"


def format_si(value: float, unit: str) -> str:
    """A short human string for an SI value, e.g. 2e-06, 's' -> '2 us'."""
    if value == 0 or not math.isfinite(value):
        return f"{value:g} {unit}"
    for prefix, factor in (("G", 1e9), ("M", 1e6), ("k", 1e3), ("", 1.0), ("m", 1e-3), ("u", 1e-6), ("n", 1e-9)):
        if abs(value) >= factor:
            return f"{value / factor:.4g} {prefix}{unit}"
    return f"{value:g} {unit}"


def counted(count: int, noun: str, plural: str | None = None) -> str:
    """A count with its noun in the number the count asks for: `counted(1, "chunk")` ->
    `"1 chunk"`, `counted(3, "chunk")` -> `"3 chunks"`; `plural` for a noun whose plural
    is not the noun with an `s` (`counted(2, "library", "libraries")`)."""
    return f"{count} {noun if count == 1 else plural or noun + 's'}"
