"""How long the README's command takes: the first run, which compiles the kernels, and later
runs, which load them from Numba's cache.

``python -m potflat_cli run samples/data/amphora.obj -o OUT`` in a child process, as a user
runs it (start-up included): ``--rounds`` times with an empty kernel cache (a fresh
``NUMBA_CACHE_DIR``: the first run of an installation), each followed by a run on the cache it
filled (a later run); and, in another fresh cache, ``potflat warmup`` (which compiles them
ahead, e.g. after installing) followed by a run. The figures are medians and ranges of the rounds, with the machine's
load average (1 minute) at the start and end of each run: on a shared machine the first run
takes as long as the cores it gets. What the first run compiles is counted from the cache it
fills: the kernels (one index file each) and their type signatures (one data file each), in
the run and its warm-up child process. Installing potflat is not counted.

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


def timed_run(cache: Path, out: Path | None) -> tuple[float, list[float]]:
    """Seconds of one ``potflat run`` of the sample into ``out`` (None: ``potflat warmup``)
    with Numba's cache in ``cache``, and the load averages (1 minute) at its start and end."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    command = ["warmup"] if out is None else ["run", str(SAMPLE), "-o", str(out)]
    load = [os.getloadavg()[0]]
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "potflat_cli", *command, "--quiet"],
                   check=True, env=env, stdin=subprocess.DEVNULL)
    seconds = time.perf_counter() - t
    return seconds, load + [os.getloadavg()[0]]


def compiled(cache: Path) -> tuple[int, int]:
    """Kernels and type signatures Numba cached in ``cache``."""
    return len(list(cache.rglob("*.nbi"))), len(list(cache.rglob("*.nbc")))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--write", action="store_true",
                    help="rewrite its blocks in docs/performance.md and README.md")
    args = ap.parse_args(argv)
    first, later, warmed, after = [], [], [], []
    loads, counts = {"first": [], "later": [], "warmup": [], "after": []}, set()
    for rnd in range(args.rounds):
        with tempfile.TemporaryDirectory(prefix="potflat-first-run-") as tmp:
            seconds, load = timed_run(Path(tmp) / "cache", Path(tmp) / "first")
            first.append(seconds)
            loads["first"] += load
            counts.add(compiled(Path(tmp) / "cache"))
            seconds, load = timed_run(Path(tmp) / "cache", Path(tmp) / "later")
            later.append(seconds)
            loads["later"] += load
            seconds, load = timed_run(Path(tmp) / "warmed", None)
            warmed.append(seconds)
            loads["warmup"] += load
            seconds, load = timed_run(Path(tmp) / "warmed", Path(tmp) / "after")
            after.append(seconds)
            loads["after"] += load
        print(f"round {rnd + 1}: first run {first[-1]:.1f} s, later run {later[-1]:.1f} s, "
              f"load {min(loads['first']):.1f}-{max(loads['first']):.1f}", flush=True)
    f, g = statistics.median(first), statistics.median(later)
    kernels = "/".join(str(k) for k, _ in sorted(counts))
    signatures = "/".join(str(n) for _, n in sorted(counts))

    def load_range(key: str) -> str:
        return f"{min(loads[key]):.1f}-{max(loads[key]):.1f}"
    command = command_line("bench_first_run.py", argv if argv is not None else sys.argv[1:])
    publish("bench_first_run",
            f"`{command}` ({machine()}), medians of {args.rounds} rounds; the first run compiled {kernels} "
            f"kernels, {signatures} type signatures (the run and its warm-up child):\n\n"
            "| run of the sample | seconds (range) | load average (1 min) |\n|---|---:|---:|\n"
            f"| first (compiles the kernels) | {f:.0f} ({min(first):.0f}-{max(first):.0f}) | {load_range('first')} |\n"
            f"| later (kernels cached) | {g:.0f} ({min(later):.0f}-{max(later):.0f}) | {load_range('later')} |\n"
            f"| `potflat warmup` (compiles the kernels) | {statistics.median(warmed):.0f} "
            f"({min(warmed):.0f}-{max(warmed):.0f}) | {load_range('warmup')} |\n"
            f"| first run after `potflat warmup` | {statistics.median(after):.0f} ({min(after):.0f}-{max(after):.0f}) "
            f"| {load_range('after')} |\n",
            args.write)
    publish("bench_first_run_readme",
            f"On a {os.cpu_count()}-core machine shared with other jobs (load average {load_range('first')}), the "
            f"first run of the sample took {_minutes(first)} minutes (it compiles "
            f"{kernels} kernels once; longer when other jobs take the cores) and later runs {g:.0f} s, {args.rounds} rounds; "
            "installing is not counted ([performance](docs/performance.md#first-run)). `potflat warmup` compiles them "
            f"ahead (after installing, or before a batch on a cluster): {_minutes(warmed)} "
            f"minutes, after which the first run took {statistics.median(after):.0f} s.\n", args.write)


def _minutes(seconds: list[float]) -> str:
    """The range of ``seconds`` in minutes to a tenth ("0.6-0.8"; one figure when both round alike)."""
    lo, hi = f"{min(seconds) / 60:.1f}", f"{max(seconds) / 60:.1f}"
    return lo if lo == hi else f"{lo}-{hi}"


if __name__ == "__main__":
    main()
