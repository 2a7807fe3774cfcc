"""The Python API (``physinfer.api``): the CLI's commands as functions returning result objects,
their settings as frozen dataclasses named as the CLI's options are."""

from __future__ import annotations

import dataclasses

import pytest
from matplotlib.figure import Figure

import physinfer.api as pi
from physinfer.errors import UserInputError


def test_simulate_returns_a_rendered_simulation_with_the_cli_json(tmp_path, physinfer_cli):
    video = tmp_path / "a.mp4"
    sim = pi.simulate("pendulum_lab", set={"length": 1.2}, seed=3, out=video)
    assert sim.params["length"] == 1.2 and sim.clip is not None and video.exists()
    cli = physinfer_cli(
        "simulate", "--plugin", "pendulum_lab", "--set", "length=1.2", "--seed", "3",
        "--out", tmp_path / "b.mp4", "--json",
    ).json()  # fmt: skip
    assert set(sim.to_dict()) == set(cli)
    assert sim.to_dict()["params"] == cli["params"]
    fig = sim.plot(n=4)
    assert isinstance(fig, Figure) and len(fig.axes) == 4


def test_the_commands_are_the_packages_own_names_imported_on_first_use():
    import subprocess
    import sys

    import physinfer

    for name in physinfer.API_NAMES:
        assert getattr(physinfer, name) is getattr(pi, name), name
        assert name in dir(physinfer)
    with pytest.raises(AttributeError, match="no attribute 'refin'"):
        _ = physinfer.refin
    code = (
        "import sys, physinfer; loaded = 'physinfer.api' in sys.modules; f = physinfer.infer; "
        "heavy = [m for m in ('torch', 'pyrender', 'ax', 'sbi') if m in sys.modules]; print(loaded, heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "[]"], out.stdout + out.stderr


def test_a_misspelt_setting_names_the_closest_one():
    with pytest.raises(UserInputError, match="no setting 'batchsize'.*'batch_size'"):
        pi.refine("pendulum_lab", batchsize=4)
    with pytest.raises(UserInputError, match="not one string"):
        pi.simulate("pendulum_lab", set="length=1.2")


def test_options_are_frozen_and_replaced_by_keywords():
    base = pi.RefineOptions(steps=7, fix={"damping": 0.3})
    with pytest.raises(dataclasses.FrozenInstanceError):
        base.steps = 3  # type: ignore[misc]
    assert dataclasses.replace(base, batch_size=2).steps == 7
    with pytest.raises(UserInputError, match="expected RefineOptions"):
        pi.refine("pendulum_lab", pi.DiagnoseOptions())


def test_refine_matches_the_cli_and_reports_progress(tmp_path, physinfer_cli):
    seen: list[tuple[int, int, float]] = []
    settings = dict(steps=5, floor_samples=0, noise_samples=0, truth={"length": 1.0})
    result = pi.refine(
        "pendulum_lab",
        pi.RefineOptions(**settings),
        out=tmp_path / "api",
        progress=lambda done, total, best: seen.append((done, total, best)),
    )
    cli = physinfer_cli(
        "refine", "--plugin", "pendulum_lab", "--steps", "5", "--floor-samples", "0",
        "--noise-samples", "0", "--truth", "length=1.0", "--out", tmp_path / "cli", "--json",
    ).json()  # fmt: skip
    ours = result.to_dict()
    assert set(ours) - {"wall_time_s"} == set(cli) - {"wall_time_s"}
    assert ours["best_params"] == cli["best_params"]  # the same seeded trials
    assert [s[0] for s in seen] == [1, 2, 3, 4, 5] and {s[1] for s in seen} == {5}
    assert seen[-1][2] == pytest.approx(result.best_distance)
    assert isinstance(result.plot(), Figure)


def _cli_parameters(*path: str) -> set[str]:
    """The Python names of a CLI command's parameters (``physinfer refine`` → ``{"steps", ...}``)."""
    import typer

    from physinfer.cli.app import mounted_app

    command = typer.main.get_command(mounted_app())
    for word in path:
        command = command.commands[word]
    return {param.name for param in command.params}


@pytest.mark.parametrize(
    ("command", "options"),
    [
        (("simulate",), pi.SimulateOptions),
        (("refine",), pi.RefineOptions),
        (("infer",), pi.InferOptions),
        (("diagnose",), pi.DiagnoseOptions),
        (("posterior", "train"), pi.PosteriorTrainOptions),
        (("evaluate", "calibration"), pi.CalibrationOptions),
        (("prepare",), pi.PrepareOptions),
        (("render",), pi.RenderOptions),
    ],
)
def test_every_cli_option_is_a_field_of_the_commands_options_and_back(command, options):
    from physinfer.cli.app import CLI_ONLY, CLI_RENAMES

    cli = {CLI_RENAMES.get(name, name) for name in _cli_parameters(*command)} - CLI_ONLY
    fields = {f.name for f in dataclasses.fields(options)}
    api_only = {"render"} if options is pi.SimulateOptions else set()  # the CLI renders iff --out
    assert cli == fields - api_only - _not_yet_on_the_cli(command)


def _not_yet_on_the_cli(command: tuple[str, ...]) -> set[str]:
    """Shared fields a command's CLI does not take (the shared dataclass is wider than it)."""
    return {
        ("simulate",): {"embedder", "weights", "device", "fix", "embedder_frames"},
    }.get(command, set())


def test_refine_and_diagnose_declare_their_shared_options_alike():
    import typer

    from physinfer.cli.app import mounted_app

    commands = typer.main.get_command(mounted_app()).commands
    helps = {
        name: {p.name: (p.opts, getattr(p, "help", None)) for p in commands[name].params}
        for name in ("refine", "diagnose")
    }
    shared = [
        f.name
        for kind in (pi.ModelOptions, pi.TargetOptions, pi.SearchOptions)
        for f in dataclasses.fields(kind)
    ]
    # What these mean differs by command: the effects tried, the video, the budget, the floor,
    # the batch (diagnose's default is the phenomenon's: two trials per GP fit for the pendulum).
    differ = {"effects", "target", "truth", "steps", "floor_samples", "batch_size"}
    for name in set(shared) - differ:
        assert helps["refine"][name] == helps["diagnose"][name], name


def test_infer_returns_the_posterior_with_a_corner_figure(tmp_path):
    report = pi.infer("flag", out=tmp_path / "post", samples=500)
    assert report.marginals["wind_speed"]["label"] == "identified"
    assert report.to_dict()["posterior"] == report.marginals
    fig = report.plot()
    assert len(fig.axes) >= 4  # at least two parameters: a 2 x 2 corner
