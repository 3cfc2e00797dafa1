"""Priors a lab can write down: tolerances of materials, sensors and strikers.

A prior is written `name=VALUE`, with the parameter's unit and SI prefixes:

- `bead_youngs_pa=203GPa+-4GPa`: normal, centre 203 GPa, standard deviation 4 GPa;
- `sensor_gain=+-2%`, `bead_radius_m=+-62.5um`: normal around the nominal value (the trace
  header's, or the parameter's default such as gain 1), absolute or relative width;
- `eta_s=0..10us`: uniform on an interval (it narrows the parameter's bounds).

Units: a width or bound written without a unit takes the unit written on the value beside
it (`203GPa+-4` is 4 GPa, `0..10us` 0 to 10 us); where nothing beside it carries a unit, a
bare number is SI (`203e9+-4e9`), except a width with no centre (`+-4`) of a parameter that
has a unit: that is refused, the width must carry its unit (`+-4GPa`) or be relative (`+-2%`).

`name` is a parameter's name (every instance of it: each file's striker velocity, each
sensor's gain) or one instance's label (`striker_velocity_m_s[run1]`, `sensor_gain[wall]`),
written as `fitting.parameters.resolve_name` reads it (a previous name warns).
A parameter with a prior is free: a tolerance is a statement that the value is not known
exactly. A parameter without a prior has a flat prior on its registry bounds (positive
where physics says so: moduli, C, gains; non-negative eta, mu).

A normal prior enters the least-squares problem as one more whitened residual,
$(x - \\mathrm{centre})/\\mathrm{sd}$ (a pseudo-measurement of the parameter), so the
least-squares optimum is the maximum a posteriori point and the Jacobian's covariance is
the Laplace approximation of the posterior with the prior included. The normal is
truncated to the parameter's bounds (far out in its tails for every tolerance a lab
quotes).
"""

from __future__ import annotations

import dataclasses
import math
import re

from hertzchain.units import parse_quantity

from .parameters import ParameterInstance, get_spec, public_label, resolve_label

_UNIFORM = re.compile(r"^(.+?)\.\.(.+)$")
# The prefix of the unit a lab writes tolerances in, for the examples of error messages.
_EXAMPLE_PREFIX = {"Pa": "G", "s": "u", "m": "u", "N": "", "m/s": ""}


class PriorError(ValueError):
    """A prior that cannot be read or applied; the message names it and the fix."""


@dataclasses.dataclass(frozen=True)
class Prior:
    """A lab's knowledge of one parameter, SI units.

    **Fields:**

    - `key`: registry name (every instance) or an instance label (registry spelling).
    - `kind`: `"normal"` or `"uniform"`.
    - `centre`: centre of a normal (None: each instance's nominal value).
    - `sd`: absolute standard deviation of a normal, or None.
    - `relative_sd`: standard deviation as a fraction of the centre, or None.
    - `low`, `high`: interval of a uniform.
    - `text`: what the user wrote (for reports).
    """

    key: str
    kind: str
    centre: float | None = None
    sd: float | None = None
    relative_sd: float | None = None
    low: float | None = None
    high: float | None = None
    text: str = ""

    @property
    def name(self) -> str:
        """The registry name of the parameter."""
        return self.key.split("[", 1)[0]


@dataclasses.dataclass(frozen=True)
class NormalRow:
    """A resolved normal prior: parameter `index` of the problem, `centre`, `sd` (SI)."""

    index: int
    centre: float
    sd: float


def _value(text: str, unit: str, where: str) -> float:
    return parse_quantity(text.strip(), unit, name=where)


def _written_unit(text: str) -> str:
    """The unit written after the number in `text` ("GPa" of "203GPa"; "" for a bare number)."""
    match = re.match(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*(.*?)\s*$", text)
    return match.group(1) if match else ""


def _with_unit_of(text: str, other: str) -> str:
    """`text` with the unit written on `other` when `text` is a bare number (see the module docstring)."""
    return text + _written_unit(other) if text and not _written_unit(text) else text


def parse_prior(text: str, *, source: str | None = None) -> Prior:
    """Read `name=203GPa+-4GPa`, `name=+-2%`, `name=1+-0.02` or `name=0..10us`; `source`: the
    argument, option or file it was written in (`priors`, `--prior`), named in the warning a
    previous name gives."""
    if "=" not in text:
        raise PriorError(
            f"prior {text!r}: expected name=VALUE+-SD, name=+-SD%, or name=LOW..HIGH "
            "(e.g. bead_youngs_pa=203GPa+-4GPa, sensor_gain=+-2%)."
        )
    written, value = (part.strip() for part in text.split("=", 1))
    key = resolve_label(written, where=source)
    spec = get_spec(key.split("[", 1)[0])
    unit = spec.unit if spec.unit in ("s", "Pa", "N", "m/s", "m") else ""
    where = f"prior {public_label(key)}"
    uniform = _UNIFORM.match(value)
    if uniform:
        low_text, high_text = (v.strip() for v in uniform.groups())
        low = _value(_with_unit_of(low_text, high_text), unit, where)
        high = _value(_with_unit_of(high_text, low_text), unit, where)
        if not low < high:
            raise PriorError(f"{where}: the interval {value!r} needs LOW < HIGH.")
        return Prior(key, "uniform", low=low, high=high, text=text)
    if "+-" not in value:
        raise PriorError(
            f"{where}: {value!r} has no width; write VALUE+-SD (e.g. 203GPa+-4GPa), +-SD% "
            "around the nominal value, or LOW..HIGH."
        )
    centre_text, width_text = (part.strip() for part in value.split("+-", 1))
    centre = _value(centre_text, unit, where) if centre_text else None
    if width_text.endswith("%"):
        relative = float(width_text[:-1]) / 100.0
        if not relative > 0:
            raise PriorError(f"{where}: the width {width_text!r} must be positive.")
        return Prior(key, "normal", centre=centre, relative_sd=relative, text=text)
    if centre_text:
        width_text = _with_unit_of(width_text, centre_text)
    elif unit and not _written_unit(width_text):
        raise PriorError(f"{where}: the width {width_text!r} has no unit; write it with the unit of {written} "
                         f"(e.g. +-{width_text}{_EXAMPLE_PREFIX.get(unit, '')}{unit}) or relative (+-2%).")
    sd = _value(width_text, unit, where)
    if not sd > 0:
        raise PriorError(f"{where}: the width {width_text!r} must be positive.")
    return Prior(key, "normal", centre=centre, sd=sd, text=text)


def parse_priors(texts, *, source: str | None = None) -> tuple[Prior, ...]:
    """Parse several priors (`source` as in `parse_prior`); a parameter given twice, in either
    spelling, is an error naming both."""
    priors = tuple(p if isinstance(p, Prior) else parse_prior(p, source=source) for p in texts or ())
    seen = {}
    for prior in priors:
        if prior.key in seen:
            raise PriorError(f"two priors for {public_label(prior.key)}: {seen[prior.key]!r} and {prior.text!r}; "
                             "keep one.")
        seen[prior.key] = prior.text
    return priors


def prior_names(priors) -> tuple[str, ...]:
    """Registry names the priors free (in order, without repeats)."""
    return tuple(dict.fromkeys(prior.name for prior in priors))


def _matches(prior: Prior, inst: ParameterInstance) -> bool:
    return prior.key == inst.label or prior.key == inst.name


def apply_priors(priors, instances, nominal) -> tuple[list[ParameterInstance], tuple[NormalRow, ...]]:
    """Bind priors to a problem's parameter instances.

    `nominal[i]`: the nominal value (SI) of instance i (header value or default), used as
    the centre of a prior written without one. Returns the instances (uniform priors
    narrow their bounds) and the normal priors' residual rows. A label given more
    precisely overrides the name's prior for that instance. A prior matching no instance
    is an error.
    """
    instances = list(instances)
    rows = {}
    for prior in sorted(priors, key=lambda p: p.key != p.name):  # names first, then labels
        matched = [i for i, inst in enumerate(instances) if _matches(prior, inst)]
        if not matched:
            raise PriorError(
                f"prior {public_label(prior.key)}: no fitted parameter has this name or label; "
                f"fitted: {', '.join(public_label(inst.label) for inst in instances)}."
            )
        for i in matched:
            inst = instances[i]
            if prior.kind == "uniform":
                rows.pop(i, None)
                instances[i] = dataclasses.replace(inst, spec=_narrowed(inst.spec, prior))
                continue
            centre = prior.centre if prior.centre is not None else float(nominal[i])
            if not math.isfinite(centre):
                raise PriorError(
                    f"prior {public_label(prior.key)}: {public_label(inst.label)} has no nominal value; write the centre "
                    f"(e.g. {public_label(prior.name)}=VALUE+-SD)."
                )
            sd = prior.sd if prior.sd is not None else abs(centre) * prior.relative_sd
            if not sd > 0:
                raise PriorError(f"prior {public_label(prior.key)}: a relative width around {centre:g} is zero; give it absolute.")
            if not inst.spec.in_bounds(centre):
                raise PriorError(
                    f"prior {public_label(prior.key)}: centre {centre:g} {inst.spec.unit} is outside the bounds "
                    f"({inst.spec.lower:g}, {inst.spec.upper:g}) of {public_label(inst.label)}."
                )
            rows[i] = NormalRow(i, centre, sd)
    return instances, tuple(rows[i] for i in sorted(rows))


def _narrowed(spec, prior: Prior):
    low, high = prior.low, prior.high
    if spec.space == "asinh":
        if low != 0:
            raise PriorError(
                f"prior {public_label(prior.key)}: {spec.public_name} may be zero, so its interval must start at 0 "
                f"(write {spec.public_name}=0..{prior.high:g})."
            )
    elif not (spec.lower <= low and high <= spec.upper):
        raise PriorError(
            f"prior {public_label(prior.key)}: {low:g}..{high:g} is not inside the bounds "
            f"({spec.lower:g}, {spec.upper:g}) of {spec.public_name}."
        )
    if high > spec.upper:
        raise PriorError(f"prior {public_label(prior.key)}: {high:g} is above the bound {spec.upper:g} of {spec.public_name}.")
    return dataclasses.replace(spec, lower=low, upper=high)


def describe(instances, rows) -> dict:
    """label -> a JSON-ready description of the prior each parameter carries."""
    normal = {row.index: row for row in rows}
    out = {}
    for i, inst in enumerate(instances):
        if i in normal:
            out[inst.label] = {"kind": "normal", "centre": normal[i].centre, "sd": normal[i].sd,
                               "unit": inst.spec.unit}
        else:
            out[inst.label] = {"kind": "uniform", "low": inst.spec.lower, "high": inst.spec.upper,
                               "unit": inst.spec.unit}
    return out
