"""Speed of the SDN forward pass on one 30×224×224 clip: fused front end vs plain torch.fft.

Prints one JSON object:

- ``ms_per_clip``: median time of the full SDN forward (fused front end + head) on one
  clip, batch of 1, inference mode; ``ms_per_clip_min`` its fastest run;
- ``ms_per_clip_fft_reference``: the same network with the plain front end
  (convolutions, ``max_pool2d``, ``torch.fft.rfft``), same run;
- ``ms_frontend`` / ``ms_frontend_fft_reference``: the two front ends alone;
  ``ms_head``: the trainable part alone;
- ``ms_per_clip_batch8``: time per clip when 8 clips go through together;
- ``max_rel_power_diff`` and ``frequency_agreement``: fused vs plain outputs;
- ``load_before`` / ``load_after``: the 1-minute load average, since the machine's cores
  are shared and other work inflates the medians.

Usage: ``python benchmarks/bench_sdn.py [--threads 2] [--repeats 30] [--device cpu]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable

import numpy as np
import torch

from physinfer_flag.sdn.frontend import ReferenceFrontEnd
from physinfer_flag.sdn.network import SDN, count_parameters
from physinfer_flag.sdn.synthetic import moving_grating


def timings_ms(
    fn: Callable[[], object], repeats: int, warmup: int, device: torch.device
) -> list[float]:
    """Wall-clock milliseconds of ``repeats`` calls after ``warmup`` calls."""
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(repeats):
        if device.type == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize()
        out.append((time.perf_counter() - start) * 1000.0)
    return out


def test_clip(n: int, seed: int = 0) -> torch.Tensor:
    """``(n, 30, 224, 224)`` uint8: travelling gratings (every pixel moves), some noise."""
    rng = np.random.default_rng(seed)
    clips = []
    for _ in range(n):
        frames = moving_grating(
            frequency_hz=rng.uniform(0.5, 5.0),
            direction_rad=rng.uniform(0, np.pi),
            n_frames=30,
            size=224,
            fps=25.0,
            wavelength_px=rng.uniform(30, 90),
            noise=0.02,
            rng=rng,
        )
        clips.append(frames)
    return torch.from_numpy(np.stack(clips))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--threads", type=int, default=2, help="torch CPU threads (the target machine has 2 cores)"
    )
    parser.add_argument("--repeats", type=int, default=30, help="timed runs of the fused network")
    parser.add_argument(
        "--reference-repeats", type=int, default=8, help="timed runs of the plain front end"
    )
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    torch.manual_seed(0)
    model = SDN().to(device).eval()
    reference = ReferenceFrontEnd(config=model.config.frontend).to(device)
    one, eight = test_clip(1).to(device), test_clip(8, seed=1).to(device)
    load_before = os.getloadavg()[0]
    with torch.inference_mode():
        features = model.frontend(one)
        fused, plain = features, reference(one)
        t_full = timings_ms(lambda: model(one), args.repeats, 3, device)
        t_front = timings_ms(lambda: model.frontend(one), args.repeats, 3, device)
        t_head = timings_ms(lambda: model.head(features), args.repeats, 3, device)
        t_batch = timings_ms(lambda: model(eight), max(3, args.repeats // 4), 1, device)
        t_ref_front = timings_ms(lambda: reference(one), args.reference_repeats, 1, device)
        t_ref_full = timings_ms(
            lambda: model.head(reference(one)), args.reference_repeats, 1, device
        )
    power_diff = (fused[:, :2] - plain[:, :2]).abs().max() / plain[:, :2].abs().max()
    agreement = (fused[:, 2:] == plain[:, 2:]).float().mean()
    median = statistics.median
    print(
        json.dumps(
            {
                "ms_per_clip": round(median(t_full), 2),
                "ms_per_clip_min": round(min(t_full), 2),
                "ms_per_clip_fft_reference": round(median(t_ref_full), 2),
                "ms_frontend": round(median(t_front), 2),
                "ms_frontend_fft_reference": round(median(t_ref_front), 2),
                "ms_head": round(median(t_head), 2),
                "ms_per_clip_batch8": round(median(t_batch) / 8, 2),
                "speedup_vs_reference": round(median(t_ref_full) / median(t_full), 2),
                "goal_ms_per_clip": 35.0,
                "max_rel_power_diff": float(power_diff),
                "frequency_agreement": float(agreement),
                "input": [1, 30, 224, 224],
                "parameters": count_parameters(model),
                "threads": torch.get_num_threads(),
                "device": str(device),
                "torch": torch.__version__,
                "machine": platform.machine(),
                "repeats": args.repeats,
                "load_before": round(load_before, 2),
                "load_after": round(os.getloadavg()[0], 2),
            }
        )
    )


if __name__ == "__main__":
    main()
