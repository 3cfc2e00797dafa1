"""Module paths that moved, kept importable for one release.

`MOVED` maps each old path to its new one. Importing an old path gives the module at the
new path (the same object, private names and all, so that code which patches it patches the
one module) and raises a `DeprecationWarning`, attributed to the line that imported the old
path, naming the new path. No file is left at an old path: an import finder
(`MovedModuleFinder`, installed by `import hertzchain`) answers for them.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

MOVED = {
    **{f"hertzchain.{name}": f"hertzchain.io.{name}"
       for name in ("atomic", "importer", "scopefiles", "summary", "tracefile")},
    "fitting.cli": "hertzchain.cli",
    **{f"fitting.cli.{name}": f"hertzchain.cli.{name}"
       for name in ("contact", "design", "diagnose", "fit")},
    "fitting.driven_cli": "hertzchain.cli.driven_experiments",
    "fitting.diagnosis_report": "fitting.diagnosis.report",
    "fitting.locate": "fitting.diagnosis.locate",
    **{f"fitting.driven_{name}": f"fitting.driven.{name}"
       for name in ("band", "candidates", "diagnosis", "experiment", "joint", "joint_report", "report")},
}


class MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds and loads the old paths of `MOVED`: each is replaced by the module at its new
    path. Below a package that moved, only the modules `MOVED` names are found."""

    def find_spec(self, name, path=None, target=None):
        if name in MOVED:
            return importlib.util.spec_from_loader(name, self)
        if name.rpartition(".")[0] in MOVED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

    def create_module(self, spec):
        return None  # a placeholder module, replaced in `exec_module`

    def exec_module(self, module):
        old_name = module.__name__
        warnings.warn(f"`{old_name}` moved to `{MOVED[old_name]}`; import it from there (the old "
                      "path goes in the next release).", DeprecationWarning, stacklevel=2)
        sys.modules[old_name] = importlib.import_module(MOVED[old_name])


def install_finder() -> None:
    """Put `MovedModuleFinder` first on `sys.meta_path` (once), so that the old paths of
    packages that moved are found before the files of their new packages."""
    if not any(isinstance(finder, MovedModuleFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedModuleFinder())
