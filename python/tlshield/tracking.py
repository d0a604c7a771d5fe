"""The task along one episode for an environment written in Python: :class:`FsaTracker` (a shell
over the core's :class:`tlshield.Monitor` that adds the one-hot FSA state) and
the ``info["shield"]`` entry of a step, :func:`tlshield.step_info.shield_info` (also here). The
Gymnasium wrappers (:mod:`tlshield.wrappers`) and the bundled environments build on these
two."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tlshield._core import Automaton, Monitor, ProgressReward, Shield
from tlshield.step_info import shield_info

#: The task rewards a tracker can pay: the progress reward or the paper's Eq. 5A1.
REWARDS = ("progress", "paper")


class FsaTracker:
    """The task automaton along one episode: a thin shell over :class:`tlshield.Monitor` (which
    holds the FSA state, the last reading of the atoms and the reward's state in the core) that
    adds what the Gymnasium wrappers need (the one-hot FSA state).

    The FSA reads every state: ``reset(s_0)`` sets ``q_0 = step(initial, s_0)`` and
    ``advance(s')`` moves to ``step(s', q)`` and returns the reward of that transition.

    With ``progress`` (a :class:`tlshield.ProgressReward` of the same automaton, from
    ``automaton.progress_reward(...)``) the reward is the progress-aware one: reaching
    acceptance out-earns not reaching it, entering a state closer to acceptance never lowers
    the potential, Eq. 5A1 shapes within a state, and the trap (``progress.trap_penalty``) is
    worst. Without it the reward is the paper's Eq. 5A1, and every step in the trap pays
    ``trap_penalty`` (which must be no better than the worst reward reachable outside it, so
    that entering the trap never pays).
    """

    def __init__(
        self,
        automaton: Automaton,
        c_r: float,
        trap_penalty: float,
        progress: ProgressReward | None = None,
        routed_by: Shield | None = None,
    ) -> None:
        self.monitor = Monitor(
            automaton, progress, c_r=c_r, trap_penalty=trap_penalty, routed_by=routed_by
        )
        self.automaton = automaton
        self.c_r = float(c_r)
        self.progress = progress
        self.trap_penalty = float(trap_penalty if progress is None else progress.trap_penalty)
        self.accepting = frozenset(automaton.accepting)
        self._eye = np.eye(automaton.num_states)

    def reset(self, s: NDArray[np.float64]) -> int:
        return self.monitor.reset(s).q

    def advance(self, s_next: NDArray[np.float64]) -> tuple[int, float]:
        """Moves to the next FSA state; returns it and the reward of the transition."""
        step = self.monitor.advance(s_next)
        return step.q, step.reward

    @property
    def q(self) -> int:
        return self.monitor.q

    @property
    def phi(self) -> float:
        return self.monitor.phi

    @property
    def goal(self) -> NDArray[np.float64] | None:
        """The CLF goal at the last state and ``q`` (None without one, or before a reset)."""
        return self.monitor.goal if self.monitor.started else None

    @property
    def success(self) -> bool:
        """The task is done (the monitor, which the env may step in the core, is in
        acceptance)."""
        return self.monitor.started and self.monitor.q in self.accepting

    @property
    def trapped(self) -> bool:
        return self.monitor.started and self.monitor.q == self.automaton.trap

    def one_hot(self, q: int | None = None) -> NDArray[np.float64]:
        return self._eye[self.q if q is None else q]


__all__ = ["REWARDS", "FsaTracker", "shield_info"]
