"""Input is validated before the first simulation (issue 25, item 3), on the pendulum example.

Every refusal here is one clear line (a :class:`UserInputError`), raised before anything is
simulated and before the run directory exists.
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from physinfer.cli.app import app, parse_render_set
from physinfer.errors import UserInputError
from physinfer.evaluation import build_pipeline
from physinfer.fixed import resolve_fixed
from physinfer.parameters import parse_assignments
from physinfer.plugins import load_registry
from physinfer.roles import Renderer
from physinfer.session import refine

BIN = Path(sys.executable).parent / "physinfer"
QUICK = {"plugin": "pendulum_lab", "steps": 2, "optimizer": "random", "progress": False, "noise_samples": 0,
         "floor_samples": 0}


@pytest.fixture(scope="module")
def registry():
    return load_registry()[0]


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("size=-5", "size=-5 is out of range"),
        ("size=big", "size='big' has the wrong type"),
        ("size=0", "size=0 is out of range"),
        ("size=100000", "size=100000 is out of range"),
        ("size=64.5", "size=64.5 has the wrong type"),
        ("distance=inf", "distance=inf is out of range"),
        ("yfov_deg=nan", "yfov_deg=nan is out of range"),
        ("yfov_deg=200", "yfov_deg=200 is out of range"),
    ],
)
def test_nonsense_render_values_are_refused_before_the_run_directory_exists(registry, tmp_path, item, message):
    out = tmp_path / "run"
    with pytest.raises(UserInputError, match=message.replace("(", r"\(")):
        refine(registry, out=out, render_set=parse_render_set([item]), **QUICK)
    assert not out.exists()


def test_the_pendulum_renderer_checks_and_types_its_render_values():
    from pendulum_example.render import PendulumRenderer

    renderer = PendulumRenderer()
    assert renderer.check_render_params({"size": 64.0}) == {"size": 64, "distance": 3.2, "yfov_deg": 50.0, "light": 4.0}
    with pytest.raises(UserInputError, match="light=-1 is out of range"):
        renderer.check_render_params({"light": -1.0})


class _Loose(Renderer):
    """A renderer that leaves ζ to the host's default check."""

    default_render_params = {"zoom": 1.0, "style": "plain", "shadows": True}

    def render(self, trajectory, render_params=None):
        raise AssertionError("not rendered in these tests")


def test_the_host_refuses_non_finite_and_non_numeric_values_for_a_renderer_without_its_own_check():
    renderer = _Loose()
    assert renderer.check_render_params({"zoom": 2.0, "style": "bold", "shadows": False})["zoom"] == 2.0
    for bad in (float("nan"), float("inf"), "wide", True):
        with pytest.raises(UserInputError, match="render setting zoom=.*give a finite number"):
            renderer.check_render_params({"zoom": bad})


def test_the_cli_refuses_a_huge_render_size_with_one_json_error_and_no_run(tmp_path):
    proc = subprocess.run(
        [str(BIN), "refine", "--plugin", "pendulum_lab", "--render-set", "size=100000", "--out", str(tmp_path / "r"),
         "--json"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "size=100000 is out of range" in json.loads(proc.stdout)["error"]
    assert not (tmp_path / "r").exists()


def test_an_unknown_device_is_refused(registry, tmp_path):
    with pytest.raises(UserInputError, match="--device 'tpu9' is not a torch device"):
        refine(registry, out=tmp_path / "r", device="tpu9", **QUICK)
    assert not (tmp_path / "r").exists()


def test_cuda_on_a_machine_without_it_is_refused_not_ignored(registry, tmp_path):
    import torch

    if torch.cuda.is_available():
        count = torch.cuda.device_count()
        with pytest.raises(UserInputError, match=f"has {count} CUDA GPU"):
            refine(registry, out=tmp_path / "r", device=f"cuda:{count}", **QUICK)
    else:
        with pytest.raises(UserInputError, match="--device cuda: this machine has no CUDA GPU"):
            refine(registry, out=tmp_path / "r", device="cuda", **QUICK)
    assert not (tmp_path / "r").exists()


def test_a_repeated_set_fix_or_effect_is_refused(registry):
    with pytest.raises(UserInputError, match=r"--set length is given twice \(length=1 and length=1.2\)"):
        parse_assignments(["length=1", "length=1.2"], "--set")
    with pytest.raises(UserInputError, match="--effect quadratic_drag is given twice"):
        build_pipeline(registry, "pendulum_lab", effects=["quadratic_drag", "quadratic_drag"], embedder="")
    space = registry.phenomenon("pendulum_lab").make_simulator([]).parameter_space
    with pytest.raises(UserInputError, match="--fix length is given twice"):
        resolve_fixed(space, ["length=1", "length=1.2"])
    with pytest.raises(UserInputError, match="length is already fixed at 1 by another --fix"):
        resolve_fixed(space, ["length=1", "len*=1.2"])


def test_simulate_refuses_a_repeated_effect_with_one_line(tmp_path):
    result = CliRunner().invoke(
        app, ["simulate", "--plugin", "pendulum_lab", "--effect", "quadratic_drag", "--effect", "quadratic_drag",
              "--out", str(tmp_path / "p.mp4"), "--json"],
    )  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "given twice" in json.loads(result.stdout)["error"]


def test_simulate_refuses_an_out_that_is_a_directory(tmp_path):
    (tmp_path / "clip.mp4").mkdir()
    result = CliRunner().invoke(app, ["simulate", "--plugin", "pendulum_lab", "--out", str(tmp_path / "clip.mp4"), "--json"])
    assert result.exit_code == 2, result.output
    assert "is a directory; give a file name" in json.loads(result.stdout)["error"]


def test_an_out_that_cannot_be_made_is_refused_with_one_line(registry, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(UserInputError, match="notes.txt is a file, so no directory can be made there"):
        refine(registry, out=tmp_path / "notes.txt" / "run", **QUICK)
    with pytest.raises(UserInputError, match="cannot write --out /proc/physinfer-test/run"):
        refine(registry, out=Path("/proc/physinfer-test/run"), **QUICK)
