"""Every source file compiles without warnings on the newest Python's rules.

Python 3.12 turns an invalid escape sequence in a string (a docstring's ``$\\sigma$``) into a
SyntaxWarning printed at import; 3.11 raises it as a DeprecationWarning at compile time,
which cached bytecode hides from the rest of the suite. Compiling the text afresh with
warnings as errors catches it on any supported Python.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = sorted(
    path for folder in ("hertzchain", "fitting", "benchmarks", "tests", "examples")
    for path in (ROOT / folder).rglob("*.py")
)


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_source_compiles_without_warnings(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        compile(path.read_text(encoding="utf-8"), str(path), "exec")
