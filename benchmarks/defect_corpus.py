"""Scans that fold over themselves: the generated defect corpus and the real scans, both sides.

The corpus is ``tests/test_defect_scans.py``'s: a two-walled cup (``make_vessel("cup",
n_vertices=3000, seed=1, texture_size=256, painting="belt")``) with each defect of
:mod:`potflat_synthetic.defects` on both walls, run through :func:`potflat.run_scan` from the
outside and from the inside (base kept, 1 px/mm), against the clean cup. Per case and side:
the edge-length RMS of the relaxed faces more than ``AWAY_MM`` from every defect against the
clean cup's over the same faces, the painted zone's median length error (defective / clean),
and what the rollout did (faces it found folded in 3D, faces trimmed off the border, faces
left out with a piece the cleaning split off). Then the real scans that carry no texture (mm),
both sides: the faces found folded, their area and places.

Reproduce::

    python benchmarks/defect_corpus.py --write
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, publish  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real"
BLOCK = "defect_corpus"
#: Faces this far (mm, 4 edge lengths of the cup) from every defect are "away" from it.
AWAY_MM = 20.0
CASES = (("crease",), ("flap",), ("spikes",), ("sheet",), ("nonmanifold",), ("noise", "crease", "spikes"))
SIDES = ("outer", "inner")
REAL = (("plastic-vase.ply", "mm"), ("sea-vase.ply", "mm"), ("goblet.stl", "mm"))


def run(scan: Path, out: Path, side: str, units: str | None = None):
    """``potflat.run_scan`` as the defect tests run it: the base kept in the rollout (the
    inside's painting is the cup's floor), 1 px/mm."""
    from potflat.files.pipeline import run_scan

    rollout = {"side": side, "keep_base": True, **({"units": units} if units else {})}
    return run_scan(scan, out, rollout=rollout, bake={"px_per_mm": 1.0})


def away_rms(result, points: np.ndarray) -> tuple[float, int]:
    """Edge RMS of the relaxed faces all of whose vertices lie more than :data:`AWAY_MM` from
    ``points`` (k, 3), and how many faces that is."""
    from scipy.spatial import cKDTree

    from potflat.mesh.distortion import summarize

    flat = result.relax.flat
    V, F = flat.mesh.vertices, flat.mesh.faces
    far = (cKDTree(points).query(V)[0][F] > AWAY_MM).all(axis=1)
    return summarize(V, flat.uv, F[far]).edge_rms, int(far.sum())


def what_the_rollout_did(record: dict) -> str:
    """The faces a rollout (its JSON ``record``) found folded in 3D, trimmed off its border and
    left out with a piece the cleaning split off, in a few words."""
    folded, trimmed, walls = record["folded"], record["trimmed"], record["walls"]
    parts = []
    if folded["faces"]:
        parts.append(f"{folded['faces']} folded ({folded['percent_of_surface']:.1f} %)")
    if trimmed["faces"]:
        parts.append(f"{trimmed['faces']} trimmed")
    if walls["faces_dropped_disconnected"]:
        parts.append(f"{walls['faces_dropped_disconnected']} left out apart")
    return ", ".join(parts) or "nothing"


def corpus_rows(work: Path) -> list[str]:
    """The corpus' table rows, its runs written under ``work``."""
    from potflat_synthetic.defects import add_defects
    from potflat_synthetic.vessels import make_vessel, write_ply_colored

    cup = make_vessel("cup", n_vertices=3000, seed=1, texture_size=256, painting="belt")
    clean_ply = write_ply_colored(cup, work / "clean" / "cup.ply")
    clean = {side: run(clean_ply, work / "clean" / side, side) for side in SIDES}
    rows = []
    for case in CASES:
        scan = add_defects(cup, case, walls=("outer", "inner"))
        ply = write_ply_colored(scan.vessel, work / "+".join(case) / "cup.ply")
        near = scan.vessel.mesh.vertices[np.unique(scan.vessel.mesh.faces[scan.defect_faces])]
        rms, zone, did = [], [], []
        for side in SIDES:
            result = run(ply, work / "+".join(case) / side, side)
            record = result.relax.record
            assert record["flipped"] == 0 and record["boundary_overlap"] == 0, (case, side)
            ours, theirs = away_rms(result, near)[0], away_rms(clean[side], near)[0]
            rms.append(f"{100 * (ours / theirs - 1):+.1f} %")
            mine, base = (r["important_zone"]["length_error_median_pct"] for r in (record, clean[side].relax.record))
            zone.append(f"{mine:.2f} / {base:.2f}")
            did.append(f"{side}: {what_the_rollout_did(result.rollout.record)}")
        rows.append(f"| {' + '.join(case)} | {rms[0]} | {rms[1]} | {zone[0]} | {zone[1]} | {'; '.join(did)} |")
    return rows


def real_rows(work: Path, data: Path) -> list[str]:
    """The real scans' table rows (both sides each), their runs written under ``work``."""
    rows = []
    for name, units in REAL:
        for side in SIDES:
            result = run(data / name, work / "real" / f"{Path(name).stem}-{side}", side, units)
            folded = result.rollout.record["folded"]
            flips = result.relax.record["flipped"]
            places = folded.get("regions_total", len(folded.get("regions") or []))
            bands = ", ".join(f"{r['band'][0]:.2f}-{r['band'][1]:.2f}" for r in (folded.get("regions") or [])[:2])
            rows.append(f"| {Path(name).stem} | {side} | {folded['faces']} | {folded['area_mm2']:.0f} | "
                        f"{folded['percent_of_surface']:.2f} | {places} | {bands or '-'} | {flips} |")
    return rows


def table(corpus: list[str], real: list[str], command: str) -> str:
    """The block of docs/robustness.md: the corpus' table, then the real scans'."""
    return "\n".join([
        f"`{command}` ({machine()}):", "",
        "| defect | outer: edge RMS away, against clean | inner | outer: zone median length error % (defective / clean) "
        "| inner | faces the rollout found folded, trimmed, left out |",
        "|---|---:|---:|---:|---:|---|", *corpus, "",
        "| real scan | side | faces folded | mm² | % of the surface | places | largest places' bands | flipped in the image |",
        "|---|---|---:|---:|---:|---:|---|---:|", *real, ""])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder of the real scans")
    ap.add_argument("--write", action="store_true", help="update the section in docs/robustness.md")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        body = table(corpus_rows(work), real_rows(work, args.data),
                     command_line("defect_corpus.py", argv if argv is not None else sys.argv[1:]))
    publish(BLOCK, body, args.write)


if __name__ == "__main__":
    main()
