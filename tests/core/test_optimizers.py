import numpy as np
import pytest

from physinfer.plugins import load_registry


def quadratic(x):
    return float(np.sum((np.asarray(x) - 0.4) ** 2))


@pytest.mark.parametrize("name,budget", [("ax", 9), ("random", 40), ("cma", 60)])
def test_optimizer_improves_on_the_centre(name, budget):
    registry, _ = load_registry()
    opt = registry.optimizer(name, dim=2, seed=0, names=["a", "b"])
    first = opt.attach(np.zeros(2))
    opt.tell(first.index, quadratic(first.x))
    best = quadratic(first.x)
    for i in range(budget - 1):
        trial = opt.ask(1)[0]
        assert trial.x.shape == (2,) and np.all(np.abs(trial.x) <= 1.0 + 1e-9)
        value = None if i == 3 else quadratic(trial.x)  # one failed trial must not break it
        opt.tell(trial.index, value)
        if value is not None:
            best = min(best, value)
    assert best < 0.5 * quadratic(np.zeros(2))


def test_cma_replays_several_generations_and_continues_as_the_uninterrupted_run():
    """A resumed run attaches and tells its logged trials without asking (pycma refused a
    second generation told that way); the next proposals are the uninterrupted run's."""
    registry, _ = load_registry()

    def run(replayed: list, fresh: int) -> list:
        # pycma draws from numpy's global generator, seeded when a strategy is made: one at a time.
        opt = registry.optimizer("cma", dim=3, seed=2)
        for x in replayed:
            trial = opt.attach(x)
            opt.tell(trial.index, quadratic(x))
        xs = []
        for _ in range(fresh):
            trial = opt.ask(1)[0]
            opt.tell(trial.index, quadratic(trial.x))
            xs.append(trial.x)
        return xs

    start = np.zeros(3)  # a warm start, as a diagnosis's augmented stages have
    uninterrupted = run([start], 28)  # four generations of pycma's default 7
    resumed = run([start, *uninterrupted[:20]], 8)
    np.testing.assert_array_equal(np.array(resumed), np.array(uninterrupted[20:]))


def test_random_is_reproducible_per_index():
    registry, _ = load_registry()
    a = registry.optimizer("random", dim=3, seed=5)
    b = registry.optimizer("random", dim=3, seed=5)
    b.attach(np.zeros(3))  # a resumed run attaches first, then continues at the same index
    a.attach(np.zeros(3))
    np.testing.assert_array_equal(a.ask(1)[0].x, b.ask(1)[0].x)


def test_ax_falls_back_to_a_seeded_random_point_when_the_gp_cannot_be_fitted(monkeypatch):
    """Fault injection: BoTorch's ModelFittingError on one step must not end the run."""
    from botorch.exceptions.errors import ModelFittingError

    from physinfer.optimizers.ax import AxOptimizer

    def fail(**_):
        raise ModelFittingError("All attempts to fit the model have failed.")

    points = []
    for _ in range(2):
        opt = AxOptimizer(dim=3, seed=4)
        monkeypatch.setattr(opt._client, "get_next_trials", fail)
        trial = opt.ask(1)[0]
        assert opt.fallbacks == 1 and np.all(np.abs(trial.x) <= 1.0)
        opt.tell(trial.index, 1.0)
        points.append(trial.x)
    assert np.array_equal(points[0], points[1]), "the fallback draw is seeded"

    from botorch.exceptions.errors import OptimizationGradientError

    def nan_gradients(**_):
        raise OptimizationGradientError("119 elements of the gradient array are NaN", current_x=np.zeros(3))

    opt = AxOptimizer(dim=3, seed=4)
    monkeypatch.setattr(opt._client, "get_next_trials", nan_gradients)
    batch = opt.ask(4)
    assert opt.fallbacks == 4 and len({tuple(t.x) for t in batch}) == 4, "a batch falls back to distinct draws"

    def nan_draw(**_):  # torch's own error when NaN acquisition values reach BoTorch's initial draws
        raise RuntimeError("probability tensor contains either `inf`, `nan` or element < 0")

    opt = AxOptimizer(dim=3, seed=4)
    monkeypatch.setattr(opt._client, "get_next_trials", nan_draw)
    assert len(opt.ask(2)) == 2 and opt.fallbacks == 2

    def other(**_):
        raise RuntimeError("a real bug")

    opt = AxOptimizer(dim=3, seed=4)
    monkeypatch.setattr(opt._client, "get_next_trials", other)
    with pytest.raises(RuntimeError, match="a real bug"):
        opt.ask(1)


def test_ax_drops_only_its_duplicate_point_fallback_warning():
    import logging

    from physinfer.optimizers.ax import AxOptimizer

    AxOptimizer(dim=1, seed=0)
    seen = []
    handler = logging.Handler()
    handler.emit = lambda record: seen.append(record.getMessage())
    logger = logging.getLogger("ax.generation_strategy.generation_node")
    logger.addHandler(handler)
    try:
        logger.warning("gen failed with error GenerationStrategy exceeded `MAX_GEN_ATTEMPTS` of 5, switching to fallback")
        logger.warning("a warning worth reading")
    finally:
        logger.removeHandler(handler)
    assert seen == ["a warning worth reading"]


def test_ax_silences_botorchs_reissued_gp_fit_warning_only():
    import warnings

    from physinfer.optimizers.ax import AxOptimizer

    AxOptimizer(dim=1, seed=0)
    with warnings.catch_warnings(record=True) as seen:
        # as botorch.fit re-issues it: warn_explicit with the file's path as its module
        warnings.warn_explicit(
            "`scipy_minimize` terminated with status OptimizationStatus.FAILURE, displaying ...",
            RuntimeWarning, "/site-packages/botorch/fit.py", 241,
        )  # fmt: skip
        warnings.warn_explicit("a warning worth reading", RuntimeWarning, "/elsewhere/mine.py", 1)
    assert [str(w.message) for w in seen] == ["a warning worth reading"]
