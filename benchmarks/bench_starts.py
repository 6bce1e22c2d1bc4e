"""Does the relaxed result depend on the start it was relaxed from?

For each bundled sample (``samples/data/*.obj`` with its ``*.truth.json``), the rollout is
relaxed (default options) from three starts:

* ``rollout``: the rollout's layout, as always;
* ``local repair``: the rollout with one interior vertex thrown far off (its fan folded),
  untangling switched off, so the folded cluster is re-embedded inside its surroundings
  (:func:`potflat.mesh.embedding.repair_folds`);
* ``Tutte's disc``: the rollout with a vertical strip mirrored (a fold reaching the border,
  which no local repair removes), untangling switched off, so the relaxation starts from
  Tutte's embedding of the whole mesh (:func:`potflat.mesh.embedding.tutte_embedding`).

It prints the edge RMS, the area distortion and the painted circles' figures of each
(``benchmarks/_figures.py``) and writes the table into block ``bench_starts`` of
``docs/robustness.md``.

Usage::

    python benchmarks/bench_starts.py [--no-write]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SAMPLES = ("amphora", "cone")


def _starts(flat):
    """Name -> (start layout, whether untangling is switched off)."""
    F, uv = flat.mesh.faces, flat.uv
    border = np.zeros(len(uv), bool)
    from potflat.mesh.embedding import boundary_loops

    for loop in boundary_loops(F, len(uv)):
        border[loop] = True
    ring = np.zeros(len(uv), bool)
    ring[F[border[F].any(axis=1)].ravel()] = True
    inner = np.flatnonzero(~ring)
    v = int(inner[np.argmin(np.linalg.norm(uv[inner] - np.median(uv, axis=0), axis=1))])
    nbr = np.unique(F[(F == v).any(axis=1)])
    local = uv.copy()
    local[v] += 5.0 * (uv[nbr].max(axis=0) - uv[nbr].min(axis=0))
    disc = uv.copy()
    u = disc[:, 0]
    a, b = np.percentile(u, [40, 55])
    strip = (u > a) & (u < b)
    disc[strip, 0] = a + b - u[strip] + 0.3 * (u[strip] - a)
    return {"rollout": (uv, False), "local repair": (local, True), "Tutte's disc": (disc, True)}


def run(log=print) -> list[dict]:
    from benchmarks._figures import measure_figures, truth_circles
    from potflat.io.scan import load_scan
    from potflat.relax import multilevel, relax
    from potflat.rollout import rollout

    rows = []
    for name in SAMPLES:
        scan = ROOT / "samples" / "data" / f"{name}.obj"
        circles = truth_circles(scan.with_suffix(".truth.json"))
        flat = rollout(load_scan(scan).mesh).flat
        base = None
        for start, (uv, off) in _starts(flat).items():
            patch = (mock.patch.object(multilevel, "untangle", lambda sp, x, rounds=200: (x, int((sp.signed_areas(x) <= 0).sum())))
                     if off else mock.patch.object(multilevel, "untangle", multilevel.untangle))
            t = time.perf_counter()
            with patch:
                result = relax(flat.replace(uv=uv))
            seconds = time.perf_counter() - t
            fig = measure_figures(result.flat, circles)
            how = ("Tutte" if any("Tutte" in n for n in result.notes) else
                   "re-embedded" if any("re-embedded" in n for n in result.notes) else "as given")
            row = {"sample": name, "start": start, "how": how, "vertices": len(uv), "flipped": result.flipped,
                   "edge_rms": result.distortion.edge_rms, "area": fig.area_mean_abs_log,
                   "circles": fig.measured, "area_ratio": fig.area_ratio, "width_mm": fig.width_mm,
                   "height_mm": fig.height_mm, "elongation": fig.elongation_max, "seconds": seconds}
            base = base or row
            row["rms_change_pct"] = 100.0 * (row["edge_rms"] / base["edge_rms"] - 1.0)
            rows.append(row)
            log(f"{name} {start}: {how}, edge RMS {row['edge_rms']:.4f} ({row['rms_change_pct']:+.2f}%), "
                f"{seconds:.1f} s")
    return rows


def table(rows: list[dict]) -> str:
    head = ("| sample | start | relaxed from | flipped | edge RMS | change | area \\|ln\\| | circles | area ratio "
            "| width mm | height mm | elongation max |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    return head + "".join(
        f"| {r['sample']} ({r['vertices']:,} v) | {r['start']} | {r['how']} | {r['flipped']} | {r['edge_rms']:.4g} | "
        f"{r['rms_change_pct']:+.2f}% | {r['area']:.4f} | {r['circles']} | {r['area_ratio']:.4f} | "
        f"{r['width_mm'][0]:.2f}-{r['width_mm'][1]:.2f} | {r['height_mm'][0]:.2f}-{r['height_mm'][1]:.2f} | "
        f"{r['elongation']:.3f} |\n" for r in rows)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/robustness.md alone")
    args = parser.parse_args(argv)
    rows = run()
    text = table(rows)
    print(text)
    if not args.no_write:
        from benchmarks._docs import write_block

        write_block("bench_starts", f"`python benchmarks/bench_starts.py`:\n\n{text}")


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
