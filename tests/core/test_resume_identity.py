"""Everything a resume depends on is the run's identity (issue 25, items 2 and 6).

A ``--resume`` that differs from the run in ``--out`` — ζ, fixed values, effects, seed, the
target video, the embedder's weights — is refused before anything is written, with a short
list of what differs in the CLI's words, not a dump of parameter specifications.
"""

import json

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.evaluation import build_pipeline
from physinfer.plugins import load_registry
from physinfer.rundir import RunDirectory, embedding_fingerprint, resume_differences
from physinfer.session import refine
from physinfer.types import Clip
from physinfer.video import write_video

#: The cheapest refinement: no noise measurement, no noise floor, small frames.
CHEAP = dict(optimizer="random", noise_samples=0, floor_samples=0, progress=False)


@pytest.fixture(scope="module")
def registry():
    return load_registry()[0]


@pytest.fixture(scope="module")
def pendulum_run(registry, tmp_path_factory):
    """A 2-trial pendulum run at 64 px with amplitude fixed at 40."""
    out = tmp_path_factory.mktemp("identity") / "run"
    refine(
        registry,
        plugin="pendulum_lab",
        steps=2,
        out=out,
        fixed=["amplitude=40"],
        render_set={"size": 64},
        **CHEAP,
    )
    return out


def resume(registry, out, **changes):
    settings = dict(
        plugin="pendulum_lab", steps=3, fixed=["amplitude=40"], render_set={"size": 64}, **CHEAP
    )
    return refine(registry, out=out, resume=True, **{**settings, **changes})


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"render_set": {}}, "--render-set size: run 64, now 128"),
        ({"render_set": {"size": 64, "light": 2.0}}, "--render-set light: run 4, now 2"),
        ({"fixed": []}, "--fix amplitude: run 40, now not fixed"),
        (
            {"seed": 3, "effects": ["quadratic_drag"]},
            "--seed: run 0, now 3; --effect: run none, now quadratic_drag",
        ),
    ],
)
def test_a_resume_that_differs_is_refused_with_a_short_diff_and_changes_nothing(
    registry, pendulum_run, changes, expected
):
    log = (pendulum_run / "trials.jsonl").read_bytes()
    with pytest.raises(UserInputError) as info:
        resume(registry, pendulum_run, **changes)
    message = str(info.value)
    assert f"it was run otherwise: {expected}. Resume with the run's settings" in message
    assert "bounds" not in message and len(message) < 300, (
        "a short diff, not a dump of parameter specs"
    )
    assert (pendulum_run / "trials.jsonl").read_bytes() == log


def test_another_target_or_other_embedder_weights_are_refused_and_the_same_settings_resume(
    registry, pendulum_run, tmp_path
):
    pipeline = build_pipeline(registry, "pendulum_lab", embedder="")
    clip = pipeline.phenomenon.default_target().clip
    other = tmp_path / "other.mp4"
    write_video(other, Clip(np.ascontiguousarray(clip.frames[:, :, ::-1]), clip.fps))  # mirrored
    with pytest.raises(UserInputError, match="--target: the video differs from the run's target"):
        resume(registry, pendulum_run, target_path=other)

    # Other weights (here: a fingerprint the run's embedder does not give on its target).
    run_file = pendulum_run / "run.json"
    original = run_file.read_text()
    info = json.loads(original)
    info["embedder_fingerprint"] = [2 * v for v in info["embedder_fingerprint"]]
    run_file.write_text(json.dumps(info))
    try:
        with pytest.raises(
            UserInputError, match="the embedder's output on the target differs from the run's"
        ):
            resume(registry, pendulum_run)
    finally:
        run_file.write_text(original)

    result = resume(registry, pendulum_run)  # no false refusal: same settings, same identity
    assert result.n_trials == 3 and [t.step for t in RunDirectory(pendulum_run).read_trials()] == [
        0,
        1,
        2,
    ]


def test_resume_and_overwrite_together_are_refused(registry, tmp_path):
    with pytest.raises(
        UserInputError, match="--resume continues the run in --out and --overwrite starts it again"
    ):
        refine(
            registry,
            plugin="pendulum_lab",
            steps=2,
            out=tmp_path / "r",
            resume=True,
            overwrite=True,
            **CHEAP,
        )


def test_resume_differences_name_what_differs_in_the_clis_words():
    space = [{"name": "length", "bounds": [0.2, 2.0], "scaling": "linear", "description": "a"}]
    stored = {
        "plugin": "pendulum_lab", "seed": 0, "effects": [], "parameters": space, "weights_sha256": "sha256:" + "a" * 64,
        "embedder_fingerprint": [1.0, -2.0, 0.5], "duration_s": None, "start_x": [0.1, -0.2],
    }  # fmt: skip
    assert resume_differences(stored, dict(stored)) == []
    reworded = [{**space[0], "description": "reworded"}]
    noise = [1.0 + 1e-7, -2.0, 0.5]
    assert (
        resume_differences(
            stored, {**stored, "parameters": reworded, "embedder_fingerprint": noise}
        )
        == []
    )
    changed = {
        **stored, "weights_sha256": None, "duration_s": 4.0, "start_x": None,
        "parameters": [{**space[0], "bounds": [0.5, 2.0]}],
    }  # fmt: skip
    assert resume_differences(stored, changed) == [
        "parameter length: run 0.2–2, now 0.5–2",
        "--weights: run sha256:aaaaaaaaaaaa…, now the plugin's shipped weights",
        "--duration: run the plugin's default, now 4",
        "search start (--model / --posterior): run (0.1, -0.2), now the centre",
    ]
    # A run.json from before these entries were recorded resumes unchecked on them.
    older = {
        k: v
        for k, v in stored.items()
        if k not in ("weights_sha256", "embedder_fingerprint", "start_x")
    }
    assert resume_differences(older, {**stored, "weights_sha256": None, "start_x": None}) == []


def test_the_fingerprint_keeps_embeddings_apart():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal(500), rng.standard_normal(500)
    fa, fb = np.array(embedding_fingerprint(a)), np.array(embedding_fingerprint(b))
    assert np.linalg.norm(fa - fb) > 0.5 * np.linalg.norm(fa)
    assert np.allclose(embedding_fingerprint(a + 1e-9), fa)
