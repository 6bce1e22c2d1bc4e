"""``potflat run`` in a child process, as a user runs it, timed and its memory sampled: the
one runner of the benchmarks that time whole runs (``bench_scale.py``, ``bench_knobs.py``,
``real_scans.py``), and the warm-up that compiles the kernels before them."""
from __future__ import annotations

import json
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

STAGES = ("rollout", "relax", "bake")
#: Each stage's JSON sidecar: its appearance ends the stage.
SIDECAR = {"rollout": ".rollout.json", "relax": ".relaxed.json", "bake": ".bake.json"}


def status_kb(pid: int) -> dict[str, int]:
    """``VmRSS`` and ``VmHWM`` (kB) of a process (empty when it is gone)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return {}
    return {k: int(v) for k, v in re.findall(r"^(VmRSS|VmHWM):\s+(\d+) kB", text, re.MULTILINE)}


def run_potflat(scan: Path, out: Path, options: tuple[str, ...] = (), *, interval: float = 0.1) -> dict:
    """``python -m potflat_cli run SCAN -o OUT OPTIONS --json`` in a child process (``out``, the
    benchmark's own folder, is emptied first). Its resident memory is sampled every
    ``interval`` seconds and split by stage at the appearance of each stage's sidecar.

    Returns
    -------
    dict
        ``rc`` (exit code), ``error`` (the ``error:`` line, "" on success), ``stderr`` (its
        tail), ``wall_s`` (start-up included), ``cpu_s`` (user + system, all threads: the figure
        to compare on a shared machine), ``peak_gb`` (the child's high-water mark), ``stages``
        (per stage: ``stage``, ``wall_s`` as the run reports it, ``peak_gb``) and ``report``
        (the run's JSON, None on failure).
    """
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "potflat_cli", "run", str(scan), "-o", str(out), *options, "--json"]
    samples: list[tuple[float, int]] = []
    marks: dict[str, float] = {}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    hwm = [0]

    def sample() -> None:
        while proc.poll() is None:
            now = time.perf_counter() - start
            st = status_kb(proc.pid)
            if "VmRSS" in st:
                samples.append((now, st["VmRSS"]))
                hwm[0] = max(hwm[0], st.get("VmHWM", 0))
            for stage in STAGES:
                if stage not in marks and (out / f"{scan.stem}{SIDECAR[stage]}").exists():
                    marks[stage] = now
            time.sleep(interval)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    stdout, stderr = proc.communicate()
    wall = time.perf_counter() - start
    thread.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    report = None
    if proc.returncode == 0:
        try:
            report = json.loads(stdout)
        except ValueError:
            report = None
    seconds = (report or {}).get("seconds", {})
    stages, t0 = [], 0.0
    for stage in STAGES:
        t1 = marks.get(stage, wall)
        window = [kb for t, kb in samples if t0 <= t <= t1 + interval]
        stages.append({"stage": stage, "wall_s": seconds.get(stage, t1 - t0), "peak_gb": max(window, default=0) / 2**20})
        t0 = t1
    error = next((" ".join(ln.split("error:", 1)[1].split()) for ln in stderr.splitlines() if ln.startswith("error")), "")
    return {"rc": proc.returncode, "error": error, "stderr": stderr[-3000:], "wall_s": wall,
            "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            # the child's own high-water mark; RUSAGE_CHILDREN's ru_maxrss is not used: Linux
            # carries the parent's resident set at fork into the child's maxrss (a generated scan
            # held by this process), so it overstates potflat's peak
            "peak_gb": hwm[0] / 2**20, "stages": stages, "report": report}


def warm_kernels() -> None:
    """Run the bundled amphora through ``potflat run`` once (in a temporary folder), then bake it
    again at 0.5 px/mm, so that no row of a table pays for compiling a kernel (a kernel is
    compiled again after its source file changed): the small atlas needs mip levels (the chart
    mask's and the push-pull's kernels, which the big scans' painted-zone search and bake use)
    only at a coarse resolution."""
    print("compiling the kernels (potflat run on the bundled amphora) ...", flush=True)
    sample = Path(__file__).resolve().parents[1] / "samples" / "data" / "amphora.obj"
    with tempfile.TemporaryDirectory(prefix="potflat-bench-warm-") as tmp:
        subprocess.run([sys.executable, "-m", "potflat_cli", "run", str(sample), "-o", tmp, "--quiet"],
                       check=True, stdin=subprocess.DEVNULL)
        subprocess.run([sys.executable, "-m", "potflat_cli", "bake", str(Path(tmp) / "amphora.relaxed.ply"),
                        "-o", str(Path(tmp) / "coarse"), "--px-per-mm", "0.5", "--quiet"],
                       check=True, stdin=subprocess.DEVNULL)
