"""report.html: one self-contained page per run, checked in a real headless Chromium.

The refine page comes from a real pendulum refinement; the browser test loads it in
Debian's chromium (installed by ``make system-deps``) through chromedriver and checks that
nothing errs in the console, that the inlined video decodes and plays, and that the page
renders as something other than a blank screen.
"""

from __future__ import annotations

import json
import re
import shutil
import stat
import sys
from pathlib import Path

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.report import REPORT_FILE, build_report, run_kind, write_report, write_report_quietly

QUICK_REFINE = (
    "--plugin",
    "pendulum_lab",
    "--steps",
    "2",
    "--optimizer",
    "random",
    "--noise-samples",
    "0",
)
CHROMIUM_FLAGS = (
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--autoplay-policy=no-user-gesture-required", "--window-size=1200,1600",
)  # fmt: skip


@pytest.fixture(scope="module")
def refine_run(tmp_path_factory, physinfer_cli) -> Path:
    """A 2-trial pendulum refinement at 64 px with a 2-sample noise floor (a few seconds)."""
    out = tmp_path_factory.mktemp("report") / "refine"
    ran = physinfer_cli("refine", *QUICK_REFINE, "--floor-samples", "2", "--out", out, "--json")
    assert ran.returncode == 0, ran.stderr[-2000:]
    return out


def _srcs(page: str) -> list[str]:
    return re.findall(r'(?:src|href)="([^"]*)"', page)


# ------------------------------------------------------------------------- the page itself


def test_a_refinement_writes_a_self_contained_page_with_its_numbers(refine_run):
    page = (refine_run / REPORT_FILE).read_text(encoding="ascii")
    result = json.loads((refine_run / "result.json").read_text())
    assert page.startswith("<!doctype html>") and "Content-Security-Policy" in page
    # Every resource is inlined: nothing for the browser to fetch.
    assert all(s.startswith("data:") for s in _srcs(page)), [s[:40] for s in _srcs(page)]
    assert page.count("data:image/png;base64,") == 1 and page.count("data:video/mp4;base64,") == 1
    assert "http://" not in page and "https://" not in page
    # The parameter table: best fit, truth and error, as result.json has them.
    for name, value in result["best_params"].items():
        row = re.search(rf"<tr><td>{name}</td>(.*?)</tr>", page)
        assert row, name
        cells = re.findall(r"<td[^>]*>([^<]*)</td>", row.group(1))
        assert cells[1] == f"{value:.4g}", (name, cells)
        assert cells[2] == f"{result['ground_truth'][name]:.4g}"
        assert cells[3] == f"{result['abs_errors'][name]:.4g}"
    floor = result["noise_floor"]
    assert f"{floor['floor']:.4g}" in page and f"{floor['gap']:.4g}" in page
    assert "optimizer" in page and "random" in page  # the settings


def test_report_rebuilds_the_page_and_refuses_what_is_not_a_run(
    refine_run, physinfer_cli, tmp_path
):
    (refine_run / REPORT_FILE).unlink()
    ran = physinfer_cli("report", refine_run, "--json")
    assert ran.returncode == 0, ran.stderr
    info = ran.json()
    assert info["kind"] == "refine" and Path(info["report"]) == refine_run / REPORT_FILE
    assert (refine_run / REPORT_FILE).stat().st_size == info["bytes"]
    (tmp_path / "notes.txt").write_text("mine")
    refused = physinfer_cli("report", tmp_path, "--json")
    assert refused.returncode == 2 and "is not a physinfer run" in refused.json()["error"]
    assert not (tmp_path / REPORT_FILE).exists()
    missing = physinfer_cli("report", tmp_path / "nowhere", "--json")
    assert missing.returncode == 2 and "is not a directory" in missing.json()["error"]


def test_damaged_files_are_one_clear_error_and_never_fail_a_run(refine_run, tmp_path, caplog):
    run = tmp_path / "copy"
    shutil.copytree(refine_run, run)
    (run / "result.json").write_text("{not json")
    with pytest.raises(UserInputError, match=r"result.json is not valid JSON"):
        build_report(run)
    with caplog.at_level("WARNING", logger="physinfer.report.page"):
        assert write_report_quietly(run) is None  # what a run's end calls: a warning, no exception
    assert "report.html not written" in caplog.text
    (run / "run.json").write_text("[]")
    with pytest.raises(UserInputError, match="is not a physinfer run"):
        run_kind(run)


def test_an_unfinished_run_and_a_huge_video_still_make_a_page(refine_run, tmp_path, monkeypatch):
    import physinfer.report.markup as markup

    run = tmp_path / "copy"
    shutil.copytree(refine_run, run)
    (run / "result.json").unlink()
    (run / "refinement.png").unlink()
    monkeypatch.setattr(markup, "MAX_INLINE_VIDEO_BYTES", 1000)
    page = write_report(run).html
    assert "has not finished" in page and "refinement.png is not in the run folder" in page
    assert (
        "data:video" not in page
        and '<a href="side_by_side.mp4">' in page
        and "too large to inline" in page
    )


def test_text_from_the_run_is_escaped(refine_run, tmp_path):
    run = tmp_path / "copy"
    shutil.copytree(refine_run, run)
    info = json.loads((run / "run.json").read_text())
    info["target"] = "<script>alert(1)</script>.mp4"
    (run / "run.json").write_text(json.dumps(info))
    page = build_report(run).html
    assert "<script>" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;.mp4" in page


def test_an_infer_run_gets_a_posterior_page(tmp_path):
    """The real writer of ``infer`` (posterior.json, samples, corner plot) ends with the page."""
    import torch

    from physinfer import ParameterSpace, ParameterSpec
    from physinfer.posterior.estimator import EstimatorConfig, PosteriorEstimator
    from physinfer.posterior.summary import correlations, marginals
    from physinfer.posterior.workflow import PosteriorReport
    from physinfer.posterior.workflow import write_report as write_posterior

    space = ParameterSpace(
        [
            ParameterSpec("length", (0.4, 1.6), "m"),
            ParameterSpec("drag", (0.1, 10.0), scaling="log"),
        ]
    )
    config = EstimatorConfig(plugin="pendulum_lab", embedder="grid_spectrum", embedder_frames=30, embedder_fps=25.0,
                             probe=[0.0], clip_seconds=2.0, parameters=space.to_dict(), x_dim=4)  # fmt: skip
    estimator = PosteriorEstimator(config, torch.nn.Identity())  # write_report reads only its space
    rng = np.random.default_rng(0)
    samples = np.tanh(
        rng.normal([0.3, -0.2], [0.05, 0.8], size=(2000, 2))
    )  # length pinned, drag not
    report = PosteriorReport(marginals(samples, space), correlations(samples, space.names), samples, space.names,
                             Path("toy.safetensors"), truth={"length": 1.2, "drag": 1.0})  # fmt: skip
    write_posterior(report, estimator, tmp_path / "infer")
    page = (tmp_path / "infer" / REPORT_FILE).read_text()
    assert run_kind(tmp_path / "infer") == "infer"
    assert "data:image/png;base64," in page and "toy.safetensors" in page
    median = report.marginals["length"]["median"]
    assert f"{median:.4g}" in page and report.marginals["length"]["label"] in page
    assert "truth in 90 %" in page


# -------------------------------------------------------------------- in a real browser


def _executable(name: str) -> str:
    path = shutil.which(name) or f"/usr/bin/{name}"
    if not Path(path).is_file():
        pytest.fail(
            f"{name} is not installed: `make system-deps` installs it (apt-get install chromium chromium-driver)"
        )
    return path


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """Headless Debian chromium through chromedriver, logging the console (no network)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = _executable("chromium")
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={tmp_path_factory.mktemp('chromium')}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(_executable("chromedriver")), options=options)
    driver.set_script_timeout(20)
    yield driver
    driver.quit()


#: Plays the page's video for ~0.4 s, then draws its current frame and measures its spread.
PLAY_VIDEO = """
const done = arguments[arguments.length - 1];
const v = document.querySelector('video');
if (!v) { done({error: 'no video element'}); return; }
const start = performance.now();
v.play().then(() => {
  const poll = () => {
    if (v.currentTime < 0.4 && performance.now() - start < 10000) { setTimeout(poll, 50); return; }
    const c = document.createElement('canvas');
    c.width = v.videoWidth; c.height = v.videoHeight;
    const g = c.getContext('2d'); g.drawImage(v, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    let s = 0, s2 = 0;
    for (let i = 0; i < d.length; i += 4) { s += d[i + 1]; s2 += d[i + 1] * d[i + 1]; }
    const n = d.length / 4;
    done({readyState: v.readyState, currentTime: v.currentTime, width: v.videoWidth,
          error: v.error && v.error.code, frameStd: Math.sqrt(s2 / n - (s / n) ** 2)});
  };
  poll();
}).catch(e => done({error: String(e)}));
"""


def _console_errors(driver) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def test_the_page_loads_plays_its_video_and_renders_in_chromium(refine_run, browser, tmp_path):
    import imageio.v3 as iio

    browser.get((refine_run / REPORT_FILE).resolve().as_uri())
    images = browser.execute_script(
        "return Array.from(document.images).map(i => i.complete && i.naturalWidth)"
    )
    assert images and all(w and w > 100 for w in images), images
    video = browser.execute_async_script(PLAY_VIDEO)
    assert not video.get("error"), video
    assert video["readyState"] >= 2 and video["currentTime"] >= 0.4 and video["width"] >= 128, video
    assert video["frameStd"] > 5, f"the decoded frame is flat: {video}"
    assert _console_errors(browser) == []
    shot = iio.imread(browser.get_screenshot_as_png())
    assert shot.shape[0] > 500 and shot[..., :3].std() > 20, "the screenshot is blank"
    # The console check can fail: an outside resource slipped into the page is refused and logged.
    bad = tmp_path / "bad.html"
    page = (refine_run / REPORT_FILE).read_text()
    bad.write_text(page.replace("</main>", '<img src="https://example.invalid/x.png"></main>'))
    browser.get(bad.resolve().as_uri())
    assert any("Content Security Policy" in m for m in _console_errors(browser))


# ------------------------------------------------------------------------ open and diagnose


def test_open_hands_the_page_to_the_browser(refine_run, tmp_path):
    """``--open`` goes through $BROWSER (a script recording the URL stands in for a desktop)."""
    import subprocess

    seen = tmp_path / "seen.txt"
    script = tmp_path / "browser.sh"
    script.write_text(f'#!/bin/sh\necho "$1" > {seen}\n')
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    physinfer = Path(sys.executable).parent / "physinfer"
    env = {"PATH": "/usr/bin:/bin", "BROWSER": str(script), "HOME": str(tmp_path)}
    proc = subprocess.run([str(physinfer), "report", str(refine_run), "--open", "--json"],
                          capture_output=True, text=True, env=env, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["opened"] is True
    assert seen.read_text().strip() == (refine_run / REPORT_FILE).resolve().as_uri()


@pytest.mark.slow
def test_a_diagnosis_gets_a_page_with_its_verdict_maps_and_video(tmp_path):
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.workflow import run_diagnosis
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    out = tmp_path / "diagnosis"
    settings = DiagnoseSettings(plugin="pendulum_lab", out=out, render_set={"size": 48}, steps=2, optimizer="random",
                                floor_samples=4, calibrate=False)  # fmt: skip
    report = run_diagnosis(registry, settings)
    page = (out / REPORT_FILE).read_text()
    assert run_kind(out) == "diagnose"
    assert page.count("data:image/png;base64,") == 2 and page.count("data:video/mp4;base64,") == 1
    assert "not misspecified" in page if not report["misspecified"] else "misspecified:" in page
    assert (
        "quadratic_drag" in page and "effect-quadratic_drag" in page
    )  # candidates and stage folders
    assert f"{report['gap_before']:.4g}" in page
    assert "Detection limits" in page and "quadratic_drag: " in page  # one line per candidate
