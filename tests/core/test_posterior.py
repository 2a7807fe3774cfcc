"""Tests of physinfer.posterior: the calibration check on a problem whose posterior is known,
summaries and labels, safe saving and loading, and train → infer → calibrate through the CLI
on a small generated pendulum dataset (sbi's NPE, the real embedder, no mocks)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physinfer import ParameterSpace, ParameterSpec
from physinfer.errors import UserInputError
from physinfer.posterior.calibration import calibrate, coverage_from_ranks
from physinfer.posterior.summary import correlations, identifiability_label, marginals

# ------------------------------------------------- calibration on a linear-Gaussian toy

SIGMA = 0.5  # x = θ + N(0, σ²), θ ~ N(0, 1): posterior N(x / (1 + σ²), σ² / (1 + σ²))


def _toy(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    theta = rng.normal(size=(n, 2))
    return theta, theta + SIGMA * rng.normal(size=(n, 2))


def _gaussian_sampler(scale: float):
    """Exact posterior samples, their spread multiplied by ``scale`` (1: exact)."""
    post_sd = np.sqrt(SIGMA**2 / (1 + SIGMA**2))

    def sample(xs: np.ndarray, n: int, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        mean = xs / (1 + SIGMA**2)
        return mean[None] + scale * post_sd * rng.normal(size=(n, *xs.shape))

    return sample


def test_calibration_finds_nominal_coverage_for_the_exact_posterior():
    theta, x = _toy(1000)
    cal = calibrate(theta, x, _gaussian_sampler(1.0), ["a", "b"], n_samples=500)
    for level in (0.5, 0.9):
        assert np.all(np.abs(cal.coverage[level] - level) <= cal.tolerance(level))
        assert [cal.verdict(level, i) for i in range(2)] == ["calibrated", "calibrated"]
    assert np.all(cal.ks_pvalue > 0.001)


def test_calibration_detects_an_over_confident_and_an_under_confident_posterior():
    theta, x = _toy(1000, seed=1)
    narrow = calibrate(theta, x, _gaussian_sampler(0.5), ["a", "b"], n_samples=500)
    # half the spread: the 90 % interval covers P(|Z| < 0.82) ≈ 0.59
    assert np.all(narrow.coverage[0.9] < 0.7)
    assert narrow.verdict(0.9, 0) == "over-confident"
    assert np.all(narrow.ks_pvalue < 1e-6)
    wide = calibrate(theta, x, _gaussian_sampler(2.0), ["a", "b"], n_samples=500)
    assert np.all(wide.coverage[0.5] > 0.75)
    assert wide.verdict(0.5, 1) == "under-confident"


def test_coverage_from_ranks_counts_the_central_interval():
    ranks = np.array([[0], [50], [99], [100]])
    # quantiles (r + 0.5) / 101: 0.005, 0.5, 0.985, 0.995; only 0.5 lies within 0.05–0.95
    assert coverage_from_ranks(ranks, 100, 0.9).tolist() == [0.25]
    assert coverage_from_ranks(np.array([[50], [60]]), 100, 0.5).tolist() == [1.0]


# ------------------------------------------------------------------ summaries and labels

SPACE = ParameterSpace(
    [
        ParameterSpec("wind", (0.0, 10.0), "m/s"),
        ParameterSpec("weight", (0.1, 0.2), "kg/m²", scaling="log"),
        ParameterSpec("bend", (0.1, 10.0), "", scaling="log"),
    ]
)


def test_marginals_label_by_contraction_and_report_intervals_in_physical_units():
    rng = np.random.default_rng(0)
    n = 20000
    wind = np.clip(0.2 + 0.05 * rng.normal(size=n), -1, 1)  # sd 0.05 of the prior's 0.58
    weight = rng.uniform(-0.6, 0.6, size=n)  # contraction 1 - 0.12 / 0.333 = 0.64
    bend = rng.uniform(-1, 1, size=n)  # the prior itself
    m = marginals(np.stack([wind, weight, bend], axis=1), SPACE)
    assert m["wind"]["label"] == "identified"
    assert m["weight"]["label"] == "weakly identified"
    assert m["bend"]["label"] == "not identified"
    assert m["wind"]["median"] == pytest.approx(6.0, abs=0.02)  # unit 0.2 → 6 m/s
    lo, hi = m["wind"]["ci90"]
    assert lo == pytest.approx(6.0 - 1.645 * 0.25, abs=0.03) and hi == pytest.approx(
        6.0 + 1.645 * 0.25, abs=0.03
    )
    assert m["wind"]["ci50"][0] > lo and m["wind"]["ci50"][1] < hi
    assert abs(m["bend"]["contraction"]) < 0.03
    assert m["wind"]["unit"] == "m/s"


def test_identifiability_thresholds():
    assert identifiability_label(0.9) == "identified"
    assert identifiability_label(0.75) == "identified"
    assert identifiability_label(0.5) == "weakly identified"
    assert identifiability_label(0.1) == "not identified"
    assert identifiability_label(-0.2) == "not identified"


def test_correlations_show_a_ridge_and_nothing_for_independent_parameters():
    rng = np.random.default_rng(1)
    a = rng.uniform(-1, 1, 5000)
    samples = np.stack([a, -a + 0.1 * rng.normal(size=5000), rng.uniform(-1, 1, 5000)], axis=1)
    pairs = correlations(samples, ["wind", "weight", "bend"])
    assert len(pairs) == 1
    assert (pairs[0]["a"], pairs[0]["b"]) == ("wind", "weight") and pairs[0]["r"] < -0.9


# ----------------------------------------------------------------- saving and loading


def _toy_pairs_and_identity():
    """400 pairs x = (θ + noise, distractor) in a 2-D space, and an estimator identity."""
    from physinfer.posterior.features import EmbeddedSet

    space = ParameterSpace(
        [ParameterSpec("a", (0.0, 1.0)), ParameterSpec("b", (1.0, 100.0), scaling="log")]
    )
    rng = np.random.default_rng(0)
    theta = rng.uniform(-1, 1, size=(400, 2)).astype(np.float32)
    x = np.concatenate(
        [theta + 0.1 * rng.normal(size=theta.shape), rng.normal(size=(400, 1))], axis=1
    )
    pairs = EmbeddedSet(space, theta, x.astype(np.float32), np.arange(400), Path("unused"))
    identity = {
        "plugin": "toy",
        "embedder": "identity",
        "embedder_frames": 10,
        "embedder_fps": 25.0,
        "probe": [0.0, 1.0, 2.0],
        "clip_seconds": 0.4,
    }
    return pairs, identity


@pytest.fixture(scope="module")
def toy_estimator():
    """A small NPE (sbi, maf) trained on x = θ + noise in 2-D, in seconds."""
    from physinfer.posterior.estimator import NetworkConfig
    from physinfer.posterior.training import train_estimator

    pairs, identity = _toy_pairs_and_identity()
    network = NetworkConfig(
        hidden_features=32, num_transforms=3, batch_size=50, learning_rate=2e-3, max_epochs=40
    )
    return train_estimator(pairs, identity, network=network, seed=0, device="cpu")


def test_an_ensemble_is_a_mixture_of_its_seeded_flows_and_round_trips(tmp_path):
    import torch

    from physinfer.posterior.estimator import NetworkConfig, PosteriorEstimator
    from physinfer.posterior.flows import FlowEnsemble
    from physinfer.posterior.training import train_estimator

    pairs, identity = _toy_pairs_and_identity()
    network = NetworkConfig(
        density="maf", hidden_features=8, num_transforms=2, learning_rate=2e-3, max_epochs=3,
        ensemble=2,
    )  # fmt: skip
    est = train_estimator(pairs, identity, network=network, seed=5, device="cpu")
    assert isinstance(est.network, FlowEnsemble) and len(est.network.members) == 2
    assert len(est.config.training["epochs"]) == 2
    first, second = (dict(m.named_parameters()) for m in est.network.members)
    assert any(not torch.equal(first[k], second[k]) for k in first)  # two seeds, two flows
    # The mixture draws half its samples from each flow, in member order.
    x = torch.tensor([[0.5, -0.5, 0.0]])
    torch.manual_seed(1)
    both = est.network.sample((6,), condition=x)
    torch.manual_seed(1)
    parts = [m.sample((3,), condition=x) for m in est.network.members]
    torch.testing.assert_close(both, torch.cat(parts))
    loaded = PosteriorEstimator.load(est.save(tmp_path / "ens.safetensors"))
    assert loaded.config == est.config
    xs = x.numpy()[0]
    np.testing.assert_allclose(
        loaded.sample_unit(xs, 100, seed=2), est.sample_unit(xs, 100, seed=2), atol=1e-6
    )


def test_training_and_sampling_leave_the_callers_random_streams_alone(toy_estimator):
    """A notebook's torch and numpy streams go on as if physinfer had not drawn (sbi seeds both)."""
    import torch

    from physinfer.posterior.estimator import NetworkConfig
    from physinfer.posterior.training import train_estimator

    def draws() -> tuple:
        return torch.rand(3).tolist(), np.random.rand(3).tolist()  # noqa: NPY002

    torch.manual_seed(123)
    np.random.seed(123)  # noqa: NPY002
    expected = draws()
    torch.manual_seed(123)
    np.random.seed(123)  # noqa: NPY002
    toy_estimator.sample_unit(np.array([0.5, -0.5, 0.0], dtype=np.float32), 50, seed=7)
    pairs, identity = _toy_pairs_and_identity()
    network = NetworkConfig(density="maf", hidden_features=8, num_transforms=1, max_epochs=1)
    train_estimator(pairs, identity, network=network, seed=5, device="cpu")
    assert draws() == expected


def test_an_estimator_round_trips_through_its_file_and_samples_alike(toy_estimator, tmp_path):
    from physinfer.posterior.estimator import PosteriorEstimator

    path = toy_estimator.save(tmp_path / "toy.safetensors")
    loaded = PosteriorEstimator.load(path)
    assert loaded.config == toy_estimator.config
    x = np.array([0.5, -0.5, 0.0], dtype=np.float32)
    np.testing.assert_allclose(
        loaded.sample_unit(x, 200, seed=3), toy_estimator.sample_unit(x, 200, seed=3), atol=1e-6
    )
    samples = loaded.sample_unit(x, 4000, seed=0)
    assert np.median(samples[:, 0]) == pytest.approx(0.5, abs=0.15)  # it learnt something
    assert np.all(np.abs(samples) <= 1.0)  # inside the prior's box


def test_a_modified_or_foreign_file_is_refused(toy_estimator, tmp_path):
    from safetensors.numpy import save_file

    from physinfer.posterior.estimator import PosteriorEstimator

    path = toy_estimator.save(tmp_path / "toy.safetensors")
    raw = bytearray(path.read_bytes())
    raw[-5] ^= 0xFF  # one weight's byte
    tampered = tmp_path / "tampered.safetensors"
    tampered.write_bytes(bytes(raw))
    with pytest.raises(UserInputError, match="modified"):
        PosteriorEstimator.load(tampered)
    cut = tmp_path / "cut.safetensors"
    cut.write_bytes(bytes(raw[:100]))
    with pytest.raises(UserInputError, match="not a readable posterior estimator"):
        PosteriorEstimator.load(cut)
    other = tmp_path / "other.safetensors"
    save_file({"w": np.zeros(3, dtype=np.float32)}, str(other))
    with pytest.raises(UserInputError, match="not a physinfer posterior estimator"):
        PosteriorEstimator.load(other)
    with pytest.raises(UserInputError, match="does not exist"):
        PosteriorEstimator.load(tmp_path / "missing.safetensors")


def test_an_estimator_for_another_plugin_or_parameter_space_is_refused(toy_estimator):
    space = toy_estimator.parameter_space
    toy_estimator.check_for("toy", space)  # its own: accepted
    with pytest.raises(UserInputError, match="trained for --plugin toy, not flag"):
        toy_estimator.check_for("flag", space)
    wider = ParameterSpace([ParameterSpec("a", (0.0, 2.0)), space["b"]])
    with pytest.raises(UserInputError, match=r"a: its range \(0.0, 1.0\), here \(0.0, 2.0\)"):
        toy_estimator.check_for("toy", wider)
    fewer = ParameterSpace([space["b"]])
    with pytest.raises(UserInputError, match="this model lacks"):
        toy_estimator.check_for("toy", fewer)


def test_nan_or_wrong_sized_embeddings_are_refused(toy_estimator):
    with pytest.raises(UserInputError, match="not finite"):
        toy_estimator.sample_unit(np.array([np.nan, 0.0, 0.0]), 10)
    with pytest.raises(UserInputError, match="dimension 2"):
        toy_estimator.sample_unit(np.zeros(2), 10)


# ------------------------------------------------------------- the pendulum, end to end


@pytest.fixture(scope="module")
def pendulum_set(tmp_path_factory, physinfer_cli) -> Path:
    """A small generated pendulum dataset: 2-s clips, 48 px, 60 training and 20 test simulations."""
    root = tmp_path_factory.mktemp("posterior") / "pendulum-set"
    proc = physinfer_cli(
        "dataset", "generate", "--plugin", "pendulum_lab", "--sims", "60,0,20", "--renders-per-sim", "1",
        "--frames", "50", "--size", "48", "--workers", "0", "--seed", "5", "--out", str(root), "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return root


@pytest.fixture(scope="module")
def pendulum_estimator(pendulum_set, physinfer_cli) -> tuple[Path, dict]:
    out = pendulum_set.parent / "pendulum.safetensors"
    proc = physinfer_cli(
        "posterior", "train", "--plugin", "pendulum_lab", "--data", str(pendulum_set), "--out", str(out),
        "--embedder-frames", "50", "--max-epochs", "40", "--device", "cpu", "--json",
        # the tests' targets are renders in memory, as the stored clips; 60 pairs make a small
        # estimator whose calibration is not what these tests are about
        "--stored", "--accept-miscalibrated",
    )  # fmt: skip
    return out, proc.json()


def test_train_writes_an_estimator_and_caches_the_embeddings(
    pendulum_set, pendulum_estimator, physinfer_cli
):
    out, summary = pendulum_estimator
    assert out.is_file() and summary["estimator"] == str(out)
    assert summary["plugin"] == "pendulum_lab" and summary["embedder"] == "grid_spectrum"
    assert summary["parameters"] == ["length", "damping", "amplitude"]
    assert summary["training"]["pairs"] == 60 and 1 <= summary["training"]["epochs"] <= 41
    cache = Path(summary["embeddings_cache"])
    assert cache.parent == pendulum_set / "embeddings" and cache.is_file()
    with np.load(cache, allow_pickle=False) as data:
        assert data["x"].shape[0] == 60
    # a second training reuses the cached embeddings (the same file, not rewritten)
    stamp = cache.stat().st_mtime_ns
    again = physinfer_cli(
        "posterior", "train", "--plugin", "pendulum_lab", "--data", str(pendulum_set),
        "--out", str(out.with_name("again.safetensors")), "--embedder-frames", "50", "--max-epochs", "5", "--json",
        "--stored", "--accept-miscalibrated",
    ).json()  # fmt: skip
    assert again["embeddings_cache"] == str(cache) and cache.stat().st_mtime_ns == stamp


def test_infer_reports_intervals_labels_and_writes_samples_and_a_corner_plot(
    pendulum_estimator, tmp_path, physinfer_cli
):
    path, _ = pendulum_estimator
    out = tmp_path / "infer"
    proc = physinfer_cli(
        "infer",
        "--plugin",
        "pendulum_lab",
        "--posterior",
        str(path),
        "--samples",
        "2000",
        "--out",
        str(out),
        "--json",
    )
    report = proc.json()
    assert set(report["posterior"]) == {"length", "damping", "amplitude"}
    for m in report["posterior"].values():
        assert set(m) == {"median", "ci50", "ci90", "contraction", "label", "unit"}
        assert m["ci90"][0] <= m["ci50"][0] <= m["median"] <= m["ci50"][1] <= m["ci90"][1]
        assert m["label"] in ("identified", "weakly identified", "not identified")
    assert report["truth"] == {"length": 1.25, "damping": 0.12, "amplitude": 42.0}
    assert set(report["truth_in_ci90"]) == {"length", "damping", "amplitude"}
    assert isinstance(report["correlations"], list)
    with np.load(out / "samples.npz", allow_pickle=False) as data:
        assert data["samples"].shape == (2000, 3) and list(data["names"]) == [
            "length",
            "damping",
            "amplitude",
        ]
        assert data["samples"][:, 0].min() >= 0.4 and data["samples"][:, 0].max() <= 1.6
    assert (out / "corner.png").stat().st_size > 1000
    assert json.loads((out / "posterior.json").read_text())["posterior"] == report["posterior"]
    human = physinfer_cli(
        "infer",
        "--plugin",
        "pendulum_lab",
        "--posterior",
        str(path),
        "--samples",
        "500",
        "--out",
        str(out),
        "--overwrite",  # the results of the infer above are replaced only when told
    )
    assert human.returncode == 0 and "length" in human.stderr and "identified" in human.stderr


def test_evaluate_calibration_reports_coverage_per_parameter(
    pendulum_set, pendulum_estimator, tmp_path, physinfer_cli
):
    path, _ = pendulum_estimator
    out = tmp_path / "cal"
    proc = physinfer_cli(
        "evaluate", "calibration", "--plugin", "pendulum_lab", "--posterior", str(path), "--data", str(pendulum_set),
        "--samples", "200", "--out", str(out), "--json",
    )  # fmt: skip
    report = proc.json()
    assert report["n_pairs"] == 20 and report["split"] == "test"
    for row in report["parameters"].values():
        assert 0.0 <= row["coverage50"] <= row["coverage90"] <= 1.0
        assert row["verdict90"] in ("calibrated", "over-confident", "under-confident")
        assert {"ks_pvalue", "median_abs_error", "mean_contraction"} <= set(row)
    assert (out / "calibration.png").stat().st_size > 1000 and (out / "calibration.json").is_file()


def test_the_api_trains_and_calibrates_with_progress_and_figures(
    pendulum_set, pendulum_estimator, tmp_path
):
    from matplotlib.figure import Figure

    import physinfer.api as pi

    seen: list[tuple[str, int, int]] = []
    trained = pi.train_posterior(
        "pendulum_lab", data=pendulum_set, out=tmp_path / "api.safetensors", embedder_frames=50,
        max_epochs=10, device="cpu", progress=lambda *args: seen.append(args),
    )  # fmt: skip
    assert trained.path.is_file() and trained.to_dict()["parameters"] == ["length", "damping", "amplitude"]
    assert {stage for stage, _, _ in seen} == {"embedding", "training", "held-out clips"}
    curve = trained.estimator.validation_curves[0]
    assert len(curve) == trained.to_dict()["training"]["epochs"]
    assert isinstance(trained.plot(), Figure)

    path, _ = pendulum_estimator
    seen.clear()
    cal = pi.evaluate_calibration(
        "pendulum_lab", pi.CalibrationOptions(data=pendulum_set, posterior=path, samples=100),
        out=tmp_path / "cal", progress=lambda *args: seen.append(args),
    )  # fmt: skip
    assert cal.to_dict()["n_pairs"] == 20 and (tmp_path / "cal" / "calibration.json").is_file()
    assert {stage for stage, _, _ in seen} == {"embedding as given", "embedding as stored", "sampling"}
    assert len(cal.plot().axes) == 4  # three rank histograms and the coverage panel
    with pytest.raises(UserInputError, match="data: give"):
        pi.evaluate_calibration("pendulum_lab", posterior=path)


def test_bad_input_to_the_posterior_commands_is_one_clear_error(
    pendulum_set, pendulum_estimator, tmp_path, physinfer_cli
):
    path, _ = pendulum_estimator
    short = tmp_path / "short.mp4"
    assert physinfer_cli("simulate", "--plugin", "pendulum_lab", "--out", str(short)).returncode == 0
    from physinfer.video import read_video, write_video

    clip = read_video(short)
    write_video(short, clip.frames[:30], fps=clip.fps)  # 1.2 s of a 2-s estimator
    import shutil

    poisoned = tmp_path / "poisoned-set"
    shutil.copytree(pendulum_set, poisoned, ignore=shutil.ignore_patterns("embeddings"))
    rows = (poisoned / "manifest.jsonl").read_text().splitlines()
    last = json.loads(rows[-1])
    last["params"]["length"] = 1e9  # a test row's θ far outside 0.4-1.6 m
    (poisoned / "manifest.jsonl").write_text("\n".join([*rows[:-1], json.dumps(last)]) + "\n")
    cases = {
        ("infer", "--plugin", "pendulum_lab", "--posterior", str(path), "--target", str(short)): "lasts 1.20 s",
        ("infer", "--plugin", "pendulum_lab", "--posterior", str(path), "--target", str(short), "--end", "1"): "measure it with `physinfer refine --plugin pendulum_lab`",
        ("infer", "--plugin", "flag", "--posterior", str(path)): "trained for --plugin pendulum_lab, not flag",
        ("infer", "--plugin", "pendulum_lab", "--posterior", str(path), "--device", "tpu9"): "not a torch device",
        ("infer", "--plugin", "pendulum_lab"): "ships no posterior estimator",
        ("posterior", "train", "--plugin", "flag", "--data", str(pendulum_set), "--out", str(tmp_path / "f.safetensors")): "generated for --plugin pendulum_lab",
        ("posterior", "train", "--plugin", "pendulum_lab", "--data", str(pendulum_set), "--out", str(tmp_path / "f.pt")): "*.safetensors",
        ("evaluate", "calibration", "--plugin", "pendulum_lab", "--posterior", str(path), "--data", str(tmp_path)): "not a dataset",
        ("evaluate", "calibration", "--plugin", "pendulum_lab", "--posterior", str(path), "--data", str(poisoned), "--out", str(tmp_path / "cal")): f"row {len(rows)} (render",
    }  # fmt: skip
    for args, message in cases.items():
        proc = physinfer_cli(*args, "--json", cwd=tmp_path)
        assert proc.returncode == 2, (args, proc.stderr[-1500:])
        assert message in proc.json()["error"], (args, proc.stdout)


def test_refine_reports_the_targets_posterior_and_starts_at_its_median(
    pendulum_estimator, tmp_path, physinfer_cli
):
    path, _ = pendulum_estimator
    out = tmp_path / "run"
    proc = physinfer_cli(
        "refine", "--plugin", "pendulum_lab", "--posterior", str(path), "--steps", "4", "--noise-samples", "0",
        "--floor-samples", "0", "--out", str(out), "--json",
    )  # fmt: skip
    result = proc.json()
    assert set(result["posterior"]) == {"length", "damping", "amplitude"}
    source = result["posterior_source"]
    assert source["kind"] == "amortized" and source["estimator"] == str(path)
    assert "noise floor was not measured" in source["not_refined"]  # --floor-samples 0
    assert result["posterior_amortized"] == result["posterior"]
    with np.load(out / "posterior_samples.npz", allow_pickle=False) as data:
        assert data["amortized"].shape[1] == 3 and "refined" not in data
    # the search box: the identified parameters' region, every trial inside it
    box = json.loads((out / "run.json").read_text())["start"]["search_box"]
    assert box == source["search_box"]
    identified = {n for n, m in result["posterior"].items() if m["label"] != "not identified"}
    assert set(box) == identified
    for line in (out / "trials.jsonl").read_text().splitlines():
        params = json.loads(line)["params"]
        assert all(lo - 1e-9 <= params[n] <= hi + 1e-9 for n, (lo, hi) in box.items())
    assert isinstance(result["correlations"], list)
    assert json.loads((out / "result.json").read_text())["posterior"] == result["posterior"]
    # the first trial is the posterior median (the warm start), not the centre of the space
    first = json.loads((out / "trials.jsonl").read_text().splitlines()[0])["params"]
    for name, m in result["posterior"].items():
        assert first[name] == pytest.approx(m["median"], rel=1e-6)
    # a model the estimator was not trained for is refused before any simulation
    drag = physinfer_cli(
        "refine", "--plugin", "pendulum_lab", "--posterior", str(path), "--effect", "quadratic_drag", "--steps", "2",
        "--out", str(tmp_path / "drag"), "--json",
    )  # fmt: skip
    assert drag.returncode == 2 and "drag_quadratic" in drag.json()["error"]
    assert not (tmp_path / "drag" / "trials.jsonl").exists()


def test_a_search_from_a_posterior_takes_the_phenomenons_shorter_default_budget(
    pendulum_estimator, tmp_path, monkeypatch
):
    """``default_steps_with_posterior``: the budget when --steps is not given and the search
    starts from an estimator (16 for the flag); without an estimator the default stays."""
    import dataclasses

    from physinfer.plugins import load_registry
    from physinfer.refinement import default_budget
    from physinfer.session import refine

    path, _ = pendulum_estimator
    registry, _ = load_registry()
    pendulum = registry.phenomenon("pendulum_lab")
    short = dataclasses.replace(pendulum, default_steps_with_posterior=3)
    assert default_budget(short, None, from_posterior=True) == 3
    assert default_budget(short, None, from_posterior=False) == pendulum.default_steps
    assert default_budget(short, 5, from_posterior=True) == 5  # --steps wins
    assert default_budget(pendulum, None, from_posterior=True) == pendulum.default_steps  # not declared
    original = registry.phenomenon
    monkeypatch.setattr(registry, "phenomenon", lambda name, *a, **k: short if name == "pendulum_lab" else original(name, *a, **k))
    common = {"plugin": "pendulum_lab", "optimizer": "random", "noise_samples": 0, "floor_samples": 0, "progress": False}
    refine(registry, posterior=path, out=tmp_path / "from_posterior", **common)
    trials = (tmp_path / "from_posterior" / "trials.jsonl").read_text().splitlines()
    assert len(trials) == 3 and json.loads((tmp_path / "from_posterior" / "run.json").read_text())["steps"] == 3
    refine(registry, use_posterior=False, steps=4, out=tmp_path / "centre", **common)
    assert len((tmp_path / "centre" / "trials.jsonl").read_text().splitlines()) == 4


# ------------------------------------------------- the refined posterior (BOLFI-style)


def _one_identified_space_and_amortized(rng):
    """``a`` identified (amortized samples around 0.2 ± 0.15 in unit coordinates), ``b`` not."""
    space = ParameterSpace([ParameterSpec("a", (0.0, 10.0)), ParameterSpec("b", (1.0, 2.0))])
    samples = np.stack(
        [np.clip(0.2 + 0.15 * rng.normal(size=4000), -1, 1), rng.uniform(-1, 1, 4000)], axis=1
    )
    return space, samples, marginals(samples, space)


def _chaotic_trials(rng, truth: float, n: int, box: tuple[np.ndarray, np.ndarray]):
    """Trials of a chaotic simulator: d = (x_a - truth)² + floor noise, b leaves no mark."""
    x = rng.uniform(box[0], box[1], size=(n, 2))
    noise = lambda size: 0.01 * np.exp(0.3 * rng.normal(size=size))  # noqa: E731
    return x, (x[:, 0] - truth) ** 2 + noise(n), noise(6)


def test_the_search_box_covers_the_identified_parameter_and_all_of_the_others():
    from physinfer.posterior.refined import informed_dims, search_box

    space, samples, m = _one_identified_space_and_amortized(np.random.default_rng(0))
    dims = informed_dims(m, space.names)
    assert dims == [0]
    lo, hi = search_box(samples, dims)
    assert -1 < lo[0] < 0.2 - 3 * 0.15 and 0.2 + 3 * 0.15 < hi[0] < 1
    assert (lo[1], hi[1]) == (-1.0, 1.0)


def test_the_refined_posterior_finds_the_distance_minimum_and_covers_it():
    from physinfer.posterior.refined import refine_posterior, search_box

    rng = np.random.default_rng(1)
    space, samples, m = _one_identified_space_and_amortized(rng)
    box = search_box(samples, [0])
    truth = 0.35  # inside the amortized 90 % interval, off its median
    x, d, floor = _chaotic_trials(rng, truth, 24, box)
    for method in ("box", "product"):
        post, why = refine_posterior(samples, m, space, x, d, floor, box, method=method, seed=0)
        assert why is None and post is not None, why
        lo, hi = np.quantile(post.samples_unit[:, 0], [0.05, 0.95])
        assert lo <= truth <= hi, (method, lo, hi)
        assert np.median(post.samples_unit[:, 0]) == pytest.approx(truth, abs=0.08)
        assert post.modelled == ["a"] and post.ess >= 200
        assert post.marginals["b"]["label"] == "not identified"


def test_no_refined_posterior_without_a_noise_scale_or_enough_trials():
    from physinfer.posterior.refined import refine_posterior, search_box

    rng = np.random.default_rng(2)
    space, samples, m = _one_identified_space_and_amortized(rng)
    box = search_box(samples, [0])
    x, d, floor = _chaotic_trials(rng, 0.3, 24, box)
    cases = {
        "deterministic": (x, d, [0.0, 0.0, 0.0]),
        "not measured": (x, d, []),
        "at least 6": (x[:3], d[:3], floor),
    }
    for words, (xs, ds, fl) in cases.items():
        post, why = refine_posterior(samples, m, space, xs, ds, fl, box)
        assert post is None and words in why, (words, why)
    # A model that does not reproduce the video (its best fit 10x further from the target than
    # from itself): no likelihood at the floor's scale; at or below the limit, as before.
    post, why = refine_posterior(samples, m, space, x, d, floor, box, noise_ratio=10.5)
    assert post is None and "noise ratio 10.5" in why and "diagnose" in why
    assert refine_posterior(samples, m, space, x, d, floor, box, noise_ratio=1.2)[0] is not None


def test_refine_prints_digits_only_for_what_the_video_determines():
    from physinfer.cli.app import refine_result_lines
    from physinfer.refinement import RefineResult

    def marginal(label: str) -> dict:
        return {
            "median": 5.0,
            "ci50": [4.5, 5.5],
            "ci90": [4.0, 6.0],
            "contraction": 0.9,
            "label": label,
            "unit": "",
        }

    result = RefineResult(
        best_params={"wind": 5.2, "weight": 0.17, "bend": 9.9}, best_distance=0.02, best_step=3,
        ground_truth={"wind": 5.0, "weight": 0.12, "bend": 1.0}, abs_errors={"wind": 0.2, "weight": 0.05, "bend": 8.9},
        n_trials=8, n_failed=0, wall_time_s=1.0, timings={}, run_dir="runs/x",
        extra={
            "posterior": {"wind": marginal("identified"), "weight": marginal("not identified"), "bend": marginal("not identified")},
            "at_bounds": {"weight": "upper", "bend": "upper"},
            "posterior_source": {"kind": "refined", "modelled": ["wind"], "estimator": "/a/est.safetensors"},
        },
    )  # fmt: skip
    text = "\n".join(refine_result_lines(result))
    assert "wind = 5.2   posterior 5 [90 %: 4 – 6]   identified   (truth 5, error 0.2)" in text
    assert (
        "not identified (the video barely narrows their ranges" in text and "weight, bend" in text
    )
    assert "error 8.9" not in text and "bound" not in text  # no digits, no bound warning for them
    assert "posterior: refined by this run's trials" in text and "est.safetensors" in text


def test_refine_from_a_model_file_with_a_posterior_reports_it_without_a_search_box(
    pendulum_estimator, tmp_path, physinfer_cli
):
    """``--model`` (a diagnosis with no effect named) warm-starts the search; the posterior is
    still reported, with no search box of its own."""
    from physinfer.discrepancy.model import write_model
    from physinfer.plugins import load_registry

    path, _ = pendulum_estimator
    space = load_registry()[0].phenomenon("pendulum_lab").make_simulator([]).parameter_space
    model = write_model(tmp_path / "model.json", plugin="pendulum_lab", effects=[], space=space,
                        values={"length": 1.2, "damping": 0.1, "amplitude": 40.0})  # fmt: skip
    out = tmp_path / "run"
    result = physinfer_cli(
        "refine", "--plugin", "pendulum_lab", "--model", tmp_path / "model.json", "--posterior", path,
        "--steps", "3", "--noise-samples", "0", "--floor-samples", "0", "--out", out, "--json",
    ).json()  # fmt: skip
    assert set(result["posterior"]) == {"length", "damping", "amplitude"}
    assert "search_box" not in result["posterior_source"]
    first = json.loads((out / "trials.jsonl").read_text().splitlines()[0])["params"]
    assert first == pytest.approx(model.values)


def test_a_nuisance_parameter_is_printed_apart_not_as_not_identified():
    from physinfer.posterior.workflow import summary_lines

    space = ParameterSpace([ParameterSpec("length", (0.1, 3.0), "m"), ParameterSpec("phase", (0.0, 1.0), "cycles")])
    rng = np.random.default_rng(0)
    samples = np.column_stack([rng.normal(0.0, 0.01, 2000), rng.uniform(-1, 1, 2000)])
    summary = marginals(samples, space)
    assert summary["phase"]["label"] == "not identified"
    plain = summary_lines(summary)
    assert any("not identified" in line and "phase" in line for line in plain)
    lines = summary_lines(summary, nuisance=("phase",))
    assert not any("not identified" in line for line in lines)
    assert lines[-1].startswith("  nuisance (what the video leaves open, not a measurement): phase = ")
    assert any(line.startswith("  length = ") for line in lines)
