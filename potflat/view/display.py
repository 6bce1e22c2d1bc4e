"""The meshes the page draws: the whole scan with its own texture, and the flattening's
surface linked to the image; both decimated for a large scan.

The whole scan (:func:`scan_display_mesh`) is the scan as loaded, parts left out of the
rollout included (handles, a trimmed rim top, the base, an inner wall). Above
:data:`DISPLAY_FACES` faces it is decimated by clustering its vertices in cubic cells of 3D
space. In a cell, the vertices joined by edges inside it make one vertex at their mean
position (two walls crossing a cell stay apart); its corners with the same texture
coordinates joined inside it make one display vertex at that position, with their mean
texture coordinates (the two sides of a texture seam stay apart and the copy has no cracks
along them). A face survives where its corners fall in three cells. Each display vertex says
what share of the vertices it stands for is in the flattening (the page hides those when it
draws the image on the vessel).

The flattening's surface (:func:`display_mesh`) is drawn from a copy made by the relaxation's
own coarse copy (:func:`potflat.relax.simplify.grid_simplification`: square cells of the flat
layout, one vertex per occupied cell at its vertices' mean 3D and flat position). Clustering in
the flat layout never joins the two sides of the seam, and the copy's triangles are
near-regular. Each display vertex carries its flat position in the image's pixels (the second
texture-coordinate set: the page textures the vessel with the baked image through it) and its
importance. Picking and measuring go back to the full mesh (:mod:`potflat.view.scene`). The
seam, the image's edge and the painted zone's outline are drawn from the full mesh
(:func:`boundary_segments`, :func:`level_segments`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.mesh._kernels.geometry import triangle_areas, vertex_normal_sums
from potflat.mesh._kernels.topology import first_equal_rows, union_find
from potflat.mesh.boundary import edges_and_boundary
from potflat.relax.simplify import cell_side, grid_simplification
from potflat.types import FlatMesh, Mesh

#: Faces of the display mesh of a large scan (a smaller scan is drawn whole).
DISPLAY_FACES = 200_000
#: Occupied cubic cells per (surface area / cell side squared): a surface crosses on average
#: 1.5 times as many cells as its area in cell faces (the mean of ``|nx| + |ny| + |nz|``).
CELLS_PER_AREA = 1.5
#: Texture coordinates of the display vertices of faces without texture (the page draws them plain).
NO_TEXTURE = -1.0


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
    spacing : float
        Side of the clustering cells, scan units (0: the full mesh).
    """

    vertices: np.ndarray
    pixels: np.ndarray
    importance: np.ndarray
    faces: np.ndarray
    decimated: bool
    spacing: float = 0.0

    def as_bytes(self) -> bytes:
        """The arrays the page reads, little-endian, one after the other: vertices (float32),
        pixels (float32), faces (uint32)."""
        parts = (self.vertices.astype("<f4"), self.pixels.astype("<f4"), self.faces.astype("<u4"))
        return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)

    def counts(self) -> dict:
        """Lengths of the arrays in :meth:`as_bytes`."""
        return {"vertices": len(self.vertices), "faces": len(self.faces), "spacing": self.spacing}


def display_mesh(flat: FlatMesh, pixels: np.ndarray, *, px_per_unit: float, faces: int = DISPLAY_FACES) -> DisplayMesh:
    """The display mesh of ``flat``: the full mesh up to ``faces`` faces, else a coarse copy.

    Parameters
    ----------
    flat : FlatMesh
        The relaxed flattening.
    pixels : (n, 2) float64
        Each vertex's position in the image (column, row).
    px_per_unit : float
        The image's pixels per scan unit.
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
                       importance=mean_importance.astype(np.float32), faces=s.faces.astype(np.uint32), decimated=True,
                       spacing=side / px_per_unit)


def boundary_segments(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The boundary edges of a cut mesh: those on the cut (both ends have a copy on the other
    side: the same position, another vertex) and the others (the mesh's own edge). Shapes
    (s, 2, 3) and (t, 2, 3) float32."""

    n = len(vertices)
    V = np.ascontiguousarray(vertices, np.float64) + 0.0  # -0.0 as 0.0: equal positions, equal bits
    rep = first_equal_rows(V.view(np.int64), False, np.zeros(n, bool))
    copies = np.bincount(rep, minlength=n)[rep] > 1
    _, segments, _ = edges_and_boundary(faces, n)
    on_cut = copies[segments[:, 0]] & copies[segments[:, 1]]
    return tuple(np.ascontiguousarray(V[segments[part]], dtype=np.float32).reshape(-1, 2, 3)
                 for part in (on_cut, ~on_cut))


@dataclass(frozen=True)
class ScanDisplay:
    """The whole scan as the page draws it.

    Attributes
    ----------
    vertices : (k, 3) float32
        Scan coordinates.
    normals : (k, 3) float32
        Unit normals (of the cell's full-resolution faces, area-weighted).
    texcoords : (k, 2) float32 or None
        Texture coordinates in the scan's texture (``(0, 0)`` its bottom-left corner;
        :data:`NO_TEXTURE` on faces without texture); None for an untextured scan.
    colors : (k, 3) uint8 or None
        Vertex colours of a scan without texture that has them.
    unrolled : (k,) float32
        Share of the full-resolution vertices it stands for that are in the flattening.
    faces : (m, 3) uint32
    decimated : bool
    spacing : float
        Side of the clustering cells, scan units (0: the scan drawn whole).
    """

    vertices: np.ndarray
    normals: np.ndarray
    texcoords: np.ndarray | None
    colors: np.ndarray | None
    unrolled: np.ndarray
    faces: np.ndarray
    decimated: bool
    spacing: float

    def as_bytes(self) -> bytes:
        """The arrays the page reads, little-endian, one after the other: vertices, normals,
        texture coordinates (if any), unrolled share (float32), colours (if any, as float32
        0..1) and faces (uint32)."""
        parts = [self.vertices.astype("<f4"), self.normals.astype("<f4")]
        if self.texcoords is not None:
            parts.append(self.texcoords.astype("<f4"))
        parts.append(self.unrolled.astype("<f4"))
        if self.colors is not None:
            parts.append((self.colors / 255.0).astype("<f4"))
        parts.append(self.faces.astype("<u4"))
        return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)

    def counts(self) -> dict:
        """Lengths and contents of the arrays in :meth:`as_bytes`."""
        return {"vertices": len(self.vertices), "faces": len(self.faces), "texcoords": self.texcoords is not None,
                "colors": self.colors is not None, "decimated": self.decimated, "spacing": self.spacing}


def scan_display_mesh(mesh: Mesh, unrolled: np.ndarray, *, faces: int = DISPLAY_FACES) -> ScanDisplay:
    """The whole scan drawn whole up to ``faces`` faces, else its copy clustered in 3D cells.

    Parameters
    ----------
    mesh : Mesh
        The scan as loaded (:func:`potflat.io.scan.load_scan`).
    unrolled : (n,) bool
        Whether each vertex of ``mesh`` is in the flattening (:func:`rows_in`).
    faces : int
        Largest face count drawn whole; a larger scan is decimated to about this many.
    """
    V, F = mesh.vertices, mesh.faces
    side = 0.0
    if len(F) > faces:
        area = float(triangle_areas(V, F).sum())
        side = math.sqrt(CELLS_PER_AREA * area / (0.5 * faces))  # two faces per vertex
    while True:
        out = _clustered(mesh, np.asarray(unrolled, bool), side)
        if side == 0.0 or len(out.faces) <= 1.25 * faces:
            return out
        side *= math.sqrt(len(out.faces) / faces)


def _clustered(mesh: Mesh, unrolled: np.ndarray, side: float) -> ScanDisplay:
    """The scan with its vertices clustered in cubic cells of ``side`` (0: each vertex its own
    cell).

    In each cell, the vertices joined by edges inside it make a piece (two walls crossing a
    cell stay apart): one position, normal and unrolled share per piece. A piece's corners
    joined inside it with the same texture coordinates make a display vertex (the two sides
    of a texture seam stay apart, at the piece's position)."""
    V, F = mesh.vertices, mesh.faces
    n, m = len(V), len(F)
    textured = mesh.texcoords is not None and mesh.texture_path is not None
    if side > 0.0:
        cell = _compact(first_equal_rows(np.floor((V - V.min(axis=0)) / side).astype(np.int64), False,
                                         np.zeros(n, bool)))
    else:
        cell = np.arange(n, dtype=np.int64)
    fv = F.ravel()
    if textured:  # corners at the same vertex with the same texture coordinates: one texture vertex
        uv = np.ascontiguousarray(mesh.texcoords, np.float64).reshape(-1, 2) + 0.0  # -0.0 as 0.0
        if mesh.untextured_faces is not None:
            uv[np.repeat(mesh.untextured_faces, 3)] = NO_TEXTURE
        corner = _texture_vertices(fv, uv, n)
    else:
        corner = fv.astype(np.int64)
    # the faces' edges (each corner to the next) inside a cell join their ends (as vertices:
    # pieces; as corners: display vertices)
    nxt = np.ascontiguousarray(F[:, [1, 2, 0]]).ravel()
    inside = cell[fv] == cell[nxt]
    piece, pieces = union_find(n, fv[inside], nxt[inside])
    corner_next = np.ascontiguousarray(corner.reshape(m, 3)[:, [1, 2, 0]]).ravel()
    cluster, clusters = union_find(int(corner.max()) + 1, corner[inside], corner_next[inside])
    cluster = cluster[corner]  # per corner

    count = np.bincount(piece, minlength=pieces).astype(np.float64)
    position = np.stack([np.bincount(piece, V[:, d], pieces) for d in range(3)], axis=1) / count[:, None]
    normal = vertex_normal_sums(V, F)[0]
    normal = np.stack([np.bincount(piece, normal[:, d], pieces) for d in range(3)], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    share = np.bincount(piece, unrolled.astype(np.float64), pieces) / count

    corner_piece = piece[fv]
    cluster_piece = np.empty(clusters, np.int64)
    cluster_piece[cluster] = corner_piece
    fp = corner_piece.reshape(m, 3)
    kept = np.flatnonzero((fp[:, 0] != fp[:, 1]) & (fp[:, 1] != fp[:, 2]) & (fp[:, 0] != fp[:, 2]))
    fk = fp[kept]
    turn = (np.argmin(fk, axis=1)[:, None] + np.arange(3)) % 3  # each face from its lowest piece: one per triple
    rep = first_equal_rows(np.ascontiguousarray(np.take_along_axis(fk, turn, axis=1)), False, np.zeros(len(kept), bool))
    display_faces = cluster.reshape(m, 3)[kept[rep == np.arange(len(kept))]]
    used = np.zeros(clusters, bool)
    used[display_faces.ravel()] = True
    at = cluster_piece[used]
    texcoords = None
    if textured:
        corners = np.bincount(cluster, minlength=clusters).astype(np.float64)
        texcoords = np.stack([np.bincount(cluster, uv[:, d], clusters) for d in range(2)], axis=1) / corners[:, None]
        texcoords = texcoords[used].astype(np.float32)
    colors = None
    if not textured and mesh.vertex_colors is not None:
        rgb = mesh.vertex_colors[:, :3].astype(np.float64)
        colors = np.stack([np.bincount(piece, rgb[:, d], pieces) for d in range(3)], axis=1) / count[:, None]
        colors = np.rint(colors[at]).astype(np.uint8)
    return ScanDisplay(vertices=position[at].astype(np.float32), normals=normal[at].astype(np.float32),
                       texcoords=texcoords, colors=colors, unrolled=share[at].astype(np.float32),
                       faces=((np.cumsum(used) - 1)[display_faces]).astype(np.uint32), decimated=side > 0.0,
                       spacing=float(side))


def _texture_vertices(fv: np.ndarray, uv: np.ndarray, n: int) -> np.ndarray:
    """Ids 0, 1, ... (in order of first corner) of the texture vertices: the corners (``fv``
    (3m,) their vertices, ``uv`` (3m, 2) their texture coordinates, -0.0 as 0.0) at the same
    vertex with the same texture coordinates. Each vertex's first corner stands for the
    corners that match it; only the others (along texture seams) go through a hash table."""
    first = np.empty(n, np.int64)
    first[fv[::-1]] = np.arange(len(fv) - 1, -1, -1)  # the last write wins: each vertex's first corner
    rep = first[fv]
    odd = np.flatnonzero((uv != uv[rep]).any(axis=1))
    if len(odd):
        K = np.empty((len(odd), 3), np.int64)
        K[:, 0] = fv[odd]
        K[:, 1:] = uv[odd].view(np.int64)
        rep[odd] = odd[first_equal_rows(K, False, np.zeros(len(odd), bool))]
    return _compact(rep)


def _compact(rep: np.ndarray) -> np.ndarray:
    """Ids 0, 1, ... of the groups of :func:`first_equal_rows`'s ``rep`` (in order of first row)."""
    first = rep == np.arange(len(rep))
    return (np.cumsum(first) - 1)[rep]


def rows_in(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Whether each row of ``points`` (n, 3) float64 is bit for bit a row of ``others`` (k, 3)
    (-0.0 and 0.0 alike). Shape (n,) bool."""
    K = np.ascontiguousarray(np.concatenate([others, points]), np.float64) + 0.0
    rep = first_equal_rows(K.view(np.int64), False, np.zeros(len(K), bool))
    return rep[len(others):] < len(others)


def level_segments(vertices: np.ndarray, faces: np.ndarray, values: np.ndarray, level: float) -> np.ndarray:
    """Where the linear interpolation of per-vertex ``values`` over the faces crosses ``level``:
    one segment per crossed face, shape (s, 2, 3) float32.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    values : (n,) float64
    level : float
    """
    above = values[faces] >= level
    count = above.sum(axis=1)
    crossed = np.flatnonzero((count == 1) | (count == 2))
    f, a = faces[crossed], above[crossed]
    odd = np.where(count[crossed] == 1, np.argmax(a, axis=1), np.argmin(a, axis=1))  # the corner alone on its side
    ends = []
    for step in (1, 2):
        i, j = f[np.arange(len(f)), odd], f[np.arange(len(f)), (odd + step) % 3]
        t = (level - values[i]) / (values[j] - values[i])
        ends.append(vertices[i] + t[:, None] * (vertices[j] - vertices[i]))
    return np.stack(ends, axis=1).astype(np.float32)
