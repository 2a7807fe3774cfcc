"""Holding parameters fixed (``--fix``), on the pendulum example plugin."""

import json

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.evaluation import build_pipeline
from physinfer.fixed import FixedParameters, resolve_fixed
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.plugins import load_registry
from physinfer.rundir import RunDirectory
from physinfer.session import refine

SPACE = ParameterSpace(
    [ParameterSpec("wind", (0.0, 10.0)), ParameterSpec("bend_a", (0.1, 10.0)), ParameterSpec("bend_b", (0.1, 10.0))]
)


def test_patterns_expand_in_the_space_order():
    assert resolve_fixed(SPACE, ["bend_*=1"]) == {"bend_a": 1.0, "bend_b": 1.0}
    assert list(resolve_fixed(SPACE, ["bend_b=2", "bend_a=3"])) == ["bend_a", "bend_b"]
    assert resolve_fixed(SPACE, []) == {}


@pytest.mark.parametrize(
    "items, message",
    [
        (["stiff*=1"], "no parameter matches 'stiff\\*'; known parameters: wind, bend_a, bend_b"),
        (["bend_*=20"], "bend_a=20 is outside its bounds \\[0.1, 10\\]"),
        (["*=1"], "fixes every parameter"),
        (["bend_a"], "expects NAME=VALUE"),
        (["bend_a=stiff"], "value is not a number"),
    ],
)
def test_bad_fixes_are_user_errors(items, message):
    with pytest.raises(UserInputError, match=message):
        resolve_fixed(SPACE, items)


def test_fixed_simulator_searches_the_free_parameters_and_simulates_the_full_model():
    registry, _ = load_registry()
    full = build_pipeline(registry, "pendulum_lab", embedder="")
    fixed = build_pipeline(registry, "pendulum_lab", embedder="", fixed=["amplitude=40"])
    assert isinstance(fixed.simulator, FixedParameters)
    assert fixed.simulator.parameter_space.names == [n for n in full.simulator.parameter_space.names if n != "amplitude"]
    free = {"length": 0.9, "damping": 0.2}
    ours = fixed.simulator.simulate(free, seed=3)
    theirs = full.simulator.simulate({**free, "amplitude": 40.0}, seed=3)
    np.testing.assert_array_equal(ours.vertices, theirs.vertices)
    other = full.simulator.simulate({**free, "amplitude": 20.0}, seed=3)
    assert not np.array_equal(ours.vertices, other.vertices), "the fixed value reaches the simulator"


def test_refine_with_fix_searches_fewer_dimensions_and_reports_the_fixed_values(tmp_path, physinfer_cli):
    out = tmp_path / "run"
    proc = physinfer_cli(
        "refine", "--plugin", "pendulum_lab", "--steps", "3", "--optimizer", "random", "--fix", "amplitude=40",
        "--truth", "amplitude=40", "--out", str(out), "--json",
    )
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["fixed"] == {"amplitude": 40.0}
    assert "amplitude" not in data["best_params"] and "amplitude" not in data["abs_errors"]
    assert all(len(t.x) == 2 for t in RunDirectory(out).read_trials())
    registry, _ = load_registry()
    with pytest.raises(UserInputError, match="--fix amplitude: run 40, now 30"):
        refine(registry, plugin="pendulum_lab", steps=4, optimizer="random", fixed=["amplitude=30"], out=out,
               resume=True, progress=False)


def test_a_bad_fix_fails_before_anything_is_written(tmp_path, physinfer_cli):
    out = tmp_path / "run"
    proc = physinfer_cli("refine", "--plugin", "pendulum_lab", "--steps", "3", "--fix", "lenght=1", "--out", str(out))
    assert proc.returncode == 2
    assert "no parameter matches 'lenght'" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


def _registry_with_a_self_fixing_pendulum():
    """The installed plugins plus ``pendulum_held``: the pendulum whose own simulator holds
    the amplitude at 40° (as the diagnose benchmark's ``flag_lite`` holds its bending)."""
    import dataclasses

    registry, _ = load_registry()
    pendulum = registry.phenomenon("pendulum_lab")

    def make(effects=()):
        return FixedParameters(pendulum.make_simulator(effects), {"amplitude": 40.0})

    held = dataclasses.replace(
        pendulum, name="pendulum_held", parameter_space=make().parameter_space, make_simulator=make
    )
    registry.scoped("tests").add_phenomenon("pendulum_held", lambda: held, "amplitude held by the phenomenon")
    return registry, held


def test_a_phenomenon_that_fixes_its_own_parameters_has_not_been_given_fix(tmp_path):
    """Only ``--fix`` counts as fixed: a phenomenon whose simulator holds parameters itself
    (the diagnose benchmark's ``flag_lite``) records no ``fixed`` (so its older runs resume)."""
    registry, _ = _registry_with_a_self_fixing_pendulum()
    refine(registry, plugin="pendulum_held", steps=2, optimizer="random", noise_samples=0, floor_samples=0,
           out=tmp_path / "own", progress=False)
    assert "fixed" not in json.loads((tmp_path / "own" / "run.json").read_text())
    refine(registry, plugin="pendulum_held", steps=2, optimizer="random", noise_samples=0, floor_samples=0,
           fixed=["length=1"], out=tmp_path / "user", progress=False)
    assert json.loads((tmp_path / "user" / "run.json").read_text())["fixed"] == {"length": 1.0}


def test_a_self_fixing_phenomenon_s_model_file_and_truth_use_its_own_space(tmp_path):
    """``refine --model`` on a model file of a phenomenon that holds parameters itself, and
    ``--truth``: its held parameters are not model parameters (they were looked through as
    if ``--fix`` had held them, so the file reported a mismatch and ``--truth`` took them)."""
    from physinfer.discrepancy.model import write_model

    registry, held = _registry_with_a_self_fixing_pendulum()
    space = held.parameter_space
    assert "amplitude" not in space.names
    values = space.from_unit(np.full(len(space), 0.5))
    write_model(tmp_path / "model.json", plugin="pendulum_held", effects=[], space=space, values=values)
    result = refine(registry, plugin="pendulum_held", model=tmp_path / "model.json", steps=2, optimizer="random",
                    noise_samples=0, floor_samples=0, out=tmp_path / "run", truth=["length=1"], progress=False)
    assert set(result.best_params) == set(space.names)
    with pytest.raises(UserInputError, match="amplitude"):
        refine(registry, plugin="pendulum_held", steps=2, optimizer="random", noise_samples=0, floor_samples=0,
               out=tmp_path / "truth", truth=["amplitude=40"], progress=False)
    # with --fix, the held parameter may have a --truth (it is the user's model parameter)
    refine(registry, plugin="pendulum_held", steps=2, optimizer="random", noise_samples=0, floor_samples=0,
           fixed=["length=1"], out=tmp_path / "fixed", truth=["length=1"], progress=False)
