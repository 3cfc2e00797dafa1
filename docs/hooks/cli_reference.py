"""mkdocs hook: one reference page per `hertzchain` command, generated from the command's own
argparse parser and module docstring at build time, so that the pages cannot go stale.

Each page holds the command's summary, its description (the module docstring), its syntax
(argparse's usage line) and a table of every option with its metavar, default and help text,
then `docs/reference/cli/notes/<command>.md` where one is written (outputs and restrictions
that the docstring does not state). The pages are `reference/cli/<command>.md`;
`reference/cli/index.md` lists the commands.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]


def _docstring(module_name: str) -> str:
    """The module's docstring, read from its source without importing it."""
    spec = importlib.util.find_spec(module_name)
    return ast.get_docstring(ast.parse(Path(spec.origin).read_text())) or ""


def _indented_block(lines: list[str], index: int) -> tuple[list[str], int]:
    """The indented block (4 spaces, blank lines inside) from `lines[index]`, unindented and
    without trailing blank lines, and the index after it."""
    block = []
    while index < len(lines) and (lines[index].startswith("    ") or not lines[index].strip()):
        block.append(lines[index][4:])
        index += 1
    while block and not block[-1].strip():
        block.pop()
    return block, index


def _markdown_of_docstring(text: str) -> str:
    """A docstring as Markdown: reST literal blocks (`::` and an indented block) become
    fenced code."""
    lines = text.splitlines()
    out, index = [], 0
    while index < len(lines):
        line = lines[index]
        if line.rstrip().endswith("::"):
            out.append(line.rstrip()[:-1] if not line.strip() == "::" else "")
            index += 1
            while index < len(lines) and not lines[index].strip():
                index += 1
            block, index = _indented_block(lines, index)
            out += ["", "```bash", *block, "```", ""]
            continue
        if line.startswith("    ") and (not out or not out[-1].strip()):  # an indented block: code
            block, index = _indented_block(lines, index)
            out += ["```bash", *block, "```", ""]
            continue
        out.append(line)
        index += 1
    return "\n".join(out).strip()


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _default(action: argparse.Action) -> str:
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        return "off" if isinstance(action, argparse._StoreTrueAction) else "on"
    if action.default in (None, argparse.SUPPRESS) or action.required:
        return "required" if action.required else "–"
    if isinstance(action.default, (list, tuple)):
        return f"`{','.join(map(str, action.default))}`" if action.default else "–"
    return f"`{action.default}`"


def _options_table(parser: argparse.ArgumentParser) -> str:
    rows = ["| option | value | default | meaning |", "|---|---|---|---|"]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        names = ", ".join(f"`{name}`" for name in action.option_strings) or f"`{action.dest.upper()}`"
        if action.nargs == 0:
            value = ""
        else:
            metavar = action.metavar or (action.dest.upper() if action.option_strings else action.dest)
            value = f"`{' '.join(metavar) if isinstance(metavar, tuple) else metavar}`"
            if action.choices is not None:
                value = " \\| ".join(f"`{choice}`" for choice in action.choices)
            if action.nargs in ("+", "*"):
                value += " …"
        help_text = (action.help or "") % {"default": action.default, "prog": parser.prog} \
            if action.help and "%(" in action.help else (action.help or "")
        rows.append(f"| {names} | {value} | {_default(action)} | {_cell(help_text)} |")
    return "\n".join(rows)


def command_page(name: str) -> str:
    """The Markdown reference page of `hertzchain NAME`."""
    from hertzchain.cli import COMMANDS

    module_name, summary = COMMANDS[name]
    parser = argparse.ArgumentParser(prog=f"hertzchain {name}", description=summary)
    importlib.import_module(module_name).add_arguments(parser)
    usage = parser.format_usage().removeprefix("usage: ").strip()
    usage = re.sub(r"\s+", " ", usage)
    return "\n\n".join([
        f"# `hertzchain {name}`",
        summary[0].upper() + summary[1:] + ".",
        "## Syntax",
        f"```text\n{_wrap(usage)}\n```",
        "## Description",
        _markdown_of_docstring(_docstring(module_name)) or summary,
        "## Options",
        "Generated from the command's parser; `hertzchain " + name + " --help` prints the same.",
        _options_table(parser),
        "## Exit status",
        "0 on success; 2 for an input error (the message names the field and the fix). "
        "Further statuses of this command, if any, are stated in its description above; every "
        "command's statuses: [Exit status](../exit-status.md).",
        *([(ROOT / "docs" / "reference" / "cli" / "notes" / f"{name}.md").read_text().strip()]
          if (ROOT / "docs" / "reference" / "cli" / "notes" / f"{name}.md").is_file() else []),
        f"*Module:* `{module_name}`.",
    ]) + "\n"


def _wrap(usage: str, width: int = 92) -> str:
    words, lines, line = usage.split(" "), [], ""
    for word in words:
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = "    " + word
        else:
            line = f"{line} {word}" if line else word
    return "\n".join([*lines, line])


def index_page() -> str:
    from hertzchain.cli import COMMANDS

    rows = ["| command | what it does |", "|---|---|"]
    rows += [f"| [`hertzchain {name}`]({name}.md) | {_cell(summary)} |" for name, (_, summary) in COMMANDS.items()]
    return "\n\n".join([
        "# Command line",
        "Every job is a subcommand of `hertzchain` (`python -m hertzchain` works too). Numbers are "
        "SI; unit suffixes such as `13mm`, `5GPa`, `2us`, `85kHz` are accepted. "
        "`hertzchain --version` prints the installed version, `hertzchain COMMAND --help` the options "
        "of one command. These pages are generated from the commands' own parsers.",
        "\n".join(rows),
    ]) + "\n"


def on_config(config):
    """Fill the navigation's "Command line" section with one entry per command, in the
    order of `hertzchain.cli.COMMANDS`, so that a new command has its page in the menu."""
    from hertzchain.cli import COMMANDS

    def fill(items):
        for item in items:
            if isinstance(item, dict):
                for title, value in item.items():
                    if title == "Command line":
                        item[title] = ["reference/cli/index.md"] + [
                            {name: f"reference/cli/{name}.md"} for name in COMMANDS]
                    elif isinstance(value, list):
                        fill(value)

    fill(config["nav"])
    return config


def on_files(files, config):
    from hertzchain.cli import COMMANDS

    pages = {"reference/cli/index.md": index_page()}
    pages |= {f"reference/cli/{name}.md": command_page(name) for name in COMMANDS}
    for file in [f for f in files if f.src_uri.startswith("reference/cli/notes/")]:
        files.remove(file)  # appended to their command's page, not pages of their own
    for uri, content in pages.items():
        existing = files.get_file_from_path(uri)
        if existing is not None:
            files.remove(existing)
        files.append(File.generated(config, uri, content=content))
    return files
