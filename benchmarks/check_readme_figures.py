"""Check that every measured figure quoted in README.md and benchmarks/README.md is stored.

The rule (for everyone who writes in these two files):

1. **What is checked.** Prose only: fenced code blocks and `inline code` are commands and
   their inputs, and are skipped. In prose, a *figure* is a number written with
   - a unit of wall time: ``s``, ``min``, ``h`` (e.g. "176 s", "about 15 min");
   - a ratio mark: ``×`` or an ``x`` right after the number ("1.5×", "22x"; not a product
     such as "22 × 512", whose × is followed by a number);
   - a throughput: a unit ending in ``/s`` other than a speed ("2.2e10 bead-steps/s",
     "2.1 ESS/s"; not m/s);
   - ``ms``, ``µs``/``us`` or ``%`` *when its sentence speaks of computing time*: it holds
     one of `TIMING_WORDS` ("0.57 ms per chain", "the gradient costs 12 % more"). Elsewhere
     these units are physics (η = 2 µs, 0.5 % noise) and are inputs or asserted by tests.
2. **Where it must be.** In a committed result file: any ``.json``, ``.csv`` or ``.md`` under
   a ``results`` folder of the repository (`RESULT_DIRS`), made by a committed script. A
   figure is found when a stored value *of the same kind* rounds to it at its printed
   precision ("176 s" is any stored time in [175.5, 176.5) s; "0.57 ms" any in [0.565,
   0.575) ms). Kinds come from the stored value's name: a JSON key (the innermost of its
   path that names a kind: ``timings_s: {total: 572.1}`` is a time) or CSV column ending in
   ``_s``/``_ms``/``_us``/``_min`` or naming ``seconds``/``time``/``wall`` is a time; one
   naming ``ratio``, ``speedup``, ``factor``, ``over`` or ending in ``_x`` a ratio; one
   ending in ``_per_s``/``flop_s``/``per_second`` or naming ``throughput`` a throughput; a
   number written with its unit in a stored Markdown or text file ("176 s", "1.5×") has
   that unit's kind, and so does a Markdown table cell under a header that names the unit
   ("wall (s)", "ratio", "×"). A percentage is found as a stored ratio, fraction or
   percentage (value/100 or value).
3. **Exceptions** are listed in `ALLOWED`: (file, figure as written, why) for figures that
   are inputs or definitions in a timing sentence (a timeout, a target from the issue
   tracker). Keep it short; a measured figure never goes there.
4. **Debt.** `UNSTORED` names the measured figures that were in benchmarks/README.md before
   this check existed and have no result file (profiling notes of earlier work). They are
   reported, not failed; an entry whose figure is gone from the text fails the check, so
   the list only shrinks. Nothing is added to it: rerun and store, or reword.

Run ``python benchmarks/check_readme_figures.py``: it lists every figure not found, with
file and line, and exits 1 if there is one; `tests/test_readme_figures.py` runs it in the
default test suite.
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
DOCUMENTS = ("README.md", "benchmarks/README.md")
RESULT_DIRS = ("benchmarks/results", "examples/lydon2015/results")
TIMING_WORDS = ("took", "takes", "take ", "taking", "ran ", "runs in", "run in", "median", "wall", "per chain",
                "per step", "per draw", "per iteration", "per fit", "per call", "per evaluation", "faster",
                "slower", "speed-up", "speedup", "throughput", "compil", "overhead", "timing", "timed")
# Figures that are not measurements although written in a timing sentence.
ALLOWED: tuple[tuple[str, str, str], ...] = (
    ("benchmarks/README.md", "1.5 µs", "η of the gradient benchmark's loss, an input"),
    ("benchmarks/README.md", "120 s", "the diagnosis's time target (issue tracker), not a measurement"),
)
_NO_FILE = "measured in earlier profiling work; no result file: rerun and store, or reword"
# Measured figures without a result file, from before this check (rule 4): only shrinks.
UNSTORED: tuple[tuple[str, str, str], ...] = tuple(("benchmarks/README.md", figure, _NO_FILE) for figure in (
    "1.11e9 bead-steps/s", "30 %", "8.4e8 bead-steps/s", "0.29 µs", "2.1×", "3.0×", "16 µs", "12 µs", "7 µs",
    "4.5×", "2.7 µs", "17 µs", "10 µs", "34×", "0.95 s", "115 GFLOP/s", "5.4×", "7.7e8 bead-steps/s",
    "3.50×", "3.53×", "6.7 s", "268 ms"))

TIME_S = {"s": 1.0, "min": 60.0, "h": 3600.0, "ms": 1e-3, "µs": 1e-6, "us": 1e-6}
_NUMBER = r"(\d+(?:,\d{3})*(?:\.\d+)?(?:e[-+]?\d+)?)"
_FIGURE = re.compile(r"(?<![×\d.])\s?" + _NUMBER + r"\s?(min|ms|µs|us|s|h|×(?!\s?\d)|x(?![\d ])|%|(?!(?:k|c|m|µ)?m/s)[A-Za-z][A-Za-z-]*/s)(?![A-Za-z0-9²/])")
_STORED = re.compile(r"(-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)\s?(min|ms|µs|us|s|h|×|x|%|[A-Za-z][A-Za-z-]*/s)?(?![A-Za-z0-9])")


def _kind_of_name(name: str) -> tuple[str, float] | None:
    """(kind, factor to SI) that a stored value's key or column name gives it, or None."""
    name = name.strip().lower()
    for suffix, factor in (("_ms", 1e-3), ("_us", 1e-6), ("_min", 60.0), ("(ms)", 1e-3), ("[ms]", 1e-3),
                           ("(us)", 1e-6), ("(µs)", 1e-6), ("(min)", 60.0)):
        if name.endswith(suffix):
            return "time", factor
    if name.endswith(("_per_s", "flop_s", "/s", "per_second")) or "throughput" in name:
        return "throughput", 1.0
    if name.endswith(("_s", "(s)", "[s]", " s")) or any(w in name for w in ("seconds", "time", "wall")):
        return "time", 1.0
    if name.endswith(("_x", "×")) or any(w in name for w in ("ratio", "speedup", "speed-up", "factor", "over", "×")):
        return "ratio", 1.0
    if any(w in name for w in ("fraction", "share", "percent", "rate", "efficiency", "misfit")):
        return "fraction", 1.0
    return None


def _unit_kind(unit: str | None) -> tuple[str, float] | None:
    if not unit:
        return None
    if unit in TIME_S:
        return "time", TIME_S[unit]
    if unit in ("×", "x"):
        return "ratio", 1.0
    if unit == "%":
        return "fraction", 0.01
    if unit.endswith("/s"):
        return "throughput", 1.0
    return None


def _walk_json(node, path, out):
    if isinstance(node, dict):
        for key, value in node.items():
            _walk_json(value, (*path, str(key)), out)
    elif isinstance(node, list):
        for value in node:
            _walk_json(value, path, out)
    elif isinstance(node, (int, float)) and not isinstance(node, bool) and math.isfinite(node):
        kind = next((k for k in map(_kind_of_name, reversed(path)) if k), None)
        if kind:
            out.append((kind[0], float(node) * kind[1]))
    elif isinstance(node, str):
        _text_values(node, out)


def _text_values(text: str, out) -> None:
    for match in _STORED.finditer(text):
        kind = _unit_kind(match.group(2))
        if kind:
            out.append((kind[0], float(match.group(1)) * kind[1]))


def _table_values(text: str, out) -> None:
    """Markdown tables: each numeric cell takes the kind its column's header names."""
    header = None
    for line in text.splitlines():
        if not line.strip().startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
            continue
        if all(re.fullmatch(r":?-+:?", c) for c in cells if c):
            continue
        for name, cell in zip(header, cells):
            kind = _kind_of_name(name)
            for part in cell.split(" / "):  # a cell may list the runs of one case: "a / b / c"
                number = re.fullmatch(r"\**(-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)\**", part.replace("×", "").strip())
                if kind and number:
                    out.append((kind[0], float(number.group(1)) * kind[1]))


def stored_values(root: Path = ROOT) -> list[tuple[str, float]]:
    """(kind, SI value) of every stored figure in the result folders."""
    out: list[tuple[str, float]] = []
    for folder in RESULT_DIRS:
        for path in sorted((root / folder).rglob("*")):
            if not path.is_file() or path.suffix not in (".json", ".csv", ".md"):
                continue
            text = path.read_text(errors="replace")
            if path.suffix == ".json":
                try:
                    _walk_json(json.loads(text), (), out)
                except json.JSONDecodeError:
                    _text_values(text, out)
            elif path.suffix == ".csv":
                rows = list(csv.reader(io.StringIO(text)))
                header = rows[0] if rows else []
                kinds = [_kind_of_name(h) for h in header]
                for row in rows[1:]:
                    for kind, cell in zip(kinds, row):
                        try:
                            value = float(cell)
                        except ValueError:
                            continue
                        if kind and math.isfinite(value):
                            out.append((kind[0], value * kind[1]))
            else:
                _text_values(text, out)
                _table_values(text, out)
    return out


def _prose(text: str):
    """(line number, sentence) of the prose: code blocks and inline code removed."""
    in_code = False
    for number, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith("```"):
            in_code = not in_code
            continue
        if not in_code:
            yield number, re.sub(r"`[^`]*`", " ", line)


def figures(text: str):
    """(line, figure as written, kind, SI value, printed decimals) of every checked figure."""
    for number, line in _prose(text):
        for sentence in re.split(r"(?<=[.;:])\s+", line):
            timing = any(word in sentence.lower() for word in TIMING_WORDS)
            for match in _FIGURE.finditer(sentence):
                digits, unit = match.group(1).replace(",", ""), match.group(2)
                if unit in ("ms", "µs", "us", "%") and not timing:
                    continue
                kind = _unit_kind(unit)
                if kind is None:
                    continue
                mantissa, _, exponent = digits.partition("e")
                decimals = (len(mantissa.split(".")[1]) if "." in mantissa else 0) - int(exponent or 0)
                yield number, match.group(0).strip(), kind[0], float(digits), kind[1], decimals


def _found(value, factor, decimals, kind, stored) -> bool:
    kinds = ("fraction", "ratio") if kind == "fraction" else (kind,)
    for stored_kind, si in stored:
        if stored_kind not in kinds:
            continue
        for scale in ((factor, 1.0) if kind == "fraction" else (factor,)):
            if round(si / scale, decimals) == round(value, decimals):
                return True
    return False


def missing(root: Path = ROOT, allowed=ALLOWED, unstored=UNSTORED) -> tuple[list[str], list[str]]:
    """('file:line: figure' of every checked figure not found in a stored result, and of
    those among them listed in `UNSTORED`); a listed figure no longer in its file is a
    problem too."""
    stored = stored_values(root)
    by_kind = {}
    for kind, si in stored:
        by_kind.setdefault(kind, []).append((kind, si))
    allowed = {(f, text) for f, text, _ in allowed}
    debt = {(f, text) for f, text, _ in unstored}
    problems, listed, seen = [], [], set()
    for document in DOCUMENTS:
        text = (root / document).read_text()
        for line, written, kind, value, factor, decimals in figures(text):
            seen.add((document, written))
            if (document, written) in allowed:
                continue
            pool = by_kind.get(kind, []) + (by_kind.get("ratio", []) if kind == "fraction" else [])
            if not _found(value, factor, decimals, kind, pool):
                where = f"{document}:{line}: {written} ({kind})"
                if (document, written) in debt:
                    listed.append(where + " is listed in UNSTORED")
                else:
                    problems.append(where + " is in no stored result")
    for document, written in sorted((allowed | debt) - seen):
        problems.append(f"{document}: {written} is listed in ALLOWED or UNSTORED but no longer in the text; "
                        "delete the entry")
    return problems, listed


def main() -> int:
    problems, listed = missing()
    for line in listed + problems:
        print(line)
    print(f"{len(problems)} figure(s) not found in {', '.join(RESULT_DIRS)}" if problems
          else "every checked figure is in a stored result")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
