"""Observables of a run that sensitivities are taken of: their names, and their values as
smooth functions of the force traces (see `hertzchain.sensitivity` for the definitions)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..chain import ChainSetup
from ..integrate import Recording
from ..peaks import first_peak_index, refine_peak
from ..theory import COS6_HALF_WIDTH
from ..traces import Traces

_CHANNEL = r"(contact_\d+|wall|sensor_\d+)"
_PULSE = re.compile(rf"^{_CHANNEL}_(peak|peak_time|arrival|duration)$")
_TRACE = re.compile(rf"^trace_{_CHANNEL}$")
_SPEED = re.compile(r"^speed_(\d+)_(\d+)$")
_RATIO = re.compile(r"^force_ratio_(\d+)$")
_DISSIPATED = ("dissipated_viscous", "dissipated_friction", "dissipated_plastic", "dissipated_total")

OBSERVABLE_FORMS = (
    "contact_K_peak, wall_peak, sensor_K_peak (N)",
    "contact_K_peak_time, contact_K_arrival, contact_K_duration (s; also for wall, sensor_K)",
    "speed_K_L (m/s, K < L)",
    "force_ratio_K (wall peak / contact K peak)",
    "dissipated_viscous, dissipated_friction, dissipated_plastic, dissipated_total (J)",
    "trace_contact_K, trace_wall, trace_sensor_K (N per sample)",
)
_UNITS = {"peak": "N", "peak_time": "s", "arrival": "s", "duration": "s"}
# The incident pulse: first local maximum above this fraction of the pulse height.
_DETECT_FRACTION = 0.3


class Observable(NamedTuple):
    """A parsed observable: `name`, `kind`, the `channels` it reads, its `unit`."""

    name: str
    kind: str
    channels: tuple[str, ...]
    unit: str
    is_trace: bool = False


def _channel_error(setup: ChainSetup, name: str, channel: str) -> str | None:
    if channel == "wall":
        return None if setup.end == "wall" else f"{name}: this chain has a free end, no wall."
    kind, number = channel.split("_")
    k = int(number)
    if kind == "contact" and not 0 <= k < setup.n_beads:
        return (
            f"{name}: contact {k} is not in the chain (contacts are 0..{setup.n_beads - 1}; "
            "contact K is between bead K and K+1)."
        )
    if kind == "sensor" and k not in setup.sensor_beads:
        return (
            f"{name}: bead {k} has no embedded sensor (sensor beads: "
            f"{list(setup.sensor_beads) or 'none'}; add it with sensor_beads / --sensor-beads)."
        )
    return None


def parse_observable(setup: ChainSetup, name: str) -> Observable:
    """Parse and check an observable name against `setup`; `ValueError` lists the valid forms."""
    if match := _PULSE.match(name):
        obs = Observable(name, match.group(2), (match.group(1),), _UNITS[match.group(2)])
    elif match := _TRACE.match(name):
        obs = Observable(name, "trace", (match.group(1),), "N", is_trace=True)
    elif match := _SPEED.match(name):
        k, l = int(match.group(1)), int(match.group(2))
        if not k < l:
            raise ValueError(f"{name}: speed_K_L needs K < L (pulse travels towards the wall).")
        obs = Observable(name, "speed", (f"contact_{k}", f"contact_{l}"), "m/s")
    elif match := _RATIO.match(name):
        obs = Observable(name, "ratio", ("wall", f"contact_{match.group(1)}"), "")
    elif name in _DISSIPATED:
        obs = Observable(name, name, (), "J")
    else:
        raise ValueError(
            f"unknown observable {name!r}; valid forms: " + "; ".join(OBSERVABLE_FORMS) + "."
        )
    for channel in obs.channels:
        if message := _channel_error(setup, name, channel):
            raise ValueError(message)
    return obs


def observable_names(setup: ChainSetup) -> tuple[str, ...]:
    """Every scalar observable name valid for `setup` (traces and speeds excluded)."""
    channels = [f"contact_{k}" for k in range(setup.n_beads)]
    channels += [f"sensor_{b}" for b in setup.sensor_beads]
    channels += ["wall"] if setup.end == "wall" else []
    names = [f"{c}_{kind}" for c in channels for kind in _UNITS]
    if setup.end == "wall":
        names += [f"force_ratio_{k}" for k in range(setup.n_beads)]
    return tuple(names) + _DISSIPATED


def recording_for(observables: Sequence[Observable]) -> Recording:
    """The `Recording` that records every contact `observables` read."""
    contacts = sorted(
        {int(c.split("_")[1]) for o in observables for c in o.channels if c.startswith("contact_")}
    )
    return Recording(contacts=tuple(contacts))


class _Pulse(NamedTuple):
    peak: jax.Array
    peak_time: jax.Array
    arrival: jax.Array
    trailing: jax.Array
    found_peak: jax.Array
    found_arrival: jax.Array
    found_trailing: jax.Array


def _pulse(force_n, dt_s: float, baseline_n, scale_n, use_global_max: bool) -> _Pulse:
    """Peak, peak time and half-height crossings of the incident pulse of one trace.

    The peak sample is `peaks.first_peak_index` of the trace above the precompression
    baseline (for the wall: the largest sample), its vertex `peaks.refine_peak`'s
    three-point parabola. Inside the jitted and differentiated observable function nothing
    can raise, so what is not found is flagged instead (its values stay finite).
    """
    y = force_n
    ys = jax.lax.stop_gradient(y)
    n = y.shape[0]
    index = jnp.arange(n)
    time = (index + 1) * dt_s
    top = jnp.max(ys)
    height_ok = top - baseline_n > 1e-6 * scale_n
    if use_global_max:
        i = jnp.argmax(ys)
    else:
        i = first_peak_index(ys - baseline_n, _DETECT_FRACTION)
    found = (i > 0) & (i < n - 1) & height_ok
    peak_time, peak = refine_peak(time, y, i)
    i = jnp.clip(i, 1, n - 2)

    level = baseline_n + 0.5 * (peak - baseline_n)
    level_s = jax.lax.stop_gradient(level)
    below = ys < level_s
    j = jnp.max(jnp.where(below & (index <= i), index, -1))
    found_arrival = found & (j >= 0)
    j = jnp.clip(j, 0, n - 2)
    rise = jnp.where(found_arrival, y[j + 1] - y[j], 1.0)
    arrival = time[j] + dt_s * (level - y[j]) / rise
    k = jnp.min(jnp.where(below & (index >= i), index, n))
    found_trailing = found_arrival & (k < n)
    k = jnp.clip(k, 1, n - 1)
    fall = jnp.where(found_trailing, y[k] - y[k - 1], -1.0)
    trailing = time[k - 1] + dt_s * (level - y[k - 1]) / fall
    return _Pulse(peak, peak_time, arrival, trailing, found, found_arrival, found_trailing)


def _contact_distance_m(setup: ChainSetup, k: int, l: int):
    """Distance at rest between the contact points K and L (K < L), m."""
    return 2.0 * jnp.sum(setup.bead_radius_m[k:l])


def evaluate_observables(
    setup: ChainSetup, traces: Traces, observables: Sequence[Observable], sample_interval_s: float
) -> tuple[dict[str, jax.Array], dict[str, jax.Array]]:
    """Values and validity flags of `observables` from a run of `setup` (jit/vmap/grad safe).

    A flag is False where the observable does not exist in the run (no pulse, a pulse that
    has not arrived or not passed before the end of the record).
    """
    baseline = setup.precompression_n
    scale = jax.lax.stop_gradient(
        jnp.max(jnp.stack([jnp.max(jnp.abs(f - baseline)) for f in traces.forces_n.values()]))
    )
    pulses: dict[str, _Pulse] = {}

    def pulse(channel: str) -> _Pulse:
        if channel not in pulses:
            pulses[channel] = _pulse(
                traces.forces_n[channel], sample_interval_s, baseline, scale, channel == "wall"
            )
        return pulses[channel]

    values, valid = {}, {}
    true = jnp.asarray(True)
    for obs in observables:
        if obs.kind in ("peak", "peak_time"):
            p = pulse(obs.channels[0])
            values[obs.name], valid[obs.name] = getattr(p, obs.kind), p.found_peak
        elif obs.kind == "arrival":
            p = pulse(obs.channels[0])
            values[obs.name], valid[obs.name] = p.arrival, p.found_arrival
        elif obs.kind == "duration":
            p = pulse(obs.channels[0])
            values[obs.name] = (p.trailing - p.arrival) / COS6_HALF_WIDTH
            valid[obs.name] = p.found_trailing
        elif obs.kind == "speed":
            a, b = pulse(obs.channels[0]), pulse(obs.channels[1])
            k, l = (int(c.split("_")[1]) for c in obs.channels)
            gap = b.arrival - a.arrival
            ok = a.found_arrival & b.found_arrival & (jax.lax.stop_gradient(gap) > 0)
            values[obs.name] = _contact_distance_m(setup, k, l) / jnp.where(ok, gap, 1.0)
            valid[obs.name] = ok
        elif obs.kind == "ratio":
            wall, incident = pulse("wall"), pulse(obs.channels[1])
            ok = wall.found_peak & incident.found_peak
            values[obs.name] = wall.peak / jnp.where(ok, incident.peak, 1.0)
            valid[obs.name] = ok
        elif obs.kind == "dissipated_viscous":
            values[obs.name], valid[obs.name] = traces.dissipated_viscous_j[-1], true
        elif obs.kind == "dissipated_friction":
            values[obs.name], valid[obs.name] = traces.dissipated_friction_j[-1], true
        elif obs.kind == "dissipated_plastic":
            values[obs.name], valid[obs.name] = traces.dissipated_plastic_j[-1], true
        elif obs.kind == "dissipated_total":
            values[obs.name], valid[obs.name] = traces.dissipated_j[-1], true
        elif obs.kind == "trace":
            values[obs.name], valid[obs.name] = traces.forces_n[obs.channels[0]], true
        else:  # pragma: no cover - parse_observable admits only the kinds above
            raise AssertionError(obs.kind)
    return values, valid


def invalid_reason(obs: Observable, t_end_s: float) -> str:
    """Why `obs` does not exist in a run of length `t_end_s` (s), and what to change."""
    channel = obs.channels[0] if obs.channels else ""
    what = {
        "peak": "no complete pulse (no local maximum inside the record)",
        "peak_time": "no complete pulse (no local maximum inside the record)",
        "arrival": "no pulse with a leading edge inside the record",
        "duration": "the pulse has not passed (no trailing half-height crossing) before the end",
        "speed": "the pulse has not arrived at both contacts",
        "ratio": "no complete pulse at the wall or at the contact",
    }.get(obs.kind, "not defined")
    return (
        f"{obs.name}: {what} at {channel or 'the channels'} within t_end = {t_end_s:.4g} s; "
        "lengthen the record (--t-end) or pick a contact the pulse reaches."
    )
