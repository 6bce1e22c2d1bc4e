"""How faithful painted figures come out in a flattening: circles of known radius, measured.

Used by ``benchmarks/bench_figures.py`` and the tests (``tests/_bench_meshes.py`` loads it).

A painted circle is the part of the surface within a 3D distance ``radius`` of its centre
(:class:`potflat_synthetic.vessels.PaintedCircle`, the circles of a ``*.truth.json``). It is measured
on a fine sample of the surface, so the result does not depend on how the mesh's triangles
meet the circle's outline: every face near the circle is cut into ``subdivisions**2`` equal
sub-triangles whose centroids (3D) are kept when they lie within the radius; the same
barycentric points in the flattening give the circle's image. Per circle:

* ``faces``: faces whose 3D centroid lies inside the circle;
* ``coverage``: the sampled 3D area inside the circle over ``pi r^2`` (the exact area of a
  sphere cut by a ball around a point on it; within a few % on smooth vessels): below
  :data:`MIN_COVERAGE` the circle is not whole in the flattening (cut away, under a handle);
* ``area_ratio``: its flat area over its 3D area;
* ``anisotropy_p95``: the 95th percentile, weighted by 3D area inside the circle, of the
  per-face ``sigma_max / sigma_min`` (:func:`potflat.mesh.distortion.face_distortion`);
* ``width_mm``, ``height_mm``: ``4 sigma`` of the image region along ``u`` and along ``v``
  (``sigma`` its standard deviation for uniform density; a uniform disc of diameter ``d`` has
  ``sigma = d / 4``), in mm; ``elongation``: its long over short principal axis;
* ``split``: the image falls in more than one piece (the seam runs through the circle).

Circles that are not whole or are split are reported but left out of the aggregates.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from potflat.mesh.distortion import face_distortion, summarize, weighted_percentile
from potflat.types import FlatMesh

#: A circle whose sampled 3D area is below this share of ``pi r^2`` is not whole in the flattening.
MIN_COVERAGE = 0.95
#: Sub-triangles per face edge of the sampling (each face near a circle gives its square).
SUBDIVISIONS = 8


@dataclass(frozen=True)
class CircleFigures:
    """One circle in a flattening (see the module docs)."""

    faces: int
    coverage: float
    area_ratio: float
    anisotropy_p95: float
    width_mm: float
    height_mm: float
    elongation: float
    split: bool

    @property
    def whole(self) -> bool:
        """Whole in the flattening and in one piece: counted in the aggregates."""
        return self.coverage >= MIN_COVERAGE and not self.split


@dataclass(frozen=True)
class FigureSummary:
    """The circles of a flattening and the whole surface's figures.

    Attributes
    ----------
    circles : tuple of CircleFigures
        Per circle, in the order given.
    measured : int
        Circles counted in the aggregates (:attr:`CircleFigures.whole`).
    anisotropy_p95 : float
        95th percentile of the per-face anisotropy over all measured circles' surface
        (weighted by 3D area inside them).
    area_ratio : float
        Their flat area over their 3D area.
    width_mm, height_mm : (float, float)
        Smallest and largest circle width (along ``u``) and height (along ``v``), mm.
    elongation_max : float
        Largest long-over-short principal axis ratio of a circle's image.
    area_mean_abs_log : float
        Mean ``|log(A_2d / A_3d)|`` over the whole flattening (area-weighted).
    edge_rms : float
        Relative edge-length RMS of the whole flattening.
    flipped : int
        Faces with non-positive flat area.
    """

    circles: tuple
    measured: int
    anisotropy_p95: float
    area_ratio: float
    width_mm: tuple
    height_mm: tuple
    elongation_max: float
    area_mean_abs_log: float
    edge_rms: float
    flipped: int

    def as_dict(self) -> dict:
        """JSON-ready figures (per-circle figures as a list of dicts)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "circles"}
        out["circles"] = [c.__dict__ | {"whole": c.whole} for c in self.circles]
        return out


def _sub_barycentric(n: int) -> np.ndarray:
    """Barycentric coordinates ``(n*n, 3)`` of the centroids of a triangle's ``n*n`` equal
    sub-triangles (its edges cut in ``n``)."""
    pts = []
    for i in range(n):
        for j in range(n - i):
            pts.append(((i + 1 / 3) / n, (j + 1 / 3) / n))  # upward sub-triangles
            if i + j <= n - 2:
                pts.append(((i + 2 / 3) / n, (j + 2 / 3) / n))  # downward ones
    b = np.array(pts)
    return np.column_stack([1.0 - b.sum(axis=1), b])


def circle_list(circles) -> list[tuple[np.ndarray, float]]:
    """``(centre (3,), radius)`` of each circle given as objects with ``centre`` and ``radius``
    (:class:`potflat_synthetic.vessels.PaintedCircle`), dicts with those keys (a truth file's
    ``circles``) or pairs."""
    out = []
    for c in circles:
        if isinstance(c, dict):
            centre, radius = c["centre"], c["radius"]
        elif hasattr(c, "centre"):
            centre, radius = c.centre, c.radius
        else:
            centre, radius = c
        centre = np.asarray(centre, float).reshape(3)
        if not (np.isfinite(centre).all() and float(radius) > 0):
            raise ValueError(f"a circle needs a finite centre and a positive radius, got {centre}, {radius}")
        out.append((centre, float(radius)))
    return out


def truth_circles(path: str | Path, side: str = "outer") -> list[tuple[np.ndarray, float]]:
    """The circles of one side of a ``*.truth.json`` (``samples/generate.py``)."""
    data = json.loads(Path(path).read_text())
    return circle_list(c for c in data["circles"] if c.get("side", "outer") == side)


def measure_figures(flat: FlatMesh, circles, *, subdivisions: int = SUBDIVISIONS) -> FigureSummary:
    """Measure painted circles in a flattening (see the module docs).

    Parameters
    ----------
    flat : FlatMesh
        ``mesh.vertices`` (n, 3) in the circles' frame, ``uv`` (n, 2) in the same units,
        ``mesh.faces`` (m, 3).
    circles : iterable
        See :func:`circle_list`; centres in the frame of ``flat.mesh.vertices``, radii in its units.
    subdivisions : int
        Sub-triangles per face edge of the sampling.

    Returns
    -------
    FigureSummary
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    V, uv, F = flat.mesh.vertices, flat.uv, flat.mesh.faces
    mm = flat.mesh.mm_per_unit
    fd = face_distortion(V, uv, F)
    aniso = fd.anisotropy
    centroid = V[F].mean(axis=1)
    reach = float(np.linalg.norm(V[F] - centroid[:, None], axis=2).max()) if len(F) else 0.0
    tree = cKDTree(centroid)
    bary = _sub_barycentric(subdivisions)
    k = len(bary)
    per, pooled = [], []
    for centre, radius in circle_list(circles):
        near = np.asarray(tree.query_ball_point(centre, radius + reach), np.int64)
        inside_faces = int(np.count_nonzero(np.linalg.norm(centroid[near] - centre, axis=1) <= radius)) if len(near) else 0
        if len(near) == 0:
            per.append(CircleFigures(0, 0.0, math.nan, math.nan, math.nan, math.nan, math.nan, False))
            pooled.append(None)
            continue
        P3 = np.einsum("sk,fkd->fsd", bary, V[F[near]])  # (faces, k, 3)
        inside = np.linalg.norm(P3 - centre, axis=2) <= radius
        w3 = np.where(inside, (fd.area_3d[near] / k)[:, None], 0.0)
        w2 = np.where(inside, (np.abs(fd.area_2d[near]) / k)[:, None], 0.0)
        a3, a2 = float(w3.sum()), float(w2.sum())
        if a3 <= 0:
            per.append(CircleFigures(inside_faces, 0.0, math.nan, math.nan, math.nan, math.nan, math.nan, False))
            pooled.append(None)
            continue
        P2 = np.einsum("sk,fkd->fsd", bary, uv[F[near]])[inside]
        wq = w2[inside]
        mean = (wq[:, None] * P2).sum(axis=0) / wq.sum()
        d = P2 - mean
        cov = (wq[:, None, None] * d[:, :, None] * d[:, None, :]).sum(axis=0) / wq.sum()
        lam = np.linalg.eigvalsh(cov)
        hit = np.flatnonzero(inside.any(axis=1))
        # pieces: the faces that hold samples, joined where they share a flattening vertex
        sub = F[near[hit]]
        inc = coo_matrix((np.ones(sub.size), (np.repeat(np.arange(len(sub)), 3), sub.ravel())),
                         shape=(len(sub), len(V))).tocsr()
        pieces = connected_components(inc @ inc.T, directed=False)[0]
        wa = w3.sum(axis=1)[hit]
        per.append(CircleFigures(
            faces=inside_faces, coverage=a3 / (math.pi * radius**2), area_ratio=a2 / a3,
            anisotropy_p95=weighted_percentile(aniso[near[hit]], wa, 95.0),
            width_mm=4.0 * math.sqrt(cov[0, 0]) * mm, height_mm=4.0 * math.sqrt(cov[1, 1]) * mm,
            elongation=math.sqrt(lam[1] / lam[0]) if lam[0] > 0 else math.inf, split=pieces > 1))
        pooled.append((aniso[near[hit]], wa, a2, a3))
    use = [p for c, p in zip(per, pooled) if c.whole]
    s = summarize(V, uv, F)
    good = [c for c in per if c.whole]
    if use:
        an = weighted_percentile(np.concatenate([u[0] for u in use]), np.concatenate([u[1] for u in use]), 95.0)
        ratio = sum(u[2] for u in use) / sum(u[3] for u in use)
    else:
        an = ratio = math.nan
    span = (lambda vals: (min(vals), max(vals)) if vals else (math.nan, math.nan))
    return FigureSummary(
        circles=tuple(per), measured=len(good), anisotropy_p95=an, area_ratio=ratio,
        width_mm=span([c.width_mm for c in good]), height_mm=span([c.height_mm for c in good]),
        elongation_max=max((c.elongation for c in good), default=math.nan),
        area_mean_abs_log=s.area_mean_abs_log, edge_rms=s.edge_rms, flipped=s.flipped)
