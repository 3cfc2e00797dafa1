"""The record every result script here stores beside its numbers: the wall time, the load
average at the start and the process's CPU time (timings on shared cores mean little alone)."""

from __future__ import annotations

import os
import resource
import time
from pathlib import Path

from hertzchain.io.atomic import json_ready, write_json


def started() -> tuple[float, list]:
    """(wall clock, load averages) at the start of a run."""
    return time.perf_counter(), list(os.getloadavg())


def write_stamped(path: Path, result: dict, start: tuple[float, list]) -> None:
    """Write `result` to `path` (JSON, atomically) with `elapsed_s`, `load_average_at_start`
    and `cpu_s` (user + system) of this process."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    result = {**result, "elapsed_s": time.perf_counter() - start[0], "load_average_at_start": start[1],
              "cpu_s": usage.ru_utime + usage.ru_stime}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_json(path, json_ready(result))
