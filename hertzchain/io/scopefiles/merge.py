"""One shot's channels merged from several scope files on a shared time grid."""

from __future__ import annotations

from pathlib import Path

from .common import (
    ScopeFileError,
    Waveforms,
)

# --- merging ------------------------------------------------------------------------------

def merge_waveforms(parts: list[Waveforms], where: str) -> Waveforms:
    """One shot's channels from several files (`where` names the shot in messages).

    The time grids must agree: same length, and first time and interval within 1e-9 of the
    interval. A channel named in two files is an error naming both."""
    if not parts:
        raise ScopeFileError(f"{where}: no files to merge; list the shot's files.")
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    n = first.time_s.size
    for part in parts[1:]:
        a, b = first.time_s, part.time_s
        if b.size != n:
            raise ScopeFileError(f"{where}: {first.path} has {n} samples and {part.path} has {b.size}; "
                                 f"one shot's files must share the time grid (same record length).")
        dt_a = (a[-1] - a[0]) / (n - 1) if n > 1 else 0.0
        dt_b = (b[-1] - b[0]) / (n - 1) if n > 1 else 0.0
        tolerance = 1e-9 * abs(dt_a)
        if abs(a[0] - b[0]) > tolerance:
            raise ScopeFileError(f"{where}: first times differ: {float(a[0])!r} s in {first.path}, {float(b[0])!r} s in "
                                 f"{part.path}; one shot's files must share the trigger and time grid.")
        if abs(dt_a - dt_b) > tolerance:
            raise ScopeFileError(f"{where}: sample intervals differ: {float(dt_a)!r} s in {first.path}, {float(dt_b)!r} s "
                                 f"in {part.path}; one shot's files must share the time base.")
    channels, range_v, lsb_v, info, owner = {}, {}, {}, {}, {}
    for part in parts:
        for name, values in part.channels.items():
            if name in channels:
                raise ScopeFileError(f"{where}: channel {name!r} is in both {owner[name]} and {part.path}; "
                                     f"each channel must come from one file.")
            owner[name] = part.path
            channels[name] = values
            range_v[name] = part.range_v.get(name)
            lsb_v[name] = part.lsb_v.get(name)
        info.update({f"{Path(part.path).name}: {key}": value for key, value in part.info.items()})
    formats = list(dict.fromkeys(p.format for p in parts))
    return Waveforms("; ".join(p.path for p in parts), "+".join(formats), first.time_s, channels,
                     range_v, lsb_v, info)
