"""Names that tlshield 0.4 removed, refused with a message naming what replaced them.

A module lists its removed names and gets a module ``__getattr__`` that raises
:class:`RemovedError`. It is an ImportError, so that ``from module import old`` shows the
message too (an AttributeError there becomes Python's bare "cannot import name")."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NoReturn

__all__ = ["RemovedError", "refuse"]


class RemovedError(ImportError):
    """A name removed in tlshield 0.4; the message names its replacement."""


def refuse(module: str, removed: Mapping[str, str]) -> Callable[[str], NoReturn]:
    """A module ``__getattr__`` for ``module``: each name in ``removed`` raises
    :class:`RemovedError` naming its replacement; any other name is an AttributeError."""

    def __getattr__(name: str) -> NoReturn:
        if name in removed:
            raise RemovedError(
                f"{module}.{name} was removed in tlshield 0.4: use {removed[name]}", name=name
            )
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__
