"""A FlagSim dataset through the CLI: the flag's θ within Table 1, ζ within 15° of the wind."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from physinfer.datasets import ClipDataset
from physinfer_flag.simulator import flag_parameter_space

BIN = Path(sys.executable).parent / "physinfer"


def test_flag_dataset_generate_small(tmp_path):
    out = tmp_path / "flagsim"
    args = [str(BIN), "dataset", "generate", "--plugin", "flag", "--out", str(out), "--sims", "2,1,1",
            "--renders-per-sim", "2", "--frames", "8", "--size", "48", "--sims-per-unit", "2",
            "--workers", "0", "--seed", "5", "--json"]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(proc.stdout)
    assert summary["renders_generated"] == 8 and summary["failed_sims"] == []

    space = flag_parameter_space()
    rows = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert len(rows) == 8 and {r["split"] for r in rows} == {"train", "val", "test"}
    for row in rows:
        for spec in space:
            low, high = spec.bounds
            assert low <= row["params"][spec.name] <= high, spec.name
        assert abs(row["render_params"]["camera_azimuth_deg"]) <= 15.0
    train = ClipDataset(out, "train")
    assert train[0].shape == (8, 48, 48, 3) and len(train.simulations()) == 2  # colour: as videos arrive
    assert np.ptp(train.clips([0, 1]).astype(float)) > 0

    again = subprocess.run(args, capture_output=True, text=True, timeout=900)
    assert again.returncode == 0 and json.loads(again.stdout)["units"]["skipped"] == summary["units"]["total"], "re-running resumes"
