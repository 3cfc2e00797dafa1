"""Check that every measured figure quoted in the project's documents cites the stored result
it comes from, and equals that result at its printed precision.

The rule (for everyone who writes in README.md, benchmarks/README.md and docs/):

1. **What is a figure.** Prose only: fenced code blocks and `inline code` are commands and
   their inputs, and are skipped. In prose, a *measured figure* is a number written with
   - a unit of wall time: ``s``, ``min``, ``h`` ("176 s", "about 15 min");
   - a throughput: a unit ending in ``/s`` other than a speed ("2.2e10 bead-steps/s");
   - ``ms``, ``µs``/``us``, ``%`` or a ratio mark (``×``, or an ``x`` right after the number:
     "1.5×", "22x"; not a product such as "22 × 512") *when its sentence speaks of computing
     time* (it holds one of `TIMING_WORDS`: "0.57 ms per chain", "1.5× faster"). Elsewhere
     these are physics (η = 2 µs, 0.5 % noise, a yield stress 0.72× the published one):
     inputs, or results that the tests and the reproduction pages' own result files hold.
   A range of one unit ("14–19 s", "−6.2 … +26.9 %") is one figure of two numbers. A number
   right after ``=`` is a setting, one right after ``±`` an uncertainty: neither is a
   figure of its own ("η = 2 µs per contact", "−2.4 ± 1.7 µs").
2. **Its source.** Each measured figure is followed by a footnote reference, ``6.8 s[^fit]``,
   whose definition names the stored value as ``path#key`` in inline code::

       [^fit]: `benchmarks/results/fit_bench/latest.json#cases.paper.cold.wall_s`

   ``path`` is relative to the repository's root. ``key`` is the value's path in a JSON file
   (keys joined by ``.``, list positions as numbers), ``ROW.COLUMN`` in a CSV file (data row
   from 0, column by its header) or ``LN`` (line N) in any other text file. A definition may
   name several values (a range's two ends): each number of the figure must then be one of
   them. Any figure with a footnote is checked this way, whatever its unit ("1357 MPa[^y]").
3. **Equal at its printed precision.** The stored value, converted to the figure's unit,
   must lie within half a unit of the figure's last printed digit ("6.8 s" holds 6.75–6.85 s).
   The stored value's unit comes from its key: the innermost key that names one (``_s``,
   ``_ms``, ``_us``, ``_min``, ``_h``; ``timings_s: {total: ...}`` is in seconds); a key that
   names none holds the figure's own unit. A percentage matches a stored fraction (× 100) or
   a stored percentage. On a text line any number written there may match.
4. **Exceptions** are listed in `ALLOWED`: (file, figure as written, why), for figures in a
   timing sentence that are inputs or definitions (a timeout, a target). A measured figure
   never goes there.

Run ``python benchmarks/check_readme_figures.py``: it lists every problem with file and line
and exits 1 if there is one; `tests/test_readme_figures.py` runs it in the default suite.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = ("README.md", "benchmarks/README.md", "docs/**/*.md")
TIMING_WORDS = ("took", "takes", "take ", "taking", "ran ", "runs in", "run in", "wall time", "wall-clock", "per chain",
                "per step", "per draw", "per iteration", "per fit", "per call", "per evaluation", "faster",
                "slower", "speed-up", "speedup", "'s speed", "throughput", "compil", "overhead", "timing", "timed",
                "costs", "cost of")
# Figures that are not measurements although written in a timing sentence.
ALLOWED: tuple[tuple[str, str, str], ...] = ()

TIME_UNITS = {"s": 1.0, "min": 60.0, "h": 3600.0, "ms": 1e-3, "µs": 1e-6, "us": 1e-6}
_NUMBER = r"[-−+]?\d+(?:,\d{3})*(?:\.\d+)?(?:e[-+]?\d+)?"
_MEASURED_UNIT = r"min|ms|µs|us|s|h|×(?!\s?\d)|x(?![\d ])|%|(?!(?:k|c|m|µ)?m/s)[A-Za-z][A-Za-z-]*/s"
_FIGURE = re.compile(
    r"(?<![\w.×^\-−+])(?P<a>" + _NUMBER + r")(?:\s?(?:–|…|-|to)\s?(?P<b>" + _NUMBER + r"))?"
    r"(?:\s?(?P<unit>" + _MEASURED_UNIT + r"))?(?![A-Za-z0-9²/])(?P<cite>\[\^[^\]\s]+\])?")
_DEFINITION = re.compile(r"^\[\^([^\]\s]+)\]:\s*(.*)$")
_SOURCE = re.compile(r"`([^`#\s]+)#([^`\s]+)`")
_KEY_UNITS = (("_ms", 1e-3), ("_us", 1e-6), ("_min", 60.0), ("_h", 3600.0), ("_s", 1.0))


def documents(root: Path = ROOT) -> list[Path]:
    """The checked documents that exist under `root`."""
    found = []
    for pattern in DOCUMENTS:
        found.extend(sorted(root.glob(pattern)))
    return [path for path in found if path.is_file()]


def _prose(text: str):
    """(line number, line) of the prose: code blocks removed, inline code blanked (an inline
    span may run over a line break, as Markdown allows)."""
    in_code = in_inline = False
    for number, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith(("```", "~~~")) and not in_inline:
            in_code = not in_code
            continue
        if in_code:
            continue
        if not line.strip():
            in_inline = False  # a span never crosses a paragraph
        kept = []
        for char in line:
            if char == "`":
                in_inline = not in_inline
                kept.append(" ")
            else:
                kept.append(" " if in_inline else char)
        yield number, "".join(kept)


def footnotes(text: str) -> dict[str, list[tuple[str, str]]]:
    """Footnote name -> the (path, key) sources its definition names."""
    notes = {}
    for line in text.splitlines():
        match = _DEFINITION.match(line.strip())
        if match:
            notes[match.group(1)] = _SOURCE.findall(match.group(2))
    return notes


def _decimals(written: str) -> int:
    mantissa, _, exponent = written.lower().partition("e")
    return (len(mantissa.split(".")[1]) if "." in mantissa else 0) - int(exponent or 0)


def _number(written: str) -> float:
    return float(written.replace("−", "-").replace(",", ""))


def figures(text: str):
    """(line, figure as written, numbers as written, unit, footnote name or None, measured)
    of every number with a unit of rule 1 or a footnote."""
    for line_number, line in _prose(text):
        if _DEFINITION.match(line.strip()):
            continue
        for sentence in re.split(r"(?<=[.;:])\s+(?=[A-Z(*])", line):
            timing = any(word in sentence.lower() for word in TIMING_WORDS)
            for match in _FIGURE.finditer(sentence):
                unit, cite = match.group("unit"), match.group("cite")
                setting = sentence[:match.start()].rstrip().endswith(("=", "±"))
                measured = unit is not None and not setting and (unit in ("s", "min", "h") or unit.endswith("/s")
                                                                 or timing)
                if not (measured or cite):
                    continue
                numbers = [n for n in (match.group("a"), match.group("b")) if n]
                written = match.group(0).strip()
                if cite:
                    written = written[: -len(cite)].strip()
                yield line_number, written, numbers, unit, cite[2:-1] if cite else None, measured


def _resolve_json(node, parts: list[str]):
    """The value at a dotted key path (keys may hold dots themselves), with the keys used."""
    if not parts:
        return node, []
    if isinstance(node, list):
        try:
            return _resolve_json(node[int(parts[0])], parts[1:])
        except (ValueError, IndexError):
            raise KeyError(parts[0]) from None
    if isinstance(node, dict):
        for size in range(len(parts), 0, -1):
            key = ".".join(parts[:size])
            if key in node:
                value, used = _resolve_json(node[key], parts[size:])
                return value, [key, *used]
    raise KeyError(parts[0])


def _unit_of_keys(keys: list[str]) -> float | None:
    """Seconds per unit of a stored time, from the innermost key that names one."""
    for key in reversed(keys):
        name = key.lower()
        for suffix, factor in _KEY_UNITS:
            if name.endswith(suffix) and not name.endswith(("_per_s", "/s")):
                return factor
    return None


def stored(root: Path, path: str, key: str) -> tuple[list[float], float | None]:
    """(candidate values, seconds per unit or None) stored in `path` at `key`; raises
    FileNotFoundError or KeyError with the reason."""
    file = root / path
    if not file.is_file():
        raise FileNotFoundError(f"{path} does not exist")
    text = file.read_text(errors="replace")
    if file.suffix == ".json":
        value, used = _resolve_json(json.loads(text), key.split("."))
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise KeyError(f"{key} holds {type(value).__name__}, not a number")
        return [float(value)], _unit_of_keys(used)
    if file.suffix == ".csv":
        row, _, column = key.partition(".")
        rows = list(csv.DictReader(io.StringIO(text)))
        try:
            cell = rows[int(row)][column]
        except (ValueError, IndexError, KeyError):
            raise KeyError(f"no row {row}, column {column!r}") from None
        try:
            return [float(cell)], _unit_of_keys([column])
        except (TypeError, ValueError):
            raise KeyError(f"{key} holds {cell!r}, not a number") from None
    match = re.fullmatch(r"L(\d+)", key)
    lines = text.splitlines()
    if not match or not 1 <= int(match.group(1)) <= len(lines):
        raise KeyError(f"{key} is not a line of the file (write L1 … L{len(lines)})")
    values = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", lines[int(match.group(1)) - 1])]
    return values, None


def _equal(written: str, unit: str | None, values: list[float], seconds_per_unit: float | None) -> bool:
    """Whether one of `values` rounds to the figure `written` (rule 3)."""
    figure, half = _number(written), 0.5 * 10.0 ** -_decimals(written)
    for value in values:
        if not math.isfinite(value):
            continue
        scaled = [value]
        if unit in TIME_UNITS and seconds_per_unit is not None:
            scaled = [value * seconds_per_unit / TIME_UNITS[unit]]
        elif unit == "%":
            scaled = [value, 100.0 * value]
        if any(abs(v - figure) <= half * (1 + 1e-9) + 1e-12 * abs(figure) for v in scaled):
            return True
    return False


def problems(root: Path = ROOT, allowed=ALLOWED) -> list[str]:
    """'file:line: figure: what is wrong' for every figure that breaks the rule."""
    allowed = {(f, written) for f, written, _ in allowed}
    found, seen = [], set()
    for path in documents(root):
        document = path.relative_to(root).as_posix()
        text = path.read_text()
        notes = footnotes(text)
        for line, written, numbers, unit, cite, measured in figures(text):
            seen.add((document, written))
            where = f"{document}:{line}: {written}"
            if cite is None:
                if (document, written) not in allowed:
                    found.append(f"{where}: cites no source (add a footnote naming `path#key`)")
                continue
            sources = notes.get(cite)
            if not sources:
                found.append(f"{where}: footnote [^{cite}] names no `path#key`")
                continue
            values, failure = [], None
            for source_path, key in sources:
                try:
                    values.append(stored(root, source_path, key))
                except (FileNotFoundError, KeyError, json.JSONDecodeError) as error:
                    failure = f"{source_path}#{key}: {error}"
                    break
            if failure:
                found.append(f"{where}: {failure}")
                continue
            for number in numbers:
                if not any(_equal(number, unit, v, factor) for v, factor in values):
                    shown = ", ".join(f"{p}#{k} = {', '.join(f'{x:.6g}' for x in v)}"
                                      for (p, k), (v, _) in zip(sources, values))
                    found.append(f"{where}: {number} is not the stored value at its precision ({shown})")
    for document, written in sorted(allowed - seen):
        found.append(f"{document}: {written} is listed in ALLOWED but no longer in the text; delete the entry")
    return found


def main() -> int:
    found = problems()
    for line in found:
        print(line)
    checked = sum(1 for path in documents() for _ in figures(path.read_text()))
    print(f"{len(found)} problem(s) in {checked} figures" if found
          else f"every one of {checked} figures cites its stored value")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
