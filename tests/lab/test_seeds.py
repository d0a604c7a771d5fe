"""Reset seed ranges live in tlshield.lab.seeds: any non-negative run seed works, seeds 0-9 keep the
published tables' reset seeds, and training, validation, evaluation and tuning reset seeds never
meet."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tlshield.lab import seeds
from tlshield.lab.evaluation import evaluate

RUN_SEEDS = st.integers(min_value=0, max_value=2**80)
INDEX = st.integers(min_value=0, max_value=seeds.STRIDE - 1)
TRIAL = st.integers(min_value=0, max_value=seeds.MAX_TRIALS - 1)


def stream_of(value: int) -> str:
    """Which stream a reset seed belongs to, from the ranges alone (an independent reading of
    the module's docstring)."""
    if value < seeds.FLOOR:  # legacy blocks and the shared trials
        if value < 10_000:
            return "training"
        if value < 20_000:
            return "evaluation"
        if value < 30_000:
            return "validation"
        return "tuning"
    return ["training", "validation", "evaluation"][value // 2**30]


@given(RUN_SEEDS, RUN_SEEDS, INDEX, INDEX, TRIAL)
def test_the_streams_never_meet(a, b, i, k, t):
    assert stream_of(seeds.train_seed(a, i)) == "training"
    assert stream_of(seeds.validation_seed(b, k)) == "validation"
    assert stream_of(seeds.eval_block_seed(b, k)) == "evaluation"
    assert stream_of(seeds.EVAL_SEED + t) == "evaluation"
    assert stream_of(seeds.TUNE_SEED + t) == "tuning"
    for value in (seeds.train_seed(a, i), seeds.validation_seed(b, k), seeds.eval_block_seed(b, k)):
        assert 0 <= value < 3 * 2**30
    assert 0 <= seeds.learner_seed(a) < 2**31


@pytest.mark.parametrize("seed", range(seeds.LEGACY_SEEDS))
def test_seeds_0_to_9_keep_the_published_reset_seeds(seed):
    assert seeds.train_seed(seed, 7) == 1000 * seed + 7
    assert seeds.validation_seed(seed, 3) == 20_000 + 1000 * seed + 3
    assert seeds.eval_block_seed(seed, 5) == 10_000 + 1000 * seed + 5
    assert seeds.learner_seed(seed) == seed


def test_other_seeds_come_from_seed_sequence_children():
    # An independent derivation: SeedSequence(seed).spawn() gives the children by spawn key.
    span = 2**30 - 2**16 - 1000
    for seed in (10, 42, 1234, 2**31 - 1, 2**64 + 5):
        children = np.random.SeedSequence(seed).spawn(4)
        starts = [int(c.generate_state(1, np.uint64)[0]) % span for c in children[:3]]
        assert seeds.train_seed(seed, 7) == 2**16 + starts[0] + 7
        assert seeds.validation_seed(seed, 3) == 2**30 + 2**16 + starts[1] + 3
        assert seeds.eval_block_seed(seed, 0) == 2**31 + 2**16 + starts[2]
        assert seeds.learner_seed(seed) == int(children[3].generate_state(1)[0]) >> 1
    firsts = {seeds.train_seed(s) for s in range(10, 210)}
    assert len(firsts) == 200


@pytest.mark.parametrize("good", [0, 9, 10, 42, 1234, 2**31 - 1, 2**64])
def test_any_non_negative_integer_is_a_seed(good):
    seeds.check_seeds([good])


@pytest.mark.parametrize("bad", [-1, 1.0, True, "1", None])
def test_a_seed_that_is_not_a_non_negative_integer_is_refused(bad):
    with pytest.raises(ValueError, match=r"seed = .*expected a non-negative integer"):
        seeds.check_seeds([0, bad])


@pytest.mark.parametrize("bad", [0, seeds.STRIDE + 1, 2.0, True])
def test_a_block_larger_than_the_stride_is_refused(bad):
    with pytest.raises(ValueError, match="episodes"):
        seeds.check_block(bad, "episodes")
    seeds.check_block(seeds.STRIDE, "episodes")


def test_more_evaluation_trials_than_the_range_holds_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"trials = 10001: expected a positive integer <= 10000"):
        evaluate(tmp_path, trials=seeds.MAX_TRIALS + 1)
