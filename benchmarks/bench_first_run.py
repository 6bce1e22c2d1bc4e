"""How long the README's command takes: the first run, which compiles the kernels, and later
runs, which load them from Numba's cache.

``python -m potflat_cli run samples/data/amphora.obj -o OUT`` in a child process, as a user
runs it (start-up included): ``--rounds`` times with an empty kernel cache (a fresh
``NUMBA_CACHE_DIR``: the first run of an installation), each followed by a run on the cache it
filled (a later run). The figures are medians of the rounds. Installing potflat is not
counted.

Reproduce (blocks ``bench_first_run`` of docs/performance.md and ``bench_first_run_readme`` of
README.md)::

    python benchmarks/bench_first_run.py --write
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import ROOT, command_line, machine, publish  # noqa: E402

SAMPLE = ROOT / "samples" / "data" / "amphora.obj"


def timed_run(cache: Path, out: Path) -> float:
    """Seconds of one ``potflat run`` of the sample with Numba's cache in ``cache``."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "potflat_cli", "run", str(SAMPLE), "-o", str(out), "--quiet"],
                   check=True, env=env, stdin=subprocess.DEVNULL)
    return time.perf_counter() - t


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--write", action="store_true",
                    help="rewrite its blocks in docs/performance.md and README.md")
    args = ap.parse_args(argv)
    first, later = [], []
    for rnd in range(args.rounds):
        with tempfile.TemporaryDirectory(prefix="potflat-first-run-") as tmp:
            first.append(timed_run(Path(tmp) / "cache", Path(tmp) / "first"))
            later.append(timed_run(Path(tmp) / "cache", Path(tmp) / "later"))
        print(f"round {rnd + 1}: first run {first[-1]:.1f} s, later run {later[-1]:.1f} s", flush=True)
    f, g = statistics.median(first), statistics.median(later)
    command = command_line("bench_first_run.py", argv if argv is not None else sys.argv[1:])
    publish("bench_first_run",
            f"`{command}` ({machine()}), medians of {args.rounds} rounds:\n\n"
            "| run of the sample | seconds (range) |\n|---|---:|\n"
            f"| first (compiles the kernels) | {f:.0f} ({min(first):.0f}-{max(first):.0f}) |\n"
            f"| later (kernels cached) | {g:.0f} ({min(later):.0f}-{max(later):.0f}) |\n", args.write)
    publish("bench_first_run_readme",
            f"On a {os.cpu_count()}-core machine shared with other jobs, the first run of the sample took "
            f"{f:.0f} s (it compiles the kernels once) and later runs {g:.0f} s, medians of {args.rounds}; "
            "installing is not counted ([performance](docs/performance.md#first-run)).\n", args.write)

if __name__ == "__main__":
    main()
