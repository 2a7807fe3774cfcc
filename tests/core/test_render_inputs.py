"""Estimators told the render settings ζ (issue 44, item 4): ``posterior train --render-input``
/ ``--told-camera`` appends each clip's camera and light to its embedding, ``infer --render-set``
tells them at inference, and the shipped estimator told the camera is chosen only when the user
tells it.

A toy problem whose embedding mixes θ with the camera (so telling the camera sharpens θ)
trains with sbi in seconds; the last test runs the flag's shipped estimators through the CLI.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from physinfer import ParameterSpace, ParameterSpec
from physinfer.errors import UserInputError
from physinfer.posterior.inputs import (
    render_context,
    render_outside,
    render_ranges,
    varied_render_settings,
)
from physinfer.types import Clip

#: The toy camera: its azimuth shifts the first embedding dimension, its light never matters.
ZETA_RANGE = (-15.0, 15.0)


def _zetas(rng: np.random.Generator, n: int) -> list[dict]:
    return [
        {
            "camera_azimuth_deg": float(rng.uniform(*ZETA_RANGE)),
            "light_intensity": float(rng.uniform(1.8, 3.5)),
            "image_size": 32,
            "texture": "finland",
            "light_direction": [0.0, 0.0, -1.0],
        }
        for _ in range(n)
    ]


def _toy_pairs(n: int = 400, seed: int = 0):
    """``n`` pairs x = (θ_a + azimuth / 15 + noise, θ_b + noise) with each clip's ζ recorded."""
    from physinfer.posterior.features import EmbeddedSet

    space = ParameterSpace([ParameterSpec("a", (0.0, 1.0)), ParameterSpec("b", (0.0, 1.0))])
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-1, 1, size=(n, 2)).astype(np.float32)
    zetas = _zetas(rng, n)
    shift = np.array([z["camera_azimuth_deg"] / 15.0 for z in zetas])
    x = np.stack([theta[:, 0] + shift, theta[:, 1]], axis=1) + 0.05 * rng.normal(size=(n, 2))
    pairs = EmbeddedSet(
        space, theta, x.astype(np.float32), np.arange(n), Path("unused/embeddings/x.npz"),
        render_params=tuple(zetas),
    )  # fmt: skip
    return pairs, zetas


IDENTITY = {
    "plugin": "toy",
    "embedder": "identity",
    "embedder_frames": 10,
    "embedder_fps": 25.0,
    "probe": [0.0, 1.0],
    "clip_seconds": 0.4,
}


def _train(pairs):
    from physinfer.posterior.estimator import NetworkConfig
    from physinfer.posterior.training import train_estimator

    network = NetworkConfig(density="maf", hidden_features=32, num_transforms=3, learning_rate=2e-3, max_epochs=40)
    return train_estimator(pairs, IDENTITY, network=network, seed=0, device="cpu")


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    """``(told_path, untold_path, zetas)``: the toy trained told the azimuth, and untold."""
    from physinfer.threads import torch_threads

    pairs, zetas = _toy_pairs()
    folder = tmp_path_factory.mktemp("render-inputs")
    ranges = render_ranges(["camera_azimuth_deg"], zetas)
    with torch_threads(1):  # a small flow: one thread is 6x faster than two on a busy 2-core box
        told = _train(pairs.with_render_inputs(ranges)).save(folder / "told.safetensors")
        untold = _train(pairs).save(folder / "untold.safetensors")
    return told, untold, zetas


# ------------------------------------------------------------------ the told settings


def test_the_varied_numeric_settings_are_the_camera_and_their_ranges_scale_to_the_unit_box():
    zetas = _zetas(np.random.default_rng(1), 50)
    # image_size never varies, texture and light_direction are no single number
    assert varied_render_settings(zetas) == ["camera_azimuth_deg", "light_intensity"]
    ranges = render_ranges(["light_intensity", "camera_azimuth_deg"], zetas)
    assert list(ranges) == ["camera_azimuth_deg", "light_intensity"]
    low, high = ranges["camera_azimuth_deg"]
    assert ZETA_RANGE[0] <= low < high <= ZETA_RANGE[1]
    told = {"camera_azimuth_deg": low, "light_intensity": ranges["light_intensity"][1]}
    assert render_context(ranges, told) == pytest.approx([-1.0, 1.0])
    assert render_outside(ranges, told) == []
    assert render_outside(ranges, {**told, "camera_azimuth_deg": 40.0}) == [
        f"camera_azimuth_deg=40 (trained on {low:.3g}..{high:.3g})"
    ]
    with pytest.raises(UserInputError, match="image_size: the setting never varies"):
        render_ranges(["image_size"], zetas)
    with pytest.raises(UserInputError, match="take one the dataset varies: camera_azimuth_deg, light_intensity"):
        render_ranges(["texture"], zetas)
    with pytest.raises(UserInputError, match="give a finite number"):
        render_context(ranges, {**told, "light_intensity": "bright"})


def test_pairs_are_conditioned_on_each_clips_told_settings_after_the_embedding():
    pairs, zetas = _toy_pairs(20)
    assert pairs.conditions is pairs.x  # told nothing: the embedding alone, as before
    told = pairs.with_render_inputs({"camera_azimuth_deg": list(ZETA_RANGE)})
    assert told.conditions.shape == (20, 3)
    assert told.conditions[:, 2] == pytest.approx([z["camera_azimuth_deg"] / 15.0 for z in zetas], abs=1e-6)
    with pytest.raises(UserInputError, match="do not record the render settings fov_deg"):
        pairs.with_render_inputs({"fov_deg": [30.0, 50.0]})


# --------------------------------------------------------- trained, saved and loaded


def test_an_estimator_told_the_camera_keeps_it_through_its_file_and_needs_it(toy):
    from physinfer.posterior.estimator import PosteriorEstimator

    told_path, untold_path, zetas = toy
    told, untold = PosteriorEstimator.load(told_path), PosteriorEstimator.load(untold_path)
    low, high = told.config.render_inputs["camera_azimuth_deg"]
    assert told.config.render_inputs == render_ranges(["camera_azimuth_deg"], zetas)
    assert told.config.x_dim == 3 and told.config.embedding_dim == 2
    # An estimator told nothing is written as before: no render_inputs key in its file.
    from safetensors import safe_open

    with safe_open(str(untold_path), framework="pt") as f:
        assert "render_inputs" not in json.loads(f.metadata()["physinfer"])
    assert untold.config.render_inputs is None and untold.config.embedding_dim == 2
    embedding = np.array([0.2, -0.3], dtype=np.float32)
    with pytest.raises(UserInputError) as refused:
        told.condition(embedding, None)
    message = str(refused.value)
    assert f"not given: camera_azimuth_deg (trained on {low:.3g}..{high:.3g})" in message
    assert "--render-set NAME=VALUE" in message and "drop --posterior" in message
    assert untold.condition(embedding, None, {"camera_azimuth_deg": 3.0}).shape == (2,)  # ignored
    # Told, the samples follow the camera: the azimuth's shift of the embedding is taken out.
    left = told.sample_unit(told.condition(embedding, None, {"camera_azimuth_deg": -10.0}), 400)
    right = told.sample_unit(told.condition(embedding, None, {"camera_azimuth_deg": 10.0}), 400)
    assert np.median(left[:, 0]) - np.median(right[:, 0]) == pytest.approx(20 / 15, abs=0.35)
    assert told.render_outside({"camera_azimuth_deg": 30.0}) != []


class _Embedder:
    """Returns a fixed embedding: the toy's video."""

    fps, n_frames = 25.0, 10

    def embed(self, clip: Clip) -> np.ndarray:
        return np.array([0.2, -0.3], dtype=np.float32)


def test_infer_refuses_without_the_told_camera_and_flags_one_outside_its_training(toy):
    from physinfer.posterior.estimator import PosteriorEstimator
    from physinfer.posterior.infer_workflow import posterior_of_clip, trust_lines

    told = PosteriorEstimator.load(toy[0])
    clip = Clip(np.zeros((10, 8, 8, 3), dtype=np.uint8), 25.0)
    with pytest.raises(UserInputError, match="needs 1 render setting; not given: camera_azimuth_deg"):
        posterior_of_clip(told, _Embedder(), clip, n_samples=200)
    report = posterior_of_clip(told, _Embedder(), clip, n_samples=200, render={"camera_azimuth_deg": 2.0})
    assert report.samples_unit.shape == (200, 2)
    assert report.inputs["render_outside"] == [] and not report.inputs["extrapolating"]
    wide = posterior_of_clip(told, _Embedder(), clip, n_samples=200, render={"camera_azimuth_deg": 40.0})
    assert wide.inputs["extrapolating"] and wide.inputs["render_outside"][0].startswith("camera_azimuth_deg=40")
    assert any("--render-set" in line and "outside" in line for line in trust_lines(wide))


# ------------------------------------------------------- choosing a shipped estimator


def test_a_shipped_estimator_told_the_camera_is_chosen_only_when_the_camera_is_told(toy):
    from physinfer.posterior.loading import load_estimator

    told_path, untold_path, _ = toy
    space = ParameterSpace([ParameterSpec("a", (0.0, 1.0)), ParameterSpec("b", (0.0, 1.0))])
    phenomenon = SimpleNamespace(
        name="toy", parameter_space=space, scene_settings=(),
        default_posterior=str(untold_path), scene_posteriors=(str(told_path),),
    )  # fmt: skip
    registry = SimpleNamespace(phenomenon=lambda name: phenomenon)

    def chosen(render=None, scene=None) -> Path:
        return load_estimator(registry, "toy", None, "cpu", scene=scene, render=render)[1]

    assert chosen() == untold_path
    assert chosen({"camera_azimuth_deg": 2.0}) == told_path
    assert chosen({"light_intensity": 2.0}) == untold_path  # not all of its inputs told
    assert chosen({"camera_azimuth_deg": 40.0}) == untold_path  # outside its training cameras
    # A given estimator is used as given.
    assert load_estimator(registry, "toy", told_path, "cpu")[1] == told_path


def _of_longer_clips(path: Path, seconds: float, folder: Path | None = None) -> Path:
    """A copy of the estimator at ``path`` recorded as trained on clips of ``seconds``, in
    ``folder`` (default: beside it)."""
    from dataclasses import replace

    from physinfer.posterior.estimator import PosteriorEstimator

    estimator = PosteriorEstimator.load(path)
    frames = round(seconds * estimator.config.embedder_fps)
    estimator.config = replace(estimator.config, clip_seconds=seconds, embedder_frames=frames)
    return estimator.save((folder or path.parent) / f"{path.stem}-{seconds:g}s.safetensors")


def test_a_longer_target_is_given_the_shipped_estimator_of_the_longest_clips_it_covers(toy):
    from physinfer.posterior.loading import load_estimator

    told_path, untold_path, _ = toy
    told_long, untold_long = _of_longer_clips(told_path, 8.0), _of_longer_clips(untold_path, 8.0)
    space = ParameterSpace([ParameterSpec("a", (0.0, 1.0)), ParameterSpec("b", (0.0, 1.0))])
    phenomenon = SimpleNamespace(
        name="toy", parameter_space=space, scene_settings=(), default_posterior=str(untold_path),
        scene_posteriors=(str(told_path), str(told_long), str(untold_long)),
    )  # fmt: skip
    registry = SimpleNamespace(phenomenon=lambda name: phenomenon)

    def chosen(seconds, render=None) -> Path:
        return load_estimator(registry, "toy", None, "cpu", render=render, seconds=seconds)[1]

    told = {"camera_azimuth_deg": 2.0}
    assert chosen(None) == untold_path and chosen(None, told) == told_path  # no length: the first
    assert chosen(0.4) == untold_path and chosen(0.4, told) == told_path  # as long as the short clips
    assert chosen(7.9) == untold_path and chosen(7.9, told) == told_path  # too short for the long ones
    assert chosen(8.0) == untold_long and chosen(8.0, told) == told_long
    assert chosen(30.0) == untold_long and chosen(30.0, told) == told_long
    assert chosen(0.1) == untold_path  # shorter than every one: the first (the embedding refuses it)
    # Told the camera, a target too short for every told estimator: the untold ones answer.
    phenomenon.scene_posteriors = (str(told_long), str(untold_long))
    assert chosen(0.4, told) == untold_path and chosen(8.0, told) == told_long


@pytest.mark.skipif(
    not (Path(__file__).parents[2] / "plugins/flag/physinfer_flag/data/posterior_camera.safetensors").is_file(),
    reason="the flag's estimator told the camera is not shipped in this checkout",
)
def test_flag_infer_tells_the_camera_with_render_set(physinfer_cli, tmp_path):
    camera = {
        "camera_azimuth_deg": 0, "camera_elevation_deg": -5, "fov_deg": 40, "framing": 1,
        "light_intensity": 2.5, "ambient_intensity": 0.3,
    }  # fmt: skip
    told = [a for k, v in camera.items() for a in ("--render-set", f"{k}={v}")]
    common = ("infer", "--plugin", "flag", "--samples", "200", "--no-check", "--json")
    proc = physinfer_cli(*common, *told, "--out", str(tmp_path / "told"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert Path(proc.json()["estimator"]).name == "posterior_camera.safetensors"
    assert proc.json()["render_set"]["fov_deg"] == 40
    proc = physinfer_cli(*common, "--out", str(tmp_path / "untold"))
    assert Path(proc.json()["estimator"]).name == "posterior_default.safetensors"
    assert "notes" not in proc.json() and "render_set" not in proc.json()
    # A camera outside its training ones: the default answers, and says why.
    wide = [a for k, v in {**camera, "fov_deg": 70}.items() for a in ("--render-set", f"{k}={v}")]
    proc = physinfer_cli(*common, *wide, "--out", str(tmp_path / "wide"))
    assert Path(proc.json()["estimator"]).name == "posterior_default.safetensors"
    assert "posterior_camera.safetensors: outside its training cameras: fov_deg=70" in proc.json()["notes"][0]
    camera_file = Path(proc.json()["estimator"]).with_name("posterior_camera.safetensors")
    proc = physinfer_cli(
        *common, "--posterior", str(camera_file), *told[:-2], "--out", str(tmp_path / "short")
    )
    assert proc.returncode == 2 and "ambient_intensity" in proc.json()["error"] and "--render-set" in proc.json()["error"]
    proc = physinfer_cli(*common, *told, "--render-set", "fov_dgr=40", "--out", str(tmp_path / "typo"))
    assert proc.returncode == 2 and "fov_dgr" in proc.json()["error"]


@pytest.mark.skipif(
    not (Path(__file__).parents[2] / "plugins/flag/physinfer_flag/data/posterior_camera.safetensors").is_file(),
    reason="the flag's estimator told the camera is not shipped in this checkout",
)
def test_refine_starts_from_the_estimator_told_the_camera_when_render_set_tells_it():
    """``refine --render-set`` (the camera of the user's video) chooses and conditions the
    shipped estimator told the camera, as ``infer --render-set`` does."""
    from physinfer.plugins import load_registry
    from physinfer.posterior.infer_workflow import posterior_for_refinement

    registry = load_registry()[0]
    phenomenon = registry.phenomenon("flag")
    target = phenomenon.default_target()
    camera = {
        "camera_azimuth_deg": 0.0, "camera_elevation_deg": -5.0, "fov_deg": 40.0, "framing": 1.0,
        "light_intensity": 2.5, "ambient_intensity": 0.3,
    }  # fmt: skip

    def estimator(render):
        report, why = posterior_for_refinement(
            registry, plugin="flag", parameter_space=phenomenon.parameter_space, clip=target.clip,
            posterior=None, device="cpu", n_samples=200, render=render,
        )  # fmt: skip
        assert report is not None, why
        return Path(report.estimator).name

    assert estimator(camera) == "posterior_camera.safetensors"
    assert estimator(None) == "posterior_default.safetensors"


@pytest.mark.skipif(
    not (Path(__file__).parents[2] / "plugins/flag/physinfer_flag/data/posterior_camera.safetensors").is_file(),
    reason="the flag's estimator told the camera is not shipped in this checkout",
)
def test_infer_and_refine_take_a_shipped_estimator_of_longer_clips_for_a_longer_video(tmp_path, monkeypatch):
    """A 3.2-s flag video told its camera: ``infer`` (which loads the target after the
    estimator) and ``refine``'s start switch to a shipped estimator of 3.2-s clips. That file
    is the shipped 2.4-s one recorded as reading 80 frames (the spectral embedding has the
    same size at any length): only the choice is tested."""
    from dataclasses import replace

    from physinfer.evaluation import build_pipeline
    from physinfer.plugins import load_registry
    from physinfer.posterior.infer_workflow import infer, posterior_for_refinement
    from physinfer.video import write_video

    registry = load_registry()[0]
    flag = registry.phenomenon("flag")
    camera_file = Path(flag.scene_posteriors[1])
    assert camera_file.name == "posterior_camera.safetensors"
    moved = _of_longer_clips(camera_file, 3.2, tmp_path)
    patched = replace(flag, scene_posteriors=(*flag.scene_posteriors, str(moved)))
    monkeypatch.setattr(registry, "phenomenon", lambda name: patched if name == "flag" else flag)
    camera = {
        "camera_azimuth_deg": 0.0, "camera_elevation_deg": -5.0, "fov_deg": 40.0, "framing": 1.0,
        "light_intensity": 2.5, "ambient_intensity": 0.3,
    }  # fmt: skip
    pipeline = build_pipeline(registry, "flag", embedder="", duration_s=3.2)
    theta = pipeline.simulator.parameter_space.complete({"wind_speed": 5.0})
    clip = pipeline.renderer.render(pipeline.simulator.simulate(theta, seed=3), pipeline.renderer.default_render_params)
    pipeline.renderer.close()
    video = write_video(tmp_path / "longer.mp4", clip)

    def answered(path) -> str:
        report = infer(
            registry, plugin="flag", out=tmp_path / "out", target_path=path, n_samples=200,
            check=False, render_set=camera,
        )  # fmt: skip
        return Path(report.estimator).name

    assert answered(video) == moved.name  # a 2.4-s video keeps posterior_camera (the test above)
    report, why = posterior_for_refinement(
        registry, plugin="flag", parameter_space=flag.parameter_space, clip=clip,
        posterior=None, device="cpu", n_samples=200, render=camera,
    )  # fmt: skip
    assert report is not None and Path(report.estimator).name == moved.name, why
