"""Output files and folders written whole or not at all (a temporary beside the target,
then renamed into place), and the rule that turns a label into a file name.

Files are created with the permissions the user's umask gives a new file (0644 under the
usual umask 022), as `open` would, so lab mates sharing a folder can read them.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import re
import shutil
import sys
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


# What a file name made from a label (a shot, a file, a parameter) may hold: nothing that
# names another folder ("/", "..") or is hidden (a leading dot).
_NOT_IN_FILE_NAMES = re.compile(r"[^A-Za-z0-9_.-]+")
# The marker file of an output folder that a command of hertzchain wrote as a whole.
FOLDER_MARKER = ".hertzchain-output"


def file_stem(label: str) -> str:
    """The file-name stem of `label`: runs of characters other than letters, digits, `_`, `.`
    and `-` become `_`, and leading dots and underscores are dropped, so that the name stays in
    its folder (`"../escaped"` gives `"escaped"`, `"/etc/x"` gives `"etc_x"`); `"_"` for a label
    with nothing left."""
    return _NOT_IN_FILE_NAMES.sub("_", str(label)).lstrip("._").rstrip("_") or "_"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _remove_orphans(target: Path) -> None:
    """Remove the temporaries of `output_folder` left beside `target` by runs that were killed
    (their process no longer exists)."""
    pattern = re.compile(rf"^\.{re.escape(target.name)}\.(?:new|old)-(\d+)-")
    for sibling in target.parent.iterdir():
        match = pattern.match(sibling.name)
        if match and not _pid_alive(int(match.group(1))):
            shutil.rmtree(sibling, ignore_errors=True)


def say_replaced(folder: str | os.PathLike, command: str) -> None:
    """One line on stderr saying that `command` replaced the results of an earlier run in
    `folder` (not an error: users rerun into the same folder)."""
    print(f"hertzchain {command}: replaced the results of an earlier run in {folder}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def output_folder(path: str | os.PathLike, command: str, result_file: str):
    """Yield a new, empty temporary folder beside `path` to write a command's outputs into; on
    success it replaces `path` as a whole, so that the folder never holds files of two runs.

    Checked before the work starts: `path` is a folder (or absent) and, when it exists, empty
    or an earlier output folder of hertzchain (it holds `FOLDER_MARKER`, written here, or the
    command's `result_file`), so that a folder holding the user's own files is never replaced.
    On an error the temporary is removed and `path` stays as it was; temporaries of killed runs
    are removed on the next run into the same `path`. Replacing an earlier output says so in one
    line on stderr (`say_replaced`).

    **Arguments:**

    - `path`: the output folder (`--out`).
    - `command`: the command's name, written into the marker.
    - `result_file`: the file every run of the command writes (`"fit.json"`): a folder that
      holds it is an earlier output, written before folders carried the marker.

    **Raises:** `FileExistsError` (a file at `path`, or a folder with other files), `OSError`
    when the parent folder cannot be written.
    """
    target = Path(path)
    for place in (target, *target.parents):
        if place.exists() and not place.is_dir():
            raise FileExistsError(f"{target}: {place} is a file, not a folder; give an output folder (--out DIR).")
    earlier = (target / FOLDER_MARKER).is_file() or (target / result_file).is_file()
    if target.is_dir() and any(target.iterdir()) and not earlier:
        raise FileExistsError(
            f"{target}: the folder holds files that hertzchain did not write; give a new or empty "
            "output folder (--out DIR), since an output folder is replaced whole by the next run.")
    target.parent.mkdir(parents=True, exist_ok=True)
    _remove_orphans(target)
    temporary = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.new-{os.getpid()}-"))
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.chmod(temporary, 0o777 & ~umask)  # as a folder made by mkdir (mkdtemp's is private)
        (temporary / FOLDER_MARKER).write_text(f"written whole by hertzchain {command}\n")
        yield temporary
        previous = None
        if target.exists():
            previous = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.old-{os.getpid()}-"))
            os.replace(target, previous / target.name)
        os.replace(temporary, target)
        if previous is not None:
            shutil.rmtree(previous, ignore_errors=True)
            if earlier:
                say_replaced(target, command)
    except BaseException:
        shutil.rmtree(temporary, ignore_errors=True)
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


def finish_figure(figure, path, *, dpi: int = 110) -> None:
    """Lay out a pyplot figure (`tight_layout`), save it atomically at `dpi` dots per inch
    and close it."""
    import matplotlib.pyplot as plt

    figure.tight_layout()
    save_figure(figure, path, dpi=dpi)
    plt.close(figure)
