"""Options of the wrong type (issue 45): a bool where a count is expected, text for a number,
an absurd count, a non-finite --truth, --roi without --target and a switch given to a
numeric render setting are refused in one line naming the option, by the library
(:class:`UserInputError`) and by the CLI (exit 2, one ``{"error": ...}`` under --json)."""

from __future__ import annotations

import pytest

import physinfer as pi
from physinfer.errors import UserInputError


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"steps": True}, "--steps True: give a whole number from 1 to at most 100,000"),
        ({"steps": 99999999999999999999}, "--steps 99999999999999999999: give a whole number"),
        ({"steps": "5"}, "--steps '5': give a whole number"),
        ({"steps": 2.5}, "--steps 2.5: give a whole number"),
        ({"seed": "seven"}, "--seed seven: give a whole number"),
        ({"seed": True}, "--seed True"),
        ({"batch_size": 10**9}, "--batch-size 1000000000: give a whole number of at most 10,000"),
        ({"noise_samples": "3"}, "--noise-samples '3'"),
        ({"duration": float("nan")}, "--duration nan: give a finite number"),
        ({"duration": "2"}, "--duration '2': give a finite number"),
        ({"resume": "yes"}, "--resume 'yes': give True or False"),
        ({"optimizer": 3}, "--optimizer 3: give a string"),
        ({"out": 3}, "--out 3: give a path"),
        ({"truth": {"length": float("nan")}}, "--truth length=nan: give a finite number"),
        ({"roi": "10,10,50,50"}, "--roi: give --target too"),
    ],
)
def test_the_library_refuses_options_of_the_wrong_type_naming_the_option(settings, words, tmp_path):
    with pytest.raises(UserInputError) as caught:
        pi.refine("pendulum_lab", **{"out": tmp_path / "run", **settings})
    assert words in str(caught.value)
    assert not (tmp_path / "run").exists()


def test_other_commands_check_types_alike(tmp_path):
    with pytest.raises(UserInputError, match="--samples True"):
        pi.infer("pendulum_lab", samples=True)
    with pytest.raises(UserInputError, match="--max-epochs '40': give a whole number"):
        pi.train_posterior("pendulum_lab", data=tmp_path, out=tmp_path / "e.safetensors", max_epochs="40")
    with pytest.raises(UserInputError, match="--overwrite 1: give True or False"):
        pi.simulate("pendulum_lab", out=tmp_path / "a.mp4", overwrite=1)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("--steps", "99999999999999999999"), "--steps 99999999999999999999: give a whole number"),
        (("--truth", "length=nan"), "--truth length=nan: give a finite number"),
        (("--truth", "length=inf"), "--truth length=inf: give a finite number"),
        (("--roi", "10,10,50,50"), "--roi: give --target too"),
        (("--render-set", "light=true"), "light=True has the wrong type (expected a number"),
    ],
)
def test_the_cli_refuses_them_in_one_line(args, words, tmp_path, physinfer_cli):
    out = tmp_path / "run"
    ran = physinfer_cli("refine", "--plugin", "pendulum_lab", *args, "--out", out, "--json")
    assert ran.returncode == 2, ran.stderr[-1500:]
    assert words in ran.json()["error"]
    assert ran.stderr.strip().count("\n") == 0 and ran.stderr.startswith("error: ")
    assert not out.exists()


def test_a_render_setting_that_is_a_number_refuses_a_switch(tmp_path, physinfer_cli):
    ran = physinfer_cli("simulate", "--plugin", "pendulum_lab", "--render-set", "light=true",
                        "--out", tmp_path / "a.mp4", "--json")  # fmt: skip
    assert ran.returncode == 2 and "light=True" in ran.json()["error"]
    assert not (tmp_path / "a.mp4").exists()
