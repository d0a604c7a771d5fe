"""The third-party adapter: Safety-Gymnasium 1.0.0 made to import and run on tlshield's stack.

safety-gymnasium 1.0.0 as published does not import with gymnasium 1.x and Python 3.11: its
package ``__init__`` imports ``gymnasium.wrappers.compatibility`` (removed in gymnasium 1.0),
and its colours are numpy arrays used as dataclass defaults (refused since Python 3.11:
unhashable), and its Car robot reads a joint by the id a sensor's view gives, a one-element
numpy array, which MuJoCo 2.3.7's ``MjModel.jnt`` refuses under numpy 2. :func:`load_builder`
checks the installed versions (:data:`VERSIONS`), makes the package importable without running
its ``__init__`` (a module shell whose ``__path__`` is the package's folder), makes the colour
arrays hashable (a view with identity hashing; the values are untouched), lets
``MjModel.jnt`` take a one-element integer array as the integer it holds (every other argument
goes through as it is), and returns its ``Builder``, the env class every Safety-Gymnasium task
is made from. Nothing else is patched, and nothing is patched before :func:`load_builder` is
called (importing this module patches nothing). ``make safety-gym`` installs the stack
(docs/guides/safety-gym.md says what and why).

This module owns the adapter and everything that touches the third-party packages' state; the
shielded envs (:mod:`tlshield.envs.safety_gym.env`) only call :func:`make_builder`.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import os
import sys
import types
import warnings
from typing import Any

import numpy as np

#: The versions the adapter was written and tested against (it patches exactly these).
VERSIONS = {"safety-gymnasium": "1.0.0", "mujoco": "2.3.7"}
#: What installs them.
INSTALL = (
    "make safety-gym (or: pip install --no-deps safety-gymnasium==1.0.0 && pip install "
    "mujoco==2.3.7 xmltodict pyyaml imageio)"
)
#: The tasks registered as ``tlshield/<task>``.
TASKS = ("SafetyPointGoal1-v0", "SafetyPointGoal2-v0", "SafetyCarGoal1-v0")
#: The tasks :func:`make_builder` makes (Safety-Gymnasium's own, unshielded).
BUILDER_TASKS = TASKS
#: The package the adapter imports, whose modules :func:`load_builder` adds to ``sys.modules``.
_PACKAGE = "safety_gymnasium"


class MissingStack(ImportError):
    """The Safety-Gymnasium stack is missing or at another version than :data:`VERSIONS`."""


def installed() -> bool:
    """Whether the Safety-Gymnasium stack of :data:`VERSIONS` is installed."""
    try:
        return all(importlib.metadata.version(p) == v for p, v in VERSIONS.items())
    except importlib.metadata.PackageNotFoundError:
        return False


class _HashableArray(np.ndarray):
    """A colour array that dataclasses accept as a default (identity hash, values as given)."""

    __hash__ = object.__hash__  # type: ignore[assignment]


@functools.cache
def load_builder() -> type:
    """Safety-Gymnasium's ``Builder`` after the adapter's checks and patches (see the module
    docs); :class:`MissingStack` (an ImportError) saying what to install when the stack is
    missing or at another version.

    **What stays patched after success, and why.** The call is cached: the patches are made
    once per process and stay for its life.

    * The module shell ``sys.modules["safety_gymnasium"]`` and the submodules imported under it
      (``safety_gymnasium.builder``, ``.assets.color``, ``.tasks...``) stay: they are the
      package as imported, and anything that resolves one of its names later (a user's
      ``import safety_gymnasium.x``, pickle or copy finding a class by its module) must find
      these modules rather than run the package's ``__init__``, which fails on gymnasium 1.x,
      or load a second copy of its classes.
    * The hashable colours stay: they are ``safety_gymnasium.assets.color.COLOR``'s values,
      already the defaults of the geoms' dataclasses.
    * ``mujoco.MjModel.jnt`` stays patched: the Car's sensors call it at every step, long after
      this call returns (``MjModel.jnt`` with any argument other than a one-element integer
      array behaves as MuJoCo's own).

    When ``safety_gymnasium`` is already in ``sys.modules`` (imported by someone else), the
    adapter neither makes a shell nor touches the colours: it patches ``MjModel.jnt`` (once)
    and imports the ``Builder`` from what is there.

    **What is undone on failure.** If anything in the call raises (the version check raises
    before anything is patched), the entries it added to ``sys.modules`` under
    ``safety_gymnasium`` (the shell, its submodules, and with them the modules holding the
    hashable colours) are removed, each also from its parent package's attributes where the
    parent stays, ``mujoco.MjModel.jnt`` is restored to what it was on entry, and the error
    propagates (nothing is cached: a later call tries again). Third-party modules imported on
    the way (mujoco, xmltodict, ...) are ordinary imports of installed packages and stay loaded,
    as after any failed import."""
    for package, wanted in VERSIONS.items():
        try:
            got = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            raise MissingStack(f"{package} is not installed; install it with {INSTALL}") from None
        if got != wanted:
            raise MissingStack(
                f"{package} {got} is installed, but the adapter patches {package} {wanted}; "
                f"install it with {INSTALL}"
            )
    import mujoco

    modules = set(sys.modules)
    jnt = mujoco.MjModel.jnt
    try:
        return _patch_and_import()
    except BaseException:
        _forget_modules(set(sys.modules) - modules)
        mujoco.MjModel.jnt = jnt
        raise


def _patch_and_import() -> type:
    # The patches and the import, in the order load_builder has always made them.
    if _PACKAGE not in sys.modules:
        spec = importlib.util.find_spec(_PACKAGE)
        assert spec is not None and spec.submodule_search_locations is not None
        root = next(iter(spec.submodule_search_locations))
        shell = types.ModuleType(_PACKAGE)
        shell.__path__ = [root]
        shell.__file__ = os.path.join(root, "__init__.py")
        sys.modules[_PACKAGE] = shell
        from safety_gymnasium.assets import color  # type: ignore[import-not-found]

        for name, value in list(color.COLOR.items()):
            color.COLOR[name] = np.asarray(value).view(_HashableArray)
    _accept_array_joint_ids()
    from safety_gymnasium.builder import Builder  # type: ignore[import-not-found]

    return Builder


def _forget_modules(added: set[str]) -> None:
    """Removes the modules of ``safety_gymnasium`` among ``added`` from ``sys.modules``, and each
    from its parent's attributes where the parent stays loaded."""
    for name in sorted(added, reverse=True):  # children before their parents
        if name != _PACKAGE and not name.startswith(_PACKAGE + "."):
            continue
        module = sys.modules.pop(name, None)
        parent, _, child = name.rpartition(".")
        if parent in sys.modules and getattr(sys.modules[parent], child, None) is module:
            delattr(sys.modules[parent], child)


def _accept_array_joint_ids() -> None:
    """``MjModel.jnt(id)`` with ``id`` a one-element integer array (a sensor view's
    ``objid``) reads joint ``int(id)``; any other argument is passed on untouched."""
    import mujoco

    jnt = mujoco.MjModel.jnt
    if getattr(jnt, "_tlshield_patched", False):
        return

    def patched(self: Any, *args: Any, **kwargs: Any) -> Any:
        if len(args) == 1 and not kwargs:
            key = args[0]
            if isinstance(key, np.ndarray) and key.size == 1 and key.dtype.kind in "iu":
                args = (int(key.reshape(())),)
        return jnt(self, *args, **kwargs)

    patched._tlshield_patched = True  # type: ignore[attr-defined]
    mujoco.MjModel.jnt = patched


def make_builder(task: str) -> Any:
    """Safety-Gymnasium's own env of ``task`` (one of :data:`BUILDER_TASKS`, e.g.
    ``"SafetyPointGoal1-v0"``), through the adapter. Its ``step`` returns Safety-Gymnasium's
    6-tuple."""
    if task not in BUILDER_TASKS:
        raise ValueError(f"task = {task!r}: the adapter supports {', '.join(BUILDER_TASKS)}")
    robot = task.removeprefix("Safety").split("Goal")[0]
    builder = load_builder()
    with warnings.catch_warnings():
        # Safety-Gymnasium builds its action Box from MuJoCo's float32 control range as
        # float64, and Gymnasium's check casts float64's limits to float32 on the way: a
        # harmless overflow warning at every make, about no value of the space.
        warnings.filterwarnings("ignore", "overflow encountered in cast", RuntimeWarning)
        return builder(task, config={"agent_name": robot})
