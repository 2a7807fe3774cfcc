"""The flag's physics stays the same bit for bit: pinned trajectories, batch = single, cache hygiene.

``data/cloth_reference.npz`` holds the first and last frames of two small flags (every
effect switched in; corner pinning) as float32, compared with a tolerance of 0. Compiled
fast-math code may round differently on another CPU architecture or numba version, so the
comparison runs only where the reference was recorded (its ``machine`` and ``numba``
entries); elsewhere it is skipped. A change meant to alter the physics regenerates it
(``python tests/plugins/flag/test_cloth_reproducible.py``) — after
``benchmarks/check_bitwise.py --compare`` has shown what else changed.
"""

from __future__ import annotations

import importlib
import platform
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

from physinfer_flag import cloth_forces, cloth_kernels, cloth_numba, cloth_wind
from physinfer_flag.cloth_numba import FASTMATH, cache_depends_on
from physinfer_flag.effects import WindGusts, WindInclination, WindShear, WindYaw
from physinfer_flag.simulator import make_simulator

REFERENCE = Path(__file__).parent / "data" / "cloth_reference.npz"
SMALL = {"grid_u": 16, "grid_v": 11, "n_frames": 10, "warmup_s": 1.0}
ALL_EFFECTS = {"gust_intensity": 0.3, "gust_timescale": 1.0, "shear_exponent": 0.2, "wind_yaw_deg": 15.0,
               "wind_inclination_deg": -8.0}


def reference_runs() -> dict[str, np.ndarray]:
    """First and last frames ``(2, V, 3)`` float32 of the pinned flags."""
    effects = make_simulator([WindGusts(), WindShear(), WindYaw(), WindInclination()], **SMALL)
    corners = make_simulator(pin_mode="corners", **SMALL)
    runs = {
        "all_effects": effects.simulate({"wind_speed": 6.0, "area_weight": 0.14, **ALL_EFFECTS}, seed=3),
        "corners": corners.simulate({"wind_speed": 7.0, "bend_45deg_c10": 2.0}, seed=1),
    }
    return {name: traj.vertices[[0, -1]] for name, traj in runs.items()}


def test_trajectories_equal_the_pinned_reference():
    reference = np.load(REFERENCE)
    recorded_on = (str(reference["machine"]), str(reference["numba"]))
    if recorded_on != (platform.machine(), numba.__version__):
        pytest.skip(f"reference recorded on {recorded_on}; fast-math rounding may differ here")
    for name, frames in reference_runs().items():
        diff = np.abs(frames.astype(np.float64) - reference[name]).max()
        assert diff == 0.0, f"{name}: the physics changed (largest difference {diff:.3g} m)"


def test_batch_equals_single_runs_with_effects_and_corner_pinning():
    sim = make_simulator([WindGusts(), WindShear()], pin_mode="corners", **SMALL)
    params = [{"wind_speed": 5.0, "gust_intensity": 0.3, "gust_timescale": 1.0},
              {"wind_speed": 8.0, "gust_intensity": 0.1, "gust_timescale": 0.5, "shear_exponent": 0.3}]
    batch = sim.simulate_batch(params, seeds=[2, 9])
    for traj, p, seed in zip(batch, params, [2, 9], strict=True):
        np.testing.assert_array_equal(traj.vertices, sim.simulate(p, seed=seed).vertices)


def test_batch_equals_single_runs_when_effects_are_off_for_some_flags():
    sim = make_simulator([WindGusts()], **SMALL)
    params = [{"wind_speed": 5.0, "gust_intensity": 0.3}, {"wind_speed": 7.0}]
    batch = sim.simulate_batch(params, seeds=[3, 3])
    for traj, p in zip(batch, params, strict=True):
        np.testing.assert_array_equal(traj.vertices, sim.simulate(p, seed=3).vertices)


def kernels() -> dict[str, CPUDispatcher]:
    """Every compiled function of the cloth solver's modules, by qualified name."""
    found = {}
    for module in (cloth_wind, cloth_forces, cloth_kernels):
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == module.__name__:
                found[f"{module.__name__}.{name}"] = value
    return found


def test_every_kernel_states_the_shared_fastmath_flags():
    # A helper without its own flags is compiled with its caller's when called, but with none
    # when a test calls it alone, and numba's cache does not tell the two apart.
    found = kernels()
    assert {"physinfer_flag.cloth_wind.wind_at_time", "physinfer_flag.cloth_kernels.run_flag"} <= set(found)
    for name, dispatcher in found.items():
        if name.endswith("run_flag_batch"):  # the threaded loop only calls run_flag
            continue
        assert dispatcher.targetoptions.get("fastmath") == FASTMATH, name


def test_kernel_caches_depend_on_the_files_they_call_into():
    stamp = cloth_kernels.run_flag._cache._cache_file._source_stamp
    assert isinstance(stamp, tuple) and len(stamp) == 2
    files = {cloth_numba._stamp(Path(m.__file__)) for m in (cloth_numba, cloth_forces, cloth_wind)}
    assert files == set(stamp[1])


def test_cache_depends_on_makes_a_cache_stale_when_a_dependency_changes(tmp_path, monkeypatch):
    (tmp_path / "bitwise_kernel.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef plus_one(x):\n    return x + 1\n"
    )
    dependency = tmp_path / "bitwise_dependency.py"
    dependency.write_text("A = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))

    def fresh_kernel():  # a new dispatcher, as a new process would build it
        for name in ("bitwise_kernel", "bitwise_dependency"):
            sys.modules.pop(name, None)
        kernel = importlib.import_module("bitwise_kernel").plus_one
        cache_depends_on([kernel], importlib.import_module("bitwise_dependency"))
        return kernel

    assert fresh_kernel()(1) == 2  # compiles and saves the index
    assert fresh_kernel()._cache._cache_file._load_index(), "unchanged files: the cache is used"
    dependency.write_text("A = 22\n")
    assert fresh_kernel()._cache._cache_file._load_index() == {}, "a changed dependency: stale"


if __name__ == "__main__":  # regenerate the reference (see the module docstring)
    REFERENCE.parent.mkdir(exist_ok=True)
    np.savez(REFERENCE, machine=platform.machine(), numba=numba.__version__, **reference_runs())
    print(f"wrote {REFERENCE}")
