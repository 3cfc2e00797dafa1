"""Output files written whole or not at all (temporary file in the same folder, then rename).

Files are created with the permissions the user's umask gives a new file (0644 under the
usual umask 022), as `open` would, so lab mates sharing a folder can read them.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np


def _umask() -> int:
    """The process's umask, read without changing it where the system says it (Linux)."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path next to `path`; on success it is renamed to `path`."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    os.close(handle)
    try:
        os.chmod(temporary, 0o666 & ~_umask())  # mkstemp's file is 0600 whatever the umask
        yield Path(temporary)
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise


def write_text(path, text: str) -> None:
    """Write `text` to `path` atomically."""
    with atomic_path(path) as temporary:
        temporary.write_text(text)


def write_csv(path, header, rows) -> None:
    """Write a CSV file atomically: the `header` cells, then one line per row of `rows`.

    Cells are written as given (format numbers before; None is an empty cell); the `csv`
    module quotes a cell that holds a comma, a quote or a line break. Lines end in "\\n".
    """
    with atomic_path(path) as temporary:
        with open(temporary, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(header)
            writer.writerows(rows)


def json_ready(value):
    """`value` as JSON can hold it: NaN and inf as None (JSON has neither).

    Dicts (keys as strings), lists and tuples are converted item by item; booleans and
    integers (Python or NumPy) stay booleans and integers; any other number or numeric array
    (NumPy, JAX, 0-d or not) becomes a Python float or nested lists of them. None, strings
    and other objects are returned unchanged.
    """
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return value
    if array.ndim:
        return [json_ready(v) for v in array.tolist()]
    number = float(array)
    return number if math.isfinite(number) else None


def write_json(path, data) -> None:
    """Write `data` as indented JSON atomically (NaN/inf are refused: JSON has none)."""
    write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


def save_figure(figure, path, **kwargs) -> None:
    """Save a matplotlib figure atomically (format from the file name's suffix)."""
    target = Path(path)
    with atomic_path(target) as temporary:
        figure.savefig(temporary, format=target.suffix.lstrip(".") or "png", **kwargs)
