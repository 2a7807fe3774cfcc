"""Can the embedder tell a phenomenon's parameters apart? ``embedding_sensitivity``.

Before refining against video, check that moving each parameter moves the embedding by
more than the phenomenon's own randomness does: a parameter whose move stays within the
seed-to-seed spread of the embedding cannot be refined by any optimizer (its distance
landscape is flat under noise), and the posterior will label it "not identified".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import combinations
from typing import Any

import numpy as np

from physinfer.roles import Embedder, Phenomenon

__all__ = ["embedding_sensitivity"]


def embedding_sensitivity(
    phenomenon: Phenomenon,
    embedder: Embedder,
    *,
    params: Mapping[str, float] | None = None,
    step: float = 0.5,
    seeds: Sequence[int] = (0, 1),
    render_params: Mapping[str, Any] | None = None,
) -> dict[str, dict[str, float]]:
    """How far each parameter's move carries the embedding, against the seed-to-seed spread.

    Every parameter in turn is moved by ``step`` of its normalised range (``[-1, 1]``,
    towards the middle of the space) from ``params``; the clip is simulated, rendered and
    embedded under each seed, and compared with the clip of ``params`` under the same seed.

    Args:
        phenomenon: The phenomenon (its baseline model, renderer and parameter space).
        embedder: The embedder the refinement will use.
        params: The θ to probe around (default: the parameter space's defaults).
        step: Move in normalised coordinates (the whole range is 2).
        seeds: Simulation seeds; two or more measure the spread of a random phenomenon.
        render_params: ζ (default: the renderer's default ζ).

    Returns:
        ``{name: {"distance", "noise", "ratio"}}``: the mean squared embedding distance the
        move causes, the mean squared distance between seeds at ``params`` (0 for a
        deterministic simulator or a single seed), and their ratio (``inf`` when the noise
        is 0 and the move shows). A ratio near or below 1 means the embedder cannot tell
        that parameter's values apart at this θ; aim for several times the noise.
    """
    space = phenomenon.parameter_space
    theta = space.complete(params or {})
    simulator = phenomenon.make_simulator(())
    renderer = phenomenon.make_renderer()
    zeta = dict(render_params if render_params is not None else renderer.default_render_params)

    def embed(values: Mapping[str, float], seed: int) -> np.ndarray:
        clip = renderer.render(simulator.simulate(values, seed=seed), zeta)
        return np.asarray(embedder.embed(clip), dtype=np.float64)

    try:
        centre = [embed(theta, s) for s in seeds]
        pairs = list(combinations(centre, 2))
        noise = float(np.mean([np.sum((a - b) ** 2) for a, b in pairs])) if pairs else 0.0
        out = {}
        u = space.to_unit(theta)
        for i, name in enumerate(space.names):
            moved_u = u.copy()
            moved_u[i] += -step if u[i] > 0 else step
            moved = {**theta, name: space.from_unit(moved_u)[name]}
            distance = float(
                np.mean(
                    [np.sum((embed(moved, s) - c) ** 2) for s, c in zip(seeds, centre, strict=True)]
                )
            )
            ratio = distance / noise if noise > 0 else (float("inf") if distance > 0 else 0.0)
            out[name] = {"distance": distance, "noise": noise, "ratio": ratio}
    finally:
        renderer.close()
    return out
