"""ζ from the target (issue 23 item 2): the flag's shipped render-parameter estimator on
generated clips at known ζ, and the estimator file's refusals.

Tolerance: each estimate within 2.5 of its reported standard errors of the truth (the
held-out rms errors: framing 0.044, azimuth 7.2°, elevation 6.2°; 90 % intervals covered
0.91/0.91/0.905 of 200 held-out dataset clips, docs/real-videos.md).
"""

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.render_estimate import (
    RenderEstimator,
    estimate_render_params,
    render_estimator_path,
)
from physinfer_flag.phenomenon import make_phenomenon, make_renderer, make_simulator


@pytest.fixture(scope="module")
def sdn():
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    return registry.embedder("sdn", model=None, device="cpu")


@pytest.fixture(scope="module")
def trajectory():
    truth = make_phenomenon().parameter_space.defaults()
    truth.update(wind_speed=6.5, area_weight=0.12)
    return make_simulator(duration_s=2.4).simulate(truth, seed=4242)


ZETAS = [
    {
        "framing": 0.95,
        "camera_azimuth_deg": -12.0,
        "camera_elevation_deg": 6.0,
        "texture": "france",
    },
    {
        "framing": 1.3,
        "camera_azimuth_deg": 12.0,
        "camera_elevation_deg": -12.0,
        "texture": "sweden",
    },
]


def test_estimates_on_generated_clips_at_known_zeta(trajectory, sdn):
    phenomenon = make_phenomenon()
    renderer = make_renderer()
    try:
        estimates = [
            estimate_render_params(phenomenon, renderer.render(trajectory, zeta), embedder=sdn)
            for zeta in ZETAS
        ]
    finally:
        renderer.close()
    for zeta, est in zip(ZETAS, estimates, strict=True):
        assert set(est["values"]) == {"framing", "camera_azimuth_deg", "camera_elevation_deg"}
        for name, value in est["values"].items():
            assert abs(value - zeta[name]) <= 2.5 * est["sd"][name], (
                name,
                value,
                zeta[name],
                est["sd"][name],
            )
            lo, hi = est["ci90"][name]
            assert lo <= value <= hi
    # The component the embedding reads best tells the two framings apart.
    assert estimates[1]["values"]["framing"] - estimates[0]["values"]["framing"] > 0.15


def test_estimator_file_round_trip_and_refusals(tmp_path, sdn):
    path = render_estimator_path(make_phenomenon())
    assert path is not None and path.is_file()
    estimator = RenderEstimator.load(path)
    again = RenderEstimator.load(estimator.save(tmp_path / "copy.npz"))
    x = np.linspace(-1, 1, estimator.mean.shape[0])
    assert np.allclose(again.predict(x), estimator.predict(x))
    estimator.check_embedder(sdn)  # the shipped SDN passes its own fingerprint
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(UserInputError, match="not a render-parameter estimator"):
        RenderEstimator.load(tmp_path / "other.npz")
    np.save(tmp_path / "pickled.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(UserInputError, match="not a render-parameter estimator"):
        RenderEstimator.load(tmp_path / "pickled.npy")
    with pytest.raises(UserInputError, match="finite"):
        estimator.predict(np.full(estimator.mean.shape, np.nan))


def test_refuses_an_embedder_it_was_not_fitted_on():
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    spectral = registry.embedder("spectral", device="cpu")
    estimator = RenderEstimator.load(render_estimator_path(make_phenomenon()))
    with pytest.raises(UserInputError, match="another 'sdn' embedder"):
        estimator.check_embedder(spectral)


def test_a_clip_too_short_is_a_note_not_an_error(trajectory, sdn):
    renderer = make_renderer()
    try:
        clip = renderer.render(
            trajectory.__class__(
                trajectory.vertices[:20], trajectory.faces, trajectory.fps, trajectory.extras
            )
        )
    finally:
        renderer.close()
    est = estimate_render_params(make_phenomenon(), clip, embedder=sdn)
    assert est["values"] == {} and "needs 2.40 s" in est["note"]


@pytest.mark.slow  # two CLI runs that each load torch and the SDN: about 45 s under load
def test_prepare_writes_the_estimate_into_prepared_json(trajectory, tmp_path):
    import json
    import subprocess
    import sys
    from pathlib import Path

    from physinfer.types import Clip
    from physinfer.video import write_video

    renderer = make_renderer()
    try:
        flag = renderer.render(trajectory, {**ZETAS[0], "image_size": 160})
    finally:
        renderer.close()
    frames = np.full((flag.n_frames, 360, 640, 3), 90, np.uint8)
    frames[:, 100:260, 400:560] = flag.frames  # off-centre in a 640x360 frame
    write_video(tmp_path / "wide.mp4", Clip(frames, flag.fps))
    cmd = [str(Path(sys.executable).parent / "physinfer"), "prepare", "--plugin", "flag", "--target",
           str(tmp_path / "wide.mp4"), "--out", str(tmp_path / "prepared.mp4"), "--json"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    estimate = json.loads(proc.stdout)["render_estimate"]
    assert json.loads((tmp_path / "prepared.json").read_text())["render_estimate"] == estimate
    # prepare reframes to the renderer's automatic square: the framing read back is about 1.
    assert abs(estimate["values"]["framing"] - 1.0) <= 2.5 * estimate["sd"]["framing"]
    for name in ("camera_azimuth_deg", "camera_elevation_deg"):
        assert abs(estimate["values"][name] - ZETAS[0][name]) <= 2.5 * estimate["sd"][name]
    proc = subprocess.run(
        [*cmd, "--no-render-estimate"], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0 and json.loads(proc.stdout)["render_estimate"] is None
