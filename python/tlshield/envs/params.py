"""An environment's parameters from keyword overrides, for every bundled environment: one check
of the names. The spellings of tlshield 0.1 were removed in 0.3: given now, each is an error
that names its new spelling; files written by 0.1 (run records, settings files) still read."""

from __future__ import annotations

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


#: The configuration with every part on: the tlshield default and the paper's method.
FULL = "rl_cbf_clf"


def check_config(config: object, where: str = "config") -> str:
    """``config`` if it is one of :data:`CONFIGS`, else a ValueError naming ``where`` and the
    four: the one check of a shield configuration, wherever one is given."""
    if not isinstance(config, str) or config not in CONFIGS:
        raise ValueError(f"{where} = {config!r}: expected one of {', '.join(CONFIGS)}")
    return config


def shielded_config(config: str, evaluation: bool) -> str:
    """The shield an environment builds for ``config``: the paper's evaluation rule turns the
    CBF on in every configuration (``rl`` -> ``rl_cbf``, ``rl_clf`` -> ``rl_cbf_clf``); in
    training it is ``config`` itself."""
    check_config(config)
    cbf, clf = CONFIGS[config]
    if evaluation and not cbf:
        return FULL if clf else "rl_cbf"
    return config


#: Parameters renamed in 0.2 (old -> new): one lower-case name per concept, ``margin`` as the
#: shield calls it. The old names were removed in 0.3 (see :func:`upgrade`).
RENAMED = {"K": "k", "cbf_margin": "margin"}

P = TypeVar("P")


def upgrade(overrides: Mapping[str, Any], where: str, *, from_file: bool = False) -> dict[str, Any]:
    """``overrides`` by their current names. An old (0.1) name read from a file written then
    (``from_file``: a run record, a settings file) becomes its new one; given now, it is a
    TypeError naming the new one. Both spellings at once is a TypeError."""
    out: dict[str, Any] = {}
    for name, value in overrides.items():
        new = RENAMED.get(name)
        if new is None:
            out[name] = value
            continue
        if not from_file:
            raise TypeError(
                f"{where}: {name!r} is now called {new!r} (renamed in tlshield 0.2; the old "
                "name was removed in 0.3)"
            )
        if new in overrides:
            raise TypeError(f"{where}: {name!r} and {new!r} given; {name!r} is the old name")
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
