"""An environment's parameters from keyword overrides, for every bundled environment: one check
of the names, and the spellings of tlshield 0.1 accepted with a ``DeprecationWarning``."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import asdict, fields, replace
from typing import Any, TypeVar

#: The configurations of the shield (the paper's four), the same for every environment: which
#: parts are on, ``(cbf, clf)``.
CONFIGS = {
    "rl": (False, False),
    "rl_cbf": (True, False),
    "rl_clf": (False, True),
    "rl_cbf_clf": (True, True),
}


class ParamsAlias:
    """``env.cfg``, the 0.2 name of an environment's ``env.params``: still readable, with a
    ``DeprecationWarning`` (removed in 0.3)."""

    params: Any

    @property
    def cfg(self) -> Any:
        warnings.warn(
            "env.cfg is deprecated: use env.params (an environment's constants are its "
            "parameters; 'config' is the shield configuration)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.params


#: The configuration with every part on: the tlshield default and the paper's method.
FULL = "rl_cbf_clf"


def shielded_config(config: str, evaluation: bool) -> str:
    """The shield an environment builds for ``config``: the paper's evaluation rule turns the
    CBF on in every configuration (``rl`` -> ``rl_cbf``, ``rl_clf`` -> ``rl_cbf_clf``); in
    training it is ``config`` itself."""
    if config not in CONFIGS:
        raise ValueError(f"config = {config!r}: expected one of {sorted(CONFIGS)}")
    cbf, clf = CONFIGS[config]
    if evaluation and not cbf:
        return FULL if clf else "rl_cbf"
    return config


#: Parameters renamed in 0.2 (old -> new): one lower-case name per concept, ``margin`` as the
#: shield calls it.
RENAMED = {"K": "k", "cbf_margin": "margin"}
#: Classes renamed in 0.2: "config" now means only a configuration of the shield (rl, rl_cbf,
#: rl_clf, rl_cbf_clf); an environment's constants are its parameters.
RENAMED_CLASSES = {
    "ChannelConfig": "ChannelParams",
    "PointMassConfig": "PointMassParams",
    "FlatWorldConfig": "FlatWorldParams",
}

P = TypeVar("P")


def upgrade(overrides: Mapping[str, Any], where: str, *, warn: bool = True) -> dict[str, Any]:
    """``overrides`` with 0.1 names replaced by their new ones (a ``DeprecationWarning`` each,
    unless ``warn`` is False, as for files written by 0.1). Both spellings at once is a
    TypeError."""
    out: dict[str, Any] = {}
    for name, value in overrides.items():
        new = RENAMED.get(name)
        if new is None:
            out[name] = value
            continue
        if new in overrides:
            raise TypeError(f"{where}: {name!r} and {new!r} given; {name!r} is the old name")
        if warn:
            warnings.warn(
                f"{where}: {name!r} is now called {new!r} (tlshield 0.2)",
                DeprecationWarning,
                stacklevel=3,
            )
        out[new] = value
    return out


def flat_names(cls: type) -> tuple[str, ...]:
    """The keyword names of an environment's parameters class: its fields, or, for a class in
    parts (:class:`tlshield.envs.ChannelParams`), its flat names."""
    own = getattr(cls, "flat_names", None)
    return tuple(own()) if own is not None else tuple(f.name for f in fields(cls))


def from_flat(cls: type[P], values: Mapping[str, Any]) -> P:
    """``cls()`` with ``values`` (flat names), unchecked."""
    own = getattr(cls, "from_flat", None)
    return own(values) if own is not None else replace(cls(), **values)  # type: ignore[type-var]


def as_flat(params: Any) -> dict[str, Any]:
    """An environment's parameters by flat name (what a run's record stores); empty for None
    (a user's environment)."""
    if params is None:
        return {}
    own = getattr(params, "flat", None)
    return own() if own is not None else asdict(params)


def build(cls: type[P], overrides: Mapping[str, Any], where: str) -> P:
    """``cls()`` with ``overrides``, checked: an unknown name is a TypeError listing the known
    ones, a bad value the ValueError of ``cls.check``."""
    overrides = upgrade(overrides, where)
    known = flat_names(cls)
    unknown = sorted(set(overrides) - set(known))
    if unknown:
        raise TypeError(f"unknown {where} parameter(s) {unknown}; known: {sorted(known)}")
    params = from_flat(cls, overrides)
    params.check()  # type: ignore[attr-defined]
    return params


def renamed_class(namespace: Mapping[str, Any], module: str, name: str) -> Any:
    """A module ``__getattr__``: the new class for a 0.1 class name, with a warning."""
    new = RENAMED_CLASSES.get(name)
    if new is None or new not in namespace:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    warnings.warn(
        f"{module}.{name} is now called {new} (tlshield 0.2)", DeprecationWarning, stacklevel=3
    )
    return namespace[new]
