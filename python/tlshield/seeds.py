"""Where every random stream of tlshield starts, in one place, so that training, validation and
evaluation reset seeds never meet and nothing is tuned on evaluation seeds.

A run seed is any non-negative integer (0, 42, 2**31 - 1, 2**64, ...). Its streams are the
spawned children of numpy's ``SeedSequence(seed)``, one per use (:data:`STREAMS`): training,
validation, the run's own evaluation block, and the learner's seed (PPO's, torch's). Each reset
stream is a block of ``STRIDE`` consecutive reset seeds (environment ``i``, episode ``k``) that
starts at a point its child draws, inside the stream's own quarter of ``[0, 2**32)``:

- training environments: ``[0, 2**30)``;
- validation episodes (checkpoint selection): ``[2**30, 2**31)``;
- evaluation blocks of one run seed (the FlatWorld and Safety-Gym benchmarks): ``[2**31,
  3 * 2**30)``;
- the evaluation trials every run shares (:func:`tlshield.evaluation.evaluate`):
  ``EVAL_SEED + k``, ``EVAL_SEED = 3 * 2**30``; the tuning trials (``tlshield tune``'s
  objective): ``TUNE_SEED + k``, ``TUNE_SEED = 3.5 * 2**30``.

The quarters never meet, so no training or validation reset seed is ever an evaluation one.
Two run seeds' blocks of the same stream may overlap (with odds of about ``STRIDE / 2**30``);
that only means two runs share a few episodes. Every reset seed is below ``2**32``, which every
environment accepts.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

#: Reset seeds per stream block: at most this many environments or episodes per run seed.
STRIDE = 1000
#: The width of each stream's quarter of ``[0, 2**32)``.
QUARTER = 2**30
#: The spawn key of each stream's child of ``SeedSequence(seed)``, and its quarter.
STREAMS = {"training": 0, "validation": 1, "evaluation": 2, "learner": 3}
#: First of the evaluation trials every run shares (trial ``k`` resets from ``EVAL_SEED + k``).
EVAL_SEED = 3 * QUARTER
#: First of the tuning trials (``tlshield tune`` evaluates its samples on ``TUNE_SEED + k``).
TUNE_SEED = EVAL_SEED + QUARTER // 2


def _start(seed: int, stream: str) -> int:
    """Where ``stream``'s block of run ``seed`` starts inside its quarter."""
    child = np.random.SeedSequence(seed, spawn_key=(STREAMS[stream],))
    offset = int(child.generate_state(1, np.uint64)[0]) % (QUARTER - STRIDE)
    return STREAMS[stream] * QUARTER + offset


def train_seed(seed: int, env: int = 0) -> int:
    """The reset seed of training environment ``env`` of run ``seed`` (SB3 seeds environment
    ``i`` of a vector env with ``train_seed(seed) + i``)."""
    return _start(seed, "training") + env


def validation_seed(seed: int, episode: int) -> int:
    """The reset seed of validation episode ``episode`` of run ``seed``."""
    return _start(seed, "validation") + episode


def eval_block_seed(seed: int, episode: int) -> int:
    """The reset seed of evaluation episode ``episode`` in run ``seed``'s own block."""
    return _start(seed, "evaluation") + episode


def learner_seed(seed: int) -> int:
    """The learner's seed for run ``seed`` (SB3's ``seed=``: Python's, numpy's and torch's
    generators and the action space), below ``2**31``."""
    child = np.random.SeedSequence(seed, spawn_key=(STREAMS["learner"],))
    return int(child.generate_state(1, np.uint32)[0]) >> 1


def check_seeds(seeds: Iterable[Any]) -> None:
    """Raises ValueError unless every seed is a non-negative integer."""
    for seed in seeds:
        if not (isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0):
            raise ValueError(f"seed = {seed!r}: expected a non-negative integer")


def check_block(count: int, what: str) -> None:
    """Raises ValueError unless ``count`` (environments or episodes of one run seed) fits in
    one block of ``STRIDE`` reset seeds."""
    if not (isinstance(count, int) and not isinstance(count, bool) and 0 < count <= STRIDE):
        raise ValueError(
            f"{what} = {count!r}: expected a positive integer <= {STRIDE} (one run seed's block "
            "of reset seeds)"
        )
