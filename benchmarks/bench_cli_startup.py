"""How long ``physinfer --help`` (and ``physinfer plugins``) take: the start-up a user waits for.

Runs each command ``--repeats`` times in a fresh process and prints one JSON object with the
minimum, median and maximum wall time per command. The test suite checks only what keeps
start-up short (no heavy library imported by ``--help``); the time itself belongs here.

Example (the numbers in docs/benchmarks.md)::

    .venv/bin/python benchmarks/bench_cli_startup.py --repeats 5
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

COMMANDS = {"--help": ["--help"], "plugins": ["plugins", "--json"]}


def wall_times(args: list[str], repeats: int) -> list[float]:
    """Seconds of each of ``repeats`` runs of ``physinfer ARGS`` in a fresh process."""
    binary = Path(sys.executable).parent / "physinfer"
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([str(binary), *args], capture_output=True, check=True)
        times.append(time.perf_counter() - start)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rows = {}
    for name, command in COMMANDS.items():
        times = wall_times(command, args.repeats)
        rows[name] = {"min_s": min(times), "median_s": statistics.median(times), "max_s": max(times)}
    print(json.dumps({"repeats": args.repeats, "commands": rows}))


if __name__ == "__main__":
    main()
