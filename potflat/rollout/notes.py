"""What a user should know of a rollout before relaxing it: its warnings, in words."""
from __future__ import annotations

import math

import numpy as np

from potflat.importance import found_no_painting
from potflat.mesh._kernels.geometry import face_geometry
from potflat.mesh.distortion import face_areas

#: Warn when more than this share of the surface is trimmed away as folded border.
WARN_TRIMMED_FRACTION = 0.05


#: Warn when the side unrolled (``--side``) is less than this share of the scan's area: the scan
#: shows little of that wall (the sea vase's inside: 6 %, a piece of its neck).
WARN_SIDE_FRACTION = 0.2


#: Warn when the axis' misfit angle (degrees; :attr:`potflat.rollout.axis.AxisFit.misfit_angle_deg`,
#: the outer wall's lean that turns once around the axis) is above this: an axis tilted by
#: 2 degrees leaves more on the shared real scans, their fitted axes less
#: (``tests/test_axis.py``). The RMS angle itself is no test: relief, flutes and a hand-made
#: wall raise it whatever the axis.
WARN_AXIS_MISFIT_DEG = 1.5


#: Warn when more than this share of the unrolled side's area lies in pieces apart from the
#: vessel's wall (a lid, a stand or turntable, a fragment scanned with it), left out.
WARN_APART_FRACTION = 0.05


#: Warn when more than this share of the unrolled area faces along the axis (normal within
#: :data:`FLANGE_ANGLE_DEG` of it: a foot's top, a base, a flat shoulder): a cylinder, cone or
#: sphere develops such a ring into a wide, lobed flange.
WARN_FLANGE_FRACTION, FLANGE_ANGLE_DEG = 0.08, 30.0


#: An open form (a plate, dish, bowl or cup whose inside is its painted side as often as not):
#: a two-walled scan at most this high for its greatest diameter. Advised to unroll its inner
#: side when no painting was found on the outer one.
OPEN_FORM_HEIGHT_PER_DIAMETER = 0.5


def rollout_notes(result) -> list[str]:
    """Warnings for the rollout's JSON and summary (``result`` a
    :class:`~potflat.rollout.unroll.RolloutResult`): what the user should know before relaxing."""
    notes = list(result.landmark_notes)
    walls = result.walls
    total = walls.outer_area + walls.inner_area
    own = walls.outer_area if walls.side == "outer" else walls.inner_area  # (the side unrolled)
    share = own / total if total > 0 else 1.0
    if share < WARN_SIDE_FRACTION:
        other = "inner" if walls.side == "outer" else "outer"
        notes.append(f"the {walls.side} wall unrolled here is only {100 * share:.0f} % of the scan's surface (the "
                     f"{other} wall: {100 - 100 * share:.0f} %): the scan shows little of it, e.g. a neck or a mouth "
                     f"seen from within; if the painting is on the {other} side, unroll it with --side {other}")
    elif walls.side == "outer" and _plain_open_form(result):
        mm = result.profile.mm_per_unit
        low, high = result.profile.height_range
        notes.append(f"an open form ({(high - low) * mm:.0f} mm high, {2 * result.profile.max_radius * mm:.0f} mm "
                     "across: a plate, dish or bowl) with no painting found on its outer side; if its inside is "
                     "painted, unroll it with --side inner")
    if result.region.repeated_from is not None:
        notes.append(f"{len(result.flat.mesh.faces) - result.region.repeated_from} faces repeat the first "
                     f"{result.region.overlap_deg:g} degrees after the seam past 360 degrees (their distortion is "
                     "counted twice in the figures)")
    if result.distortion.flipped:
        why = (" (kept attachments: a handle cannot be unrolled without folds; leave them out)"
               if result.attachments_kept and result.attachments.n_faces else "")
        if result.distortion.flipped > 0.05 * len(result.flat.mesh.faces):
            why = (" (they face the other way: the two sides of the wall were not told apart"
                   + (", the scan's faces were read as pointing inwards" if result.walls.normals_inverted else "")
                   + "; check the axis (--axis) or try --side inner)")
        notes.append(f"{result.distortion.flipped} faces stay flipped{why}; the relax stage starts from a fold-free "
                     "layout (it refuses only a mesh that is not a disk)")
    if len(result.disk_cut_faces):
        notes.append(f"the selected faces were not a disk, which no layout in the plane shows without a fold: "
                     f"{result.disk_cut.reason}; {len(result.disk_cut_faces)} faces "
                     f"({result.disk_cut_area * result.flat.mesh.mm_per_unit ** 2:.4g} mm2) left out along the cuts")
    folded = result.folds.note() if result.folds is not None else None
    if folded:
        notes.append(folded)
    if result.boundary_overlap:
        notes.append(f"the border overlaps itself at {result.boundary_overlap} places; the relax stage unfolds it "
                     "(and refuses a result that still overlaps)")
    if own > 0 and walls.apart_area > WARN_APART_FRACTION * own:
        notes.append(f"{100 * walls.apart_area / own:.0f} % of the {walls.side} surface lies in pieces apart from the "
                     "vessel's wall (a lid, a stand or turntable, a fragment scanned with it) and is left out of the "
                     "image; if such a piece is painted, unroll it on its own (split the file)")
    if walls.ground_area:
        notes.append(f"{100 * walls.ground_area / walls.outer_area:.0f} % of the outer surface "
                     "is a flat piece around the foot facing up (a table or the ground the vessel stood on, scanned "
                     "with it) and is left out of the image")
    if result.other_objects_faces:
        notes.append(f"{result.other_objects_faces} faces of separate objects that do not share the vessel's axis "
                     "(another vessel or fragment in the same file) were left out; split the file or give --axis")
    if result.trimmed_area:
        kept = float(face_areas(result.flat.mesh.vertices, result.flat.mesh.faces).sum())
        share = result.trimmed_area / (result.trimmed_area + kept)
        if share > WARN_TRIMMED_FRACTION:
            notes.append(f"{100 * share:.0f} % of the surface was trimmed away as folded border (rim top, base "
                         "underside, breaks, a foot turned under); if painting is lost there, unroll the painted "
                         "height only (--band LO HI) or try another --proxy")
    share = _facing_axis_share(result)
    if share > WARN_FLANGE_FRACTION and result.proxy.kind != "ortho":
        notes.append(f"{100 * share:.0f} % of the unrolled surface faces along the axis (a foot, a base or a flat "
                     "shoulder): the proxy unrolls it as a wide, lobed flange; if the painting is elsewhere, unroll "
                     "the painted height only (--band LO HI)")
    if result.axis.mouth_guessed:
        notes.append("no open rim or inner wall tells the mouth from the foot (a sherd, or a closed scan without a "
                     "cavity): the wider end is taken as the mouth, so the image may be upside down; check it, and "
                     "roll out again with --flip if it is")
    if result.axis.misfit_angle_deg > WARN_AXIS_MISFIT_DEG:
        notes.append(f"the axis looks tilted or off-centre: the wall's normals lean {result.axis.misfit_angle_deg:.1f} "
                     "deg RMS to one side and the other as they go round it (a foot, handle or break misleads the "
                     "fit, or the axis given is off), so horizontal bands of the painting come out wavy; give the "
                     "axis (--axis px,py,pz,dx,dy,dz) or unroll the painted height only (--band LO HI)")
    return notes


def _plain_open_form(result) -> bool:
    """Whether the scan is a two-walled open form (:data:`OPEN_FORM_HEIGHT_PER_DIAMETER`) whose
    unrolled side's colours show no painting."""
    profile = result.profile
    if (profile is None or not profile.two_walled or not np.isfinite(profile.max_radius)
            or result.importance is None or not found_no_painting(result.importance)):
        return False
    low, high = profile.height_range
    return high - low <= OPEN_FORM_HEIGHT_PER_DIAMETER * 2.0 * profile.max_radius


def _facing_axis_share(result) -> float:
    """Share of the unrolled 3D area whose normal lies within :data:`FLANGE_ANGLE_DEG` of the axis."""
    mesh = result.flat.mesh
    normal, twice, _, _ = face_geometry(np.ascontiguousarray(mesh.vertices, dtype=np.float64),
                                        np.ascontiguousarray(mesh.faces, dtype=np.int64))  # |normal| = twice
    along = np.abs(normal @ result.axis.direction) > math.cos(math.radians(FLANGE_ANGLE_DEG)) * twice
    total = float(twice.sum())
    return float(twice[along].sum()) / total if total > 0 else 0.0
