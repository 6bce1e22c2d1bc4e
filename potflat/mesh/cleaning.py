"""Cleaning of scanned meshes: weld, drop junk, orient, and report every action.

Real scans are messy (holes, stray fragments, non-manifold edges, duplicate vertices,
zero-area faces, seams split by texture atlases). :func:`clean_mesh` repairs what must be
repaired without deleting painted surface and returns a :class:`CleaningReport` counting
each action, for the JSON sidecars:

1. weld vertices at the same position (exactly, or within a tolerance relative to the
   bounding-box diagonal), keeping every face corner's texture coordinate;
2. drop degenerate (zero-area) and duplicate faces;
3. drop stray components whose area is below a fraction of the largest one (substantial
   components are all kept and reported: two vessels, or two walls, are decided later);
4. count non-manifold edges and vertices and, by default, split them (each fan of faces
   gets its own copy of the vertex; no face is removed);
5. orient faces consistently per component (keeping the file's majority orientation) and
   outward: the components, each hole and open rim closed by a cap, must enclose a
   positive volume (a closed shell as it is; an open vessel, bowl or sherd its body; a
   flat piece nothing), turned over together so they keep their relative orientation (a
   separate inner wall keeps facing the axis); with ``outward=False`` the file's majority
   orientation stays (the face of a dish or bowl scanned alone, which that volume would
   show from below: a sheet whose caps close about as much as its faces is turned over
   with a warning);
6. count boundary loops (holes and open rims) and drop unreferenced vertices.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from potflat.mesh._kernels.geometry import face_geometry

from potflat.mesh._kernels.topology import edge_table, fan_joins, first_equal_rows, propagate_orientation, union_find
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.types import Mesh
from potflat.mesh.distortion import bounds
from potflat.mesh.tolerances import DEGENERATE

#: Removing more than this fraction of the total area as stray components adds a warning.
REMOVED_AREA_WARNING = 0.05
#: Turning an open surface over to enclose a positive volume adds a warning when its caps are
#: more than this share of the capped surface: a sheet its caps close about as much as its
#: faces do (a sherd, or the face of a dish or plate scanned alone: 0.46 for the test dish)
#: encloses a body on its convex side whichever way it faces (the shared scans: at most 0.11).
SHEET_CAP_SHARE = 0.4


@dataclass(frozen=True)
class CleaningReport:
    """What loading and cleaning did to a scan (all counts; JSON-ready via :meth:`as_dict`).

    Attributes
    ----------
    input_vertices, input_faces : int
        As read from the file (faces after triangulating polygons).
    polygons_triangulated : int
        Polygons with more than three corners, fan-triangulated by the loader.
    duplicate_vertices_merged : int
        Vertices welded into another at the same position (atlas seams, STL soups).
    degenerate_faces_removed, duplicate_faces_removed : int
        Zero-area faces and repeated faces (same three vertices, either winding).
    components : int
        Connected components (by manifold edges) before removing stray ones.
    components_removed, faces_in_removed_components : int
        Stray components whose area is below ``min_component_fraction`` of the largest.
    removed_area_fraction : float
        Their area as a fraction of the total area.
    kept_component_area_fractions : tuple of float
        Area of each kept component as a fraction of the kept total, largest first.
    non_manifold_edges, non_manifold_vertices : int
        Edges with more than two faces; vertices whose faces form more than one fan.
    vertices_added_by_split : int
        Copies made when splitting non-manifold vertices (0 when not split).
    orientation_conflicts : int
        Adjacent face pairs that cannot be oriented consistently (non-orientable input).
    faces_reoriented : int
        Faces whose winding was reversed (consistency and outward orientation).
    components_reversed_outward : int
        Components turned over because the largest one pointed inward (all of them are).
    boundary_edges, boundary_loops : int
        Open edges and the loops they form (holes, rims, the missing base).
    unreferenced_vertices_removed : int
        Vertices used by no face.
    output_vertices, output_faces : int
        Size of the cleaned mesh.
    cleaned : bool
        False when cleaning was turned off (only welding and checks ran).
    warnings : tuple of str
        Things a user should look at (several substantial components, large removals...).
    """

    input_vertices: int = 0
    input_faces: int = 0
    polygons_triangulated: int = 0
    duplicate_vertices_merged: int = 0
    degenerate_faces_removed: int = 0
    duplicate_faces_removed: int = 0
    components: int = 0
    components_removed: int = 0
    faces_in_removed_components: int = 0
    removed_area_fraction: float = 0.0
    kept_component_area_fractions: tuple[float, ...] = ()
    non_manifold_edges: int = 0
    non_manifold_vertices: int = 0
    vertices_added_by_split: int = 0
    orientation_conflicts: int = 0
    faces_reoriented: int = 0
    components_reversed_outward: int = 0
    boundary_edges: int = 0
    boundary_loops: int = 0
    unreferenced_vertices_removed: int = 0
    output_vertices: int = 0
    output_faces: int = 0
    cleaned: bool = True
    warnings: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        """The report as a JSON-serialisable dict (tuples become lists)."""
        out = asdict(self)
        out["kept_component_area_fractions"] = list(self.kept_component_area_fractions)
        out["warnings"] = list(self.warnings)
        return out


def _name(mesh: Mesh) -> str:
    return str(mesh.source) if mesh.source is not None else "the mesh"


def _apply_vertex_map(mesh: Mesh, rep: np.ndarray) -> Mesh:
    """Replace each vertex by ``rep[v] <= v`` and drop the vertices that are no longer used
    as representatives (order of the remaining ones kept)."""
    keep = rep == np.arange(len(rep))
    new_index = np.cumsum(keep) - 1
    colors = mesh.vertex_colors[keep] if mesh.vertex_colors is not None else None
    return mesh.replace(vertices=mesh.vertices[keep], faces=new_index[rep[mesh.faces]],
                        vertex_colors=colors)


def check_cleaning_options(*, weld_tolerance: float = 0.0, min_component_fraction: float = 0.01) -> None:
    """Raise :class:`InvalidOptionError` for out-of-range cleaning options (before any work)."""
    if not (np.isfinite(weld_tolerance) and 0.0 <= weld_tolerance < 0.01):
        raise InvalidOptionError(f"weld tolerance must be in [0, 0.01) of the diagonal, got {weld_tolerance!r}")
    if not (np.isfinite(min_component_fraction) and 0.0 <= min_component_fraction <= 1.0):
        raise InvalidOptionError(f"min_component_fraction must be in [0, 1], got {min_component_fraction!r}")


def weld_vertices(mesh: Mesh, *, tolerance: float = 0.0) -> tuple[Mesh, int]:
    """Merge vertices at the same position; faces keep their per-corner texture coordinates.

    Parameters
    ----------
    mesh : Mesh
        Any mesh (e.g. split at the seams of a texture atlas, or an STL triangle soup).
    tolerance : float
        0 merges exactly equal positions; a positive value merges positions closer than
        ``tolerance`` times the bounding-box diagonal (transitively).

    Returns
    -------
    mesh : Mesh
        Welded mesh; the first vertex of each group (and its colour) is kept, in file order.
    merged : int
        Number of vertices merged away.
    """
    check_cleaning_options(weld_tolerance=tolerance)
    n = len(mesh.vertices)
    if n == 0:
        return mesh, 0
    V = mesh.vertices + 0.0  # -0.0 -> 0.0 so that equal positions have equal bits
    rep = first_equal_rows(V.view(np.int64), False, np.zeros(n, bool))
    if tolerance > 0.0:
        from scipy.spatial import cKDTree

        uniq = np.flatnonzero(rep == np.arange(n))
        lo, hi = bounds(V)
        diag = float(np.linalg.norm(hi - lo))
        pairs = cKDTree(V[uniq]).query_pairs(tolerance * diag, output_type="ndarray")
        if len(pairs):
            label, _ = union_find(len(uniq), pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64))
            low = np.unique(label, return_index=True)[1]
            rep = uniq[low[label]][np.searchsorted(uniq, rep)]
    merged = int(n - np.count_nonzero(rep == np.arange(n)))
    if merged == 0:
        return mesh, 0
    return _apply_vertex_map(mesh, rep), merged


def _select_faces(mesh: Mesh, keep: np.ndarray) -> Mesh:
    if keep.all():
        return mesh
    index = np.flatnonzero(keep)  # (rows gathered by take: 2-3x faster than a boolean row mask)
    return mesh.replace(faces=np.take(mesh.faces, index, axis=0), **mesh.face_fields(index))


def _reverse_faces(mesh: Mesh, flip: np.ndarray) -> Mesh:
    """Reverse the winding of the faces where ``flip`` is True (swap corners 1 and 2)."""
    if not flip.any():
        return mesh
    F = mesh.faces.copy()
    F[flip, 1], F[flip, 2] = mesh.faces[flip, 2], mesh.faces[flip, 1]
    tc = None
    if mesh.texcoords is not None:
        tc = mesh.texcoords.copy()
        tc[flip, 1], tc[flip, 2] = mesh.texcoords[flip, 2], mesh.texcoords[flip, 1]
    return mesh.replace(faces=F, texcoords=tc)


def _drop_unreferenced(mesh: Mesh) -> tuple[Mesh, int]:
    n = len(mesh.vertices)
    used = np.zeros(n, bool)
    used[mesh.faces.ravel()] = True
    dropped = int(n - used.sum())
    if dropped == 0:
        return mesh, 0
    new_index = np.cumsum(used) - 1
    colors = mesh.vertex_colors[used] if mesh.vertex_colors is not None else None
    return mesh.replace(vertices=mesh.vertices[used], faces=new_index[mesh.faces],
                        vertex_colors=colors), dropped


@dataclass(frozen=True)
class _Topology:
    """Edges and manifold face adjacency of a triangle mesh (half-edge ``3 f + k`` runs
    from corner ``k`` to corner ``(k + 1) % 3`` of face ``f``)."""

    count: np.ndarray  # (ne,) faces per edge
    h1: np.ndarray  # (k,) first half-edge of each manifold edge ...
    h2: np.ndarray  # (k,) ... and the second
    same: np.ndarray  # (k,) True when both run the edge the same way
    odd: np.ndarray  # (b,) half-edges whose edge does not have two faces, increasing
    odd_single: np.ndarray  # (b,) True for those whose edge has one face (the open border)


def _topology(F: np.ndarray, n: int) -> _Topology:
    edge_of, _, count, halves = edge_table(F, n)
    man = count == 2
    h1, h2 = halves[man, 0], halves[man, 1]
    del halves
    flat = F.ravel()
    same = flat[h1] == flat[h2]
    faces_on = count[edge_of]
    del edge_of
    odd = np.flatnonzero(faces_on != 2)
    return _Topology(count, h1, h2, same, odd, faces_on[odd] == 1)


def _orient_components(topo: _Topology, m: int) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`propagate_orientation` over the manifold edges of ``topo`` (``m`` faces): the
    (m, 3) neighbour tables are made here and dropped after."""
    nbr = np.full(3 * m, -1, np.int64)
    nbr[topo.h1], nbr[topo.h2] = topo.h2 // 3, topo.h1 // 3
    nbr_same = np.zeros(3 * m, np.int8)
    nbr_same[topo.h1] = nbr_same[topo.h2] = topo.same
    return propagate_orientation(nbr.reshape(-1, 3), nbr_same.reshape(-1, 3))


def _corner_fans(F: np.ndarray, topo: _Topology) -> tuple[np.ndarray, int]:
    """Fan label of each face corner (3m,): corners joined across manifold edges."""
    return union_find(3 * len(F), *fan_joins(topo.h1, topo.h2, topo.same))


def _split_nonmanifold(mesh: Mesh, topo: _Topology, apply: bool) -> tuple[Mesh, int, int]:
    """Give each fan of faces around a vertex its own copy of the vertex (if ``apply``).

    Corners are joined across manifold edges only, so vertices on edges with more than two
    faces and bow-tie vertices are split; faces keep their order. Returns the mesh, the
    number of non-manifold vertices and the number of vertices added.
    """
    F = mesh.faces
    m, n = len(F), len(mesh.vertices)
    label, nlab = _corner_fans(F, topo)
    vertex_of_label = np.empty(nlab, np.int64)
    vertex_of_label[label] = F.ravel()
    copies = np.bincount(vertex_of_label, minlength=n)
    nonmanifold = int(np.count_nonzero(copies > 1))
    if nonmanifold == 0 or not apply:
        return mesh, nonmanifold, 0
    order = np.lexsort((np.arange(nlab), vertex_of_label))
    new_id = np.empty(nlab, np.int64)
    new_id[order] = np.arange(nlab)
    src_vertex = vertex_of_label[order]
    colors = mesh.vertex_colors[src_vertex] if mesh.vertex_colors is not None else None
    split = mesh.replace(vertices=mesh.vertices[src_vertex], faces=new_id[label].reshape(m, 3),
                         vertex_colors=colors)
    return split, nonmanifold, int(nlab - np.count_nonzero(copies))


def _open_border(F: np.ndarray, n: int, topo: _Topology, split: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """The open border of ``F``: its half-edges (b,) (edges with one face; also the
    non-manifold ones when those were split apart), the loop of each (b,) int64 and the
    number of loops."""
    hb = topo.odd if split else topo.odd[topo.odd_single]
    if len(hb) == 0:
        return hb, np.zeros(0, np.int64), 0
    flat = F.ravel()
    a, b = flat[hb], flat[hb - hb % 3 + (hb + 1) % 3]
    label, _ = union_find(n, a, b)
    _, loop = np.unique(label[a], return_inverse=True)
    return hb, loop.astype(np.int64), int(loop.max()) + 1


def _outward_flips(vertices: np.ndarray, faces: np.ndarray, cross: np.ndarray, area2: np.ndarray,
                   centroid: np.ndarray, flip: np.ndarray, comp: np.ndarray, border: np.ndarray,
                   loop: np.ndarray, outward: bool = True) -> tuple[np.ndarray, int, float]:
    """Faces to reverse for a consistent, outward orientation, components reversed and the
    caps' share of the capped surface (0 without open border).

    ``flip`` (from :func:`propagate_orientation`) makes each component consistent relative
    to its first face; each component then takes the orientation of the (area) majority of
    its faces in the file, so a scanner's orientation is kept where it is consistent. The
    components are then turned over together when they enclose a negative volume: their
    faces and, over each loop of the open border (``border`` (b,) half-edges, ``loop`` (b,)
    their loops), a cap of triangles to the loop's mean vertex. Closed by its caps, an open
    vessel, bowl or sherd encloses its body and a flat piece nothing, so the sign does not
    hang on where the area lies (a table or ground plane joined to the foot, or apart from
    the vessel and larger than it). Turning all of them keeps the file's relative
    orientation (a separate inner wall keeps facing the axis). Without ``outward`` each
    component keeps its majority orientation.
    """
    ncomp = int(comp.max()) + 1
    agree = np.bincount(comp, weights=np.where(flip, -area2, area2), minlength=ncomp)
    flip = flip ^ (agree < 0)[comp]
    if not outward:
        return flip, 0, 0.0
    sign = np.where(flip, -1.0, 1.0)
    c = (area2[:, None] * centroid).sum(axis=0) / max(float(area2.sum()), np.finfo(float).tiny)
    d = centroid - c
    # six times the volume of the cones from c to the faces ...
    flux = float((sign * np.einsum("ij,ij->i", cross, d)).sum())
    scale = float((area2 * np.sqrt(np.einsum("ij,ij->i", d, d))).sum())
    # ... and to the caps' triangles (b, a, apex) on each border half-edge a -> b
    if len(border):
        flat = faces.ravel()
        xa = vertices[flat[border]] - c
        xb = vertices[flat[border - border % 3 + (border + 1) % 3]] - c
        count = np.bincount(loop)
        apex = np.stack([np.bincount(loop, weights=xa[:, k]) for k in range(3)], axis=1) / count[:, None]
        cap_cross = np.cross(xa - xb, apex[loop] - xb)
        flux += float((sign[border // 3] * np.einsum("ij,ij->i", cap_cross, xb)).sum())
        cap_area = float(np.linalg.norm(cap_cross, axis=1).sum())
        cap_share = cap_area / (cap_area + float(area2.sum()))
    else:
        cap_share = 0.0
    if flux < -1e-6 * scale:  # clearly inward (a flat patch stays as it is)
        return ~flip, ncomp, cap_share
    return flip, 0, cap_share


def clean_mesh(mesh: Mesh, *, weld_tolerance: float = 0.0, min_component_fraction: float = 0.01,
               split_nonmanifold: bool = True, orient: bool = True, outward: bool = True,
               min_faces: int = 4) -> tuple[Mesh, CleaningReport]:
    """Clean a scanned mesh without deleting painted surface, and report what was done.

    Parameters
    ----------
    mesh : Mesh
        The mesh as loaded (texture coordinates per face corner, colours per vertex).
    weld_tolerance : float
        See :func:`weld_vertices` (0: exact positions).
    min_component_fraction : float
        Components with less area than this fraction of the largest component are removed
        as stray fragments (0 keeps everything).
    split_nonmanifold : bool
        Split non-manifold vertices and edges into separate fans (no face is removed).
    orient : bool
        Make the winding consistent per component and outward.
    outward : bool
        With ``orient``: turn the components over together when they do not enclose a
        positive volume with their holes capped; False: each keeps the orientation of most
        of its faces in the file (a scanner's, facing the side it saw).
    min_faces : int
        Fewer faces than this after cleaning is an error.

    Returns
    -------
    mesh : Mesh
        The cleaned mesh (texcoords, untextured-face flags and vertex colours follow their
        faces and vertices).
    report : CleaningReport
        Every action with counts.

    Raises
    ------
    InvalidInputError
        When every face is degenerate or too few faces remain.
    """
    check_cleaning_options(weld_tolerance=weld_tolerance, min_component_fraction=min_component_fraction)
    name = _name(mesh)
    n0, m0 = len(mesh.vertices), len(mesh.faces)
    warnings: list[str] = []

    mesh, merged = weld_vertices(mesh, tolerance=weld_tolerance)

    # degenerate faces: repeated vertex or (numerically) zero area
    F = mesh.faces
    _, area2, longest2, _ = face_geometry(mesh.vertices, F)  # cross, centroid: made again when needed
    degenerate = ((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
                  | (area2 <= DEGENERATE * longest2))  # twice the area against the longest edge squared
    del longest2
    n_degenerate = int(degenerate.sum())
    if n_degenerate == len(F):
        raise InvalidInputError(f"{name}: all {len(F)} faces are degenerate (zero area); "
                                "give a scan with a real surface")
    # duplicate faces (same vertex set, either winding): keep the first
    dup = first_equal_rows(F, True, degenerate) != np.arange(len(F))
    n_dup = int(np.count_nonzero(dup))
    keep = ~(degenerate | dup)
    mesh = _select_faces(mesh, keep)
    if not keep.all():
        area2 = area2[keep]

    # stray components, by manifold-edge connectivity
    n = len(mesh.vertices)
    topo = _topology(mesh.faces, n)
    flip, comp, conflicts = _orient_components(topo, len(mesh.faces))
    comp_area = np.bincount(comp, weights=area2)
    n_comp = len(comp_area)
    small = comp_area < min_component_fraction * comp_area.max()
    drop = small[comp]
    removed_fraction = float(comp_area[small].sum() / comp_area.sum())
    if removed_fraction > REMOVED_AREA_WARNING:
        warnings.append(f"{small.sum()} small components hold {removed_fraction:.1%} of the area and "
                        "were removed; lower min_component_fraction to keep them")
    if drop.any():
        mesh = _select_faces(mesh, ~drop)
        area2 = area2[~drop]
        topo = _topology(mesh.faces, n)
        flip, comp, conflicts = _orient_components(topo, len(mesh.faces))
    n_nm_edges = int(np.count_nonzero(topo.count > 2))

    # non-manifold vertices (split: faces keep their order, so topo's pairs stay valid)
    mesh, nm_vertices, added = _split_nonmanifold(mesh, topo, split_nonmanifold)
    if n_nm_edges or nm_vertices:
        action = "split into separate fans" if split_nonmanifold else "left as they are"
        warnings.append(f"{n_nm_edges} non-manifold edges and {nm_vertices} non-manifold vertices, {action}")
    border, loop, b_loops = _open_border(mesh.faces, len(mesh.vertices), topo, split_nonmanifold)
    b_edges = len(border)  # (one half-edge per open edge)
    del topo

    # orientation: consistent per component, then outward
    n_reoriented = 0
    reversed_out = 0
    if orient:
        # the same values as at the start, face for face (splitting only renumbers vertices)
        cross, _, _, centroid = face_geometry(mesh.vertices, mesh.faces)
        total_flip, reversed_out, cap_share = _outward_flips(mesh.vertices, mesh.faces, cross, area2, centroid,
                                                             flip.astype(bool), comp, border, loop, outward)
        del cross, centroid
        if reversed_out and cap_share > SHEET_CAP_SHARE:
            warnings.append("the scan is an open sheet that the caps of its holes close about as much as its faces "
                            "(a sherd, or the face of a dish or bowl scanned alone) and faces the other way in the "
                            "file: it was turned to face out of its convex side; if it is the inside of a dish or "
                            "bowl, keep the file's orientation (--keep-orientation) and unroll its inner side "
                            "(--side inner), else the painting comes out mirrored")
        n_reoriented = int(np.count_nonzero(total_flip))
        mesh = _reverse_faces(mesh, total_flip)
        if conflicts:
            warnings.append(f"{conflicts} face pairs cannot be oriented consistently (non-orientable surface)")
    mesh, unreferenced = _drop_unreferenced(mesh)

    kept_area = np.bincount(comp, weights=area2)
    kept_area = kept_area[kept_area > 0]
    fractions = tuple(float(x) for x in np.sort(kept_area / kept_area.sum())[::-1])
    if len(fractions) > 1:
        warnings.append(f"{len(fractions)} substantial components kept (area fractions "
                        + ", ".join(f"{x:.2f}" for x in fractions[:5])
                        + (", ..." if len(fractions) > 5 else "")
                        + "): several vessels, fragments or walls; a later stage decides")
    if len(mesh.faces) < min_faces:
        raise InvalidInputError(f"{name}: only {len(mesh.faces)} usable faces after cleaning "
                                f"(at least {min_faces} needed); give the whole scan")
    report = CleaningReport(
        input_vertices=n0, input_faces=m0, duplicate_vertices_merged=merged,
        degenerate_faces_removed=n_degenerate, duplicate_faces_removed=n_dup,
        components=n_comp, components_removed=int(small.sum()),
        faces_in_removed_components=int(drop.sum()), removed_area_fraction=removed_fraction,
        kept_component_area_fractions=fractions, non_manifold_edges=n_nm_edges,
        non_manifold_vertices=nm_vertices, vertices_added_by_split=added,
        orientation_conflicts=conflicts, faces_reoriented=n_reoriented,
        components_reversed_outward=reversed_out, boundary_edges=b_edges, boundary_loops=b_loops,
        unreferenced_vertices_removed=unreferenced, output_vertices=len(mesh.vertices),
        output_faces=len(mesh.faces), cleaned=True, warnings=tuple(warnings))
    return mesh, report
