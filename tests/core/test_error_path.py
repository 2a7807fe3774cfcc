"""One error path (issue 45, item 2): a parse error under ``--json`` is one JSON object, a
full disk is one line, a plugin's own command group takes the path too, and text of the
user's (a path with square brackets) is printed as it is, never read as rich markup."""

from __future__ import annotations

import json
import resource
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import typer
from typer.testing import CliRunner

from physinfer.errors import UserInputError

BIN = Path(sys.executable).parent / "physinfer"


def _one_error_line(stderr: str) -> str:
    """The one ``error:`` line, the last on stderr (progress bars may come before it)."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    errors = [line for line in lines if "error" in line.lower()]
    assert errors == lines[-1:] and errors[0].startswith("error: "), stderr[-2000:]
    assert "Traceback" not in stderr
    return errors[0]


def test_a_parse_error_under_json_is_one_json_error(physinfer_cli):
    cases = {
        ("refine", "--steps", "ten"): "Invalid value for '--steps'",
        ("render", "--plugin", "pendulum_lab"): "Missing option '--trajectory'",
        ("simulate", "--plugin", "pendulum_lab", "--no-such-option"): "No such option: --no-such-option",
    }
    for args, words in cases.items():
        ran = physinfer_cli(*args, "--json")
        assert ran.returncode == 2, (args, ran.stdout, ran.stderr)
        error = ran.json()["error"]
        assert words in error and "--help" in error, (args, error)
        assert "╭" not in ran.stdout + ran.stderr and "Usage:" not in ran.stdout + ran.stderr
        _one_error_line(ran.stderr)


def test_the_console_script_gives_one_json_error_for_a_parse_error():
    proc = subprocess.run(
        [str(BIN), "refine", "--steps", "ten", "--json"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2, proc.stderr
    assert "Invalid value for '--steps'" in json.loads(proc.stdout)["error"]
    _one_error_line(proc.stderr)


def _small_files(limit: int):
    def preexec() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return preexec


def test_a_full_disk_is_one_error_line_not_a_traceback(tmp_path):
    """``ulimit -f``: writing the video fails with EFBIG, as a full disk fails with ENOSPC."""
    for command in (
        ["simulate", "--plugin", "pendulum_lab", "--out", str(tmp_path / "s.mp4")],
        ["refine", "--plugin", "pendulum_lab", "--steps", "2", "--optimizer", "random",
         "--noise-samples", "0", "--floor-samples", "2", "--out", str(tmp_path / "run")],
    ):  # fmt: skip
        proc = subprocess.run(
            [str(BIN), *command, "--json"], capture_output=True, text=True, timeout=300,
            preexec_fn=_small_files(4096), cwd=tmp_path,
        )  # fmt: skip
        assert proc.returncode == 2, (command, proc.stderr[-2000:])
        line = _one_error_line(proc.stderr)
        assert "too large" in line or "no space" in line, line
        assert "free space" in json.loads(proc.stdout)["error"], proc.stdout


def test_a_plugin_command_group_takes_the_one_error_path(monkeypatch, tmp_path):
    """A plugin that registers a whole ``typer.Typer`` (not a function) had its commands run
    outside :func:`handle_errors`: a user error became an internal one, a usage box under --json."""
    import physinfer.cli.app as cli_app

    group = typer.Typer()

    @group.command("wrong")
    def wrong(as_json: bool = typer.Option(False, "--json")) -> None:
        raise UserInputError("--size 0: give a positive size")

    @group.command("broken")
    def broken(json_out: bool = typer.Option(False, "--json")) -> None:
        raise RuntimeError("a bug in the plugin")

    cli_app.wrap_plugin_group(group)
    runner = CliRunner()
    ran = runner.invoke(group, ["wrong", "--json"])
    assert ran.exit_code == 2 and json.loads(ran.stdout) == {"error": "--size 0: give a positive size"}
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    ran = runner.invoke(group, ["broken", "--json"])
    assert ran.exit_code == 1, ran.stdout
    reply = json.loads(ran.stdout)
    assert "RuntimeError: a bug in the plugin" in reply["error"] and Path(reply["traceback"]).is_file()


def test_square_brackets_in_the_users_text_are_printed_as_they_are(physinfer_cli, tmp_path):
    odd = tmp_path / "[bold]flag[/bold].txt"
    ran = physinfer_cli("simulate", "--plugin", "pendulum_lab", "--out", odd)
    assert ran.returncode == 2
    assert f"--out {odd}: write a .mp4 or .gif file" in _one_error_line(ran.stderr)
    video = tmp_path / "[red]x[/red].mp4"
    ran = physinfer_cli("simulate", "--plugin", "pendulum_lab", "--render-set", "size=32", "--out", video)
    assert ran.returncode == 0, ran.stderr
    assert str(video) in ran.stderr


def _kill_the_first_pool_worker(stop: threading.Event) -> None:
    """SIGKILL the first spawned pool worker of this process, as the kernel's OOM killer would."""
    me = psutil.Process()
    while not stop.is_set():
        for child in me.children(recursive=True):
            try:
                if "spawn_main" in " ".join(child.cmdline()):  # not multiprocessing's resource tracker
                    child.send_signal(signal.SIGKILL)
                    return
            except psutil.Error:
                continue
        time.sleep(0.02)


def test_a_worker_killed_mid_run_is_one_error_line_that_says_how_to_go_on(physinfer_cli, tmp_path):
    stop = threading.Event()
    killer = threading.Thread(target=_kill_the_first_pool_worker, args=(stop,), daemon=True)
    killer.start()
    try:
        ran = physinfer_cli(
            "refine", "--plugin", "pendulum_lab", "--steps", "8", "--optimizer", "random", "--workers", "1",
            "--no-posterior", "--out", str(tmp_path / "run"),
        )  # fmt: skip
    finally:
        stop.set()
        killer.join(timeout=10)
    assert ran.returncode == 1, ran.stderr[-2000:]
    line = _one_error_line(ran.stderr)
    assert "a worker process stopped abruptly (BrokenProcessPool)" in line
    assert "memory" in line and "--workers 0 runs in this process" in line and "continue with --resume" in line
    assert "internal error" not in line and "traceback saved" not in line  # not filed as a bug of ours


def test_an_interrupted_command_says_what_it_keeps_and_only_that():
    from physinfer.cli.common import handle_errors

    def interrupted() -> None:
        raise KeyboardInterrupt

    said = {}
    for name, decorate in {
        "infer": handle_errors(),
        "refine": handle_errors(kept="completed trials are saved: continue with --resume"),
    }.items():
        app = typer.Typer()
        app.command()(decorate(interrupted))
        ran = CliRunner().invoke(app, [])
        assert ran.exit_code == 130
        said[name] = ran.output.strip()
    assert said == {"infer": "interrupted", "refine": "interrupted; completed trials are saved: continue with --resume"}
