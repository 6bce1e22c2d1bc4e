"""How far a relaxation's iteration count moves with the last bits of its start.

Relaxes one rollout (``NAME.rollout.ply``, e.g. a row of ``real_scans.py``: ``OUT/sea-vase/
1000000/run/sea-vase.rollout.ply``) with the defaults ``--runs`` times in this process, its
layout scaled by ``1 + k 1e-12`` in run ``k`` (a change in the last bits of every coordinate),
and gives each run's full-mesh iterations, relax seconds, final energy, edge-length RMS and
anisotropy p95.

Reproduce::

    python benchmarks/relax_spread.py OUT/sea-vase/1000000/run/sea-vase.rollout.ply --runs 4 --write
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, publish  # noqa: E402

BLOCK = "relax_spread"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rollout", type=Path, help="a NAME.rollout.ply")
    ap.add_argument("--runs", type=int, default=4, help="starts relaxed (default 4)")
    ap.add_argument("--write", action="store_true", help="update the section in docs/performance.md")
    args = ap.parse_args(argv)

    from potflat.io.flat_ply import read_flat_ply
    from potflat.relax import relax

    flat = read_flat_ply(args.rollout)
    rows = []
    for k in range(args.runs):
        start = dataclasses.replace(flat, uv=flat.uv * (1.0 + k * 1e-12))
        t = time.perf_counter()
        result = relax(start)
        seconds = time.perf_counter() - t
        d = result.distortion
        rows.append((k, result.levels[-1].iterations, seconds, result.energy_history[-1], d.edge_rms, d.anisotropy_p95))
        print(rows[-1], flush=True)
    energy = [r[3] for r in rows]
    lines = [f"`{command_line('relax_spread.py', argv if argv is not None else sys.argv[1:])}` ({machine()}), "
             f"{len(flat.uv):,} vertices:", "",
             "| start scaled by | full-mesh iterations | relax s | energy | edge-length RMS | anisotropy p95 |",
             "|---|---:|---:|---:|---:|---:|"]
    lines += [f"| 1 + {k}e-12 | {its} | {s:.1f} | {e:.6g} | {rms:.4f} | {p95:.3f} |" for k, its, s, e, rms, p95 in rows]
    iterations = [r[1] for r in rows]
    lines += ["", f"Full-mesh iterations {min(iterations)}-{max(iterations)}, energies within "
              f"{100 * (max(energy) / min(energy) - 1):.2f} %.", ""]
    publish(BLOCK, "\n".join(lines), args.write)


if __name__ == "__main__":
    main()
