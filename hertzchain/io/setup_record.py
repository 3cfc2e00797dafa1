"""A setup as a record: every field by name, in a canonical JSON-ready form.

The one serialisation of a `ChainSetup`, written into the sweep manifest (and hashed there)
and into simulate's summary.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..chain import ChainSetup


def canonical(value):
    """A JSON-ready, canonical form of a setup value: arrays as numbers or lists, non-finite
    numbers as strings, equinox modules as their class name and fields (recursively)."""
    import equinox as eqx

    if isinstance(value, eqx.Module):
        return {"class": type(value).__name__,
                **{f.name: canonical(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    if isinstance(value, (bool, np.bool_, str)) or value is None:
        return value.item() if isinstance(value, np.bool_) else value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (tuple, list)):
        return [canonical(v) for v in value]
    if isinstance(value, dict):
        return {str(k): canonical(v) for k, v in value.items()}
    array = np.asarray(value, dtype=float)
    numbers = [x if math.isfinite(x) else str(x) for x in array.ravel().tolist()]
    return numbers[0] if array.ndim == 0 else numbers


# The laws' coefficients that ChainSetup names as attributes (`law_attributes`), as options and
# grids name them: (field holding the law, index in a sequence or None, the law's field, name).
_NAMED_COEFFICIENTS = (
    ("dissipation", 0, "eta_s", "eta_s"),
    ("dissipation", 1, "gamma_n_s_m", "dashpot_n_s_m"),
    ("contact_law", None, "exponent", "contact_exponent"),
    ("contact_law", None, "reference_overlap_m", "exponent_reference_overlap_m"),
)


def setup_record(setup: ChainSetup) -> dict:
    """Every field of a (non-batched) setup, by name, in a canonical JSON-ready form: a field
    added to `ChainSetup` (or a law object inside it) is covered without naming it here.

    The coefficients that `ChainSetup` names (`eta_s`, `dashpot_n_s_m`, a power law's
    `contact_exponent`) stand under those names, as grids and options give them; every other
    law stands under its class name with its fields (`contact_law.class`,
    `dissipation.VelocitySquared.c_n_s2_m2`), so a difference is named to the coefficient."""
    record = canonical(setup)
    laws_given = record["dissipation"]
    for holder, index, field, name in _NAMED_COEFFICIENTS:
        law = record[holder] if index is None else laws_given[index]
        if field in law:
            record[name] = law.pop(field)
    others: dict = {}
    for law in laws_given[2:]:
        name = law.pop("class")
        others[name if name not in others else f"{name}#{sum(k.split('#')[0] == name for k in others) + 1}"] = law
    record["dissipation"] = others
    return record
