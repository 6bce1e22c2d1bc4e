"""Relax-stage benchmark: presets, the paper dynamics and libigl ARAP side by side.

Every (size, method) run happens in its own subprocess (clean peak memory, no shared
caches beyond Numba's compiled kernels); repeated runs are summarised by their median.

    python benchmarks/bench_relax.py                       # 0.1M 0.5M 1M 2.5M, all presets + ARAP
    python benchmarks/bench_relax.py --sizes 0.1 --repeat 3
    python benchmarks/bench_relax.py --write               # also rewrite block bench_relax of docs/performance.md

Meshes: ``benchmarks/_meshes.py`` bulgy amphora-like vessels (foot to lip), irregular
triangles, cut open along a meridian and rolled out on a cylinder proxy.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, write_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CACHE = Path(tempfile.gettempdir()) / "potflat-bench-meshes"


def _mesh(size_m: float):
    """The benchmark vessel with about ``size_m`` million vertices (cached as .npz)."""
    import numpy as np

    sys.path.insert(0, str(ROOT))
    from benchmarks._meshes import vessel_rollout
    from potflat.types import FlatMesh, Mesh

    CACHE.mkdir(exist_ok=True)
    path = CACHE / f"vessel-{size_m:g}M.npz"
    if path.exists():
        d = np.load(path)
        return FlatMesh(Mesh(d["V"], d["F"], units="mm"), d["uv"])
    flat = vessel_rollout(int(size_m * 1e6), seed=0)
    np.savez(path, V=flat.mesh.vertices, F=flat.mesh.faces, uv=flat.uv)
    return flat


def _paper_energy(flat, uv) -> float:
    """Paper Eq. 1 (k = 1, uniform, edge and cross springs) in normalised units, per spring."""
    import numpy as np

    from potflat.relax.energy import SpringSystem

    V, F = flat.mesh.vertices, flat.mesh.faces
    unit = float(np.linalg.norm(V[F[:, [1, 2, 0]]] - V[F], axis=2).mean())
    sp = SpringSystem(np.ascontiguousarray(V / unit), F, len(V), k=1.0, relative=False)
    return sp.spring_energy(np.ascontiguousarray(uv / unit)) / sp.n_springs


def _worker(size_m: float, method: str, budget: float, target: float | None) -> dict:
    """One run in this process; returns the figures."""
    import numpy as np

    from potflat.mesh.distortion import summarize

    flat = _mesh(size_m)
    V, F = flat.mesh.vertices, flat.mesh.faces
    out: dict = {"size": size_m, "method": method, "vertices": len(V)}
    if method == "arap":
        from benchmarks._arap import ARAP_ITERATIONS, libigl_arap

        uv, precompute, seconds = libigl_arap(flat)
        out.update(seconds=seconds, precompute=precompute, iterations=ARAP_ITERATIONS, converged=None)
    else:
        from benchmarks._meshes import vessel_rollout
        from potflat.relax import relax

        relax(vessel_rollout(300), preset="preview")  # load the compiled kernels before timing
        preset, _, weighting = method.partition(":")
        trace: list[tuple[float, float]] = []
        t0 = time.perf_counter()

        def cb(info):
            trace.append((time.perf_counter() - t0, info["energy"]))

        kw = {"preset": preset, "time_budget": budget}
        if weighting == "springs":  # the springs alone: no per-face terms, no final scaling
            kw.update(shape=0.0, rigidity=0.0, area=0.0, true_scale=False)
        elif weighting:
            kw["weighting"] = weighting
        r = relax(flat, callback=cb if preset == "paper" else None, **kw)
        uv = r.flat.uv
        out.update(seconds=r.timings.solve + r.timings.setup, solve=r.timings.solve,
                   setup=r.timings.setup, iterations=r.iterations, converged=r.converged,
                   levels=[(lv.level, lv.iterations) for lv in r.levels], notes=list(r.notes))
        if preset == "paper" and target is not None and trace:
            # time at which the dynamics first reached the target energy (its own, per spring)
            from potflat.relax.energy import SpringSystem

            unit = float(np.linalg.norm(V[F[:, [1, 2, 0]]] - V[F], axis=2).mean())
            nspr = SpringSystem(np.ascontiguousarray(V / unit), F, len(V), k=1.0, relative=False).n_springs
            hit = [t for t, e in trace if e / 0.5 / nspr <= target]
            out["paper_time_to_target"] = hit[0] if hit else None
            out["paper_energy_end"] = trace[-1][1] / 0.5 / nspr
    d = summarize(V, uv, F)
    out.update(energy=_paper_energy(flat, uv), edge_rms=d.edge_rms, area=d.area_mean_abs_log,
               anisotropy_p95=d.anisotropy_p95, flipped=d.flipped,
               peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    if method != "arap":
        out["boundary_overlap"] = r.boundary_overlap
    return out


def _run(size_m: float, method: str, budget: float, threads: int, target: float | None = None) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads))
    cmd = [sys.executable, __file__, "--worker", f"{size_m}", method, f"{budget}", json.dumps(target)]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        return {"size": size_m, "method": method, "error": res.stderr.strip().splitlines()[-1:]}
    return json.loads(res.stdout.strip().splitlines()[-1])


def _median(runs: list[dict]) -> dict:
    ok = [r for r in runs if "error" not in r]
    if not ok:
        return runs[0]
    out = dict(ok[len(ok) // 2])
    out["seconds"] = statistics.median(r["seconds"] for r in ok)
    out["runs"] = len(ok)
    return out


def _table(rows: list[dict]) -> str:
    head = ("| vertices | method | time s | iterations | energy/spring | edge RMS | mean abs log area | "
            "anisotropy p95 | flips | boundary crossings | peak MB |\n|---|---|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['size']}M | {r['method']} | error: {' '.join(r['error'])} |||||||||")
            continue
        lines.append(f"| {r['vertices']:,} | {r['method']} | {r['seconds']:.1f} | {r['iterations']} | {r['energy']:.3e} | "
                     f"{r['edge_rms']:.4f} | {r['area']:.4f} | {r['anisotropy_p95']:.2f} | {r['flipped']} | "
                     f"{r.get('boundary_overlap', '-')} | {r['peak_mb']:.0f} |")
    return head + "\n".join(lines) + "\n"


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    methods = sorted({r["method"] for r in rows if "error" not in r})
    for m in methods:
        pts = sorted((r for r in rows if r["method"] == m and "error" not in r), key=lambda r: r["size"])
        for ax, key in zip(axes, ("energy", "edge_rms")):
            ax.plot([r["seconds"] for r in pts], [r[key] for r in pts], "o-", label=m)
            for r in pts:
                ax.annotate(f"{r['size']:g}M", (r["seconds"], r[key]), fontsize=7)
    axes[0].set_ylabel("residual energy per spring (paper Eq. 1, k = 1)")
    axes[1].set_ylabel("edge-length RMS")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("seconds (2 cores)")
        ax.grid(alpha=0.3)
    axes[0].set_yscale("log")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(_worker(float(sys.argv[2]), sys.argv[3], float(sys.argv[4]), json.loads(sys.argv[5]))))
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="0.1,0.5,1,2.5", help="million vertices, comma separated")
    ap.add_argument("--methods", default="preview,standard,archival,paper,arap",
                    help="PRESET[:uniform|relative|springs] (springs: no shape term, no true scale), paper, arap")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--budget", type=float, default=600.0, help="time budget (s) of each relax run")
    ap.add_argument("--paper-max-size", type=float, default=0.5, help="largest size for the paper dynamics")
    ap.add_argument("--write", action="store_true", help="rewrite block bench_relax of docs/performance.md")
    ap.add_argument("--json", type=Path, help="also dump all rows here")
    ap.add_argument("--note", default="", help="with --from-json: how the rows were measured")
    ap.add_argument("--from-json", type=Path, nargs="+", help="no runs: tabulate rows dumped by earlier --json runs")
    args = ap.parse_args()
    sizes = [float(s) for s in args.sizes.split(",")]
    methods = args.methods.split(",")
    rows = []
    for path in args.from_json or []:
        rows += json.loads(path.read_text())
    for size in sizes if not args.from_json else []:
        _mesh(size)
        for m in methods:
            if m == "paper":
                if size > args.paper_max_size:
                    continue
                # the paper dynamics until it reaches what standard with its own (uniform) weighting reaches
                ref = _run(size, "standard:uniform", args.budget, args.threads)
                rows.append(ref)
                print(_table([ref]), flush=True)
                target = ref.get("energy")
                runs = [_run(size, "paper", args.budget, args.threads, target) for _ in range(args.repeat)]
            else:
                runs = [_run(size, m, args.budget, args.threads) for _ in range(args.repeat)]
            row = _median(runs)
            rows.append(row)
            print(_table([row]), flush=True)
    table = _table(rows)
    print(table)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.write:
        png = ROOT / "docs" / "relax_performance.png"
        _plot(rows, png)
        extra = []
        for r in rows:
            if r.get("method") == "paper" and "error" not in r:
                ref = next((q for q in rows if q.get("method") == "standard:uniform" and q["size"] == r["size"]), None)
                t = r.get("paper_time_to_target")
                if ref is not None:
                    extra.append(f"- {r['vertices']:,} vertices: `standard` with uniform weighting reached energy/spring "
                                 f"{ref['energy']:.3e} in {ref['seconds']:.1f} s; the paper dynamics "
                                 + (f"reached it after {t:.1f} s ({t / ref['seconds']:.0f}x slower)." if t else
                                    f"did not reach it within {r['seconds']:.0f} s (ended at {r.get('paper_energy_end', float('nan')):.3e}; "
                                    f"more than {r['seconds'] / ref['seconds']:.0f}x slower)."))
        how = (f"`{command_line('bench_relax.py', sys.argv[1:])}`" if not args.from_json else args.note)
        text = (f"{how} ({machine()}, {args.threads} threads):\n\n" + table
                + "\n![time vs energy and edge RMS](relax_performance.png)\n"
                + ("\nPaper dynamics against the default solver on the same energy:\n\n" + "\n".join(extra) + "\n"
                   if extra else ""))
        write_block("bench_relax", text)


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
