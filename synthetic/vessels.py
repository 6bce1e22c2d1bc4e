"""Synthetic painted vessels with known geometry: test, benchmark and demo data.

:func:`make_vessel` builds a surface of revolution with an archaeological profile (or a
cylinder / cone frustum as developable known-answer cases), meshes it with irregular
triangles (jittered rings of samples joined by strips, planar Delaunay caps at closed
poles; no seam duplication: one connected manifold like a real scan), poses it
arbitrarily in space, paints it with measurable features and bakes the painting into a
multi-chart texture atlas as photogrammetry software does (UV seams lie inside the
surface). Real-vessel kinds too: two-walled cups, handles (intersecting or welded), holes and
sherds.

:func:`write_obj` writes OBJ + MTL + PNG (one ``v`` per 3D point, several ``vt`` where
charts meet), :func:`write_ply_colored` a binary vertex-coloured PLY. Units are mm.

The painting is a function of the 3D surface point (:meth:`SyntheticVessel.paint`), so
it is exact whatever the parameterisation: filled circles are the surface points within
a 3D distance of a centre on the surface, bands are height ranges along the axis, bars
are arc-length ranges about a meridian.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from potflat_synthetic.atlas import _atlas_coords, _chart_layouts, _render_atlas
from potflat_synthetic.geometry import (
    _build_generatrix,
    _check_manifold,
    _compact,
    _Generatrix,
    _handle_mesh,
    _largest_component,
    _outer_polyline,
    _parts_of,
    _place_holes,
    _plain_colours,
    _remove_faces,
    _revolve,
    _sherd_region,
    _thicken_sherd,
    _weld_handles,
)
from potflat_synthetic.painting import (
    _in_zone,
    _layout_painting,
    _paint,
    _shade,
    _shading_rng,
)
from potflat_synthetic.spec import (
    _SPECS,
    KINDS,
    PAINTINGS,
    PART_BASE,
    PART_BREAK,
    PART_HANDLE,
    PART_INNER,
    PART_NAMES,
    PART_OUTER,
    PART_RIM,
    Hole,
    PaintedCircle,
    Painting,
)

from potflat.errors import InvalidOptionError
from potflat.types import Mesh

__all__ = ["KINDS", "PAINTINGS", "PART_BASE", "PART_BREAK", "PART_HANDLE", "PART_INNER", "PART_NAMES", "PART_OUTER",
           "PART_RIM", "Hole", "PaintedCircle", "Painting", "SyntheticVessel", "make_vessel", "obj_texcoord_indices",
           "truth", "write_obj", "write_ply_colored", "write_truth"]

@dataclass(frozen=True, eq=False)
class SyntheticVessel:
    """A synthetic painted vessel and the truth about it.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    mesh : Mesh
        World-coordinate mesh in mm, faces CCW seen from outside, per-corner ``texcoords``
        into :attr:`texture` (``texture_path`` is None until written).
    texture : (S, S, 3) uint8
        The texture atlas, row 0 at the top (texture coordinate v = 1).
    axis_point : (3,) float64
        Point on the rotation axis at the foot (canonical height 0).
    axis_direction : (3,) float64
        Unit axis direction from the foot to the mouth.
    profile : (k, 2) float64
        Outer wall profile: columns ``height`` (along the axis from ``axis_point``,
        strictly increasing) and ``radius`` (mm). The surface's generatrix is exactly this
        polyline, so ``np.interp(h, profile[:, 0], profile[:, 1])`` is exact on the wall.
    generatrix : (g, 2) float64
        The whole section curve ``(radius, height)``: base, outer wall, rim, inner wall,
        floor, in order along the surface.
    painting : Painting
        Painting description (canonical frame).
    features : tuple of PaintedCircle
        Painted circles with known radius, world coordinates (also in :attr:`painting`).
    holes : tuple of Hole
        Patches removed from the surface.
    pose : (4, 4) float64
        Canonical -> world transform (rotation and translation).
    face_part, vertex_part : (m,) / (n,) int8
        Part label (:data:`PART_NAMES`) of every face / vertex.
    face_chart : (m,) int64
        Texture chart of every face.
    options : dict
        The arguments of :func:`make_vessel`.
    """

    kind: str
    mesh: Mesh
    texture: np.ndarray
    axis_point: np.ndarray
    axis_direction: np.ndarray
    profile: np.ndarray
    generatrix: np.ndarray
    painting: Painting
    features: tuple
    holes: tuple
    pose: np.ndarray
    face_part: np.ndarray
    vertex_part: np.ndarray
    face_chart: np.ndarray
    options: dict
    _geometry: _Generatrix = field(repr=False)

    def radius_at(self, heights) -> np.ndarray:
        """Outer wall radius (mm) at ``heights`` along the axis from :attr:`axis_point`."""
        return np.interp(np.asarray(heights, float), self.profile[:, 0], self.profile[:, 1])

    def to_canonical(self, points) -> np.ndarray:
        """World points ``(n, 3)`` to the canonical frame (axis = z, foot at the origin)."""
        p = np.asarray(points, float).reshape(-1, 3)
        return (p - self.pose[:3, 3]) @ self.pose[:3, :3]

    def paint(self, points) -> np.ndarray:
        """Painting colour (``(n, 3)`` uint8) at world points on (or near) the body surface.

        The point is projected to the nearest point of the section curve, so the colour is
        exact on the surface and well defined on chords of its triangles. Handles are
        painted plain black (see :meth:`vertex_colors`).
        """
        return _paint(self.painting, self._geometry, self.to_canonical(points))

    def vertex_colors(self) -> np.ndarray:
        """Colour of every mesh vertex as a scan shows it, ``(n, 3)`` uint8.

        The painting (:meth:`paint`); handles are black, a thick sherd's back and break
        faces plain clay (:data:`CLAY`); with ``shading`` lit and noisy like the texture.
        """
        col = self.paint(self.mesh.vertices)
        for part, rgb in _plain_colours(self._geometry).items():
            col[self.vertex_part == part] = rgb
        if self.options.get("shading", False):
            col = _shade(col, self.to_canonical(self.mesh.vertices), self._geometry,
                         _shading_rng(self.options["seed"], 1))
        return col

    def painted_zone(self, points) -> np.ndarray:
        """Whether world points ``(n, 3)`` on the body lie in the painted zone, ``(n,)`` bool.

        The zone is the part of the outer wall that carries the painting (the whole outer
        wall for ``frieze`` and ``allover``; the belt or the panel, see
        :attr:`Painting.zone`); the inner wall and handles are not in it.
        """
        return _in_zone(self.painting, self._geometry, self.to_canonical(points))

    def zone_faces(self) -> np.ndarray:
        """Faces of the outer wall whose centroid lies in the painted zone, ``(m,)`` bool."""
        F = self.mesh.faces
        return (self.face_part == PART_OUTER) & self.painted_zone(self.mesh.vertices[F].mean(axis=1))


# --------------------------------------------------------------------------- public API


def _check_int(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise InvalidOptionError(f"{name} must be an integer from {lo} to {hi}, got {value!r}")
    return int(value)


def _check_float(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not lo <= float(value) <= hi:
        raise InvalidOptionError(f"{name} must be a number from {lo} to {hi}, got {value!r}")
    return float(value)


def _random_pose(rng) -> np.ndarray:
    """Random rotation (axis at least 15 degrees from every coordinate axis) and shift."""
    from scipy.spatial.transform import Rotation

    while True:
        q = rng.normal(size=4)
        R = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
        if np.max(np.abs(R[:, 2])) < math.cos(math.radians(15.0)):
            break
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = rng.uniform(-150.0, 150.0, 3)
    return T


def make_vessel(
    kind: str,
    *,
    n_vertices: int = 20000,
    seed: int = 0,
    pose: bool = True,
    texture_size: int = 1024,
    base: bool | None = None,
    walls: int | None = None,
    thickness: float = 4.0,
    handles: bool | str = False,
    holes: int = 0,
    sherd_of: str = "hydria",
    sherd_span: float = 80.0,
    sherd_thickness: float = 0.0,
    painting: str = "frieze",
    shading: bool = False,
) -> SyntheticVessel:
    """Build a synthetic painted vessel with known axis, profile, painting and pose.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`: a profile (``amphora`` ... ``aryballos``), a developable
        ``cylinder`` (R 100, H 200 mm) or ``cone`` frustum (R 60 -> 120 over 200 mm), a
        two-walled ``cup`` or ``bowl`` or a ``sherd`` (fragment of ``sherd_of``).
    n_vertices : int
        Target vertex count (about; the body alone), 500 to 20,000,000.
    seed : int
        Random seed: the same arguments give identical output.
    pose : bool
        Apply a random rotation and translation (axis not aligned to any coordinate axis).
    texture_size : int
        Side of the square texture atlas in pixels (64 to 16384).
    base : bool or None
        Close the foot with a flat base disc (default: only for ``cup`` and ``bowl``).
    walls : int or None
        1 = outer wall only; 2 = outer and inner wall joined by a rounded rim, a closed
        shell (``cup``, ``bowl`` and ``kylix`` only; default 2 for ``cup`` and ``bowl``). The inner floor carries
        a painted tondo.
    thickness : float
        Wall thickness in mm for ``walls=2`` (1 to 10).
    handles : bool or str
        Add handle tubes (``amphora``, ``hydria``, ``lekythos``, ``kylix``; ``bowl``: one
        handle arching over the rim from the outer wall into the inner wall), part of the
        same mesh (:data:`PART_HANDLE`). ``True`` or ``"intersecting"``: separate tubes whose
        open ends sink 2 mm into the intact wall (as in merged scans); ``"welded"``: the wall
        is cut around each root and stitched to the tube, one manifold surface of genus
        = number of handles (as in a single scan surface); ``"joined"``: stitched so, but
        the wall under each root kept, every edge of the root's outline shared by three faces
        (a non-manifold join).
    holes : int
        Number of holes cut into the painted outer wall (0 to 20).
    sherd_of : str
        Parent profile of a ``sherd``.
    sherd_span : float
        Angular width of a ``sherd`` in degrees (10 to 300); it covers about 60% of the
        wall height around the frieze, with irregular break edges.
    sherd_thickness : float
        0 = the sherd's painted outer surface only; otherwise (1 to 15 mm) a closed
        fragment: the back is the outer surface offset inwards along the section normal,
        joined by break faces (:data:`PART_BREAK`); back and breaks are plain clay.
    painting : str
        One of :data:`PAINTINGS`. ``frieze``: a frieze of circles between black bands, a
        hatched grid above and bars below on terracotta. ``belt``: the frieze between its
        bands, lustrous black glaze on the rest of the outer wall. ``panel``: a panel of
        100-140 degrees around a group of the frieze's circles, from the bars to the grid,
        black glaze elsewhere (also on the rest of the frieze). ``allover``: staggered rows of circles
        over the whole outer wall (where it is wide enough) on a lattice of thin lines, no
        large plain area. The painted zone is :meth:`SyntheticVessel.painted_zone`; the
        feature circles are those inside it.
    shading : bool
        Light the texture (and vertex colours) like a scan: a smooth gradient (factor
        :data:`SHADING_RANGE` across the vessel) and per-texel noise (:data:`SHADING_NOISE`
        grey levels). :meth:`SyntheticVessel.paint` stays the unlit painting. The mesh and
        painting do not depend on it.

    The options ``painting`` and ``shading`` are recorded in :attr:`SyntheticVessel.options`
    only when they are not the defaults, so existing vessels' files stay byte-identical.

    Returns
    -------
    SyntheticVessel
    """
    if kind not in KINDS:
        raise InvalidOptionError(f"unknown vessel kind {kind!r}; use one of {', '.join(KINDS)}")
    n_vertices = _check_int("n_vertices", n_vertices, 500, 20_000_000)
    seed = _check_int("seed", seed, 0, 2**63 - 1)
    texture_size = _check_int("texture_size", texture_size, 64, 16384)
    holes = _check_int("holes", holes, 0, 20)
    thickness = _check_float("thickness", thickness, 1.0, 10.0)
    sherd_span = _check_float("sherd_span", sherd_span, 10.0, 300.0)
    if sherd_thickness != 0:
        sherd_thickness = _check_float("sherd_thickness", sherd_thickness, 1.0, 15.0)
        if kind != "sherd":
            raise InvalidOptionError(f"sherd_thickness applies to kind 'sherd', not {kind!r}; drop it")
    if not isinstance(pose, bool):
        raise InvalidOptionError(f"pose must be True or False, got {pose!r}")
    if handles not in (False, True, "intersecting", "welded", "joined") or not isinstance(handles, (bool, str)):
        raise InvalidOptionError(f"handles must be False, True, 'intersecting', 'welded' or 'joined', got {handles!r}")
    handles = "intersecting" if handles is True else handles
    if painting not in PAINTINGS:
        raise InvalidOptionError(f"unknown painting {painting!r}; use one of {', '.join(PAINTINGS)}")
    if not isinstance(shading, bool):
        raise InvalidOptionError(f"shading must be True or False, got {shading!r}")
    if base is not None and not isinstance(base, bool):
        raise InvalidOptionError(f"base must be True, False or None, got {base!r}")
    parent = kind
    if kind == "sherd":
        if sherd_of not in _SPECS:
            raise InvalidOptionError(f"sherd_of must be one of {', '.join(_SPECS)}, got {sherd_of!r}")
        parent = sherd_of
        if handles or base or walls == 2:
            raise InvalidOptionError("a sherd has no handles, base or inner wall; drop those options")
    spec = _SPECS[parent]
    if walls is None:
        walls = 1 if kind == "sherd" else spec.walls
    if walls not in (1, 2) or isinstance(walls, bool):
        raise InvalidOptionError(f"walls must be 1 or 2, got {walls!r}")
    if walls == 2 and spec.floor is None:
        raise InvalidOptionError(f"walls=2 is available for cup, bowl and kylix, not {kind}; use walls=1")
    if handles and not spec.handles:
        raise InvalidOptionError(f"{kind} has no handles; use handles=False")
    base = (spec.base and kind != "sherd") if base is None else base
    options = dict(kind=kind, n_vertices=n_vertices, seed=seed, pose=pose, texture_size=texture_size,
                   base=base, walls=walls, thickness=thickness, handles=handles, holes=holes,
                   sherd_of=sherd_of if kind == "sherd" else None,
                   sherd_span=sherd_span if kind == "sherd" else None,
                   sherd_thickness=float(sherd_thickness) if kind == "sherd" else None)
    if painting != "frieze":
        options["painting"] = painting
    if shading:
        options["shading"] = True

    rng = np.random.default_rng(seed)
    g = _build_generatrix(spec, walls=walls, base=base, thickness=thickness)
    painting = _layout_painting(g, spec, walls, rng, painting)

    region = None
    n_body = n_vertices
    if kind == "sherd":
        region = _sherd_region(g, painting, sherd_span, rng)
        n_body = int(min(20_000_000, n_vertices / region[-1]))
    V, F, vs, vth, h = _revolve(g, n_body, rng)
    vertex_part = _parts_of(g, vs)
    face_part = _parts_of(g, vs[F].mean(axis=1))
    face_handle = np.full(len(F), -1, np.int64)
    handle_radii = []
    ends = []
    if handles:
        for hd in spec.handles:
            hV, hF, hs, hphi, hends = _handle_mesh(g, hd, h, rng, sink=2.0 if handles == "intersecting" else 0.0)
            ends += [(A, nA, ring + len(V), hd.radius, part) for A, nA, ring, part in hends]
            F = np.concatenate([F, hF + len(V)])
            V = np.concatenate([V, hV])
            vs, vth = np.concatenate([vs, hs]), np.concatenate([vth, hphi])
            vertex_part = np.concatenate([vertex_part, np.full(len(hV), PART_HANDLE, np.int8)])
            face_part = np.concatenate([face_part, np.full(len(hF), PART_HANDLE, np.int8)])
            face_handle = np.concatenate([face_handle, np.full(len(hF), len(handle_radii))])
            handle_radii.append(hd.radius)
    preset = None  # caller-made chart layouts: (piece per face or -1, corner layouts)
    if handles in ("welded", "joined"):
        chi = len(V) - len(np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]),
                                                  axis=1), axis=0)) + len(F)
        V, F, (vs, vth, vertex_part), (face_part, face_handle), weld = _weld_handles(
            V, F, [vs, vth, vertex_part], [face_part, face_handle], ends, h, keep_wall=handles == "joined")
        if handles == "welded":
            _check_manifold(F, len(V), holes_expected=2 - (chi - 2 * len(spec.handles)))
        preset = (np.full(len(F), -1, np.int64), np.zeros((len(F), 3, 2)))
        preset[0][weld[0]], preset[1][weld[0]] = weld[2], weld[1]

    remove = np.zeros(len(F), bool)
    circles = painting.circles
    if region is not None:
        inside, circle_ok = region[0], region[1]
        cth = np.arctan2(V[F, 1].mean(axis=1), V[F, 0].mean(axis=1))
        keep = (face_part == PART_OUTER) & inside(cth, vs[F].mean(axis=1))
        keep = _largest_component(F, keep)
        remove = _remove_faces(F, ~keep)
        remove = ~_largest_component(F, ~remove)
        circles = tuple(c for c in circles if circle_ok(c))
    hole_list = []
    if holes:
        avoid = [(A, a + 2 * h + 5.0) for A, _, _, a, _ in ends]
        hole_list = _place_holes(g, painting, holes, rng, region, avoid)
        cen = V[F].mean(axis=1)
        for hc, hr in hole_list:
            remove |= (face_part == PART_OUTER) & (np.linalg.norm(cen - hc, axis=1) <= hr)
        remove = _remove_faces(F, remove)
    if np.any(remove):
        F, face_part, face_handle = F[~remove], face_part[~remove], face_handle[~remove]
        if preset is not None:
            preset = (preset[0][~remove], preset[1][~remove])
        V, F, vs, vth, vertex_part = _compact(V, F, vs, vth, vertex_part)

    if kind == "sherd" and sherd_thickness > 0:
        V, F, vs, vth, face_part, vertex_part, breaks = _thicken_sherd(g, V, F, vs, vth, sherd_thickness)
        face_handle = np.full(len(F), -1, np.int64)
        preset = (np.full(len(F), -1, np.int64), np.zeros((len(F), 3, 2)))
        preset[0][breaks[0]], preset[1][breaks[0]] = breaks[2], breaks[1]
    n_sectors = 12 if kind == "sherd" else 4
    face_chart, chart_uv = _chart_layouts(V, F, vs, vth, face_part, face_handle, handle_radii,
                                          g, n_sectors, rng, preset)
    texcoords, _ = _atlas_coords(chart_uv, face_chart, texture_size, rng)

    T = _random_pose(rng) if pose else np.eye(4)
    R, t = T[:3, :3], T[:3, 3]
    Vw = V @ R.T + t
    mesh = Mesh(Vw, F, texcoords=texcoords, units="mm")
    features = tuple(
        PaintedCircle(c.centre @ R.T + t, c.radius, c.colour, c.side, c.height, c.angle) for c in circles
    )
    _, prof_r, prof_z = _outer_polyline(g)
    profile = np.stack([prof_z, prof_r], axis=1)
    vessel = SyntheticVessel(
        kind=kind, mesh=mesh, texture=np.zeros((1, 1, 3), np.uint8),
        axis_point=t.copy(), axis_direction=R[:, 2].copy(), profile=profile,
        generatrix=np.stack([g.r, g.z], axis=1), painting=painting, features=features,
        holes=tuple(Hole(hc @ R.T + t, hr) for hc, hr in hole_list), pose=T,
        face_part=face_part, vertex_part=vertex_part, face_chart=face_chart, options=options,
        _geometry=g,
    )
    shade = None
    if shading:
        def shade(colours, P):
            return _shade(colours, vessel.to_canonical(P), g, _shading_rng(seed, 0))
    texture = _render_atlas(vessel.paint, _plain_colours(g), Vw, F, face_part, texcoords, texture_size, shade)
    object.__setattr__(vessel, "texture", texture)
    return vessel


# --------------------------------------------------------------------------- writers


def obj_texcoord_indices(vessel: SyntheticVessel) -> tuple[np.ndarray, np.ndarray]:
    """The OBJ ``vt`` table: one entry per (vertex, chart) pair.

    Returns
    -------
    vt : (t, 2) float64
        Texture coordinates.
    corner_vt : (m, 3) int64
        0-based ``vt`` index of every face corner.
    """
    F = vessel.mesh.faces
    n_ch = int(vessel.face_chart.max()) + 1
    key = (F * n_ch + vessel.face_chart[:, None]).ravel()
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    vt = vessel.mesh.texcoords.reshape(-1, 2)[first]
    return vt, inv.reshape(F.shape).astype(np.int64)


def write_obj(vessel: SyntheticVessel, path: str | os.PathLike) -> Path:
    """Write ``vessel`` as OBJ + MTL + PNG (``NAME.obj``, ``NAME.mtl``, ``NAME.png``).

    One ``v`` per 3D point (mm) and one ``vt`` per (vertex, texture chart): where charts
    meet, a vertex has several texture coordinates, so a loader must weld by position.
    Faces are ``f v/vt`` triples, counter-clockwise seen from outside. Every file is
    written atomically; the OBJ last.

    Parameters
    ----------
    vessel : SyntheticVessel
    path : path-like
        Output ``.obj`` path; the MTL and PNG are written beside it with the same stem.

    Returns
    -------
    Path
        The OBJ path.
    """
    import cv2

    from potflat.io.atomic import write_bytes_atomic
    from potflat.io.obj import write_textured_obj

    path = Path(path)
    if path.suffix.lower() != ".obj":
        raise InvalidOptionError(f"{path} does not end in .obj; give an .obj output path")
    png = path.with_suffix(".png")
    ok, buf = cv2.imencode(".png", vessel.texture[:, :, ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise RuntimeError("PNG encoding failed")
    write_bytes_atomic(png, buf.tobytes())
    vt, corner_vt = obj_texcoord_indices(vessel)
    return write_textured_obj(path, vessel.mesh.vertices, vessel.mesh.faces, vt, corner_vt, png.name,
                              header=f"potflat synthetic {vessel.kind} seed {vessel.options['seed']}, units mm",
                              vertex_format="%.4f")


def write_ply_colored(vessel: SyntheticVessel, path: str | os.PathLike) -> Path:
    """Write ``vessel`` as a binary little-endian PLY with per-vertex painting colours.

    Vertex properties ``x y z`` (double, mm) and ``red green blue`` (uchar); faces
    ``vertex_indices`` (uchar count, int indices), counter-clockwise seen from outside.

    Returns
    -------
    Path
        ``path``.
    """
    from potflat.io.atomic import write_bytes_atomic

    path = Path(path)
    mesh = vessel.mesh
    n, m = len(mesh.vertices), len(mesh.faces)
    vert = np.empty(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"),
                              ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    vert["x"], vert["y"], vert["z"] = mesh.vertices.T
    col = vessel.vertex_colors()
    vert["red"], vert["green"], vert["blue"] = col.T
    face = np.empty(m, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face["n"] = 3
    face["i"] = mesh.faces
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment potflat synthetic {vessel.kind} seed {vessel.options['seed']}\n"
        "comment units mm\n"
        f"element vertex {n}\nproperty double x\nproperty double y\nproperty double z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {m}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return write_bytes_atomic(path, header.encode("ascii") + vert.tobytes() + face.tobytes())


def truth(vessel: SyntheticVessel) -> dict:
    """JSON-ready ground truth: axis, pose, profile, painted features, holes, options.

    The profile is sampled about every millimetre of arc length (interpolating it
    linearly is then within a few micrometres of the exact polyline, see
    :attr:`SyntheticVessel.profile`).
    """
    p = vessel.painting
    prof = vessel.profile
    step = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(prof, axis=0), axis=1))])
    keep = np.unique(np.concatenate([np.searchsorted(step, np.arange(0.0, step[-1], 1.0)),
                                     [len(prof) - 1]]))
    return {
        "kind": vessel.kind,
        "units": "mm",
        "options": vessel.options,
        "axis_point": vessel.axis_point,
        "axis_direction": vessel.axis_direction,
        "pose": vessel.pose,
        "profile": {"height": prof[keep, 0].round(6), "radius": prof[keep, 1].round(6),
                    "note": "outer wall, sampled about every 1 mm of arc length"},
        "circles": [{"centre": c.centre, "radius": c.radius, "colour": list(c.colour),
                     "side": c.side, "height": c.height, "angle": c.angle} for c in vessel.features],
        "bands": [{"z_low": lo if math.isfinite(lo) else None, "z_high": hi if math.isfinite(hi) else None,
                   "colour": list(c)} for lo, hi, c in p.bands],
        "bars": [{"angle": a, "width": w, "z_low": lo, "z_high": hi, "colour": list(c)}
                 for a, w, lo, hi, c in p.bars],
        "holes": [{"centre": h.centre, "radius": h.radius} for h in vessel.holes],
        "counts": {"vertices": len(vessel.mesh.vertices), "faces": len(vessel.mesh.faces),
                   "charts": int(vessel.face_chart.max()) + 1},
    }


def write_truth(vessel: SyntheticVessel, path: str | os.PathLike) -> Path:
    """Write :func:`truth` as JSON (atomically); returns ``path``."""
    from potflat.io.atomic import write_json_atomic

    return write_json_atomic(path, truth(vessel))
