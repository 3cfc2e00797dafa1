"""mkdocs hook: the tutorial pages, made from the examples in `examples/` by running them.

Each `examples/NN_name.py` (a percent-format script) is run cell by cell at its small size by
`docs/hooks/run_example.py`, two at a time; its page `tutorials/NN_name.md` shows each
markdown cell as text, each code cell as code with what it printed below it, and the figures
it wrote. An example that fails fails the build. Runs are kept in `build/docs-examples/`,
keyed by a digest of the example and of every source file of `hertzchain` and `fitting`, so a
rebuild runs only what changed; `HERTZCHAIN_DOCS_RERUN=1` runs every example again.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
CACHE = ROOT / "build" / "docs-examples"
RUNNER = Path(__file__).with_name("run_example.py")


def examples() -> list[Path]:
    return sorted(ROOT.glob("examples/[0-9][0-9]_*.py"))


def _digest(example: Path) -> str:
    digest = hashlib.sha256(example.read_bytes())
    for path in sorted([*ROOT.glob("hertzchain/**/*"), *ROOT.glob("fitting/**/*"), RUNNER]):
        if path.is_file() and path.suffix in (".py", ".cc", ".h", ".cu"):
            digest.update(path.relative_to(ROOT).as_posix().encode() + path.read_bytes())
    return digest.hexdigest()[:16]


def _run(example: Path) -> Path:
    """The folder holding the example's recorded run (`cells.json` and its figures)."""
    out = CACHE / f"{example.stem}-{_digest(example)}"
    if (out / "cells.json").is_file() and os.environ.get("HERTZCHAIN_DOCS_RERUN") != "1":
        return out
    shutil.rmtree(out, ignore_errors=True)
    for stale in CACHE.glob(f"{example.stem}-*"):
        shutil.rmtree(stale, ignore_errors=True)
    env = os.environ | {"PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, str(RUNNER), str(example), str(out)], env=env,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise PluginError(f"example {example.name} failed:\n{done.stdout[-3000:]}\n{done.stderr[-6000:]}")
    return out


def page(example: Path, folder: Path) -> tuple[str, list[str]]:
    """(Markdown of the tutorial page, figure file names it embeds)."""
    recorded = json.loads((folder / "cells.json").read_text())
    note = (f"*This page is `examples/{example.name}` run at its small size (`HERTZCHAIN_EXAMPLE_SMALL=1`) "
            f"when the documentation was built; `python examples/{example.name}` runs it at full size, "
            "writing to `out/examples/` (`HERTZCHAIN_EXAMPLE_OUT` to change it).*")
    parts, figures = [], []
    for number, cell in enumerate(recorded):
        if cell["kind"] == "markdown":
            parts.append(cell["source"])
            if number == 0:
                parts.append(note)
            continue
        parts.append(f"```python\n{cell['source']}\n```")
        if cell.get("output", "").strip():
            parts.append(f"```text\n{cell['output'].rstrip()}\n```")
        for name in cell.get("figures", []):
            figures.append(name)
            parts.append(f"![{Path(name).stem}](figures/{example.stem}/{Path(name).name})")
    return "\n\n".join(parts) + "\n", figures


def on_files(files, config):
    CACHE.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(_run, examples()))
    for example, folder in zip(examples(), runs):
        text, figures = page(example, folder)
        files.append(File.generated(config, f"tutorials/{example.stem}.md", content=text))
        for name in figures:
            files.append(File.generated(config, f"tutorials/figures/{example.stem}/{Path(name).name}",
                                        abs_src_path=str(folder / name)))
    return files
