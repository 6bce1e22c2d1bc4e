"""The display mesh the page draws: the flattening's surface, decimated for a large scan.

A scan of millions of vertices is drawn from a copy of about :data:`DISPLAY_FACES` faces
made by the relaxation's own coarse copy (:func:`potflat.relax.simplify.grid_simplification`:
square cells of the flat layout, one vertex per occupied cell at its vertices' mean 3D and
flat position). Clustering in the flat layout never joins the two sides of the seam, and the
copy's triangles are near-regular. Each display vertex carries its flat position in the
image's pixels (the second texture-coordinate set: the page textures the vessel with the
baked image through it) and its importance (the painted zone's outline). Picking and measuring
go back to the full mesh (:mod:`potflat.view.scene`). The seam is drawn from the full mesh's
cut edges (:func:`seam_segments`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from potflat.mesh._kernels.topology import first_equal_rows
from potflat.mesh.boundary import edges_and_boundary
from potflat.relax.simplify import cell_side, grid_simplification
from potflat.types import FlatMesh

#: Faces of the display mesh of a large scan (a smaller scan is drawn whole).
DISPLAY_FACES = 200_000


@dataclass(frozen=True)
class DisplayMesh:
    """The surface the page draws.

    Attributes
    ----------
    vertices : (k, 3) float32
        Scan coordinates.
    pixels : (k, 2) float32
        Flat position in the image's pixels (column, row; ``(0, 0)`` the top-left corner).
    importance : (k,) float32
        0 plain surface .. 1 painting (all 1 when the run has no painted zone).
    faces : (m, 3) uint32
        Counter-clockwise seen from outside.
    decimated : bool
        Whether this is a coarse copy (False: the full mesh).
    """

    vertices: np.ndarray
    pixels: np.ndarray
    importance: np.ndarray
    faces: np.ndarray
    decimated: bool

    def as_bytes(self) -> bytes:
        """The arrays the page reads, little-endian, one after the other: vertices (float32),
        pixels (float32), importance (float32), faces (uint32)."""
        parts = (self.vertices.astype("<f4"), self.pixels.astype("<f4"), self.importance.astype("<f4"),
                 self.faces.astype("<u4"))
        return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)

    def counts(self) -> dict:
        """Lengths of the arrays in :meth:`as_bytes`."""
        return {"vertices": len(self.vertices), "faces": len(self.faces)}


def display_mesh(flat: FlatMesh, pixels: np.ndarray, *, faces: int = DISPLAY_FACES) -> DisplayMesh:
    """The display mesh of ``flat``: the full mesh up to ``faces`` faces, else a coarse copy.

    Parameters
    ----------
    flat : FlatMesh
        The relaxed flattening.
    pixels : (n, 2) float64
        Each vertex's position in the image (column, row).
    faces : int
        Largest face count drawn whole; a larger mesh is decimated to about this many.
    """

    V, F = flat.mesh.vertices, flat.mesh.faces
    n = len(V)
    importance = np.ones(n) if flat.importance is None else np.asarray(flat.importance, np.float64)
    if len(F) <= faces:
        return DisplayMesh(vertices=V.astype(np.float32), pixels=np.asarray(pixels, np.float32),
                           importance=importance.astype(np.float32), faces=F.astype(np.uint32), decimated=False)
    side = cell_side(pixels, 2.0 * n / faces)  # a cell gives two triangles
    s = grid_simplification(V, pixels, side)
    count = np.bincount(s.cluster, minlength=len(s.vertices)).astype(np.float64)
    mean_importance = np.bincount(s.cluster, importance, minlength=len(s.vertices)) / np.maximum(count, 1.0)
    return DisplayMesh(vertices=s.vertices.astype(np.float32), pixels=s.uv.astype(np.float32),
                       importance=mean_importance.astype(np.float32), faces=s.faces.astype(np.uint32), decimated=True)


def seam_segments(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The boundary edges of a cut mesh that lie on the cut: both ends have a copy on the
    other side (the same position, another vertex). Shape (s, 2, 3) float32."""

    n = len(vertices)
    V = np.ascontiguousarray(vertices, np.float64) + 0.0  # -0.0 as 0.0: equal positions, equal bits
    rep = first_equal_rows(V.view(np.int64), False, np.zeros(n, bool))
    copies = np.bincount(rep, minlength=n)[rep] > 1
    _, segments, _ = edges_and_boundary(faces, n)
    on_cut = copies[segments[:, 0]] & copies[segments[:, 1]]
    return np.ascontiguousarray(V[segments[on_cut]], dtype=np.float32).reshape(-1, 2, 3)
