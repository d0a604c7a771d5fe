"""Where every random stream of tlshield starts, in one place, so that training, validation and
evaluation reset seeds never meet and nothing is tuned on evaluation seeds.

- A training run has a seed ``s`` in ``[0, MAX_SEED)``; its environment ``i`` resets from
  ``train_seed(s, i) = STRIDE * s + i`` (below ``EVAL_SEED``).
- Validation episode ``k`` of run ``s`` (checkpoint selection) resets from
  ``VALIDATION_SEED + STRIDE * s + k``.
- Evaluation trial ``k`` resets from ``EVAL_SEED + k``; the FlatWorld benchmark gives each seed
  its own block, ``EVAL_SEED + STRIDE * s + k`` (below ``VALIDATION_SEED``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

#: Reset seeds per run seed: at most this many environments or episodes per block.
STRIDE = 1000
#: Training seeds are ``0 .. MAX_SEED - 1``.
MAX_SEED = 10
#: First evaluation reset seed.
EVAL_SEED = 10_000
#: First validation reset seed (checkpoint selection; never evaluation).
VALIDATION_SEED = 20_000


def train_seed(seed: int, env: int = 0) -> int:
    """The reset seed of training environment ``env`` of run ``seed``."""
    return STRIDE * seed + env


def validation_seed(seed: int, episode: int) -> int:
    """The reset seed of validation episode ``episode`` of run ``seed``."""
    return VALIDATION_SEED + STRIDE * seed + episode


def eval_block_seed(seed: int, episode: int) -> int:
    """The reset seed of evaluation episode ``episode`` in run ``seed``'s own block."""
    return EVAL_SEED + STRIDE * seed + episode


def check_seeds(seeds: Iterable[Any]) -> None:
    """Raises ValueError unless every seed is an integer in ``[0, MAX_SEED)``: their reset
    seeds (``STRIDE * seed + i``) then stay below the evaluation seeds and their validation
    seeds below the tuning seeds."""
    for seed in seeds:
        if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < MAX_SEED):
            raise ValueError(
                f"seed = {seed!r}: expected an integer in [0, {MAX_SEED}) (training reset seeds "
                f"seed * {STRIDE} + i must stay below the evaluation seeds, {EVAL_SEED}+)"
            )


def check_block(count: int, what: str) -> None:
    """Raises ValueError unless ``count`` (environments or episodes of one run seed) fits in
    one block of ``STRIDE`` reset seeds."""
    if not (isinstance(count, int) and not isinstance(count, bool) and 0 < count <= STRIDE):
        raise ValueError(
            f"{what} = {count!r}: expected a positive integer <= {STRIDE} (one run seed's block "
            "of reset seeds)"
        )
