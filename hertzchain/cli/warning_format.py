"""Warnings as the command line shows them: one line each, in the command's own terms.

The library's warnings advise in API terms (`plasticity=True`, `on_yield='ignore'`); a
command prints instead `hertzchain simulate: warning: ...` with the advice in its options.
The warnings themselves are unchanged (the API, and `pytest.warns`, see them as they are).
"""

from __future__ import annotations

import contextlib
import re
import warnings

# Commands whose chain is described by the setup options (`setup_options`).
SETUP_COMMANDS = ("simulate", "sweep", "synth", "sensitivity", "design")
_YIELD_ADVICE = "Lower --striker-velocity, or model the yield with --plasticity thornton (or jackson_green)."


def _in_options(text: str) -> str:
    """Field names of the chain replaced by the options that set them."""
    from .setup_options import option_of_field

    return re.sub(r"\b[a-z0-9]+(?:_[a-z0-9]+)+\b", lambda m: option_of_field(m.group(0)) or m.group(0), text)


def cli_text(message: Warning, command: str) -> str:
    """The text of a warning as the command `command` shows it."""
    finding = getattr(message, "finding", None)
    if finding is None:
        return " ".join(str(message).split())
    if command not in SETUP_COMMANDS:
        return finding
    advice = _YIELD_ADVICE if type(message).__name__ == "YieldWarning" else ""
    return f"{_in_options(finding)} {advice}".strip()


@contextlib.contextmanager
def command_warnings(command: str):
    """While the command runs, warnings are printed as one line `hertzchain COMMAND: warning:
    TEXT` (`warnings.formatwarning`; filters and recording, as `pytest.warns` does, unchanged)."""
    def format_warning(message, category, filename, lineno, line=None):
        text = cli_text(message, command) if isinstance(message, Warning) else " ".join(str(message).split())
        return f"hertzchain {command}: warning: {text}\n"

    previous = warnings.formatwarning
    warnings.formatwarning = format_warning
    try:
        yield
    finally:
        warnings.formatwarning = previous
