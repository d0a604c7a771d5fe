"""Reset seed ranges live in tlshield.seeds: training, validation and evaluation never meet."""

import pytest

from tlshield import seeds


def test_the_seed_ranges_never_meet():
    train = {seeds.train_seed(s, i) for s in range(seeds.MAX_SEED) for i in range(seeds.STRIDE)}
    validation = {
        seeds.validation_seed(s, k) for s in range(seeds.MAX_SEED) for k in range(seeds.STRIDE)
    }
    evaluation = {seeds.EVAL_SEED + k for k in range(seeds.STRIDE)}
    blocks = {
        seeds.eval_block_seed(s, k) for s in range(seeds.MAX_SEED) for k in range(seeds.STRIDE)
    }
    assert not train & (validation | evaluation | blocks)
    assert not validation & (evaluation | blocks)


@pytest.mark.parametrize("bad", [-1, seeds.MAX_SEED, 1.0, True, "1"])
def test_a_seed_outside_the_range_is_refused(bad):
    with pytest.raises(ValueError, match=r"seed = .*expected an integer in \[0, 10\)"):
        seeds.check_seeds([0, bad])


@pytest.mark.parametrize("bad", [0, seeds.STRIDE + 1, 2.0, True])
def test_a_block_larger_than_the_stride_is_refused(bad):
    with pytest.raises(ValueError, match="episodes"):
        seeds.check_block(bad, "episodes")
    seeds.check_block(seeds.STRIDE, "episodes")
