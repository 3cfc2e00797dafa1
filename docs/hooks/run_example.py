"""Run one percent-format example (`# %%` cells) cell by cell and record what each cell printed
and which figures it wrote, for the tutorial pages (`docs/hooks/tutorials.py`).

    python docs/hooks/run_example.py examples/01_simulate_paper_chain.py OUT_DIR

runs the example at its small size (`HERTZCHAIN_EXAMPLE_SMALL=1`) with its outputs in
`OUT_DIR` and writes `OUT_DIR/cells.json`: one entry per cell, `{"kind": "markdown" | "code",
"source": ..., "output": ..., "figures": [file names in OUT_DIR]}`. An exception in a cell
stops the run with exit status 1 and its traceback.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import sys
from pathlib import Path


def cells(source: str) -> list[dict]:
    """The cells of a percent-format script: markdown cells without their comment marks."""
    found = []
    for block in re.split(r"^# %%", source, flags=re.MULTILINE)[1:]:
        header, _, body = block.partition("\n")
        if "[markdown]" in header:
            text = "\n".join(line[2:] if line.startswith("# ") else line.lstrip("#")
                             for line in body.strip().splitlines())
            found.append({"kind": "markdown", "source": text})
        else:
            found.append({"kind": "code", "source": body.strip("\n")})
    return found


def _files(folder: Path) -> dict[str, float]:
    return {p.relative_to(folder).as_posix(): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


def main(argv: list[str]) -> int:
    example, out = Path(argv[0]).resolve(), Path(argv[1]).resolve()
    out.mkdir(parents=True, exist_ok=True)
    os.environ.update(HERTZCHAIN_EXAMPLE_SMALL="1", HERTZCHAIN_EXAMPLE_OUT=str(out), MPLBACKEND="Agg")
    os.chdir(out)
    namespace = {"__name__": "__main__", "__file__": str(example)}
    recorded = cells(example.read_text())
    for cell in recorded:
        if cell["kind"] != "code":
            continue
        before = _files(out)
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            exec(compile(cell["source"], str(example), "exec"), namespace)
        after = _files(out)
        cell["output"] = printed.getvalue()
        cell["figures"] = sorted(name for name, stamp in after.items()
                                 if name.endswith(".png") and before.get(name) != stamp)
    (out / "cells.json").write_text(json.dumps(recorded, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
