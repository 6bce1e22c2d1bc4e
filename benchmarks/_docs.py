"""The generated parts of the documents: each benchmark rewrites its own blocks.

A block is the text between ``<!-- begin: NAME -->`` and ``<!-- end: NAME -->`` in a Markdown
document; :data:`BLOCKS` says which document holds each. A benchmark run with ``--write``
replaces what lies between its markers and leaves every other line alone: the headings and
the hand-written reading of each table stay as they are.
"""
from __future__ import annotations

import os
import platform
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PERFORMANCE_MD = ROOT / "docs" / "performance.md"
ROBUSTNESS_MD = ROOT / "docs" / "robustness.md"
README_MD = ROOT / "README.md"
#: Every generated block: its name (the benchmark's, and a suffix when it writes several) and
#: the document that holds it.
BLOCKS = {
    "bench_scale": PERFORMANCE_MD,
    "bench_first_run": PERFORMANCE_MD,
    "bench_first_run_readme": README_MD,
    "bench_knobs": PERFORMANCE_MD,
    "bench_relax": PERFORMANCE_MD,
    "bench_bake": PERFORMANCE_MD,
    "bench_figures": PERFORMANCE_MD,
    "bench_figures_knobs": PERFORMANCE_MD,
    "bench_starts": ROBUSTNESS_MD,
    "defect_corpus": ROBUSTNESS_MD,
    "bench_view": PERFORMANCE_MD,
    "bench_relief": PERFORMANCE_MD,
    "real_scans": PERFORMANCE_MD,
    "relax_spread": PERFORMANCE_MD,
}


def markers(name: str) -> tuple[str, str]:
    """The begin and end lines of block ``name``."""
    return f"<!-- begin: {name} -->", f"<!-- end: {name} -->"


def replace_block(text: str, name: str, body: str) -> str:
    """``text`` with the lines between block ``name``'s markers replaced by ``body``.

    Raises ``ValueError`` naming the block when its markers are missing, repeated or out of
    order."""
    begin, end = markers(name)
    lines = text.split("\n")
    starts = [i for i, line in enumerate(lines) if line.strip() == begin]
    ends = [i for i, line in enumerate(lines) if line.strip() == end]
    if len(starts) != 1 or len(ends) != 1 or ends[0] < starts[0]:
        raise ValueError(f"block {name!r}: expected one {begin!r} line followed by one {end!r} line")
    return "\n".join(lines[:starts[0] + 1] + [body.strip("\n")] + lines[ends[0]:])


def write_block(name: str, body: str) -> None:
    """Replace block ``name`` of its document (:data:`BLOCKS`) by ``body``."""
    doc = BLOCKS[name]
    try:
        doc.write_text(replace_block(doc.read_text(), name, body))
    except ValueError as exc:
        raise SystemExit(f"{doc}: {exc}; add the two marker lines where the table belongs") from None


def command_line(script: str, argv: list[str]) -> str:
    """The command that reproduces a benchmark's table: ``python benchmarks/SCRIPT`` and its
    arguments, less ``--keep DIR`` and ``--json FILE`` (where files went is not part of the
    benchmark)."""
    given, out = list(argv), []
    skip = False
    for arg in given:
        if skip:
            skip = False
        elif arg in ("--keep", "--json"):
            skip = True
        elif not arg.startswith(("--keep=", "--json=")):
            out.append(arg if all(ch.isalnum() or ch in "-_,:.=/" for ch in arg) else f"'{arg}'")
    return " ".join(["python", f"benchmarks/{script}", *out])


def machine() -> str:
    """The machine in a few words: cores, architecture, Python."""
    return f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"


def publish(name: str, body: str, write: bool) -> None:
    """Print a benchmark's block; with ``write``, also put it into its document."""
    print(body)
    if write:
        write_block(name, body)
        print(f"updated {BLOCKS[name]} ({name})")
