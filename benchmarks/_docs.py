"""Writing a benchmark's section of ``docs/performance.md``."""
from __future__ import annotations

from pathlib import Path

#: The performance document the benchmarks write to.
PERFORMANCE_MD = Path(__file__).resolve().parents[1] / "docs" / "performance.md"


def write_section(section: str, doc: Path = PERFORMANCE_MD) -> None:
    """Replace the section of ``doc`` whose heading is ``section``'s first line (``## ...``),
    up to the next ``## `` heading, by ``section``; append it when there is none. Other
    sections are untouched."""
    heading = section.split("\n", 1)[0]
    text = doc.read_text() if doc.exists() else "# Performance\n"
    start = text.find(heading + "\n")
    if start < 0:
        text = text.rstrip("\n") + "\n\n" + section
    else:
        nxt = text.find("\n## ", start + len(heading))
        text = text[:start] + section.rstrip("\n") + "\n" + ("\n" + text[nxt + 1:] if nxt >= 0 else "")
    doc.write_text(text.rstrip("\n") + "\n")


def command_line(script: str, argv: list[str]) -> str:
    """The command that reproduces a benchmark's table: ``python benchmarks/SCRIPT`` and its
    arguments, less ``--keep DIR`` (where the files went is not part of the benchmark)."""
    given = list(argv)
    if "--keep" in given:
        del given[given.index("--keep"):given.index("--keep") + 2]
    return " ".join(["python", f"benchmarks/{script}", *(a for a in given if not a.startswith("--keep="))])


def publish(section: str, write: bool) -> None:
    """Print a benchmark's section; with ``write``, also put it into :data:`PERFORMANCE_MD`."""
    print(section)
    if write:
        write_section(section)
        print(f"updated {PERFORMANCE_MD}")
