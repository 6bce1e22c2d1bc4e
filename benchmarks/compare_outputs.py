"""Compare two output folders of ``potflat run`` (before and after a change).

Usage: ``python benchmarks/compare_outputs.py [--pixels] BEFORE AFTER``

Every PLY, PNG, TIFF, CSV and SVG must be byte-identical; every JSON equal once timings
(keys ``seconds`` and ``timings``), the versions of the provenance record and the folder
part of file paths (the file's own folder and the folder compared) are set aside, and with
them what follows only from a JSON file's timings: the SHA-256 of a JSON input and a JSON
file's size in a batch manifest. A CSV with a ``seconds`` column (the batch summary) is
compared with that column and the folders set aside. With ``--pixels`` a PNG is compared by
its decoded pixels and resolution (across a change of the deflate library). Prints one line
per file and exits 1 on any difference or on a file that is in one folder only.
"""
from __future__ import annotations

import csv
import io
import json
import sys
from pathlib import Path

BYTE_EXACT = (".ply", ".png", ".tif", ".tiff", ".csv", ".svg")
TIMING_KEYS = ("seconds", "timings")


def _set_aside(key: str, value, node: dict):
    """What stands for ``node[key]`` when it is, or follows only from, a timing or version."""
    if key in TIMING_KEYS:
        return "<timing>"
    if key == "versions":
        return "<versions>"
    if key == "sha256" and str(node.get("path", "")).endswith(".json"):
        return "<hash of a JSON with timings>"
    if key.endswith(".json") and isinstance(value, int):
        return "<size of a JSON with timings>"
    return None


def _normalised(node, folder: str, root: str):
    """``node`` with timings and versions dropped, ``folder`` and ``root`` cut from paths."""
    if isinstance(node, dict):
        out = {}
        for k, v in node.items():
            aside = _set_aside(k, v, node)
            out[k] = aside if aside is not None else _normalised(v, folder, root)
        return out
    if isinstance(node, list):
        return [_normalised(v, folder, root) for v in node]
    if isinstance(node, str):
        return node.replace(folder, "<folder>").replace(root, "<root>")
    return node


def _json_differences(a, b, where: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{where}/{k}: only in one" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            out += _json_differences(a[k], b[k], f"{where}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            out += _json_differences(x, y, f"{where}[{i}]")
        return out
    return [] if a == b else [f"{where}: {a!r} != {b!r}"[:300]]


def _timed_csv(path: Path) -> bool:
    header = path.read_text().splitlines()[:1]
    return bool(header) and "seconds" in header[0].split(",")


def _csv_rows(path: Path, folder: str) -> list[list[str]]:
    """The CSV's rows with the ``seconds`` column blanked and ``folder`` cut from cells."""
    rows = list(csv.reader(io.StringIO(path.read_text())))
    column = rows[0].index("seconds")
    return [rows[0]] + [[("" if i == column else cell.replace(folder, "<folder>"))
                         for i, cell in enumerate(row)] for row in rows[1:]]


def _same_png_pixels(a: Path, b: Path) -> bool:
    import numpy as np
    from PIL import Image

    with Image.open(a) as x, Image.open(b) as y:
        return (x.mode, x.size, x.info.get("dpi")) == (y.mode, y.size, y.info.get("dpi")) and np.array_equal(
            np.asarray(x), np.asarray(y))


def compare(before: Path, after: Path, *, pixels: bool = False) -> list[str]:
    """Lines describing every difference between the two folders (empty: none); ``pixels``:
    PNGs compared by their pixels."""
    problems = []
    names = sorted({p.relative_to(before) for p in before.rglob("*") if p.is_file()}
                   | {p.relative_to(after) for p in after.rglob("*") if p.is_file()})
    for name in names:
        a, b = before / name, after / name
        if not (a.is_file() and b.is_file()):
            problems.append(f"{name}: in one folder only")
        elif name.suffix.lower() == ".csv" and _timed_csv(a):
            same = _csv_rows(a, str(a.parent)) == _csv_rows(b, str(b.parent))
            print(f"{'equal    ' if same else 'DIFFERENT'}  {name}")
            if not same:
                problems.append(f"{name}: rows differ beyond the seconds column")
        elif pixels and name.suffix.lower() == ".png":
            same = _same_png_pixels(a, b)
            print(f"{'same px  ' if same else 'DIFFERENT'}  {name}")
            if not same:
                problems.append(f"{name}: pixels or resolution differ")
        elif name.suffix.lower() in BYTE_EXACT:
            same = a.read_bytes() == b.read_bytes()
            print(f"{'identical' if same else 'DIFFERENT'}  {name}")
            if not same:
                problems.append(f"{name}: bytes differ")
        elif name.suffix.lower() == ".json":
            diffs = _json_differences(
                _normalised(json.loads(a.read_text()), str(a.parent), str(before)),
                _normalised(json.loads(b.read_text()), str(b.parent), str(after)))
            print(f"{'equal    ' if not diffs else 'DIFFERENT'}  {name}")
            problems += [f"{name}{d}" for d in diffs]
    return problems


def main(argv: list[str]) -> int:
    pixels = "--pixels" in argv
    argv = [a for a in argv if a != "--pixels"]
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    problems = compare(Path(argv[0]), Path(argv[1]), pixels=pixels)
    for line in problems:
        print(line)
    print("no differences" if not problems else f"{len(problems)} differences")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
