"""Painted figures benchmark: how round and true to size painted circles come out.

Vessels generated like the samples (``potflat_synthetic.vessels.make_vessel``), painted only in a
panel or a belt (black glaze elsewhere) or all over, and the bundled amphora sample. Each is
written as OBJ + PNG and loaded as a user's scan would be; its painted circles (known
centre and radius) are measured in every flattening by ``benchmarks/_figures.py``.

Methods (one row each):

* ``rollout``: the whole vessel unrolled onto its proxy (cylinder, cone or sphere), not
  relaxed: what a proxy unrolling as in GigaMesh or CloudCompare gives;
* ``cut-out ARAP``, ``cut-out relax``: only the painted zone (the panel or belt; the sample's
  frieze belt), rolled out alone and flattened by libigl ARAP from the rollout, or relaxed
  by potflat with the springs alone (no importance, no shape term, no rescaling);
* ``ARAP``: the whole vessel, libigl ARAP from the rollout;
* ``ARAP, true scale``: the same flattening scaled as potflat's true scale scales its own
  (the area-weighted median length scale brought to 1): ARAP's result comes out 4-6% small,
  and the mean |log area ratio| depends on the scale, so this is the fair comparison of area;
* ``relax (springs)``: the whole vessel, potflat relax with the springs alone (no
  importance, no shape, rigidity or area term, no rescaling);
* the variants of :data:`VARIANTS` (or ``--variant NAME=JSON``): the whole vessel, keyword
  dicts of ``RolloutOptions`` (``importance``, ...) and ``RelaxOptions`` (``shape``,
  ``importance_contrast``, ``true_scale``, ``preset``, ...); a variant with a keyword this
  version does not have is skipped with a note;
* ``exact zone`` (vessels with a zone): the defaults with the painted zone itself (the panel
  or belt, exactly, hard-edged) as the importance instead of the zone found in the colours:
  what the detection could reach at best.

    python benchmarks/bench_figures.py                   # all vessels, about 40k vertices
    python benchmarks/bench_figures.py --quick           # 3 small cases, about a minute
    python benchmarks/bench_figures.py --variant 'shape1={"shape": 1.0}' --variants default
    python benchmarks/bench_figures.py --write --plot    # blocks bench_figures and bench_figures_knobs

With ``--write`` two blocks of docs/performance.md are rewritten: ``bench_figures`` (each vessel
under the rollout, libigl ARAP and potflat's defaults, with the targets of each row) and
``bench_figures_knobs`` (each variant on the vessels of :data:`KNOB_CASES`).

Targets, checked per row and listed under the table: panels within 10% of the cut-out's
anisotropy excess (its anisotropy p95 above 1), panels and belts within 2% of the cut-out's
area or nearer their true area than it (a belt's cut-out is nearly developable, so its
anisotropy is compared without a target); vessels painted all over at or below ARAP's
circle anisotropy with at least 10% less area distortion; the sample's circles within 5% of
20 mm.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from benchmarks._docs import command_line, machine, write_block  # noqa: E402

CACHE = Path(tempfile.gettempdir()) / "potflat-bench-figures"

#: Whole-vessel potflat variants: name -> rollout and relax keywords (the trade plot's points).
VARIANTS: dict[str, dict] = {
    "default": {},
    "shape 0": {"shape": 0.0},
    "shape 0.1": {"shape": 0.1},
    "shape 0.2": {"shape": 0.2},
    "shape 0.5": {"shape": 0.5},
    "shape 1": {"shape": 1.0},
    "shape 2": {"shape": 2.0},
    "rigidity 0": {"rigidity": 0.0},
    "rigidity 1": {"rigidity": 1.0},
    "rigidity 4": {"rigidity": 4.0},
    "area 0": {"area": 0.0},
    "area 1": {"area": 1.0},
    "area 4": {"area": 4.0},
    "limit 1.3": {"max_anisotropy": 1.3},
    "limit 1.45": {"max_anisotropy": 1.45},
    "no importance": {"importance": "none"},
}
#: The relax of the springs alone (no importance, no per-face terms, no rescaling): the keywords
#: this version has are used.
SPRINGS_ALONE = {"importance": "none", "shape": 0.0, "rigidity": 0.0, "area": 0.0, "importance_contrast": 1.0, "true_scale": False}
#: (kind, painting) of the generated vessels.
CASES = [(k, p) for k in ("hydria", "aryballos", "amphora") for p in ("panel", "belt", "allover")] + [
    ("alabastron", "allover")]
QUICK_CASES = [("hydria", "panel"), ("aryballos", "allover")]
SAMPLE = ROOT / "samples" / "data" / "amphora.obj"
#: The vessels of the knobs' table (vessel, painting).
KNOB_CASES = (("hydria", "panel"), ("hydria", "allover"), ("amphora sample", "frieze"))
#: Rows that are not potflat's whole-vessel variants.
REFERENCES = ("cut-out ARAP", "cut-out relax", "rollout", "ARAP", "ARAP, true scale", "relax (springs)")


# --------------------------------------------------------------------------- inputs


@dataclasses.dataclass
class Case:
    """One vessel: its scan, painted zone (None: painted all over) and circles."""

    name: str
    painting: str
    scan: Path
    zone: object  # callable: world points (k, 3) -> (k,) bool, or None
    circles: list


def _synthetic(kind: str, painting: str, n_vertices: int) -> Case:
    from potflat_synthetic.vessels import make_vessel, write_obj

    vessel = make_vessel(kind, n_vertices=n_vertices, seed=0, painting=painting, texture_size=2048)
    path = CACHE / f"{kind}-{painting}-{n_vertices}.obj"
    if not path.exists():
        CACHE.mkdir(exist_ok=True)
        write_obj(vessel, path)
    zone = vessel.painted_zone if painting != "allover" else None
    return Case(kind, painting, path, zone, [c for c in vessel.features if c.side == "outer"])


def _sample() -> Case:
    """The bundled amphora: its frieze circles; its cut-out is the frieze belt (the same
    vessel's ``belt`` painting gives the zone)."""
    from benchmarks._figures import truth_circles
    from potflat_synthetic.vessels import make_vessel

    truth = json.loads(SAMPLE.with_suffix(".truth.json").read_text())
    opts = {k: v for k, v in truth["options"].items() if v is not None}
    belt = make_vessel(opts.pop("kind"), **{**opts, "painting": "belt"})
    return Case("amphora sample", "frieze", SAMPLE, belt.painted_zone, truth_circles(SAMPLE.with_suffix(".truth.json")))


# --------------------------------------------------------------------------- methods


def _option_names() -> tuple[set, set]:
    """Field names of this version's ``RolloutOptions`` and ``RelaxOptions``."""
    from potflat.relax import RelaxOptions
    from potflat.rollout import RolloutOptions

    return {f.name for f in dataclasses.fields(RolloutOptions)}, {f.name for f in dataclasses.fields(RelaxOptions)}


def _split(keywords: dict) -> tuple[dict, dict] | str:
    """Rollout and relax keywords of a variant, or the note why it cannot run here."""
    roll, rel = _option_names()
    unknown = sorted(set(keywords) - roll - rel)
    if unknown:
        return f"this version has no option {', '.join(unknown)}"
    return ({k: v for k, v in keywords.items() if k in roll}, {k: v for k, v in keywords.items() if k in rel})


def _springs_alone() -> dict:
    """:data:`SPRINGS_ALONE` with the keywords this version has."""
    roll, rel = _option_names()
    return {k: v for k, v in SPRINGS_ALONE.items() if k in roll | rel}


def _row(case: Case, method: str, flat, seconds: float, **extra) -> dict:
    from benchmarks._figures import measure_figures

    m = measure_figures(flat, case.circles)
    return {"vessel": case.name, "painting": case.painting, "method": method, "vertices": len(flat.mesh.vertices),
            "circles": len(case.circles), "measured": m.measured, "anisotropy_p95": m.anisotropy_p95,
            "area_ratio": m.area_ratio, "width_mm": list(m.width_mm), "height_mm": list(m.height_mm),
            "area": m.area_mean_abs_log, "edge_rms": m.edge_rms, "flipped": m.flipped, "seconds": seconds, **extra}


def run_case(case: Case, variants: dict[str, dict], log=print) -> list[dict]:
    """All methods on one vessel; rows for the table."""
    import numpy as np

    from benchmarks._arap import libigl_arap
    from potflat.io.scan import load_scan
    from potflat.mesh.distortion import true_scale_factor
    from potflat.relax import relax
    from potflat.rollout import rollout

    mesh = load_scan(case.scan).mesh
    rows = []
    rollouts: dict[str, object] = {}

    def rolled(keywords: dict, face_mask=None):
        key = json.dumps(keywords, sort_keys=True) + ("cut" if face_mask is not None else "")
        if key not in rollouts:
            t0 = time.perf_counter()
            rollouts[key] = (rollout(mesh, face_mask=face_mask, **keywords), time.perf_counter() - t0)
        return rollouts[key]

    def relaxed(name: str, keywords: dict, face_mask=None, **extra):
        split = _split(keywords)
        if isinstance(split, str):
            log(f"  {case.name} {case.painting}: {name} skipped: {split}")
            return
        roll_kw, relax_kw = split
        r, t_roll = rolled(roll_kw, face_mask)
        try:
            res = relax(r.flat, **relax_kw)
        except Exception as exc:  # a failed variant is a row, not the end of the benchmark
            log(f"  {case.name} {case.painting}: {name} failed: {type(exc).__name__}: {exc}")
            return
        imp = r.importance
        rows.append(_row(case, name, res.flat, res.timings.setup + res.timings.solve,
                         zone_fraction=None if imp is None or imp.values is None else imp.zone_fraction,
                         keywords=keywords, **extra))

    def arap(name: str, flat, *, true_scale: bool = False, **extra):
        try:
            uv, _, secs = libigl_arap(flat)
        except RuntimeError as exc:  # libigl refuses some meshes (e.g. an isolated vertex): a note, not the end
            log(f"  {case.name} {case.painting}: {name} failed: {exc}")
            return
        rows.append(_row(case, name, flat.replace(uv=uv), secs, **extra))
        if true_scale:
            V, F = flat.mesh.vertices, flat.mesh.faces
            centre = uv.mean(axis=0)
            scaled = centre + (uv - centre) * true_scale_factor(V, uv, F, None)
            rows.append(_row(case, f"{name}, true scale", flat.replace(uv=scaled), secs, **extra))

    springs = _springs_alone()
    none_kw = {k: v for k, v in springs.items() if k == "importance"}
    if case.zone is not None:
        F = mesh.faces
        cut = case.zone(mesh.vertices[F].mean(axis=1))
        arap("cut-out ARAP", rolled(none_kw, cut)[0].flat, cut_out=True)
        relaxed("cut-out relax", springs, cut, cut_out=True)
    proxy, t_proxy = rolled(none_kw)
    rows.append(_row(case, "rollout", proxy.flat, t_proxy))
    arap("ARAP", proxy.flat, true_scale=True)
    relaxed("relax (springs)", springs)
    for name, kw in variants.items():
        relaxed(name, kw)
    if case.zone is not None:
        r, _ = rolled({})
        exact = case.zone(r.flat.mesh.vertices).astype(np.float64)
        res = relax(r.flat.replace(importance=exact))
        rows.append(_row(case, "exact zone", res.flat, res.timings.setup + res.timings.solve,
                         zone_fraction=float(exact.mean()), keywords={}))
    assert all(np.isfinite(row["area"]) for row in rows)
    return rows


# --------------------------------------------------------------------------- report


def _fmt_range(lo_hi) -> str:
    lo, hi = lo_hi
    return "-" if not (math.isfinite(lo) and math.isfinite(hi)) else f"{lo:.1f}-{hi:.1f}"


def table(rows: list[dict]) -> str:
    head = ("| vessel | painting | method | circles | circle anisotropy p95 | circles' area ratio | "
            "widths mm | heights mm | mean abs log area | edge RMS | flips | s |\n"
            "|---|---|---|---|---:|---:|---|---|---:|---:|---:|---:|\n")
    lines = []
    for r in rows:
        lines.append(f"| {r['vessel']} | {r['painting']} | {r['method']} | {r['measured']}/{r['circles']} | "
                     f"{r['anisotropy_p95']:.3f} | {r['area_ratio']:.3f} | {_fmt_range(r['width_mm'])} | "
                     f"{_fmt_range(r['height_mm'])} | {r['area']:.3f} | {r['edge_rms']:.3f} | {r['flipped']} | "
                     f"{r['seconds']:.1f} |")
    return head + "\n".join(lines) + "\n"


def _cases(rows: list[dict]) -> list[tuple[str, str]]:
    return list(dict.fromkeys((r["vessel"], r["painting"]) for r in rows))


def _pick(rows: list[dict], case: tuple[str, str]) -> dict[str, dict]:
    return {r["method"]: r for r in rows if (r["vessel"], r["painting"]) == case}


def compare_table(rows: list[dict]) -> str:
    """One line per vessel: the rollout, libigl ARAP and potflat's defaults side by side."""
    def cell(same: dict, methods: tuple[str, ...], key: str) -> str:
        return " / ".join(f"{same[m][key]:.3f}" if m in same else "-" for m in methods)

    lines = ["| vessel | painting | circles | circle anisotropy p95: rollout / ARAP / potflat (cut-out) "
             "| mean abs log area: rollout / ARAP / ARAP at true scale / potflat | potflat circles mm "
             "| s: ARAP / potflat |",
             "|---|---|---|---|---|---|---|"]
    for case in _cases(rows):
        same = _pick(rows, case)
        d = same.get("default")
        if d is None:
            continue
        cut = f" ({same['cut-out ARAP']['anisotropy_p95']:.3f})" if "cut-out ARAP" in same else ""
        arap_s = f"{same['ARAP']['seconds']:.1f}" if "ARAP" in same else "-"
        lines.append(f"| {case[0]} | {case[1]} | {d['measured']}/{d['circles']} | "
                     f"{cell(same, ('rollout', 'ARAP', 'default'), 'anisotropy_p95')}{cut} | "
                     f"{cell(same, ('rollout', 'ARAP', 'ARAP, true scale', 'default'), 'area')} | "
                     f"{_fmt_range(d['width_mm'])} x {_fmt_range(d['height_mm'])} | {arap_s} / {d['seconds']:.1f} |")
    return "\n".join(lines) + "\n"


def knobs_table(rows: list[dict]) -> str:
    """One line per variant: circle anisotropy p95, mean abs log area and seconds on each of
    :data:`KNOB_CASES` that ran."""
    cases = [c for c in KNOB_CASES if c in _cases(rows)]
    variants = list(dict.fromkeys(r["method"] for r in rows if r["method"] not in REFERENCES))
    lines = ["| variant | " + " | ".join(f"{v}, {p}: anisotropy p95 / area / s" for v, p in cases) + " |",
             "|---|" + "---|" * len(cases)]
    for name in variants:
        cells = []
        for case in cases:
            r = _pick(rows, case).get(name)
            cells.append("-" if r is None else f"{r['anisotropy_p95']:.3f} / {r['area']:.3f} / {r['seconds']:.1f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def targets(rows: list[dict]) -> list[str]:
    """The targets (module docs) for each whole-vessel potflat row (the variants)."""
    out = []
    for r in rows:
        if r["method"] in REFERENCES:
            continue
        same = {q["method"]: q for q in rows if q["vessel"] == r["vessel"] and q["painting"] == r["painting"]}
        checks = []
        if r["vessel"] == "amphora sample":
            ok = all(19.0 <= x <= 21.0 for x in r["width_mm"] + r["height_mm"])
            checks.append(f"circles {_fmt_range(r['width_mm'])} x {_fmt_range(r['height_mm'])} mm "
                          f"{'within' if ok else 'NOT within'} 20 mm +-5%")
        elif r["painting"] == "allover":
            a = same.get("ARAP")
            if a is None:
                continue
            ok1, ok2 = r["anisotropy_p95"] <= a["anisotropy_p95"], r["area"] <= 0.9 * a["area"]
            checks.append(f"anisotropy p95 {r['anisotropy_p95']:.3f} {'<=' if ok1 else '>'} ARAP's "
                          f"{a['anisotropy_p95']:.3f}; area {r['area']:.3f} {'<=' if ok2 else '>'} 0.9 x ARAP's "
                          f"{a['area']:.3f}")
            t = same.get("ARAP, true scale")
            if t is not None:
                checks.append(f"{100 * (r['area'] / t['area'] - 1):+.1f}% of the area distortion of ARAP at "
                              f"true scale ({t['area']:.3f})")
        else:
            c = same.get("cut-out ARAP")
            if c is None:
                continue
            darea = r["area_ratio"] / c["area_ratio"] - 1
            # (a figure nearer its true area than the cut-out's is no fault)
            truer = abs(r["area_ratio"] - 1) < abs(c["area_ratio"] - 1)
            verdict = "ok" if abs(darea) <= 0.02 else "nearer true area than the cut-out" if truer else "over 2%"
            area = (f"area ratio {r['area_ratio']:.3f}, {100 * darea:+.1f}% of the cut-out's {c['area_ratio']:.3f} "
                    f"({verdict})")
            if r["painting"] == "belt":  # a nearly developable cut-out: a share of its excess is no target
                checks.append(f"anisotropy p95 {r['anisotropy_p95']:.3f} against the cut-out's "
                              f"{c['anisotropy_p95']:.3f}, {area}")
            else:
                excess = (r["anisotropy_p95"] - 1) / max(c["anisotropy_p95"] - 1, 1e-9)
                checks.append(f"anisotropy excess {excess:.2f} x the cut-out's "
                              f"({'ok' if excess <= 1.1 else 'over 1.1'}), {area}")
        if r["flipped"]:
            checks.append(f"{r['flipped']} flips")
        out.append(f"- {r['vessel']} {r['painting']}, {r['method']}: " + "; ".join(checks))
    return out


def plot(rows: list[dict], path: Path) -> None:
    """Area distortion against circle anisotropy p95, one panel per vessel: a point per variant,
    ARAP and the springs alone beside them, the cut-out's anisotropy as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys((r["vessel"], r["painting"]) for r in rows))
    cols = min(4, len(cases))
    nrows = math.ceil(len(cases) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(3.6 * cols, 3.2 * nrows), squeeze=False)
    for ax, (vessel, painting) in zip(axes.ravel(), cases):
        sel = [r for r in rows if r["vessel"] == vessel and r["painting"] == painting]
        for r in sel:
            if r["method"] == "rollout":  # far off the trade curves: it would squeeze them
                continue
            if r.get("cut_out"):
                if r["method"] == "cut-out ARAP":
                    ax.axvline(r["anisotropy_p95"], ls="--", c="grey", lw=1)
                continue
            style = {"ARAP": ("s", "tab:red"), "ARAP, true scale": ("D", "tab:red"),
                     "relax (springs)": ("^", "tab:grey")}.get(r["method"], ("o", "tab:blue"))
            ax.plot(r["anisotropy_p95"], r["area"], style[0], c=style[1])
            ax.annotate(r["method"], (r["anisotropy_p95"], r["area"]), fontsize=6, xytext=(3, 2),
                        textcoords="offset points")
        for knob, colour in (("shape", "tab:blue"), ("rigidity", "tab:green"), ("area", "tab:orange")):
            curve = sorted((r["keywords"][knob], r["anisotropy_p95"], r["area"]) for r in sel
                           if set(r.get("keywords") or {}) == {knob})
            if len(curve) > 1:  # one setting's trade, the other at its default
                ax.plot([c[1] for c in curve], [c[2] for c in curve], "-", c=colour, lw=0.8, alpha=0.6)
        ax.set_title(f"{vessel}, {painting}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(cases):]:
        ax.axis("off")
    fig.supxlabel("circle anisotropy p95 (dashed: cut-out ARAP)", fontsize=8)
    fig.supylabel("mean |log area ratio|, whole surface", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def _variants(args) -> dict[str, dict]:
    names = list(VARIANTS) if args.variants is None else [n for n in args.variants.split(",") if n]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variant {', '.join(unknown)}; the table has {', '.join(VARIANTS)}")
    out = {n: VARIANTS[n] for n in names}
    for spec in args.variant or []:
        name, _, kw = spec.partition("=")
        try:
            out[name] = json.loads(kw)
        except json.JSONDecodeError as exc:
            raise SystemExit(f"--variant {spec!r}: give NAME=JSON, e.g. 'shape1={{\"shape\": 1.0}}' ({exc})") from None
        if not isinstance(out[name], dict):
            raise SystemExit(f"--variant {spec!r}: the JSON must be an object of option keywords")
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vertices", type=int, default=40000, help="vertices of the generated vessels")
    ap.add_argument("--cases", help="comma-separated kind:painting (default: all), or 'none'")
    ap.add_argument("--no-sample", action="store_true", help="leave out the bundled amphora")
    ap.add_argument("--variants", help=f"comma-separated names from the table ({', '.join(VARIANTS)}); default all")
    ap.add_argument("--variant", action="append", help="NAME=JSON keyword dict, added to the variants")
    ap.add_argument("--quick", action="store_true", help="2 small vessels, the sample, default variant only")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", type=Path, help="also dump the rows here")
    ap.add_argument("--write", action="store_true", help="rewrite blocks bench_figures and bench_figures_knobs of docs/performance.md")
    ap.add_argument("--plot", action="store_true", help="write the trade plot docs/img/figures_trade.png")
    args = ap.parse_args(argv)
    os.environ.setdefault("NUMBA_NUM_THREADS", str(args.threads))
    if args.quick:
        args.vertices = min(args.vertices, 10000)
        args.variants = args.variants or "default"
    variants = _variants(args)
    cases = QUICK_CASES if args.quick else CASES
    if args.cases:
        cases = [] if args.cases == "none" else [tuple(c.split(":")) for c in args.cases.split(",")]
    t_all = time.perf_counter()
    from benchmarks._meshes import vessel_rollout
    from potflat.relax import relax

    relax(vessel_rollout(300), preset="preview")  # compile the kernels before timing
    todo = [lambda k=k, p=p: _synthetic(k, p, args.vertices) for k, p in cases]
    if not args.no_sample:
        todo.append(_sample)
    rows = []
    for make in todo:
        case = make()
        t0 = time.perf_counter()
        case_rows = run_case(case, variants)
        rows += case_rows
        print(table(case_rows).split("\n", 2)[2].rstrip() + f"   [{time.perf_counter() - t0:.0f} s]", flush=True)
    total = time.perf_counter() - t_all
    command = command_line("bench_figures.py", list(argv if argv is not None else sys.argv[1:]))
    text = table(rows)
    goals = targets(rows)
    print("\n" + text + "\nTargets:\n" + "\n".join(goals))
    print(f"\nreproduce: {command}   ({total / 60:.1f} min)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.plot:
        plot(rows, ROOT / "docs" / "img" / "figures_trade.png")
    if args.write:
        head = f"`{command}` ({machine()}; generated vessels of {args.vertices:,} vertices):\n\n"
        write_block("bench_figures", head + compare_table(rows) + "\nTargets at the default:\n\n"
                    + "\n".join(g for g in goals if ", default:" in g) + "\n")
        write_block("bench_figures_knobs", head + knobs_table(rows)
                    + ("\n![area distortion against circle anisotropy](img/figures_trade.png)\n" if args.plot else ""))


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
