"""Speed of the flag cloth simulator, single and batched, against NVIDIA Warp's cloth on CPU.

Measures, at the default resolution and time step of :class:`FlagSimConfig`:

* ``compile_s_cold``: first call in a fresh process with an empty numba cache (compiling
  every kernel), and ``first_call_s_cached``: first call in a fresh process that finds
  the cache (what a user sees every time after the first);
* ``clip_s_single``: one 60-frame clip including the 2 s warm-up (median of ``--repeats``),
  and ``ms_per_sim_s_single`` = wall milliseconds per simulated second;
* ``ms_per_sim_s_batched``: ``--batch`` flags through ``simulate_batch`` (numba threads,
  ``threads`` of them), wall milliseconds per simulated second per flag; the same with one
  thread as ``ms_per_sim_s_batched_1thread``;
* ``warp_ms_per_sim_s``: Warp's cloth (``warp.sim``, warp-lang 1.9.1, the last release
  with it, optional benchmark-only dependency) on CPU with ``--batch`` flags of the same
  grid in one model, stepped with its semi-implicit (symplectic Euler) integrator at the
  same time step: FEM triangles with aerodynamic drag/lift, dihedral bending, gravity, a
  pinned hoist edge. ``warp_ms_per_sim_s_single`` is one flag. Warp runs its CPU kernels
  on one thread. If Warp cannot be imported or run, the Warp fields are null and
  ``warp_error`` says why.
* ``ratio_vs_warp`` = ``ms_per_sim_s_batched`` / ``warp_ms_per_sim_s`` (per flag, batched).

Usage::

    python benchmarks/bench_cloth.py --batch 64 --repeats 5

Prints exactly one JSON object on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

FIRST_CALL = (
    "import time; t = time.perf_counter(); "
    "from physinfer_flag.simulator import make_simulator; "
    "make_simulator().simulate({'wind_speed': 5.0}); print(time.perf_counter() - t)"
)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=64, help="flags per batch (default: 64)")
    parser.add_argument("--repeats", type=int, default=5, help="single-clip repeats (default: 5)")
    parser.add_argument("--warp-seconds", type=float, default=0.5,
                        help="simulated seconds per Warp measurement (default: 0.5)")
    parser.add_argument("--skip-warp", action="store_true", help="do not try Warp")
    parser.add_argument("--skip-compile", action="store_true", help="do not time cold/cached first calls")
    return parser.parse_args(argv)


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def machine() -> str:
    """CPU model and count, for the record."""
    model = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as fh:
            model = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{platform.machine()}, {os.cpu_count()} CPUs, {model}"


def first_call_seconds(cache_dir: str | None) -> float:
    """First-call latency in a fresh interpreter (``cache_dir``: a private numba cache)."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, check=True, capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def measure_ours(batch: int, repeats: int) -> dict[str, Any]:
    """Single-clip and batched timings of physinfer_flag's solver."""
    import numba

    from physinfer_flag.simulator import make_simulator

    sim = make_simulator()
    sim.simulate({"wind_speed": 5.0})  # compile or load the cache
    rng = np.random.default_rng(0)
    space = sim.parameter_space
    params = [space.from_unit(u) for u in rng.uniform(-1, 1, (max(batch, repeats), len(space)))]
    times = []
    for k in range(repeats):
        start = time.perf_counter()
        sim.simulate(params[k], seed=k)
        times.append(time.perf_counter() - start)
    clip_s = statistics.median(times)
    sim_seconds = sim.config.duration
    log(f"single clip: median {clip_s:.3f} s over {repeats} ({sim_seconds:.1f} simulated s)")

    threads = numba.get_num_threads()
    start = time.perf_counter()
    sim.simulate_batch(params[:batch], seeds=list(range(batch)))
    batched = time.perf_counter() - start
    log(f"batch of {batch} with {threads} threads: {batched:.2f} s")
    numba.set_num_threads(1)
    try:
        start = time.perf_counter()
        sim.simulate_batch(params[:batch], seeds=list(range(batch)))
        batched_1 = time.perf_counter() - start
    finally:
        numba.set_num_threads(threads)
    log(f"batch of {batch} with 1 thread: {batched_1:.2f} s")
    return {
        "grid": [sim.config.grid_u, sim.config.grid_v],
        "flag_size_m": [sim.config.width, sim.config.height],
        "nodes": sim.mesh.n_vertices,
        "triangles": int(sim.mesh.faces.shape[0]),
        "hinges": int(sim.mesh.hinges.shape[0]),
        "dt_s": sim.config.dt,
        "substeps_per_frame": sim.config.steps_per_frame,
        "simulated_s_per_clip": sim_seconds,
        "clip_s_single": round(clip_s, 4),
        "clip_s_single_all": [round(t, 4) for t in times],
        "ms_per_sim_s_single": round(1000 * clip_s / sim_seconds, 2),
        "batch": batch,
        "threads": threads,
        "ms_per_sim_s_batched": round(1000 * batched / (batch * sim_seconds), 2),
        "ms_per_sim_s_batched_1thread": round(1000 * batched_1 / (batch * sim_seconds), 2),
    }


def build_warp_model(wp: Any, sim_module: Any, n_flags: int, nu: int, nv: int, cell: float, area_weight: float):
    """``n_flags`` copies of the flag grid, hoist edge fixed, side by side in one Warp model."""
    builder = sim_module.ModelBuilder(up_vector=(0.0, 0.0, 1.0), gravity=-9.81)
    mass = area_weight * cell * cell
    for k in range(n_flags):
        builder.add_cloth_grid(
            pos=wp.vec3(0.0, 3.0 * k, 1.95), rot=wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), 0.5 * np.pi),
            vel=wp.vec3(0.0, 0.0, 0.0), dim_x=nu - 1, dim_y=nv - 1, cell_x=cell, cell_y=cell, mass=mass,
            fix_left=True, tri_ke=100.0, tri_ka=100.0, tri_kd=0.01, tri_drag=0.1, tri_lift=0.1,
            edge_ke=1e-3, edge_kd=0.0, particle_radius=0.0,
        )
    model = builder.finalize(device="cpu")
    model.ground = False
    return model


def measure_warp(config: Any, batch: int, seconds: float) -> dict[str, Any]:
    """Warp's cloth on CPU at the same grid and time step; raises if Warp is unavailable."""
    import warp as wp

    wp.config.quiet = True
    wp.init()
    import warp.sim as wsim

    cell = config.width / (config.grid_u - 1)
    steps = int(round(seconds / config.dt))
    out: dict[str, Any] = {"warp_version": wp.config.version, "warp_device": "cpu", "warp_steps": steps}
    for label, n_flags in (("single", 1), ("batched", batch)):
        model = build_warp_model(wp, wsim, n_flags, config.grid_u, config.grid_v, cell, 0.135)
        integrator = wsim.SemiImplicitIntegrator()
        s0, s1 = model.state(), model.state()
        for _ in range(10):  # compile the kernels and warm up
            s0.clear_forces()
            integrator.simulate(model, s0, s1, config.dt)
            s0, s1 = s1, s0
        wp.synchronize()
        start = time.perf_counter()
        for _ in range(steps):
            s0.clear_forces()
            integrator.simulate(model, s0, s1, config.dt)
            s0, s1 = s1, s0
        wp.synchronize()
        elapsed = time.perf_counter() - start
        finite = bool(np.isfinite(s0.particle_q.numpy()).all())
        per_flag = 1000 * elapsed / (n_flags * steps * config.dt)
        log(f"warp {label} ({n_flags} flags, {model.particle_count} particles): {per_flag:.1f} ms per simulated s per flag")
        key = "warp_ms_per_sim_s" if label == "batched" else "warp_ms_per_sim_s_single"
        out[key] = round(per_flag, 2)
        out[f"warp_finite_{label}"] = finite
        out["warp_triangles_per_flag"] = int(model.tri_count // n_flags)
        out["warp_bending_edges_per_flag"] = int(model.edge_count // n_flags)
    return out


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print one JSON object."""
    args = parse_args(argv)
    from physinfer_flag.simulator import FlagSimConfig

    result: dict[str, Any] = {
        "benchmark": "cloth",
        "date": datetime.date.today().isoformat(),
        "machine": machine(),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
    if not args.skip_compile:
        with tempfile.TemporaryDirectory() as cache:
            result["compile_s_cold"] = round(first_call_seconds(cache), 2)
        first_call_seconds(None)  # make sure the shared cache is populated
        result["first_call_s_cached"] = round(first_call_seconds(None), 2)
        log(f"first call: cold {result['compile_s_cold']} s, cached {result['first_call_s_cached']} s")
    result.update(measure_ours(args.batch, args.repeats))
    warp_fields = {"warp_ms_per_sim_s": None, "warp_ms_per_sim_s_single": None, "ratio_vs_warp": None,
                   "warp_error": None}
    if args.skip_warp:
        warp_fields["warp_error"] = "skipped (--skip-warp)"
    else:
        try:
            # Warp prints its notices on stdout; keep stdout for the one JSON object.
            with contextlib.redirect_stdout(sys.stderr):
                warp_fields.update(measure_warp(FlagSimConfig(), args.batch, args.warp_seconds))
            warp_fields["ratio_vs_warp"] = round(result["ms_per_sim_s_batched"] / warp_fields["warp_ms_per_sim_s"], 3)
        except Exception as exc:  # any failure of the optional dependency is reported, not raised
            warp_fields["warp_error"] = f"{type(exc).__name__}: {exc}"
            log(f"warp unavailable: {warp_fields['warp_error']}")
    result.update(warp_fields)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
