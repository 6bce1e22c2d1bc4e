"""The benchmarks' measuring code against the library as it is: a changed result type would
otherwise only show when a benchmark is next run (bench_relax reads relax()'s results)."""
from __future__ import annotations

import math

from _bench_meshes import load_benchmark


def test_bench_relax_measures_a_small_vessel(tmp_path, monkeypatch):
    bench = load_benchmark("bench_relax")
    monkeypatch.setattr(bench, "CACHE", tmp_path)
    row = bench._worker(0.003, "preview", 60.0, None)
    assert row["vertices"] > 2000 and row["iterations"] > 0 and row["flipped"] == 0
    assert row["boundary_overlap"] == 0
    assert math.isclose(row["seconds"], row["solve"] + row["setup"]) and row["seconds"] > 0
    assert list(tmp_path.iterdir())  # the vessel went to the cache it was given
