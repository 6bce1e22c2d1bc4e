"""Stage 1, rollout: find the axis, select the region, cut a seam and unroll on a proxy.

``rollout(mesh)`` returns a :class:`RolloutResult` whose :attr:`~RolloutResult.flat` is a
disk-topology mesh covering every selected face, cut exactly along the seam's meridian (the
faces across it split, as GigaMesh does: :func:`potflat.rollout.seam.cut_region`) with the
vertices on the seam duplicated (one copy per side). The selected faces are the painted side asked for (the outer
wall, or the inner one seen from inside: :mod:`potflat.rollout.walls`), without attachments such as
handles (:mod:`potflat.rollout.attachments`), without a base the development would smear (shown
apart, seen along the axis: :mod:`potflat.rollout.base`) and without the border faces that fold
the development over (the rim top, a base's underside, break faces: :func:`border_folds`); folds inside the
region, from the scan itself, are unfolded (:func:`untangle`), so the result has no flipped
face and no overlapping border, and everything left out is reported. The file stage
(reading a scan, writing ``NAME.rollout.ply`` and its sidecars) is
:func:`potflat.files.rollout_stage.run_rollout_stage`.

Angles: the reference direction of the axis (:attr:`AxisFit.reference`) is 0 degrees; the
seam angle is measured from it counter-clockwise about the axis (axis pointing up). Angles
of the region (``angles``) and of the output (``u = R theta`` on a cylinder) are measured
from the seam. A region that does not go all the way round (a sherd, a frieze, a scan
with a gap from foot to rim) needs no cut.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from potflat import importance as _importance
from potflat._heap import release_free_memory
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.images import read_ahead
from potflat.mesh.boundary import edges_and_boundary, outline_turning
from potflat.mesh.distortion import DistortionSummary, face_areas, summarize
from potflat.rollout import proxy as _proxy
from potflat.rollout.attachments import AttachmentSelection, detect_attachments
from potflat.rollout.axis import AxisFit, estimate_axis, manual_axis
from potflat.rollout.base import (
    BaseCut,
    BaseSplit,
    base_disc,
    cut_base,
    disc_figures,
    split_base,
    unrolled_errors,
)
from potflat.rollout.border import (
    TRIM_ROUNDS,
    border_folds,
    crossing_segments,
    untangle,
)
from potflat.rollout.folds import ScanFolds, fold_masks, scan_folds, smoothing_steps
from potflat.rollout.landmarks import find_landmark, zone_centre
from potflat.rollout.objects import _main_object, _submesh
from potflat.rollout.options import RolloutOptions
from potflat.rollout.profile import Profile, vessel_profile
from potflat.rollout.seam import (
    CutOrigins,
    _auto_seam,
    _corner_angles,
    _covered,
    _gap_middle,
    cut_open,
    cut_region,
)
from potflat.rollout.topology import DiskCut, disk_cut
from potflat.rollout.walls import (
    FaceGraph,
    WallCut,
    WallSelection,
    check_axis,
    cut_between_walls,
    face_frame,
    select_wall,
)
from potflat.types import FlatMesh, Mesh, RolloutMarks, StepClock

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Region:
    """The part of the scan that was unrolled.

    Attributes
    ----------
    band : (float, float)
        Height band, fractions of the axial extent (0 = foot, 1 = mouth).
    angles_deg : (float, float) or None
        Requested angle range from the seam, degrees.
    height_range : (float, float)
        Heights above the foot covered by the selected faces, scan units.
    theta_range_deg : (float, float)
        Angles covered by the output vertices, degrees from :attr:`RolloutResult.theta_origin`
        (the seam, or the origin of ``angles``).
    faces, faces_total : int
        Faces selected, faces in the scan.
    cut : bool
        Whether the region went all the way round and had to be cut open.
    overlap_deg : float
        Degrees repeated past 360 (0: none).
    repeated_from : int or None
        With an overlap, the first output face of the repeat: faces from it on repeat the
        first ``overlap_deg`` degrees after the seam.
    """

    band: tuple[float, float]
    angles_deg: tuple[float, float] | None
    height_range: tuple[float, float]
    theta_range_deg: tuple[float, float]
    faces: int
    faces_total: int
    cut: bool
    overlap_deg: float = 0.0
    repeated_from: int | None = None

    def as_dict(self) -> dict:
        """JSON-ready description."""
        d = asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


@dataclass(frozen=True, eq=False)
class RolloutResult:
    """The rollout of a scan.

    Attributes
    ----------
    flat : FlatMesh
        The cut region with its flattened ``uv`` (scan units).
    axis : AxisFit
        Axis used, with its fit quality.
    proxy : Proxy
        Proxy used, its parameters, the candidates' figures and the reason.
    seam_angle : float
        Seam angle in degrees from the axis' reference direction, in ``[0, 360)``.
    seam_method : str
        How the seam was chosen (``user``, ``texture``, ``colours``, ``geometry``, ``gap``).
    region : Region
        What was selected.
    distortion : DistortionSummary
        Distortion of the rollout.
    face_index : (m_out,) int64
        Input face of each output face (a face the seam or a window's side cut appears once
        per piece).
    vertex_index : (n_out,) int64
        Input vertex of each output vertex; -1 for a vertex the cut added on an input edge.
    seam_vertices : int
        Vertex copies added by the cut (each seam vertex once more).
    cut_vertices, cut_faces : int
        Vertices the cut added where the seam's meridian (or a window's side) crosses an
        input edge or an input vertex near it was moved onto it (each once: their copies
        are in ``seam_vertices``), and input faces it split into pieces or reshaped.
    split_vertices : int
        Vertex copies added where the input was not manifold (a vertex whose faces form
        separate fans becomes one vertex per fan).
    walls : WallSelection
        The painted side's faces (``side`` outer or inner) and the wall labels.
    attachments : AttachmentSelection
        Handles, spouts, knobs found off the surface of revolution.
    attachments_kept : bool
        Whether the attachments were kept in the rollout (``keep_attachments``).
    attachment_roots : (k,) int64
        Rollout faces (indices into ``flat.mesh.faces``) where a left-out attachment met
        the wall: its footprint, to show as a mask in the bake (empty when kept or none).
    trimmed : (t,) int64
        Input faces left out because they are edge-on to the proxy at the region's border
        (the rim top, a base's underside, a sherd's break faces): their development folds
        over (see :func:`border_folds`).
    trimmed_area : float
        Their 3D area, scan units squared.
    untangled_faces, untangled_vertices : int
        Faces folded inside the development (creases of the scan surface, slivers) before
        :func:`untangle`, and the vertices it moved to unfold them.
    boundary_overlap : int
        Crossing pairs of boundary segments left in the development (0: its outline and
        holes do not overlap).
    outline_turning : float
        Total turning of the development's outline and holes
        (:func:`potflat.mesh.boundary.outline_turning`: 1 for a convex outline; a ragged
        edge adds about twice the angle of every tooth).
    other_objects_faces : int
        Faces of separate objects left out.
    landmark : Landmark or None
        What ``seam`` and ``angles`` were measured from (:mod:`potflat.rollout.landmarks`).
    theta_origin : float
        Degrees from the reference direction that the output angles (:attr:`Region.theta_range_deg`)
        are measured from: the seam, or the origin of ``angles``.
    landmark_notes : tuple of str
        What was used where a named landmark is missing.
    folds : ScanFolds or None
        Where the scan folds over itself in 3D (creases, flaps, duplicated sheets;
        :mod:`potflat.rollout.folds`).
    profile : Profile or None
        The vessel's profile (:func:`potflat.rollout.profile.vessel_profile` of both walls
        around :attr:`axis`, attachments left out unless kept; height bins of
        ``options.profile_mm``).
    base : BaseSplit or None
        Where the faces at the foot that face along the axis went (:mod:`potflat.rollout.base`):
        left out of :attr:`flat` and shown as their own disc (``base.flat``), or kept; None
        for the ``ortho`` proxy (a view already).
    disk_cut : DiskCut or None
        What made the selected faces other than a disk (:mod:`potflat.rollout.topology`); its
        ``faces`` are of the first development.
    disk_cut_faces : (c,) int64
        Input faces left out to make the selection a disk.
    disk_cut_area : float
        Their 3D area, scan units squared.
    wall_cut : WallCut or None
        The line along which :attr:`walls` was cut off from the other wall
        (:func:`potflat.rollout.walls.cut_between_walls`); None for a scan with one wall and
        for the ``ortho`` proxy.
    """

    flat: FlatMesh
    axis: AxisFit
    proxy: _proxy.Proxy
    seam_angle: float
    seam_method: str
    region: Region
    distortion: DistortionSummary
    face_index: np.ndarray
    vertex_index: np.ndarray
    seam_vertices: int
    split_vertices: int
    walls: WallSelection
    attachments: AttachmentSelection
    attachments_kept: bool
    attachment_roots: np.ndarray
    trimmed: np.ndarray
    trimmed_area: float
    untangled_faces: int
    untangled_vertices: int
    boundary_overlap: int
    outline_turning: float = 0.0
    other_objects_faces: int = 0
    cut_vertices: int = 0
    cut_faces: int = 0
    landmark: object = None
    theta_origin: float = 0.0
    landmark_notes: tuple = ()
    importance: _importance.Importance | None = None
    timings: dict = field(default_factory=dict)
    folds: ScanFolds | None = None
    profile: Profile | None = None
    base: BaseSplit | None = None
    disk_cut: DiskCut | None = None
    disk_cut_faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    disk_cut_area: float = 0.0
    wall_cut: WallCut | None = None

    @property
    def side(self) -> str:
        """The painted side unrolled, ``outer`` or ``inner``."""
        return self.walls.side

    @property
    def marks(self) -> RolloutMarks:
        """What the bake marks on the images of this rollout and of its relaxation."""
        folds = self.folds
        return RolloutMarks(
            attachment_roots=np.zeros(0, np.int64) if self.attachments_kept else np.asarray(self.attachment_roots,
                                                                                            np.int64),
            repeated_from=self.region.repeated_from, overlap_deg=self.region.overlap_deg,
            folded_faces=np.zeros(0, np.int64) if folds is None else np.asarray(folds.faces, np.int64),
            folded_area_mm2=0.0 if folds is None else folds.area_mm2,
            folded_percent=0.0 if folds is None else folds.percent,
            folded_regions=0 if folds is None else len(folds.regions))


def rollout(mesh: Mesh, *, options: RolloutOptions | None = None, face_mask: np.ndarray | None = None,
            **option_fields) -> RolloutResult:
    """Unroll a scan: axis, painted side, region, seam cut and proxy development.

    After the axis, the attachments (handles, spouts, knobs) are found and, unless
    ``keep_attachments``, left out; the painted side (``side``: the outer wall, or the inner
    one seen from inside with ``u`` mirrored so that faces keep their orientation) is
    selected, so the two walls of a cup are never mixed. Faces at the foot facing along the
    axis that the development would show less truly than a view along it (a base, a floor)
    are left out and shown as their own disc (:attr:`RolloutResult.base`; ``keep_base``
    keeps them). Strips at the region's border
    that are edge-on to the proxy and fold over in the development (the rim top, a base's
    underside, a sherd's break faces) are trimmed and reported (:func:`border_folds`);
    folds inside the region (scan noise) stay for the relax stage to untangle.

    Parameters
    ----------
    mesh : Mesh
        The scan (outward-oriented faces), e.g. ``load_scan(path).mesh``.
    options : RolloutOptions, optional
        All options; or give them as keywords (``rollout(mesh, proxy="cone")``), not both.
    face_mask : (m,) bool, optional
        Faces that may be unrolled, further restricting the painted side's faces; the band
        and angles select within them. The axis is fitted on the whole scan and the band's
        fractions refer to the whole scan's height.
    **option_fields
        Fields of :class:`RolloutOptions`.

    Returns
    -------
    RolloutResult

    Raises
    ------
    AxisNotFoundError
        When no axis is given and the scan has no rotational symmetry.
    InvalidOptionError
        When an option is invalid or the region selects no face.
    InvalidInputError
        When ``side="inner"`` and the scan has no inner wall, or ``face_mask`` is malformed.
    """
    if options is None:
        options = RolloutOptions(**option_fields)
    elif option_fields:
        raise InvalidOptionError("give either options= or option keywords to rollout(), not both")
    if not isinstance(mesh, Mesh):
        raise InvalidInputError(f"rollout needs a potflat Mesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0:
        raise InvalidInputError(f"{mesh.source or 'mesh'} has no faces; give a triangle mesh of the vessel")
    F = mesh.faces
    if face_mask is not None:
        face_mask = np.asarray(face_mask)
        if face_mask.dtype != bool or face_mask.shape != (len(F),):
            raise InvalidInputError(f"face_mask must be a bool array of shape ({len(F)},), got "
                                    f"{face_mask.dtype} {face_mask.shape}")
    texture = mesh.texture_path if mesh.texcoords is not None and mesh.texture_path is not None else None
    # the texture's decodes run on the second core: the seam's grey levels while the axis and
    # the attachments are found (steps that keep about one core busy), the painted zone's
    # colours once the unrolling's peak of memory is past (``later``)
    with read_ahead(texture, grey=options.seam is None), contextlib.ExitStack() as later:
        return _rollout_steps(mesh, options, face_mask, texture, later)


def _rollout_steps(mesh: Mesh, options: RolloutOptions, face_mask: np.ndarray | None,
                   texture: Path | None, later: contextlib.ExitStack) -> RolloutResult:
    """:func:`rollout` after its checks of the input; ``texture`` the path of the texture it
    reads (None: none), ``later`` holds the read-aheads it starts."""
    V, F = mesh.vertices, mesh.faces
    clock = StepClock()
    other_objects = np.zeros(len(F), bool)
    if options.axis is not None:
        axis = manual_axis(mesh, options.axis[:3], options.axis[3:], flip=options.flip)
    else:
        main = _main_object(mesh)
        if main is None:
            axis = estimate_axis(mesh, flip=options.flip)
        else:
            axis = estimate_axis(_submesh(mesh, main), flip=options.flip)
            other_objects = ~main
            face_mask = main if face_mask is None else face_mask & main
    clock.lap("axis")
    # the face adjacency, found once for the attachments (if they need it) and the walls
    graph = FaceGraph(F, shared=True)
    others = other_objects if other_objects.any() else None  # (a second vessel beside this one)
    attachments = detect_attachments(mesh, axis.point, axis.direction, graph=graph, others=others)
    clock.lap("attachments")
    frame = face_frame(mesh, *check_axis(axis.point, axis.direction), graph=graph)  # the walls' and the profile's
    walls = select_wall(mesh, axis.point, axis.direction, side=options.side,
                        exclude=None if options.keep_attachments else attachments.face_mask, others=others,
                        graph=graph, frame=frame, inside_out=not options.keep_orientation)
    del graph
    # the two walls of a scan meet along a smooth line, the faces across it cut along it (a
    # projection along the axis is not cut)
    left_out = other_objects | walls.ground_mask
    if not options.keep_attachments:
        left_out |= attachments.face_mask
    wall_cut = None if options.proxy == "ortho" else cut_between_walls(F, len(V), walls, exclude=left_out)
    allowed = walls.face_mask if wall_cut is None else wall_cut.face_mask
    if face_mask is not None:
        allowed = allowed & face_mask
    clock.lap("walls")
    # the vessel's profile, both walls, attachments, other objects and a table at the foot
    # left out (docs/profile.md)
    bins = (None if options.profile_mm is None
            else max(1, math.ceil(axis.height * mesh.mm_per_unit / options.profile_mm)))
    profile = vessel_profile(mesh, axis.point, axis.direction, bins=bins, labels=walls.labels, frame=frame,
                             face_mask=~left_out if left_out.any() else None)
    centroid = frame.centroid  # (the faces' centroids, computed with the frame)
    n_axial = frame.n_axial
    del frame
    clock.lap("profile")

    area = face_areas(V, F)
    h_c, r_c, theta_c = axis.cylindrical(centroid)
    del centroid
    h_v, r_v, theta_v = axis.cylindrical(V)  # once for every unrolling and the seam (and the base)
    band = options.band or (0.0, 1.0)
    # the level cuts before the seam's: the line between the walls, a band's planes, then the base's plane
    floors = ()

    def angle_of(points):
        return axis.cylindrical(points)[2]

    if wall_cut is not None and len(wall_cut.faces):
        across = np.zeros(len(F), bool)
        across[wall_cut.faces] = True
        floors = ((across, wall_cut.levels, angle_of),)
    if options.band is not None and options.proxy != "ortho":  # cut along its planes: every face reaching into it
        allowed, cuts = _band_cuts(axis, band, h_v, F, allowed, angle_of)
        floors += cuts
    else:  # (a projection is not cut: the faces whose centres lie in it)
        allowed = allowed & _in_band(axis, band, h_c)
    landmark, landmark_notes = _find_landmark(mesh, axis, options, attachments, allowed, theta_c, theta_v, area,
                                             h_c)
    trimmed = np.zeros(len(F), bool)
    un = _unroll(mesh, axis, options, allowed, theta_c, theta_v, area, h_c, landmark=landmark, floors=floors)
    # the cut's temporaries (the largest of the rollout) back to the system: the base and
    # the trimming come on top of the heap otherwise (at 3M vertices some 30 MB of the peak)
    release_free_memory()
    clock.lap("unroll")
    base = None
    if options.proxy != "ortho":  # (a view along the axis shows the base as it is)
        region, first = np.unique(un.face_index, return_index=True)  # (a repeat past 360 degrees once)
        # (peak memory: the development's edge table is not held while the base is decided; it
        # is found again only when the development stays)
        un = dataclasses.replace(un, table=None)
        base = split_base(mesh, region, unrolled_errors(un.flat, first), n_axial=n_axial, height=h_c, radius=r_c,
                          vertex_radius=r_v, vertex_theta=theta_v, area=area, vessel_height=axis.height,
                          side=options.side,
                          keep=options.keep_base)
        if base.left_out:  # cut off along a plane across the axis, unrolled again without it:
            # the proxy is fitted to the wall alone
            wall = np.setdiff1d(region, np.concatenate([base.disc_faces, base.hidden_faces]))
            base_cut, whole, cut_note = cut_base(V, F, base.disc_faces, wall, h_v, axis.height,
                                                 -axis.direction if base.view == "below" else axis.direction)
            base = dataclasses.replace(base, disc_faces=whole, cut=base_cut, cut_note=cut_note)
            if base_cut is not None and len(base_cut.faces):
                cut_mask = np.zeros(len(F), bool)
                cut_mask[base_cut.faces] = True
                floors += ((cut_mask, functools.partial(_base_levels, base_cut, axis, h_v), angle_of),)
            allowed = allowed.copy()
            allowed[base.disc_faces] = allowed[base.hidden_faces] = False
            seam = (un.seam, un.seam_method)
            del un  # (peak memory: the unrolling it replaces is not held while it is made)
            un = _unroll(mesh, axis, options, allowed, theta_c, theta_v, area, h_c,
                         seam=seam, landmark=landmark, floors=floors)
        del region, first
        if un.table is None:
            un = dataclasses.replace(un, table=edges_and_boundary(un.flat.mesh.faces, len(un.vertex_index)))
    del n_axial, r_c, r_v
    clock.lap("base")
    # a piece that is not a disk (a handle joined at both ends, a closed part, an edge of three
    # faces) cannot be laid flat without a fold: cut into one
    disk = disk_cut(un.flat.mesh.faces, un.flat.mesh.vertices,
                    un.origins.vertex_values(attachments.vertex_offset, un.vertex_index))
    cut_faces = np.unique(un.face_index[disk.faces])
    if len(cut_faces):
        allowed = allowed.copy()
        allowed[cut_faces] = False
        un = _without(un, ~disk.faces)
    clock.lap("disk")
    graph = None  # the development's face adjacency, shared by the border_folds calls on one face set
    for rnd in range(TRIM_ROUNDS):
        if graph is None:
            graph = FaceGraph(un.flat.mesh.faces)
        fold = border_folds(un.flat.mesh.faces, un.flat.uv, un.face_area, points=un.flat.mesh.vertices, graph=graph)
        if not fold.any() or fold.all():
            break
        trimmed[un.face_index[fold]] = True
        graph = None
        un = _without(un, ~fold)
        if rnd < TRIM_ROUNDS - 1:
            un = _developed_again(un, axis, len(V), options)
    clock.lap("unroll")
    # where the scan folds in 3D, judged on the development before untangling, kept per scan face
    facing_in, overlapping = (np.zeros(len(F), bool) for _ in range(2))
    fold_steps = smoothing_steps(un.flat.mesh.vertices, un.table[0], mesh.mm_per_unit)
    for scan_mask, mask in zip((facing_in, overlapping),
                               fold_masks(un.flat.mesh.faces, un.flat.uv, steps=fold_steps)):
        scan_mask[un.face_index[mask]] = True
    clock.lap("folds")
    uv, n_untangled, moved = untangle(un.flat.mesh.faces, un.flat.uv, table=un.table)
    for _ in range(TRIM_ROUNDS):  # folds pushed against the border by untangling are trimmed
        if graph is None:
            graph = FaceGraph(un.flat.mesh.faces)
        fold = border_folds(un.flat.mesh.faces, uv, un.face_area, points=un.flat.mesh.vertices, graph=graph)
        if not fold.any() or fold.all():
            break
        trimmed[un.face_index[fold]] = True
        un = _without(dataclasses.replace(un, flat=un.flat.replace(uv=uv)), ~fold)
        graph = None
        uv, more, moved_more = untangle(un.flat.mesh.faces, un.flat.uv, table=un.table)
        n_untangled, moved = n_untangled + more, moved + moved_more
    del graph
    clock.lap("untangle")
    # past the unrolling's peak: the memory its temporaries left free goes back to the system
    # (else the painted zone's texture and paint land above it), and the full texture for the
    # painted zone's colours is decoded beside the checks
    release_free_memory()
    later.enter_context(read_ahead(texture, rgb=options.importance == "auto"))
    overlap = len(crossing_segments(uv, un.table[1])[0])
    turning = outline_turning(un.flat.mesh.faces, uv, segments=un.table[1])
    distortion = un.distortion
    if n_untangled or distortion is None:
        distortion = summarize(un.flat.mesh.vertices, uv, un.flat.mesh.faces, edges=un.table[0])
    if options.keep_attachments or not attachments.n_faces:
        roots = np.zeros(0, np.int64)
    else:
        roots = np.flatnonzero(attachments.root_faces(F)[un.face_index]).astype(np.int64)

    theta_deg = np.degrees(un.theta)
    repeated = un.origins.repeated  # (they come last)
    repeated_from = int(np.argmax(repeated)) if repeated.any() else None
    region = Region(
        band=tuple(band), angles_deg=options.angles,
        height_range=(float(h_c[un.face_index].min()), float(h_c[un.face_index].max())),
        theta_range_deg=(float(theta_deg.min()), float(theta_deg.max())),
        faces=len(un.face_index), faces_total=len(F), cut=un.seam_vertices > 0,
        overlap_deg=options.overlap if repeated_from is not None else 0.0, repeated_from=repeated_from)
    cut = un.flat.mesh
    if mesh.texcoords is not None:  # attached once, to the final faces (see _unroll)
        cut = cut.replace(**un.origins.face_fields(mesh))
    flat = un.flat.replace(mesh=cut, uv=uv)
    clock.lap("checks")
    importance = _find_importance(flat, options, axis, theta_deg)
    clock.lap("importance")
    folds = scan_folds(cut.vertices, cut.faces, facing_in[un.face_index], overlapping[un.face_index],
                       height=axis.cylindrical(cut.vertices)[0], vessel_height=axis.height, angle_deg=theta_deg,
                       mm_per_unit=mesh.mm_per_unit, steps=fold_steps)
    clock.lap("folds")
    if base is not None and base.left_out:
        disc, disc_proxy = base_disc(mesh, base.disc_faces, axis, view=base.view, up_angle=un.seam, cut=base.cut)
        disc_area, orthographic = disc_figures(disc, axis, base.view)
        base = dataclasses.replace(base, flat=disc, proxy=disc_proxy, disc_area=disc_area,
                                   orthographic_error_pct=orthographic,
                                   distortion=summarize(disc.mesh.vertices, disc.uv, disc.mesh.faces))
        clock.lap("base")
    added = un.vertex_index >= len(V)
    return RolloutResult(
        flat=flat.replace(importance=importance.values), importance=importance, axis=axis, proxy=un.proxy,
        seam_angle=float(math.degrees(un.seam) % 360.0), seam_method=un.seam_method, region=region,
        distortion=distortion, face_index=un.face_index, vertex_index=np.where(added, -1, un.vertex_index),
        seam_vertices=un.seam_vertices, split_vertices=un.split_vertices, walls=walls,
        cut_vertices=len(np.unique(un.vertex_index[added])),
        cut_faces=len(np.unique(un.face_index[un.origins.pieces])),
        attachments=attachments, attachments_kept=options.keep_attachments, attachment_roots=roots,
        trimmed=np.flatnonzero(trimmed).astype(np.int64), trimmed_area=float(area[trimmed].sum()),
        untangled_faces=n_untangled, untangled_vertices=moved, boundary_overlap=overlap, outline_turning=turning,
        other_objects_faces=int(other_objects.sum()), landmark=landmark,
        theta_origin=float(math.degrees(un.origin) % 360.0), landmark_notes=tuple(landmark_notes),
        timings=clock.total(), folds=folds, profile=profile, base=base, disk_cut=disk,
        disk_cut_faces=cut_faces.astype(np.int64), disk_cut_area=float(area[cut_faces].sum()), wall_cut=wall_cut)


@dataclass(frozen=True, eq=False)
class _Unrolled:
    """One unrolling of a face selection (what :func:`rollout` repeats while trimming)."""

    flat: FlatMesh
    proxy: _proxy.Proxy
    #: the development's distortion figures (None: not found yet, after faces were cut from it)
    distortion: DistortionSummary | None
    face_index: np.ndarray
    #: the scan vertex of each vertex (``>= origins.n``: added by the cut)
    vertex_index: np.ndarray
    theta: np.ndarray
    seam: float
    seam_method: str
    seam_vertices: int
    split_vertices: int
    origin: float
    #: ``edges_and_boundary`` of the development's faces (its edges, boundary segments and their
    #: faces), found once for each face set
    table: tuple
    #: where the faces and vertices come from (pieces of cut faces, added vertices, repeats)
    origins: CutOrigins
    #: 3D area of each face
    face_area: np.ndarray


def _unroll(mesh: Mesh, axis: AxisFit, options: RolloutOptions, allowed: np.ndarray, theta_c,
            theta_v, area, h_c, seam: tuple[float, str] | None = None, landmark=None, floors=()) -> _Unrolled:
    """Select the region within ``allowed`` (the band's faces already), cut it open and develop it on the proxy (with
    ``seam`` = (radians, method) from an earlier unrolling, or a seam chosen here; angles
    measured from ``landmark``; ``theta_v``: the angle of every scan vertex; ``h_c``: the height
    of every face's centroid; ``floors``: the
    line between the walls and a base cut off, as :func:`potflat.rollout.seam.cut_region`
    takes them)."""
    V = mesh.vertices
    sub_f, corner_theta, origins, seam, seam_method, origin = _select(
        mesh, axis, options, allowed, theta_c, theta_v, area, h_c, seam, landmark, floors)
    face_index = origins.face_index
    inner = options.side == "inner"

    if options.proxy == "ortho":  # a projection: nothing to cut
        vertex_index = np.flatnonzero(np.bincount(sub_f.ravel(), minlength=len(V)))
        new_index = np.zeros(len(V), np.int64)
        new_index[vertex_index] = np.arange(len(vertex_index))
        new_faces = new_index[sub_f]
        theta_new = np.zeros(len(vertex_index))
        theta_new[new_faces.ravel()] = corner_theta.ravel()
        n_seam = n_split = 0
    else:
        new_faces, vertex_index, theta_new, n_seam, n_split = cut_open(sub_f, corner_theta)

    del sub_f, corner_theta
    table = edges_and_boundary(new_faces, len(vertex_index))
    # without texture coordinates (and untextured-face flags): rollout() attaches them to the
    # final faces only (a copy per unrolling would be the largest array here)
    cut_mesh = Mesh(
        origins.vertex_values(V, vertex_index), new_faces, texture_path=mesh.texture_path,
        vertex_colors=None if mesh.vertex_colors is None else origins.vertex_values(mesh.vertex_colors, vertex_index),
        units=mesh.units, source=mesh.source)
    face_area = area[face_index]
    if len(origins.pieces):
        face_area[origins.pieces] = face_areas(cut_mesh.vertices, new_faces[origins.pieces])
    h, r, _ = axis.cylindrical(cut_mesh.vertices)
    vert_area = _fit_weights(new_faces, face_area, vertex_index, len(V))
    # the inner side is seen from the axis: u runs clockwise (seen from above), which is the
    # development of -theta (an exact mirror of u for every proxy)
    dev_theta = -theta_new if inner else theta_new

    if options.proxy == "ortho":
        view = options.view
        if view is None:
            view = _default_view(axis, theta_c[face_index], area[face_index], seam)
            view = -view if inner else view
        prox = _proxy.ortho_proxy(axis.direction, axis.reference, np.asarray(view, float))
        prox = _proxy.Proxy(prox.kind, prox.params, reason="requested (orthographic projection)")
        uv = _proxy.project_ortho(prox, cut_mesh.vertices, axis.point)
        summary = summarize(cut_mesh.vertices, uv, new_faces, edges=table[0])
    else:
        prox, uv, summary = _on_proxy(cut_mesh.vertices, new_faces, h, r, dev_theta, vert_area, table[0], options.proxy)
    return _Unrolled(FlatMesh(cut_mesh, uv), prox, summary, face_index, vertex_index, theta_new, seam,
                     seam_method, n_seam, n_split, origin, table, origins, face_area)


def _without(un: _Unrolled, keep: np.ndarray) -> _Unrolled:
    """The same development restricted to the faces in ``keep`` ((m,) bool), vertices compacted."""
    mesh = un.flat.mesh
    faces = np.take(mesh.faces, np.flatnonzero(keep), axis=0)
    used = np.flatnonzero(np.bincount(faces.ravel(), minlength=len(mesh.vertices)))
    new_index = np.zeros(len(mesh.vertices), np.int64)
    new_index[used] = np.arange(len(used))
    cut = mesh.replace(vertices=mesh.vertices[used], faces=new_index[faces],
                       vertex_colors=None if mesh.vertex_colors is None else mesh.vertex_colors[used])
    uv = un.flat.uv[used]
    vertex_index = un.vertex_index[used]
    copies = len(used) - int(np.count_nonzero(np.bincount(vertex_index)))
    seam = min(un.seam_vertices, copies)
    table = edges_and_boundary(cut.faces, len(used))
    return _Unrolled(FlatMesh(cut, uv), un.proxy, None,
                     un.face_index[keep], vertex_index, un.theta[used], un.seam, un.seam_method, seam, copies - seam,
                     un.origin, table, un.origins.subset(keep), un.face_area[keep])


def _vertex_areas(faces: np.ndarray, face_area: np.ndarray, n: int) -> np.ndarray:
    """Each of ``n`` vertices' share of the surface ((n,) float64): a third of its faces'
    areas ``face_area`` ((m,) float64 of ``faces`` (m, 3))."""
    return np.bincount(faces.ravel(), np.repeat(face_area / 3.0, 3), n)


def _fit_weights(faces: np.ndarray, face_area: np.ndarray, vertex_index: np.ndarray, n_scan: int) -> np.ndarray:
    """The proxy fit's weight of each vertex of a cut region ((k,) float64): its share of the
    3D surface, 0 for the vertices the cut added (``vertex_index >= n_scan``: the proxy is
    fitted to the scan's vertices, not to the cut's, which lie on chords)."""
    weights = _vertex_areas(faces, face_area, len(vertex_index))
    weights[vertex_index >= n_scan] = 0.0
    return weights


def _on_proxy(vertices: np.ndarray, faces: np.ndarray, h: np.ndarray, r: np.ndarray, theta: np.ndarray,
              vert_area: np.ndarray, edges: np.ndarray, kind: str
              ) -> tuple[_proxy.Proxy, np.ndarray, DistortionSummary]:
    """A cut region's development on the proxy of ``kind`` fitted to it (``"auto"``: the
    least distorting, :func:`potflat.rollout.proxy.choose`): the proxy, ``uv`` (k, 2) and its
    distortion figures (``h, r, theta``: the vertices' cylindrical coordinates, ``theta``
    unwrapped and signed as developed; ``vert_area``: the fit's weights; ``edges``: the
    faces' undirected edges)."""
    if kind == "auto":
        return _proxy.choose(vertices, faces, h, r, theta, vert_area, edges=edges)
    prox = _proxy.fit(kind, h, r, theta, vert_area)
    prox = _proxy.Proxy(prox.kind, prox.params, reason="requested")
    uv = _proxy.develop(prox, h, r, theta)
    return prox, uv, summarize(vertices, uv, faces, edges=edges)


def _developed_again(un: _Unrolled, axis: AxisFit, n_scan: int, options: RolloutOptions) -> _Unrolled:
    """The development ``un`` on its proxy fitted (or chosen, as ``options.proxy`` says) again
    to its own faces, as :func:`_unroll` develops a cut region (``n_scan``: the scan's vertex
    count; the cut's added vertices come after and carry no weight in the fit)."""
    if options.proxy == "ortho":
        return un
    mesh = un.flat.mesh
    h, r, _ = axis.cylindrical(mesh.vertices)
    vert_area = _fit_weights(mesh.faces, un.face_area, un.vertex_index, n_scan)
    theta = -un.theta if options.side == "inner" else un.theta
    prox, uv, summary = _on_proxy(mesh.vertices, mesh.faces, h, r, theta, vert_area, un.table[0], options.proxy)
    return dataclasses.replace(un, flat=un.flat.replace(uv=uv), proxy=prox, distortion=summary)


#: Seam methods of a seam placed by the user (an angle, a point, a landmark), not chosen here.
_PLACED_SEAMS = ("user", "point", "handle", "opposite painted zone")


def _find_landmark(mesh: Mesh, axis: AxisFit, options: RolloutOptions, attachments, face_mask, theta_c, theta_v,
                   area, h_c):
    """The landmark the options name (:func:`potflat.rollout.landmarks.find_landmark`), or None when
    seam and angles are measured as before (from the reference direction, angles from the seam)."""

    if options.seam_at is None and options.landmark is None and (options.angles is None or options.seam is not None):
        return None, []
    keep = np.flatnonzero(face_mask)
    if len(keep) == 0:
        raise InvalidOptionError("the band and angle range select no faces; widen --band or --angles")
    return find_landmark(
        mesh, axis, seam_at=options.seam_at, landmark=options.landmark, attachments=attachments,
        painted_zone=lambda: _painted_zone_centre(mesh, axis, options, face_mask, theta_c, theta_v, area, h_c),
        auto_seam=lambda: _auto_seam(mesh, keep, theta_c, theta_v, area, h_c)[0])


def _painted_zone_centre(mesh: Mesh, axis: AxisFit, options: RolloutOptions, face_mask, theta_c, theta_v,
                         area, h_c) -> tuple[float | None, str]:
    """Centre angle of the importance zone (:func:`_find_importance` on an all-round unrolling
    with the automatic seam), or None and why."""

    plain = dataclasses.replace(options, seam=None, angles=None, seam_at=None, landmark=None, overlap=0.0)
    un = _unroll(mesh, axis, plain, face_mask, theta_c, theta_v, area, h_c)
    flat = un.flat
    if mesh.texcoords is not None:
        flat = flat.replace(mesh=flat.mesh.replace(**un.origins.face_fields(mesh)))
    importance = _find_importance(flat, options, axis, np.degrees(un.theta))
    if importance.values is None:
        return None, importance.reason
    vertex_area = _vertex_areas(flat.mesh.faces, un.face_area, len(flat.uv))
    angle, length = zone_centre(axis.cylindrical(flat.mesh.vertices)[2], importance.values * vertex_area)
    if angle is None:
        return None, f"the importance zone goes round evenly (resultant {length:.3f})"
    return angle, f"centre of the importance zone ({importance.method}: {importance.reason}), resultant {length:.2f}"


def _in_band(axis: AxisFit, band, h_c) -> np.ndarray:
    """The faces whose centres' heights ``h_c`` ((m,) float64) lie in ``band`` (fractions of the
    axis' height), (m,) bool."""
    frac = h_c / axis.height if axis.height > 0 else np.zeros(len(h_c))
    return (frac >= band[0]) & (frac <= band[1])


def _select(mesh: Mesh, axis: AxisFit, options: RolloutOptions, face_mask, theta_c, theta_v, area, h_c,
            seam_given: tuple[float, str] | None = None, landmark=None, floors=()):
    """The region's faces (:func:`potflat.rollout.seam.cut_region`: the seam and a window's
    sides cut exactly along their meridians), their corners' unwrapped angles, where they
    come from in the scan, the seam (radians, and how it was chosen) and the angle (radians)
    the angles are measured from.

    With an overlap the faces within ``overlap`` degrees after the seam are listed twice, the
    repeats last, their angles one turn on."""
    F = mesh.faces
    keep = face_mask.copy()
    placed = landmark is not None and (options.seam_at is not None or options.landmark is not None)
    if seam_given is not None:
        seam, seam_method = seam_given
    elif options.angles is not None and landmark is not None and options.angles[1] - options.angles[0] >= 360.0:
        seam, seam_method = landmark.angle + math.radians(options.angles[0]), "window edge"
    elif options.seam is not None:
        seam, seam_method = (landmark.angle if placed else 0.0) + math.radians(options.seam % 360.0), "user"
    elif placed:
        seam = landmark.angle + (math.pi if landmark.kind == "painted zone" else 0.0)
        seam_method = {"point": "point", "handle": "handle"}.get(landmark.kind, "opposite painted zone")
    else:
        sel = np.flatnonzero(keep)
        if len(sel) == 0:
            low, high = options.band or (0.0, 1.0)
            raise InvalidOptionError(f"band {low:g} {high:g} selects no faces; widen it")
        seam, seam_method = _auto_seam(mesh, sel, theta_c, theta_v, area, h_c)
    seam %= TWO_PI
    # angles are measured from the landmark, else from the seam
    origin = landmark.angle if options.angles is not None and landmark is not None else seam

    # centroid angle from the origin, in [lo, lo + 2 pi): faces are unwrapped around it
    lo = math.radians(options.angles[0]) if options.angles is not None else 0.0
    rel_c = (theta_c - origin - lo) % TWO_PI + lo
    exact = options.proxy != "ortho"  # (a projection has no sides to cut)
    if options.angles is not None and not exact:
        keep &= rel_c <= math.radians(options.angles[1])
    face_index = np.flatnonzero(keep)
    if len(face_index) == 0:
        raise InvalidOptionError("the band and angle range select no faces; widen --band or --angles")
    gap = None
    if options.angles is None and seam_method in _PLACED_SEAMS:
        # a region that does not go round is not cut: unwrap from the middle of its gap
        corners = _corner_angles(theta_v, F, face_index, rel_c[face_index], origin)
        gap = _gap_middle(_covered(rel_c[face_index], corners))
        if gap is not None:
            rel_c = (theta_c - origin - gap) % TWO_PI + gap
            rel_c -= TWO_PI * np.round(np.average(rel_c[face_index], weights=area[face_index]) / TWO_PI)
    centre = rel_c[face_index]
    repeat = bool(options.overlap) and gap is None and seam_method != "gap"
    if exact and (gap is None or floors):  # the sides cut exactly along their meridians
        corners = _corner_angles(theta_v, F, face_index, centre, origin)
        start, end = lo, math.radians(options.angles[1]) if options.angles is not None else TWO_PI + (
            math.radians(options.overlap) if repeat else 0.0)
        if gap is not None:  # no side to cut (a region with a gap): only the level cuts
            start, end = float(corners.min()), float(corners.max())
        faces, corner_theta, origins = cut_region(
            mesh.vertices, F, face_index, centre, corners,
            start=start, end=end, repeat_from=TWO_PI if repeat else None,
            meridian=lambda angle: (axis.point, _meridian_normal(axis, origin + angle)),
            floors=[(faces_cut, levels, functools.partial(_angle_from, angle, origin))
                    for faces_cut, levels, angle in floors])
        if len(faces) == 0:
            raise InvalidOptionError("the band and angle range select no faces; widen --band or --angles")
        return faces, corner_theta, origins, seam, seam_method, origin
    repeated = np.zeros(len(face_index), bool)
    if repeat:
        again = face_index[rel_c[face_index] < math.radians(options.overlap)]
        face_index = np.concatenate([face_index, again])
        centre = np.concatenate([centre, rel_c[again] + TWO_PI])
        repeated = np.concatenate([repeated, np.ones(len(again), bool)])
    corner_theta = _corner_angles(theta_v, F, face_index, centre, origin)
    return (np.take(F, face_index, axis=0), corner_theta, CutOrigins.whole(face_index, repeated, len(mesh.vertices)),
            seam, seam_method, origin)


def _angle_from(angle, origin: float, points: np.ndarray) -> np.ndarray:
    """``angle(points)`` (radians, (k,) float64) less ``origin``."""
    return angle(points) - origin


def _heights(axis: AxisFit, vertex_height: np.ndarray, index: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Heights (k,) float64 along the axis of the vertices ``index`` ((k,) int64: scan vertices,
    whose heights ``vertex_height`` (n,) float64 gives, then vertices a cut added) at
    ``points`` (k, 3) float64."""
    height = np.empty(len(index))
    scan = index < len(vertex_height)
    height[scan] = vertex_height[index[scan]]
    height[~scan] = axis.cylindrical(points[~scan])[0]
    return height


def _base_levels(cut: BaseCut, axis: AxisFit, vertex_height: np.ndarray, index: np.ndarray,
                 points: np.ndarray) -> np.ndarray:
    """:meth:`BaseCut.levels` of the vertices ``index`` at ``points`` (as :func:`_heights`)."""
    return cut.levels(_heights(axis, vertex_height, index, points), index)


def _band_levels(axis: AxisFit, vertex_height: np.ndarray, height: float, sign: float, index: np.ndarray,
                 points: np.ndarray) -> np.ndarray:
    """``sign`` times the height above ``height`` of the vertices ``index`` at ``points`` (as
    :func:`_heights`)."""
    return sign * (_heights(axis, vertex_height, index, points) - height)


def _band_cuts(axis: AxisFit, band, vertex_height: np.ndarray, faces: np.ndarray, allowed: np.ndarray, angle_of
               ) -> tuple[np.ndarray, tuple]:
    """The faces of ``allowed`` ((m,) bool) reaching into the height band ``band`` (fractions of
    the axis' height), and the level cuts along its lower and upper planes (as
    :func:`potflat.rollout.seam.cut_region` takes them), so that the band's edges are exact
    lines at its heights, not a staircase of whole faces."""
    low, high = (b * axis.height for b in band)
    at = vertex_height[faces]
    lowest, highest = at.min(axis=1), at.max(axis=1)
    allowed = allowed & (highest > low) & (lowest < high)
    cuts = []
    for height, sign in ((low, 1.0), (high, -1.0)):
        across = allowed & (lowest < height) & (highest > height)
        if across.any():
            cuts.append((across, functools.partial(_band_levels, axis, vertex_height, height, sign), angle_of))
    return allowed, tuple(cuts)


def _meridian_normal(axis: AxisFit, angle: float) -> np.ndarray:
    """Unit normal of the meridian half-plane at ``angle`` (radians from the axis' reference),
    towards increasing angles: the signed distance of a point is ``r sin(theta - angle)``."""
    other = np.cross(axis.direction, axis.reference)
    return math.cos(angle) * other - math.sin(angle) * axis.reference


def _default_view(axis: AxisFit, theta_c: np.ndarray, area: np.ndarray, seam: float) -> np.ndarray:
    """From the axis towards the region's (area-weighted) centre angle; opposite the seam if all round."""
    s, c = area @ np.sin(theta_c), area @ np.cos(theta_c)
    angle = math.atan2(s, c) if np.hypot(s, c) >= 1e-6 * area.sum() else seam + math.pi
    other = np.cross(axis.direction, axis.reference)
    return math.cos(angle) * axis.reference + math.sin(angle) * other


def _find_importance(flat: FlatMesh, options: RolloutOptions, axis: AxisFit, theta_deg: np.ndarray
                     ) -> _importance.Importance:
    """The importance of the rollout's vertices as ``options.importance`` asks."""
    method = options.importance
    if method == "none":
        return _importance.Importance(None, "none", 1.0, "importance off: the whole surface counts alike")
    if method == "auto":
        return _importance.auto_importance(flat)
    if method == "mask":
        return _importance.image_mask_importance(flat, options.importance_mask, options.importance_image)
    if method == "texture-mask":
        return _importance.texture_mask_importance(flat, options.importance_mask)
    h = axis.cylindrical(flat.mesh.vertices)[0]
    return _importance.band_importance(flat, h / max(axis.height, np.finfo(float).tiny), theta_deg,
                                       options.importance_band, options.importance_arc)


