"""Real museum scans at full resolution beside the synthetic vessel: upsampled copies of the
shared real scans and the generated amphora of ``bench_scale.py`` at the same sizes, through
``potflat run`` with the defaults, side by side in one run.

Each scan of ``--data`` (default ``../shared/data/real`` beside the repository) is read as
potflat reads it, without cleaning (exact welding only, so stray pieces, pinholes and
non-manifold joins stay), and refined to each target vertex count by midpoint subdivision:
every triangle into 4 (the new vertex of an edge at its 3D midpoint, each face corner's
texture coordinates carried to the midpoint of its two corners, so texture seams stay
seams) while that stays under the target, then the longest edges are split (their triangles
into 2, 3 or 4, the shorter diagonal of a quadrilateral) up to the target exactly. Textured
copies are written as OBJ + MTL + the scan's own texture image, untextured ones as binary
PLY, both in millimetres. The copies are cached in ``--out`` (a later run reuses a copy
made with the same settings); the native scan itself is the ``native`` size. The synthetic
vessel (``synthetic``: :func:`bench_scale.make_scan`, an 8192 x 8192 atlas) is generated at
each size but ``native``, cached alike.

Then, size after size, each scan runs through ``python -m potflat_cli run COPY -o DIR
--json`` in its own process (:func:`_run.run_potflat`: resident memory sampled every 0.1 s;
a failure is a row, not an abort) and the row is read off the JSON sidecars: stage times
(and the rollout's steps), time per vertex, relax iterations per level, flipped triangles
and boundary crossings (of the rollout and of the result, or of the refusal), the painted
zone's length error (median, p95), the share of the scan's surface in the image, the
outline's total turning (sum of absolute exterior angles over 2 pi, all boundary loops) of
the rollout and the relaxed layout and of the scan's boundary on the surface (what a layout
keeping every triangle's shape turns), and the peak memory. Below the table, each real scan's
whole run at 1M vertices against the synthetic vessel's.

Reproduce::

    python benchmarks/real_scans.py --out /tmp/real --sizes native 0.1e6 0.3e6 1e6 3e6 --write
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, publish  # noqa: E402
from _run import run_potflat, warm_kernels  # noqa: E402
from bench_scale import make_scan  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real"
SCANS = ("dragon-jar.glb", "colonoware-pot.glb", "plastic-vase.ply", "sea-vase.ply", "goblet.stl")
#: The synthetic vessel's name in ``--scans`` and the table, and its atlas (as bench_scale's).
SYNTHETIC = "synthetic"
SYNTHETIC_TEXTURE = 8192
#: Target: a real scan's whole run at 1M vertices within this multiple of the synthetic vessel's.
GOAL_RATIO = 1.5
BLOCK = "real_scans"
#: The copy's settings: a cached copy made with other settings is made again.
COPY_VERSION = 1

# local corner indices of a face being split: corners 0-2, then the midpoints of edges
# 0-1, 1-2, 2-0 as 3-5 (after rotating the face so that its split edges come first)
_ONE = np.array([[0, 3, 2], [3, 1, 2]])  # edge 0-1 split
_TWO = {True: np.array([[3, 1, 4], [0, 3, 4], [0, 4, 2]]),  # edges 0-1, 1-2 split; diagonal 0-4
        False: np.array([[3, 1, 4], [0, 3, 2], [3, 4, 2]])}  # diagonal 3-2
_ALL = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])


def split_edges(vertices: np.ndarray, faces: np.ndarray, texcoords: np.ndarray | None,
                n_split: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Split edges at their midpoints: all of them (``n_split`` None: each triangle into 4) or
    the ``n_split`` longest (their triangles into 2, 3 or 4).

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    texcoords : (m, 3, 2) float64 or None
        Per face corner; a new corner gets the mean of its edge's two corners in that face.
    n_split : int or None

    Returns
    -------
    vertices : (n + s, 3) float64
    faces : (m', 3) int64
        Counter-clockwise as the input.
    texcoords : (m', 3, 2) float64 or None
    """
    from potflat.mesh._kernels.topology import edge_table

    F = np.ascontiguousarray(faces, np.int64)
    edge_of, edges, _, _ = edge_table(F, len(vertices))
    if n_split is None:
        chosen = np.arange(len(edges))
    else:
        length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
        chosen = np.sort(np.argsort(-length, kind="stable")[:n_split])
    new_id = np.full(len(edges), -1, np.int64)
    new_id[chosen] = len(vertices) + np.arange(len(chosen))
    V = np.concatenate([vertices, 0.5 * (vertices[edges[chosen, 0]] + vertices[edges[chosen, 1]])])
    mid = new_id[edge_of.reshape(-1, 3)]  # (m, 3): midpoint of edge k (corner k to k + 1)
    split = mid >= 0
    ns = split.sum(axis=1)
    # rotate each face so that its split edges come first: one split edge -> edge 0; two ->
    # edges 0 and 1 (the unsplit one last)
    shift = np.zeros(len(F), np.int64)
    shift[ns == 1] = np.argmax(split[ns == 1], axis=1)
    shift[ns == 2] = (np.argmin(split[ns == 2], axis=1) + 1) % 3
    order = (np.arange(3)[None, :] + shift[:, None]) % 3
    rows = np.arange(len(F))[:, None]
    ids = np.concatenate([F[rows, order], mid[rows, order]], axis=1)  # (m, 6)
    tc = None
    if texcoords is not None:
        corners = texcoords[rows, order]  # (m, 3, 2)
        tc = np.concatenate([corners, 0.5 * (corners + np.roll(corners, -1, axis=1))], axis=1)  # (m, 6, 2)
    out_f, out_t = [], []

    def emit(sel: np.ndarray, template: np.ndarray) -> None:
        out_f.append(ids[sel][:, template].reshape(-1, 3))
        if tc is not None:
            out_t.append(tc[sel][:, template].reshape(-1, 3, 2))

    emit(ns == 0, np.array([[0, 1, 2]]))
    emit(ns == 1, _ONE)
    two = np.flatnonzero(ns == 2)
    d04 = np.linalg.norm(V[ids[two, 0]] - V[ids[two, 4]], axis=1)
    d32 = np.linalg.norm(V[ids[two, 3]] - V[ids[two, 2]], axis=1)
    emit(two[d04 <= d32], _TWO[True])
    emit(two[d04 > d32], _TWO[False])
    emit(ns == 3, _ALL)
    return V, np.concatenate(out_f), (np.concatenate(out_t) if tc is not None else None)


def upsample(vertices: np.ndarray, faces: np.ndarray, texcoords: np.ndarray | None, target: int):
    """Midpoint subdivision to ``target`` vertices: whole 1-to-4 steps while they stay at or
    under it, then the longest edges split up to it (see the module docstring)."""
    from potflat.mesh._kernels.topology import edge_table

    V, F, T = vertices, faces, texcoords
    while True:
        n_edges = len(edge_table(np.ascontiguousarray(F, np.int64), len(V))[1])
        if len(V) + n_edges > target:
            break
        V, F, T = split_edges(V, F, T)
    if target > len(V):
        V, F, T = split_edges(V, F, T, target - len(V))
    return V, F, T


def _write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    from potflat.io.atomic import atomic_path

    head = (f"ply\nformat binary_little_endian 1.0\ncomment units mm\nelement vertex {len(vertices)}\n"
            "property double x\nproperty double y\nproperty double z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    rec = np.empty(len(faces), dtype=[("k", "u1"), ("f", "<i4", 3)])
    rec["k"], rec["f"] = 3, faces
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(head)
            fh.write(np.ascontiguousarray(vertices, "<f8").tobytes())
            fh.write(rec.tobytes())


def make_copy(scan: Path, target: int, folder: Path) -> tuple[Path, dict]:
    """The copy of ``scan`` refined to ``target`` vertices, in ``folder`` (reused when a copy
    with the same settings is there); its path and figures (vertices, faces, 3D area mm²)."""
    from potflat.io.obj import write_textured_obj
    from potflat.io.scan import load_scan
    from potflat.types import mm_per_unit

    settings = {"scan": scan.name, "size": scan.stat().st_size, "target": target, "version": COPY_VERSION}
    record = folder / "copy.json"
    if record.is_file():
        kept = json.loads(record.read_text())
        if kept.get("settings") == settings and (folder / kept["file"]).is_file():
            return folder / kept["file"], kept["info"]
    folder.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    mesh = load_scan(scan, clean=False).mesh
    V, F, T = upsample(mesh.vertices * mm_per_unit(mesh.units), mesh.faces, mesh.texcoords, target)
    if T is not None:
        image = folder / f"{scan.stem}-texture{mesh.texture_path.suffix}"
        shutil.copyfile(mesh.texture_path, image)
        vt, corner = np.unique(T.reshape(-1, 2), axis=0, return_inverse=True)
        path = write_textured_obj(folder / f"{scan.stem}.obj", V, F, vt, corner.reshape(-1, 3), image.name,
                                  header=f"{scan.name} upsampled to {len(V)} vertices by midpoint subdivision, "
                                         "units mm")
    else:
        path = folder / f"{scan.stem}.ply"
        _write_ply(path, V, F)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    info = {"vertices": len(V), "faces": len(F), "area_mm2": float(area), "make_s": time.perf_counter() - t}
    record.write_text(json.dumps({"settings": settings, "file": path.name, "info": info}))
    return path, info


def native_info(scan: Path) -> dict:
    """Vertices, faces and 3D area (mm²) of a scan as read (exact welding only)."""
    from potflat.io.scan import load_scan
    from potflat.types import mm_per_unit

    mesh = load_scan(scan, clean=False).mesh
    V, F = mesh.vertices * mm_per_unit(mesh.units), mesh.faces
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    return {"vertices": len(V), "faces": len(F), "area_mm2": float(area)}


def _load(path: Path) -> dict:
    return json.loads(path.read_text()) if path.is_file() else {}


def figures(out: Path, name: str, run: dict, area_mm2: float) -> dict:
    """One row's figures from the sidecars in ``out`` (whatever stages were written)."""
    ro, re_, ba = (_load(out / f"{name}.{s}.json") for s in ("rollout", "relaxed", "bake"))
    row: dict = {k: run[k] for k in ("rc", "error", "wall_s", "cpu_s", "peak_gb")}
    t = ro.get("timings", {})
    row["rollout_s"] = t.get("total")
    row["steps"] = {k: v for k, v in t.get("rollout_steps", {}).items() if k != "total"}
    row["relax_s"] = re_.get("timings", {}).get("total")
    row["bake_s"] = ba.get("timings", {}).get("total")
    row["rollout_overlap"] = ro.get("boundary_overlap")
    row["levels"] = [(lv.get("level"), lv.get("iterations")) for lv in re_.get("levels", [])]
    row["notes"] = re_.get("notes", [])
    row["flipped"] = re_.get("flipped")
    row["crossings"] = re_.get("boundary_overlap")
    m = re.search(r"(\d+) flipped triangles and (\d+) boundary crossings", run["error"])
    if m:
        row["flipped"], row["crossings"] = int(m.group(1)), int(m.group(2))
    zone = re_.get("important_zone") or {}
    imp = ro.get("importance") or {}
    row["zone"] = _zone(imp)
    row["zone_err"] = (zone.get("length_error_median_pct"), zone.get("length_error_p95_pct"))
    row["in_image_pct"] = 100 * ba["surface_area_mm2"] / area_mm2 if "surface_area_mm2" in ba else None
    turning = re_.get("outline_turning") or {}
    row["turning"] = (ro.get("outline_turning"), turning.get("relaxed"), turning.get("surface"))
    return row


def _zone(importance: dict) -> str:
    """The painted zone's share of the rollout, or why there is none, in a word or two."""
    reason = importance.get("reason", "")
    if not importance:
        return "-"
    if not importance.get("uniform"):
        return f"{100 * importance['zone_fraction']:.0f}%"
    return "all over" if reason.startswith("painted all") else "no colours" if reason.startswith("no texture") else "none"


def _f(x, fmt: str = ".1f") -> str:
    return "-" if x is None else format(x, fmt)


def _per_vertex(seconds: float | None, vertices: int) -> str:
    return _f(None if seconds is None else 1e6 * seconds / vertices, ".0f")


def ratios(rows: list[dict], size: int = 1_000_000) -> list[str]:
    """Each real scan's whole run at ``size`` vertices against the synthetic vessel's, wall and CPU."""
    at = {r["scan"]: r for r in rows if r["size"] == size and r["rc"] == 0}
    synthetic = at.get(SYNTHETIC)
    if synthetic is None:
        return []
    out = [f"Whole run at {size / 1e6:g}M vertices, real scan / synthetic vessel (target at most {GOAL_RATIO:g}): "
           + ", ".join(f"{name} {r['wall_s'] / synthetic['wall_s']:.2f} (CPU {r['cpu_s'] / synthetic['cpu_s']:.2f})"
                       for name, r in at.items() if name != SYNTHETIC) + "."]
    return out if len(at) > 1 else []


def table(rows: list[dict], command: str) -> str:
    """The block of docs/performance.md: one row per scan and size, then the ratios."""
    lines = [f"`{command}` ({machine()}):", "",
             "| scan | vertices | result | rollout s | unroll s | untangle s | relax s | bake s | whole s (CPU s) "
             "| rollout / relax / CPU us per vertex | peak GB | iterations | flips | crossings | turning | zone "
             "| zone error % | image % |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---|---:|---|---:|---|---|---|---|---:|"]
    for r in rows:
        result = "image" if r["rc"] == 0 else ("refused: " + r["error"][:60] if r["error"] else f"exit {r['rc']}")
        v = r["vertices"]
        lines.append("| " + " | ".join([
            r["scan"], f"{v:,}", result, _f(r["rollout_s"]), _f(r["steps"].get("unroll")),
            _f(r["steps"].get("untangle")), _f(r["relax_s"]), _f(r["bake_s"]),
            f"{_f(r['wall_s'])} ({_f(r['cpu_s'], '.0f')})",
            " / ".join([_per_vertex(r["rollout_s"], v), _per_vertex(r["relax_s"], v), _per_vertex(r["cpu_s"], v)]),
            _f(r["peak_gb"], ".2f"), " ".join(str(it) for _, it in r["levels"]) or "-", _f(r["flipped"], "d"),
            f"{_f(r['rollout_overlap'], 'd')} / {_f(r['crossings'], 'd')}",
            f"{_f(r['turning'][0])} / {_f(r['turning'][1])} ({_f(r['turning'][2])})", r["zone"],
            f"{_f(r['zone_err'][0])} / {_f(r['zone_err'][1])}", _f(r["in_image_pct"])]) + " |")
    return "\n".join(lines + [""] + ratios(rows) + [""])


def _size(text: str) -> str | int:
    if text == "native":
        return text
    try:
        return int(float(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a size is 'native' or a vertex count, got {text!r}") from None


def _scan_at(name: str, size: str | int, data: Path, folder: Path) -> tuple[Path, dict] | None:
    """The file of scan ``name`` at ``size`` (made or reused in ``folder``) and its vertices,
    faces and area (mm²); None for the synthetic vessel's ``native`` and a real scan's sizes at
    or below its native one."""
    if name == SYNTHETIC:
        if size == "native":
            return None
        print(f"synthetic vessel with {size:,} vertices ...", flush=True)
        path, _ = make_scan(size, folder / "scan", texture_size=SYNTHETIC_TEXTURE)
        return path, native_info(path)
    native = native_info(data / name)
    if size == "native":
        return data / name, native
    if size <= native["vertices"]:  # (subdivision only adds vertices)
        return None
    print(f"{name}: copy with {size:,} vertices ...", flush=True)
    return make_copy(data / name, size, folder / "copy")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for the copies (kept, reused) and the runs")
    ap.add_argument("--sizes", type=_size, nargs="+", default=["native", 100_000, 300_000, 1_000_000, 3_000_000],
                    help="'native' and/or vertex counts (default: native 0.1e6 0.3e6 1e6 3e6)")
    ap.add_argument("--scans", nargs="+", default=[*SCANS, SYNTHETIC],
                    help=f"file names in --data and/or '{SYNTHETIC}' (default: all five and {SYNTHETIC})")
    ap.add_argument("--data", type=Path, default=DATA, help="folder of the real scans")
    ap.add_argument("--run-options", default="", help="more options for every `potflat run`, one string")
    ap.add_argument("--no-warm", action="store_true", help="skip compiling the kernels first")
    ap.add_argument("--write", action="store_true", help="update the section in docs/performance.md")
    args = ap.parse_args(argv)

    if not args.no_warm:
        warm_kernels()
    rows = []
    for size in args.sizes:
        for name in args.scans:
            folder = args.out / Path(name).stem / str(size)
            found = _scan_at(name, size, args.data, folder)
            if found is None:
                continue
            path, info = found
            print(f"{name} ({info['vertices']:,} vertices): potflat run ...", flush=True)
            run = run_potflat(path, folder / "run", tuple(args.run_options.split()))
            row = {"scan": Path(name).stem, "size": size, "vertices": info["vertices"],
                   **figures(folder / "run", path.stem, run, info["area_mm2"])}
            print(f"  {'image' if run['rc'] == 0 else 'FAILED: ' + run['error']} in {run['wall_s']:.1f} s, "
                  f"{run['cpu_s']:.0f} s CPU, {run['peak_gb']:.2f} GB", flush=True)
            (folder / "row.json").write_text(json.dumps(row, indent=1, default=str))
            rows.append(row)
    publish(BLOCK, table(rows, command_line("real_scans.py", argv if argv is not None else sys.argv[1:])), args.write)


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
