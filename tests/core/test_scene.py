"""Scene settings (issue 23, item 0): ``--scene-set NAME=VALUE`` for what the user knows.

Typed and validated like ``--render-set`` (one clear line naming the valid settings),
refused for a phenomenon that declares none, recorded in ``run.json`` as a resume key and in
``result.json``, carried to worker processes and into a dataset's configuration, and kept
away from a posterior estimator trained on another scene.
"""

import json

import pytest

from physinfer.errors import UserInputError
from physinfer.plugins import load_registry
from physinfer.rundir import resume_differences
from physinfer.scene import (
    SceneSetting,
    bind_scene,
    default_scene,
    resolve_scene,
    same_scene,
    scene_of,
)
from physinfer.session import refine
from physinfer.trial_workers import PipelineSpec, scene_items, worker_pipeline

#: A small flag: an 11 × 7 grid simulates in a fraction of a second.
SMALL = {"flag_length": "0.5", "flag_height": "0.3"}


@pytest.fixture(scope="module")
def registry():
    return load_registry()[0]


@pytest.mark.parametrize(
    ("item", "expected"),
    [
        (
            "flag_lenght=3",
            "unknown scene setting(s) flag_lenght for 'flag'; known: flag_length (float, m, 0.5..4, "
            "default 1.5); flag_height",
        ),
        ("flag_length=long", "--scene-set flag_length=long: give a number"),
        ("flag_length=9", "--scene-set flag_length=9: out of range; give 0.5 to 4 m"),
        ("flag_length=nan", "--scene-set flag_length=nan: give a finite number"),
        ("pinning=corner", "--scene-set pinning=corner: choose one of hoist, corners"),
        ("flag_height=3", "--scene-set pole_height=3 is too short for flag_height=3"),
        ("flag_length", "--scene-set expects NAME=VALUE, got 'flag_length'"),
    ],
)
def test_bad_scene_settings_are_one_clear_line_before_anything_runs(
    physinfer_cli, tmp_path, item, expected
):
    out = tmp_path / "t.npz"
    ran = physinfer_cli(
        "simulate", "--plugin", "flag", "--scene-set", item, "--trajectory-out", out, "--json"
    )
    assert ran.returncode == 2
    assert expected in ran.json()["error"]
    assert not out.exists()


def test_a_plugin_without_scene_settings_refuses_scene_set(physinfer_cli, tmp_path):
    ran = physinfer_cli(
        "simulate", "--plugin", "pendulum_lab", "--scene-set", "length=2", "--trajectory-out",
        tmp_path / "t.npz", "--json",
    )  # fmt: skip
    assert ran.returncode == 2
    assert ran.json()["error"] == (
        "the phenomenon 'pendulum_lab' has no scene settings (its plugin declares none); drop --scene-set"
    )


def test_resolve_scene_types_values_and_completes_them_with_defaults(registry):
    flag = registry.phenomenon("flag")
    assert resolve_scene(flag, None) is None and resolve_scene(flag, {}) is None
    scene = resolve_scene(flag, {"flag_length": "3", "pinning": " corners"})
    assert scene == {
        "flag_length": 3.0,
        "flag_height": 1.0,
        "pinning": "corners",
        "pole_height": 3.0,
    }
    assert resolve_scene(flag, {"flag_length": 3}) == {**default_scene(flag), "flag_length": 3.0}
    with pytest.raises(UserInputError, match="give a number"):
        resolve_scene(flag, {"flag_length": True})
    assert same_scene(flag, None, default_scene(flag)) and not same_scene(flag, None, scene)
    count = SceneSetting("count", "int", 2, (1, 5))
    assert count.coerce("3") == 3
    with pytest.raises(UserInputError, match="give an integer"):
        count.coerce("2.5")
    with pytest.raises(ValueError, match="default 7.0 outside"):
        SceneSetting("bad", "float", 7.0, (0.0, 1.0))


def test_a_bound_phenomenon_builds_the_scene_and_workers_rebuild_it(registry):
    flag = registry.phenomenon("flag")
    scene = resolve_scene(flag, {"flag_length": 3, "flag_height": 2})
    bound = bind_scene(flag, scene)
    assert scene_of(bound) == scene and scene_of(flag) is None
    assert bind_scene(flag, None) is flag
    assert bound.make_simulator((), duration_s=0.4).config.width == 3.0  # duration_s still accepted
    spec = PipelineSpec("flag", scene=scene_items(scene), threads=None)
    config = worker_pipeline(spec).simulator.config
    assert (config.width, config.height, config.grid_u, config.grid_v) == (3.0, 2.0, 61, 41)
    assert worker_pipeline(PipelineSpec("flag", threads=None)).simulator.config.width == 1.5


def test_a_dataset_records_its_scene_and_estimators_refuse_another(registry):
    from physinfer.datasets import generator_for
    from physinfer.datasets.resume import dataset_config
    from physinfer.posterior.workflow import load_estimator

    flag = registry.phenomenon("flag")
    preset = next(iter(generator_for(flag).presets().values()))
    scene = resolve_scene(flag, {"flag_length": 3})
    # No scene given: no "scene" entry, so datasets made before scenes existed still resume.
    assert "scene" not in dataset_config(generator_for(flag), preset, 0)
    assert dataset_config(generator_for(bind_scene(flag, scene)), preset, 0)["scene"] == scene
    estimator, path = load_estimator(registry, "flag", None)
    assert estimator.config.scene is None  # the shipped one: trained on 1.5 m × 1 m flags
    estimator.check_scene(flag, None)
    estimator.check_scene(flag, default_scene(flag))  # the defaults given: the same scene
    with pytest.raises(
        UserInputError,
        match=r"trained on clips of the default scene, not of the scene flag_length=3,",
    ) as refused:
        estimator.check_scene(flag, scene, path)
    # the way forward: the commands that make an estimator for this scene, or refine without one
    corners = resolve_scene(flag, {"pinning": "corners", "flag_length": 3, "flag_height": 2})
    with pytest.raises(UserInputError) as refused:
        estimator.check_scene(flag, corners, path)
    text = str(refused.value)
    assert "physinfer dataset generate --plugin flag --scene-set flag_height=2 --scene-set flag_length=3" in text
    assert "--scene-set pinning=corners" in text and "physinfer posterior train --plugin flag" in text
    assert "physinfer refine --plugin flag" in text and "which searches without a posterior" in text


def test_run_json_records_the_scene_and_a_resume_with_another_is_refused(registry, tmp_path):
    out = tmp_path / "run"
    settings = dict(
        plugin="flag", steps=2, optimizer="random", embedder="spectral", noise_samples=0,
        floor_samples=0, progress=False, render_set={"image_size": 64}, out=out,
    )  # fmt: skip
    result = refine(registry, scene_set=SMALL, **settings)
    scene = {"flag_length": 0.5, "flag_height": 0.3, "pinning": "hoist", "pole_height": 3.0}
    assert json.loads((out / "run.json").read_text())["scene"] == scene
    assert json.loads((out / "result.json").read_text())["scene"] == scene
    # The shipped posterior was trained on 1.5 m flags: not used, and the note says why.
    assert "posterior" not in result.extra
    assert (
        "trained on clips of the default scene, not of the scene flag_length=0.5"
        in result.extra["posterior_note"]
    )
    assert result.extra["posterior_note"].startswith("searching without a posterior: ")
    assert "\n" not in result.extra["posterior_note"] and "dataset generate" not in result.extra["posterior_note"]
    log = (out / "trials.jsonl").read_bytes()
    for other, expected in (
        ({**SMALL, "flag_length": "0.6"}, "--scene-set flag_length: run 0.5, now 0.6"),
        (None, "--scene-set flag_height: run 0.3, now not set"),
    ):
        with pytest.raises(UserInputError, match="cannot resume") as info:
            refine(
                registry,
                scene_set=other,
                resume=True,
                use_posterior=False,
                **{**settings, "steps": 3},
            )
        assert expected in str(info.value)
    assert (out / "trials.jsonl").read_bytes() == log
    stored = json.loads((out / "run.json").read_text())
    same = resolve_scene(registry.phenomenon("flag"), {"flag_height": 0.3, "flag_length": 0.5})
    assert resume_differences(stored, {**stored, "scene": same}) == []


def test_plugins_json_lists_each_phenomenons_scene_settings(physinfer_cli):
    listed = physinfer_cli("plugins", "--json").json()["scene_settings"]
    flag = {s["name"]: s for s in listed["flag"]}
    assert flag["pinning"]["choices"] == ["hoist", "corners"] and flag["flag_length"]["unit"] == "m"
    assert listed["pendulum_lab"] == []
