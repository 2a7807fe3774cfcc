"""Tests of physinfer.datasets: presets, planning, generation, resume, executors, loader, CLI.

A tiny phenomenon defined here (a numpy "wave" sheet and a numpy point rasteriser) keeps
every test fast; the engine itself runs unmocked, on the in-process executor, on spawned
local processes and on a real Dask ``LocalCluster``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pickle
import socket
import types
from pathlib import Path

import numpy as np
import pytest

from physinfer import (
    Clip,
    ParameterSpace,
    ParameterSpec,
    Phenomenon,
    Renderer,
    Simulator,
    Target,
    Trajectory,
)
from physinfer.datasets import (
    CPU_PRESET,
    PAPER_PRESET,
    SPLITS,
    ClipDataset,
    ClipFormat,
    DatasetPreset,
    PhenomenonDatasetGenerator,
    SplitCounts,
    generate_dataset,
    generator_for,
    parse_split_counts,
    plan_dataset,
)
from physinfer.datasets.storage import file_digest, npz_digest
from physinfer.datasets.worker import to_stored
from physinfer.errors import SimulationFailed, UserInputError
from physinfer.hooks import hookimpl
from physinfer.locking import DirectoryLock

# ----------------------------------------------------------------- a tiny phenomenon

SPACE = ParameterSpace(
    [
        ParameterSpec("frequency", (0.5, 3.0), "Hz"),
        ParameterSpec("amplitude", (0.05, 0.5), "m", scaling="log"),
    ]
)
FAIL_ABOVE_HZ = 2.0  # the "fragile" simulator fails above this frequency


class WaveSimulator(Simulator):
    """A 6×5 sheet whose height travels as a sine wave; the seed sets the phase."""

    parameter_space = SPACE

    def __init__(self, fragile: bool = False, n_frames: int = 16) -> None:
        self.fragile = fragile
        self.n_frames = n_frames

    def simulate(self, params, *, seed=0):
        if self.fragile and params["frequency"] > FAIL_ABOVE_HZ:
            raise SimulationFailed("too fast")
        phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
        x, y = np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 5))
        t = np.arange(self.n_frames)[:, None] / 25.0
        z = params["amplitude"] * np.sin(2 * np.pi * params["frequency"] * t + 3 * x.ravel() + phase)
        verts = np.stack([np.broadcast_to(x.ravel(), z.shape), np.broadcast_to(y.ravel(), z.shape), z], -1)
        faces = np.array([[0, 1, 6], [1, 7, 6]], dtype=np.int32)
        return Trajectory(verts.astype(np.float32), faces, 25.0)


class DotRenderer(Renderer):
    """Rasterises vertices as bright dots on a 40×48 RGB canvas; ζ: brightness and shift."""

    default_render_params = {"brightness": 200, "shift": 0.0}

    def sample_render_params(self, rng):
        return {"brightness": int(rng.integers(80, 256)), "shift": float(rng.uniform(-0.1, 0.1))}

    def render(self, trajectory, render_params=None):
        zeta = {**self.default_render_params, **(render_params or {})}
        frames = np.zeros((trajectory.n_frames, 40, 48, 3), dtype=np.uint8)
        v = trajectory.vertices
        cols = np.clip(((v[..., 0] + zeta["shift"]) * 40 + 4).astype(int), 0, 47)
        rows = np.clip(((v[..., 1] + v[..., 2]) * 25 + 8).astype(int), 0, 39)
        t = np.repeat(np.arange(trajectory.n_frames), v.shape[1])
        frames[t, rows.ravel(), cols.ravel()] = [zeta["brightness"], zeta["brightness"] // 2, 30]
        return Clip(frames, trajectory.fps)


def _target() -> Target:
    return Target(clip=DotRenderer().render(WaveSimulator().simulate({"frequency": 1.0, "amplitude": 0.2})))


def make_wave(fragile: bool = False) -> Phenomenon:
    return Phenomenon(
        name="wave",
        description="a numpy sine sheet (tests)",
        parameter_space=SPACE,
        make_simulator=lambda effects: WaveSimulator(fragile=fragile),
        make_renderer=DotRenderer,
        default_embedder="grid_spectrum",
        default_target=_target,
    )


TINY = DatasetPreset(
    name="tiny",
    sims=SplitCounts(5, 2, 2),
    renders=SplitCounts(10, 5, 4),  # val: 3 + 2 renders, uneven on purpose
    clip=ClipFormat(n_frames=12, fps=25.0, height=24, width=24, channels=1),
    sims_per_unit=2,
)


def snapshot(root: Path) -> dict[str, str]:
    """Everything deterministic in a dataset: manifest bytes, shard and trajectory digests."""
    out = {"manifest": (root / "manifest.jsonl").read_text()}
    out.update({p.name: file_digest(p) for p in sorted((root / "shards").glob("*.npy"))})
    out.update({p.name: npz_digest(p) for p in sorted((root / "trajectories").glob("*.npz"))})
    return out


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """The tiny dataset generated in this process, uninterrupted."""
    root = tmp_path_factory.mktemp("ref") / "data"
    generate_dataset(PhenomenonDatasetGenerator(phenomenon=make_wave()), root, preset=TINY, seed=7, workers=0)
    return root


# ---------------------------------------------------------------------------- presets


def test_paper_preset_matches_flagsim():
    assert PAPER_PRESET.sims.to_dict() == {"train": 1000, "val": 150, "test": 85}
    assert PAPER_PRESET.renders.to_dict() == {"train": 14000, "val": 3800, "test": 3500}
    assert (PAPER_PRESET.clip.n_frames, PAPER_PRESET.clip.fps, PAPER_PRESET.clip.shape[1:]) == (60, 25.0, (300, 300))
    for preset in (PAPER_PRESET, CPU_PRESET):
        for split in SPLITS:
            per_sim = [preset.renders_of(split, i) for i in range(preset.sims[split])]
            assert sum(per_sim) == preset.renders[split]
            assert max(per_sim) - min(per_sim) <= 1


def test_overrides_split_a_total_like_the_preset():
    p = PAPER_PRESET.with_overrides(sims=100)
    assert p.sims.total == 100 and min(p.sims.to_dict().values()) >= 1
    assert p.sims.train > p.sims.val > p.sims.test
    q = CPU_PRESET.with_overrides(sims=SplitCounts(3, 1, 0), renders_per_sim=2, n_frames=30, size=(64, 80))
    assert q.renders.to_dict() == {"train": 6, "val": 2, "test": 0}
    assert q.clip.shape == (30, 64, 80) and q.name == "cpu+custom"
    assert parse_split_counts("7", "--sims") == 7
    assert parse_split_counts("4,2,1", "--sims") == SplitCounts(4, 2, 1)
    for bad in ("x", "1,2", "-1"):
        with pytest.raises(UserInputError):
            parse_split_counts(bad, "--sims")
    with pytest.raises(UserInputError):
        CPU_PRESET.with_overrides(renders_per_sim=0)


def test_plan_is_keyed_by_split_and_index():
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    base = plan_dataset(gen, TINY, seed=7)
    more_test = plan_dataset(gen, TINY.with_overrides(sims=SplitCounts(5, 2, 4)), seed=7)
    sims = [s for u in base for s in u.sims]
    assert [s.sim for s in sims] == list(range(9))
    assert [len(u.sims) for u in base] == [2, 2, 1, 2, 2]  # units never cross splits
    # Growing the test split leaves train and val simulations unchanged.
    grown = {(s.split, s.local): s for u in more_test for s in u.sims}
    assert all(grown[(s.split, s.local)].params == s.params for s in sims)
    assert plan_dataset(gen, TINY, seed=8)[0].sims[0].params != sims[0].params


# ------------------------------------------------------------------------- generation


def test_splits_bounds_and_loader(reference):
    rows = [json.loads(line) for line in (reference / "manifest.jsonl").read_text().splitlines()]
    assert [r["render"] for r in rows] == list(range(19))
    for split in SPLITS:
        split_rows = [r for r in rows if r["split"] == split]
        assert len({r["sim"] for r in split_rows}) == TINY.sims[split]
        assert len(split_rows) == TINY.renders[split]
    train_sims = {r["sim"] for r in rows if r["split"] == "train"}
    assert train_sims.isdisjoint({r["sim"] for r in rows if r["split"] != "train"})
    for r in rows:
        for spec in SPACE:
            assert spec.bounds[0] <= r["params"][spec.name] <= spec.bounds[1]
        assert r["checksum"].startswith("sha256:") and set(r["render_params"]) == {"brightness", "shift"}

    ds = ClipDataset(reference, "val")
    assert len(ds) == 5 and ds.params.shape == (5, 2) and ds.param_names == ["frequency", "amplitude"]
    assert np.all(np.abs(ds.params_unit) <= 1.0)
    clip = ds[0]
    assert clip.shape == (12, 24, 24) and clip.dtype == np.uint8 and isinstance(clip, np.memmap)
    assert clip.max() > 0  # the dots are there
    batch = ds.clips([0, 4])
    assert batch.shape == (2, 12, 24, 24) and np.array_equal(batch[1], ds[4])
    assert [len(ds.indices_of(s)) for s in ds.simulations()] == [3, 2]
    traj = ds.trajectory(int(ds.sim_ids[0]))
    assert traj.vertices.shape == (16, 30, 3)
    assert len(ClipDataset(reference, None)) == 19
    assert np.array_equal(pickle.loads(pickle.dumps(ds))[4], ds[4])  # DataLoader workers reopen maps
    with pytest.raises(UserInputError, match="unknown split"):
        ClipDataset(reference, "training")


def test_renders_differ_between_and_within_simulations(reference):
    ds = ClipDataset(reference, "train")
    a, b = ds.indices_of(int(ds.simulations()[0]))
    assert not np.array_equal(ds[a], ds[b])  # another ζ
    assert ds.render_params[a] != ds.render_params[b]
    assert not np.array_equal(ds.params[0], ds.params[-1])


def test_local_processes_and_dask_give_the_same_dataset(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    pool = generate_dataset(gen, tmp_path / "pool", preset=TINY, seed=7, workers=2)
    assert pool.executor.kind == "processes" and pool.units_generated == 5
    with distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None
    ) as cluster:
        dask = generate_dataset(gen, tmp_path / "dask", preset=TINY, seed=7, scheduler=cluster.scheduler_address)
    assert dask.executor.kind == "dask" and dask.executor.workers == 2
    records = [json.loads(p.read_text()) for p in (tmp_path / "dask" / "units").glob("*.json")]
    workers_used = {r["timing"]["worker"] for r in records}
    assert len(records) == 5 and 1 <= len(workers_used) <= 2
    assert f"{socket.gethostname()}:{os.getpid()}" not in workers_used
    assert snapshot(tmp_path / "pool") == snapshot(reference)
    assert snapshot(tmp_path / "dask") == snapshot(reference)


class StopAfter:
    """A progress receiver that interrupts generation after ``n`` units, like Ctrl-C."""

    def __init__(self, n: int) -> None:
        self.n, self.units = n, 0

    def start(self, phase, total, done=0):
        pass

    def advance(self, n):
        self.units += 1
        if self.units >= self.n:
            raise KeyboardInterrupt


def test_resume_after_interruption_matches_uninterrupted_run(reference, tmp_path):
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    root = tmp_path / "data"
    with pytest.raises(KeyboardInterrupt):
        generate_dataset(gen, root, preset=TINY, seed=7, workers=0, progress=StopAfter(2))
    assert len(list((root / "units").glob("*.json"))) == 2 and not (root / "manifest.jsonl").exists()
    with pytest.raises(UserInputError, match="incomplete"):
        ClipDataset(root, "train")
    # A hard kill also leaves a temporary file and files of a unit without its record.
    (root / "shards" / ".unit-00004.npy.abc123.npy").write_bytes(b"partial")
    (root / "shards" / "unit-00004.npy").write_bytes(b"stale")
    result = generate_dataset(gen, root, preset=TINY, seed=7, workers=0)
    assert (result.units_skipped, result.units_generated, result.units_regenerated) == (2, 3, 0)
    assert not list((root / "shards").glob(".*"))
    assert snapshot(root) == snapshot(reference)
    again = generate_dataset(gen, root, preset=TINY, seed=7, workers=0)
    assert (again.units_generated, again.renders_generated, sum(again.renders.values())) == (0, 0, 19)
    assert again.executor.kind == "none"


def test_corrupted_and_truncated_shards_are_regenerated(reference, tmp_path):
    import shutil

    root = tmp_path / "data"
    shutil.copytree(reference, root)
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    flipped = root / "shards" / "unit-00001.npy"
    data = bytearray(flipped.read_bytes())
    data[-5] ^= 0xFF  # same size, different content: only the checksum notices
    flipped.write_bytes(bytes(data))
    truncated = root / "shards" / "unit-00003.npy"
    truncated.write_bytes(truncated.read_bytes()[:-100])
    (root / "trajectories" / "sim-000008.npz").unlink()
    (root / "units" / "unit-00000.json").write_text('{"unit": 0, "sims": [0, 1], "shard"')

    quick = generate_dataset(gen, root, preset=TINY, seed=7, workers=0, verify=False)
    # Truncation, a lost file and a torn record are found without reading the data.
    assert (quick.units_regenerated, quick.units_generated) == (3, 3)
    full = generate_dataset(gen, root, preset=TINY, seed=7, workers=0)
    assert (full.units_regenerated, full.units_generated) == (1, 1)  # the flipped byte, by checksum
    assert snapshot(root) == snapshot(reference)


def test_failed_simulations_are_skipped_and_reported(tmp_path):
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave(fragile=True))
    preset = TINY.with_overrides(sims=SplitCounts(12, 0, 0), renders_per_sim=1)
    result = generate_dataset(gen, tmp_path / "d", preset=preset, seed=3, workers=0)
    planned = [s for u in plan_dataset(gen, preset, 3) for s in u.sims]
    too_fast = {s.sim for s in planned if s.params["frequency"] > FAIL_ABOVE_HZ}
    assert too_fast, "the seed should draw some failing simulations"
    assert {f["sim"] for f in result.failed_sims} == too_fast
    ds = ClipDataset(tmp_path / "d", "train")
    assert set(ds.sim_ids.tolist()) == {s.sim for s in planned} - too_fast


def test_directory_guards(reference, tmp_path):
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    with pytest.raises(UserInputError, match="different dataset.*seed"):
        generate_dataset(gen, reference, preset=TINY, seed=8, workers=0)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(UserInputError, match="not empty"):
        generate_dataset(gen, tmp_path / "other", preset=TINY, seed=7, workers=0)
    lock = DirectoryLock(tmp_path / "busy")
    assert lock.acquire()
    try:
        with pytest.raises(UserInputError, match=f"physinfer process {os.getpid()}"):
            generate_dataset(gen, tmp_path / "busy", preset=TINY, seed=7, workers=0)
    finally:
        lock.release()


def make_lasting_wave() -> Phenomenon:
    """The wave whose simulator factory accepts ``duration_s`` (records as long as asked)."""

    def make_simulator(effects, *, duration_s=None):
        return WaveSimulator(n_frames=16 if duration_s is None else int(np.ceil(duration_s * 25.0 - 1e-9)))

    return dataclasses.replace(make_wave(), make_simulator=make_simulator)


def test_longer_clips_than_the_default_simulation_when_the_phenomenon_allows(reference, tmp_path):
    long = dataclasses.replace(TINY, clip=dataclasses.replace(TINY.clip, n_frames=40))
    generate_dataset(PhenomenonDatasetGenerator(phenomenon=make_lasting_wave()), tmp_path / "long",
                     preset=long, seed=7, workers=0)
    for split in ("train", "test"):
        longer, short = ClipDataset(tmp_path / "long", split), ClipDataset(reference, split)
        assert longer[0].shape[0] == 40
        # The same seeds: a longer recording starts with the shorter one's frames.
        np.testing.assert_array_equal(longer[0][:12], short[0])
    # A phenomenon that cannot record longer says so instead of storing short clips.
    with pytest.raises(Exception, match="make the phenomenon simulate longer"):
        generate_dataset(PhenomenonDatasetGenerator(phenomenon=make_wave()), tmp_path / "short",
                         preset=long, seed=7, workers=0)


# -------------------------------------------------------------------- pieces


def test_to_stored_resamples_crops_and_converts_colour():
    frames = np.zeros((30, 20, 40, 3), dtype=np.uint8)
    frames[:, :, :, 0] = np.arange(30, dtype=np.uint8)[:, None, None] * 8  # red ramps over time
    clip = Clip(frames, 50.0)
    gray = to_stored(clip, ClipFormat(n_frames=10, fps=25.0, height=10, width=10, channels=1))
    assert gray.shape == (10, 10, 10) and gray.dtype == np.uint8
    # 50 → 25 fps keeps every other frame; luma of pure red is 0.299·R.
    assert gray[3, 5, 5] == round(0.299 * 6 * 8)
    rgb = to_stored(clip, ClipFormat(n_frames=5, fps=50.0, height=20, width=20, channels=3))
    assert rgb.shape == (5, 20, 20, 3) and rgb[4, 0, 0, 0] == 32
    with pytest.raises(Exception, match="choose fewer frames"):
        to_stored(clip, ClipFormat(n_frames=20, fps=25.0, height=10, width=10, channels=1))


class TwoPresetGenerator(PhenomenonDatasetGenerator):
    def presets(self):
        return {"tiny": TINY}


def test_generator_for_resolves_the_phenomenon_field():
    assert type(generator_for(make_wave())) is PhenomenonDatasetGenerator
    ref = f"{__name__}:TwoPresetGenerator"
    wave = make_wave()
    custom = generator_for(Phenomenon(**{**wave.__dict__, "dataset_generator": ref}))
    assert isinstance(custom, TwoPresetGenerator) and list(custom.presets()) == ["tiny"]
    with pytest.raises(UserInputError, match="cannot load"):
        generator_for(Phenomenon(**{**wave.__dict__, "dataset_generator": "no_such_module:X"}))
    with pytest.raises(UserInputError, match="not a physinfer.datasets.DatasetGenerator"):
        generator_for(Phenomenon(**{**wave.__dict__, "dataset_generator": f"{__name__}:SPACE"}))


# ------------------------------------------------------------------------------- CLI


@hookimpl
def _register_wave(registry):
    registry.add_phenomenon("wave", make_wave, "numpy sine sheet")


@pytest.fixture
def wave_registry(monkeypatch):
    import physinfer.plugins
    from physinfer.cli import common  # imported before the patch, so that it binds the real one

    real = physinfer.plugins.load_registry
    plugin = types.SimpleNamespace(physinfer_register_phenomena=_register_wave)
    monkeypatch.setattr(
        physinfer.plugins,
        "load_registry",
        lambda: real(extra_plugins={"wave_plugin": plugin}, load_entry_points=False),
    )
    yield
    # The CLI's registry, built once per process, must not be the wave-only one: a test run in
    # this process after this one would find no `dataset` command (seen when this file ran alone).
    common.registry_and_infos.cache_clear()


def test_cli_generate_prints_one_json_object(wave_registry, tmp_path):
    from typer.testing import CliRunner

    from physinfer.cli.dataset_cmd import dataset_app

    runner = CliRunner()
    args = ["generate", "--plugin", "wave", "--out", str(tmp_path / "d"), "--sims", "3,1,1"]
    args += ["--renders-per-sim", "2", "--frames", "8", "--size", "16x20", "--workers", "0", "--json"]
    result = runner.invoke(dataset_app, args)
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["renders"] == {"train": 6, "val": 2, "test": 2} and summary["renders_per_minute"] > 0
    assert summary["clip"]["n_frames"] == 8 and ClipDataset(tmp_path / "d", "test")[0].shape == (8, 16, 20, 3)

    again = runner.invoke(dataset_app, args)
    assert json.loads(again.stdout)["units"]["skipped"] == summary["units"]["total"]

    bad = runner.invoke(dataset_app, ["generate", "--plugin", "nope", "--out", str(tmp_path / "x"), "--json"])
    assert bad.exit_code == 2
    assert "installed: wave" in json.loads(bad.stdout)["error"]
    bad_preset = runner.invoke(dataset_app, ["generate", "-p", "wave", "--out", str(tmp_path / "y"), "--preset", "big"])
    assert bad_preset.exit_code == 2 and "choose one of cpu, paper" in bad_preset.output


# -------------------------------------------------------------- seeds per θ (issue 5)


def _sims(units) -> list:
    return [s for u in units for s in u.sims]


def test_one_seed_per_theta_keeps_the_plan_and_the_stored_identity():
    from physinfer.datasets.plan import SIM_STREAM, THETA_STREAM, seed_sequence
    from physinfer.datasets.resume import dataset_config

    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    assert TINY.seeds_per_theta == 1
    for sim in _sims(plan_dataset(gen, TINY, seed=7)):
        # The rule as it was before the option existed: θ and seed from the simulation's own key.
        theta_rng = np.random.default_rng(seed_sequence(7, sim.split, sim.local, THETA_STREAM))
        assert sim.params == gen.sample_params(theta_rng)
        assert sim.seed == int(seed_sequence(7, sim.split, sim.local, SIM_STREAM).generate_state(1)[0] & 0x7FFFFFFF)
    same = TINY.with_overrides(seeds_per_theta=1)
    assert same == TINY and same.name == "tiny"
    # Datasets made before the option existed store no such key, and must still resume.
    assert "seeds_per_theta" not in TINY.to_dict()
    assert "seeds_per_theta" not in json.dumps(dataset_config(gen, TINY, 7))


def test_consecutive_simulations_share_theta_and_keep_their_own_seed():
    gen = PhenomenonDatasetGenerator(phenomenon=make_wave())
    one = {(s.split, s.local): s for s in _sims(plan_dataset(gen, TINY, seed=7))}
    for n in (2, 3):
        preset = TINY.with_overrides(seeds_per_theta=n)
        assert preset.name == "tiny+custom" and preset.to_dict()["seeds_per_theta"] == n
        assert DatasetPreset.from_dict(preset.to_dict()) == preset
        shared = _sims(plan_dataset(gen, preset, seed=7))
        assert [s.sim for s in shared] == list(range(TINY.sims.total))
        for s in shared:
            assert s.params == one[(s.split, s.local // n)].params  # θ of the group's key
            assert s.seed == one[(s.split, s.local)].seed  # the simulation's own seed
        for split in SPLITS:
            in_split = [s for s in shared if s.split == split]
            groups: dict[int, list] = {}
            for s in in_split:
                groups.setdefault(s.local // n, []).append(s)
            # The last group of a split is short when n does not divide its count.
            assert [len(g) for g in groups.values()] == [
                min(n, len(in_split) - n * k) for k in range(len(groups))
            ]
            for g in groups.values():
                assert len({s.seed for s in g}) == len(g)
                assert all(s.params == g[0].params for s in g)
            thetas = [tuple(g[0].params.values()) for g in groups.values()]
            assert len(set(thetas)) == len(thetas)


def test_seeds_per_theta_is_validated():
    for bad in (0, -2):
        with pytest.raises(UserInputError, match="--seeds-per-theta must be a whole number of at least 1"):
            TINY.with_overrides(seeds_per_theta=bad)
        with pytest.raises(ValueError, match="seeds_per_theta must be at least 1"):
            DatasetPreset(name="x", sims=SplitCounts(2, 0, 0), renders=SplitCounts(2, 0, 0), seeds_per_theta=bad)


def test_cli_seeds_per_theta_gives_theta_groups_of_seeds_times_renders(wave_registry, tmp_path):
    from typer.testing import CliRunner

    from physinfer.cli.dataset_cmd import dataset_app

    runner = CliRunner()
    root = tmp_path / "d"
    args = ["generate", "--plugin", "wave", "--out", str(root), "--sims", "6,2,2"]
    args += ["--renders-per-sim", "2", "--frames", "8", "--size", "16", "--workers", "0", "--json"]
    result = runner.invoke(dataset_app, [*args, "--seeds-per-theta", "2"])
    assert result.exit_code == 0, result.output
    assert json.loads((root / "dataset.json").read_text())["config"]["preset"]["seeds_per_theta"] == 2

    for split in SPLITS:
        ds = ClipDataset(root, split)
        # The grouping `physinfer train --positives parameters` uses: clips with identical θ.
        _, theta_groups, theta_sizes = np.unique(ds.params, axis=0, return_inverse=True, return_counts=True)
        _, sim_sizes = np.unique(ds.sim_ids, return_counts=True)
        assert set(theta_sizes) == {2 * 2} and set(sim_sizes) == {2}
        for group in range(len(theta_sizes)):
            sims = np.unique(ds.sim_ids[theta_groups.reshape(-1) == group])
            trajectories = [ds.trajectory(int(s)).vertices for s in sims]
            assert len(sims) == 2 and not np.array_equal(*trajectories)  # two seeds, two realisations

    # The option is part of the dataset's identity: resuming with another value is refused.
    other = runner.invoke(dataset_app, [*args, "--seeds-per-theta", "3"])
    assert other.exit_code == 2 and "seeds_per_theta: 2 there, 3 now" in json.loads(other.stdout)["error"]
    plain = runner.invoke(dataset_app, args)
    assert plain.exit_code == 2 and "seeds_per_theta" in json.loads(plain.stdout)["error"]
    bad = runner.invoke(dataset_app, [*args[:4], str(tmp_path / "e"), "--seeds-per-theta", "0", "--json"])
    assert bad.exit_code == 2 and "--seeds-per-theta must be a whole number" in json.loads(bad.stdout)["error"]


def test_a_damaged_or_cut_manifest_is_refused_and_generate_rewrites_it(tmp_path, physinfer_cli):
    from physinfer.datasets.loader import ClipDataset
    from physinfer.errors import UserInputError

    args = ["dataset", "generate", "--plugin", "pendulum_lab", "--sims", "4,0,2", "--frames", "20", "--size", "32",
            "--workers", "0", "--out", tmp_path / "d", "--json"]  # fmt: skip
    assert physinfer_cli(*args).returncode == 0
    manifest = tmp_path / "d" / "manifest.jsonl"
    good = manifest.read_text()
    n = len(ClipDataset(tmp_path / "d", "train"))
    manifest.write_text(good[: len(good) // 2])  # cut mid-line
    with pytest.raises(UserInputError, match=r"line \d+ is not a manifest row"):
        ClipDataset(tmp_path / "d", "train")
    manifest.write_text("".join(good.splitlines(keepends=True)[:3]))  # cut at a line boundary
    with pytest.raises(UserInputError, match=f"train 3 of {n}"):
        ClipDataset(tmp_path / "d", "train")
    assert physinfer_cli(*args).returncode == 0  # generate again: the manifest is rewritten
    assert manifest.read_text() == good


def test_a_binary_model_file_is_one_clear_line(tmp_path, physinfer_cli):
    model = tmp_path / "model.json"
    model.write_bytes(bytes(range(256)) * 4)
    proc = physinfer_cli("refine", "--plugin", "pendulum_lab", "--model", model, "--out", tmp_path / "r", "--json")
    assert proc.returncode == 2 and "is not JSON" in proc.json()["error"]

