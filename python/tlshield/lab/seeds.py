"""Where every random stream of tlshield starts, in one place, so that training, validation and
evaluation reset seeds never meet and nothing is tuned on evaluation seeds.

A run seed is any non-negative integer (0, 42, 2**31 - 1, 2**64, ...). Each of its streams is a
block of ``STRIDE`` consecutive reset seeds (environment ``i``, episode ``k``):

- **Seeds 0-9** (:data:`LEGACY_SEEDS`) keep the reset seeds every bundled table was measured
  with: training environment ``i`` of run ``s`` resets from ``1000 s + i``, validation episode
  ``k`` from ``20,000 + 1000 s + k``, the run's own evaluation block from ``10,000 + 1000 s +
  k``, and the learner (PPO) takes ``s`` itself. So the published numbers stay reproducible.
- **Every other seed** draws its streams from the spawned children of numpy's
  ``SeedSequence(seed)``, one per use (:data:`STREAMS`): training, validation, the evaluation
  block, the learner. Each reset block starts where its child says, inside the stream's own
  quarter of ``[0, 2**32)`` and above ``FLOOR`` (so past every legacy reset seed):
  training ``[FLOOR, 2**30)``, validation ``[2**30 + FLOOR, 2**31)``, evaluation blocks
  ``[2**31 + FLOOR, 3 * 2**30)``.

The evaluation trials every run shares (:func:`tlshield.lab.evaluation.evaluate`) reset from
``EVAL_SEED + k`` (10,000+), and ``tlshield tune`` evaluates its samples on ``TUNE_SEED + k``
(30,000+). No training or validation reset seed is ever an evaluation or tuning one. Two run
seeds' blocks of one stream may overlap (odds about ``STRIDE / 2**30`` for drawn blocks): two
runs then share a few episodes, nothing more. Every reset seed is below ``2**32``, which every
environment accepts.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

#: Reset seeds per stream block: at most this many environments or episodes per run seed.
STRIDE = 1000
#: Run seeds below this keep tlshield 0.1's reset seeds (``1000 s + i``: the bundled tables').
LEGACY_SEEDS = 10
#: First of the evaluation trials every run shares (trial ``k`` resets from ``EVAL_SEED + k``).
EVAL_SEED = 10_000
#: The most evaluation trials of one policy (so that ``EVAL_SEED + k`` stays below
#: ``VALIDATION_SEED``).
MAX_TRIALS = 10_000
#: First legacy validation reset seed (``VALIDATION_SEED + 1000 s + k`` for a legacy seed).
VALIDATION_SEED = 20_000
#: First of the tuning trials (``tlshield tune`` evaluates its samples on ``TUNE_SEED + k``).
TUNE_SEED = 30_000
#: The width of each drawn stream's quarter of ``[0, 2**32)``.
QUARTER = 2**30
#: Drawn blocks start at or above ``stream quarter + FLOOR``: past the legacy, evaluation and
#: tuning reset seeds (all below 40,000 for up to 10,000 trials).
FLOOR = 2**16
#: The spawn key of each stream's child of ``SeedSequence(seed)``, and its quarter.
STREAMS = {"training": 0, "validation": 1, "evaluation": 2, "learner": 3}


def _start(seed: int, stream: str) -> int:
    """Where ``stream``'s block of run ``seed`` starts."""
    if seed < LEGACY_SEEDS:
        legacy = {"training": 0, "validation": VALIDATION_SEED, "evaluation": EVAL_SEED}
        return legacy[stream] + STRIDE * seed
    child = np.random.SeedSequence(seed, spawn_key=(STREAMS[stream],))
    offset = int(child.generate_state(1, np.uint64)[0]) % (QUARTER - FLOOR - STRIDE)
    return STREAMS[stream] * QUARTER + FLOOR + offset


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
    generators and the action space): the seed itself for a legacy seed, else drawn, below
    ``2**31`` (numpy's legacy seeding inside SB3 takes only 32 bits)."""
    if seed < LEGACY_SEEDS:
        return seed
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
