"""Compare two output folders of ``potflat run`` (before and after a change).

Usage: ``python benchmarks/compare_outputs.py BEFORE AFTER``

Every PLY, PNG, TIFF, CSV and SVG must be byte-identical; every JSON equal once timings
(keys ``seconds`` and ``timings``), the versions of the provenance record, the checksums of
input JSON files (they hold timings) and the folder part of file paths are set aside. Prints
one line per file and exits 1 on any difference or on a file that is in one folder only.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

BYTE_EXACT = (".ply", ".png", ".tif", ".tiff", ".csv", ".svg")
TIMING_KEYS = ("seconds", "timings")


def _normalised(node, folder: str):
    """``node`` with timings and versions dropped and ``folder`` cut from path strings."""
    if isinstance(node, dict):
        # the checksum of an input JSON (a provenance record) covers that JSON's timings
        json_input = str(node.get("path", "")).endswith(".json")
        return {k: ("<timing>" if k in TIMING_KEYS else "<versions>" if k == "versions"
                    else "<checksum of a JSON>" if json_input and k == "sha256"
                    else _normalised(v, folder)) for k, v in node.items()}
    if isinstance(node, list):
        return [_normalised(v, folder) for v in node]
    if isinstance(node, str):
        return node.replace(folder, "<folder>")
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


def compare(before: Path, after: Path) -> list[str]:
    """Lines describing every difference between the two folders (empty: none)."""
    problems = []
    names = sorted({p.relative_to(before) for p in before.rglob("*") if p.is_file()}
                   | {p.relative_to(after) for p in after.rglob("*") if p.is_file()})
    for name in names:
        a, b = before / name, after / name
        if not (a.is_file() and b.is_file()):
            problems.append(f"{name}: in one folder only")
        elif name.suffix.lower() in BYTE_EXACT:
            same = a.read_bytes() == b.read_bytes()
            print(f"{'identical' if same else 'DIFFERENT'}  {name}")
            if not same:
                problems.append(f"{name}: bytes differ")
        elif name.suffix.lower() == ".json":
            diffs = _json_differences(_normalised(json.loads(a.read_text()), str(a.parent)),
                                      _normalised(json.loads(b.read_text()), str(b.parent)))
            print(f"{'equal    ' if not diffs else 'DIFFERENT'}  {name}")
            problems += [f"{name}{d}" for d in diffs]
    return problems


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    problems = compare(Path(argv[0]), Path(argv[1]))
    for line in problems:
        print(line)
    print("no differences" if not problems else f"{len(problems)} differences")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
