"""CMA-ES leaves numpy's global generator alone (issue 24, item 4).

pycma seeds ``np.random`` when a strategy is made and draws from it on every ask: a library
user's global state was reset by ``--optimizer cma``, and the user's own draws shifted the
strategy's proposals.
"""

import numpy as np
import pytest

from physinfer.optimizers.cma import CMAOptimizer


def _global_state() -> tuple:
    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    return kind, keys.copy(), pos, has_gauss, gauss


def _same(a: tuple, b: tuple) -> bool:
    return a[0] == b[0] and np.array_equal(a[1], b[1]) and a[2:] == b[2:]


def _run(generations: int, *, user_draws: bool, dim: int = 3, seed: int = 4) -> list[np.ndarray]:
    """Trials of a seeded CMA run told a fixed function; optionally drawing from np.random
    between every call, as a user's code (or another library) would."""
    opt = CMAOptimizer(dim=dim, seed=seed)
    xs = []
    for _ in range(generations * opt._es.popsize):
        if user_draws:
            np.random.rand(3)
        (trial,) = opt.ask(1)
        xs.append(trial.x)
        if user_draws:
            np.random.randn()
        opt.tell(trial.index, float(np.sum((trial.x - 0.3) ** 2)))
    return xs


def test_cma_leaves_the_global_numpy_state_untouched():
    np.random.seed(12345)
    before = _global_state()
    _run(2, user_draws=False)
    assert _same(_global_state(), before), "np.random's state changed"
    np.random.seed(12345)
    expected = np.random.rand(5)
    np.random.seed(12345)
    _run(1, user_draws=False, dim=1)  # the padded 1-D case too
    assert np.array_equal(np.random.rand(5), expected)


def test_seeded_cma_runs_are_reproducible_whatever_else_draws_from_np_random():
    np.random.seed(0)
    alone = _run(3, user_draws=False)
    np.random.seed(99)
    interleaved = _run(3, user_draws=True)
    assert all(np.array_equal(a, b) for a, b in zip(alone, interleaved, strict=True))
    other_seed = _run(1, user_draws=False, seed=5)
    assert not np.array_equal(other_seed[1], alone[1])


def test_two_strategies_at_once_each_draw_their_own_stream():
    one, two = CMAOptimizer(dim=2, seed=1), CMAOptimizer(dim=2, seed=1)
    a = [t.x for t in one.ask(3)]
    b = [t.x for t in two.ask(3)]
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("cut", [1, 2, 3, 6, 7, 9])
def test_a_run_resumed_in_the_middle_of_a_generation_continues_as_the_uninterrupted_one(cut):
    """Replaying ``cut`` logged trials (attach + tell), then asking, proposes what the
    uninterrupted run proposed next (found by killing refine: a run cut after 2 trials
    repeated its second trial's point)."""

    def run(replayed: list[np.ndarray], total: int = 16) -> list[np.ndarray]:
        opt = CMAOptimizer(dim=3, seed=4)
        xs = []
        for x in replayed or [np.zeros(3)]:  # a refinement's first trial is the centre
            trial = opt.attach(x)
            opt.tell(trial.index, float(np.sum((trial.x - 0.3) ** 2)))
            xs.append(trial.x)
        while len(xs) < total:
            (trial,) = opt.ask(1)
            opt.tell(trial.index, float(np.sum((trial.x - 0.3) ** 2)))
            xs.append(trial.x)
        return xs

    straight = run([])
    resumed = run(straight[:cut])
    assert all(np.array_equal(a, b) for a, b in zip(straight, resumed, strict=True))
