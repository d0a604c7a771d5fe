"""The 0.1 names of the modules that moved into :mod:`tlshield.lab` (``tlshield.training``,
``tlshield.plots.curves``, ...): importing one gives the module at its new name, the same
object, with a DeprecationWarning. Removed in 0.3."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from types import ModuleType

#: The modules (and packages) that moved into :mod:`tlshield.lab`, by their last name.
MOVED = frozenset(
    {
        "benchmark",
        "benchmark_safety_gym",
        "callbacks",
        "cli",
        "cluster",
        "evaluation",
        "measures",
        "plots",
        "policies",
        "presets",
        "report",
        "runs",
        "saved",
        "seeds",
        "settings",
        "training",
        "tune",
    }
)


def new_name(fullname: str) -> str | None:
    """The new name of a moved module's old name (submodules of ``plots`` included), or
    None."""
    parts = fullname.split(".")
    if len(parts) >= 2 and parts[0] == "tlshield" and parts[1] in MOVED:
        return ".".join(["tlshield", "lab", *parts[1:]])
    return None


class OldNames(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """A finder, first on ``sys.meta_path``, that answers only for the moved modules' old
    names. First: else ``tlshield.plots.curves`` would be found again by path inside the
    moved package and loaded a second time, as a copy."""

    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        if new_name(fullname) is None:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = new_name(spec.name)
        assert new is not None
        warnings.warn(
            f"{spec.name} moved to {new} in tlshield 0.2 (the library apart from its "
            "experiments); the old name is removed in 0.3",
            DeprecationWarning,
            stacklevel=2,
        )
        return importlib.import_module(new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the module is the one at its new name, already executed."""


def install() -> None:
    """Puts :class:`OldNames` on ``sys.meta_path`` once."""
    if not any(isinstance(f, OldNames) for f in sys.meta_path):
        sys.meta_path.insert(0, OldNames())
