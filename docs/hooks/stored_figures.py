"""mkdocs hook: the figures stored with the results (`benchmarks/results/**.png`,
`examples/**/results/**.png`) as files of the site, at `stored/<their path in the repository>`,
so that a page shows a stored figure without a copy of it in `docs/`."""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
PATTERNS = ("benchmarks/results/**/*.png", "examples/**/results/**/*.png")


def on_files(files, config):
    for pattern in PATTERNS:
        for path in sorted(ROOT.glob(pattern)):
            uri = "stored/" + path.relative_to(ROOT).as_posix()
            files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files
