"""Scan defects added to a synthetic vessel: creases, flaps, spikes, duplicated sheets,
non-manifold edges and noise, as photogrammetry and laser scans show them.

:func:`add_defects` takes a :class:`~potflat_synthetic.vessels.SyntheticVessel` and returns
a copy whose mesh carries the defects asked for, on the wall(s) named, with
:attr:`DefectScan.defect_faces` marking the faces made or moved by them. The painting is a
function of the 3D point, so :func:`~potflat_synthetic.vessels.write_ply_colored` writes the
defective scan with its colours. Every defect is placed at mid-height of a wall, each at
its own angle, in the vessel's canonical frame (axis = z):

* ``crease``: a Z-fold across the wall: the surface runs on, back over itself and on again
  (three sheets 0.4 mm apart), its faces in the middle sheet facing into the wall.
* ``flap``: a tongue of the wall cut free on three sides and folded back over its
  neighbour about the fourth (its faces face into the wall), leaving a hole.
* ``spikes``: single vertices thrown 3 edge lengths off the wall (outliers).
* ``sheet``: a tongue of the wall cut free on three sides and slid along the wall, off it,
  by half its length: its far half lies over the wall beyond (the same surface scanned
  twice, fused where two misregistered passes meet), every face still facing out.
* ``nonmanifold``: fins (a third face on an edge) and a small fan hanging on one vertex.
* ``noise``: every vertex of the wall moved along the wall's normal, Gaussian, 5% of the
  edge length (no face is marked: it is everywhere).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from potflat_synthetic.vessels import PART_INNER, PART_OUTER, SyntheticVessel

from potflat.errors import InvalidOptionError
from potflat.types import Mesh

#: Defect kinds accepted by :func:`add_defects`.
DEFECTS = ("crease", "flap", "spikes", "sheet", "nonmanifold", "noise")
#: Walls a defect may be put on.
WALLS = {"outer": PART_OUTER, "inner": PART_INNER}
#: Gap between the sheets of a crease, the flap and the wall, the duplicated sheet and the wall (mm).
SHEET_GAP_MM = 0.4
#: Standard deviation of ``noise``, as a fraction of the median edge length.
NOISE_FRACTION = 0.05


@dataclass(frozen=True, eq=False)
class DefectScan:
    """A synthetic vessel with scan defects.

    Attributes
    ----------
    vessel : SyntheticVessel
        The vessel with the defective mesh (``vessel.mesh``); its painting, axis and profile
        are the clean vessel's.
    defect_faces : (m,) bool
        Faces of ``vessel.mesh`` made or moved by a defect.
    defects : tuple of str
    walls : tuple of str
    """

    vessel: SyntheticVessel
    defect_faces: np.ndarray
    defects: tuple
    walls: tuple


class _Builder:
    """The mesh being damaged, in the canonical frame, with per-face and per-vertex labels."""

    def __init__(self, vessel: SyntheticVessel):
        self.vessel = vessel
        self.V = vessel.to_canonical(vessel.mesh.vertices)
        self.F = vessel.mesh.faces.copy()
        self.texcoords = vessel.mesh.texcoords
        self.face_part = vessel.face_part.copy()
        self.vertex_part = vessel.vertex_part.copy()
        self.face_chart = vessel.face_chart.copy()
        self.defect = np.zeros(len(self.F), bool)
        e = self.V[self.F]
        self.edge = float(np.median(np.linalg.norm(e[:, 1] - e[:, 0], axis=1)))

    # -- geometry of a wall ---------------------------------------------------------
    def cyl(self, idx=slice(None)):
        p = self.V[idx]
        return np.hypot(p[..., 0], p[..., 1]), np.arctan2(p[..., 1], p[..., 0]), p[..., 2]

    def wall_vertices(self, part: int) -> np.ndarray:
        return np.flatnonzero(self.vertex_part == part)

    def site(self, part: int, angle: float, half_height: float) -> tuple[float, float]:
        """Height at the middle of the wall ``part`` with ``half_height`` clear above and below."""
        _, _, z = self.cyl(self.wall_vertices(part))
        lo, hi = np.percentile(z, [5, 95])
        if hi - lo < 2 * half_height:
            raise InvalidOptionError("the wall is too low for this defect; use a larger vessel")
        return angle, 0.5 * (lo + hi)

    def normal_offset(self, idx: np.ndarray, part: int) -> np.ndarray:
        """Unit directions (k, 3) off the wall at vertices ``idx``, towards the side the wall is seen from."""
        p = self.V[idx]
        radial = np.zeros_like(p)
        r = np.maximum(np.hypot(p[:, 0], p[:, 1]), 1e-9)
        radial[:, 0], radial[:, 1] = p[:, 0] / r, p[:, 1] / r
        return radial if part == PART_OUTER else -radial

    def add(self, V_new: np.ndarray, F_new: np.ndarray, part: int, texcoords: np.ndarray | None, chart: np.ndarray):
        """Append vertices (canonical frame) and faces (indices into the grown vertex list)."""
        self.V = np.concatenate([self.V, V_new])
        self.vertex_part = np.concatenate([self.vertex_part, np.full(len(V_new), part, np.int8)])
        self.F = np.concatenate([self.F, F_new])
        self.face_part = np.concatenate([self.face_part, np.full(len(F_new), part, np.int8)])
        self.face_chart = np.concatenate([self.face_chart, chart])
        if self.texcoords is not None:
            self.texcoords = np.concatenate([self.texcoords, texcoords])
        self.defect = np.concatenate([self.defect, np.ones(len(F_new), bool)])

    def patch(self, part: int, angle: float, height: float, half_width: float, half_height: float) -> np.ndarray:
        """Faces of wall ``part`` whose centroid lies within the arc-length ``half_width`` (mm)
        of ``angle`` and within ``half_height`` of ``height``."""
        r, t, z = self.cyl(self.F)
        r, t, z = r.mean(axis=1), _mean_angle(t), z.mean(axis=1)
        s = r * _wrap(t - angle)
        return (self.face_part == part) & (np.abs(s) <= half_width) & (np.abs(z - height) <= half_height)

    # -- defects --------------------------------------------------------------------
    def crease(self, part: int, angle: float):
        width, half_h = 1.5 * self.edge, 4.0 * self.edge
        angle, height = self.site(part, angle, half_h)
        idx = self.wall_vertices(part)
        r, t, z = self.cyl(idx)
        s = r * _wrap(t - angle)
        taper = np.clip(1.0 - ((z - height) / half_h) ** 2, 0.0, None)  # the crease dies out at its ends
        bump = np.exp(-0.5 * (s / width) ** 2)
        # s -> s - k s bump: folds back where k taper > 1 (three sheets across the crease)
        shift = -1.8 * taper * s * bump
        lift = SHEET_GAP_MM * taper * (s / width) * bump
        moved = np.abs(shift) > 1e-9 * self.edge
        new_t = t + shift / np.maximum(r, 1e-9)
        self.V[idx, 0] = r * np.cos(new_t)
        self.V[idx, 1] = r * np.sin(new_t)
        self.V[idx] += lift[:, None] * self.normal_offset(idx, part)
        self._mark_vertices(idx[moved & (taper * bump > 0.05)])

    def _tongue(self, part: int, angle: float, half_w: float, half_h: float):
        """Cut a tongue of wall ``part`` free on three sides (hinge at ``angle``, running
        towards larger angles): its faces get copies of its vertices off the hinge.
        Returns the tongue's faces, its loose vertices' copies, their distance from the hinge
        (mm), angle, radius and height."""
        angle, height = self.site(part, angle, half_h)
        faces = np.flatnonzero(self.patch(part, angle + half_w / self._radius(part, height), height, half_w, half_h))
        verts = np.unique(self.F[faces])
        r, t, z = self.cyl(verts)
        hinge_s = r * _wrap(t - angle)
        loose = verts[hinge_s > np.min(hinge_s) + 0.5 * self.edge]
        copy = np.arange(len(self.V), len(self.V) + len(loose))
        remap = np.arange(len(self.V))
        remap[loose] = copy
        self.V = np.concatenate([self.V, self.V[loose]])
        self.vertex_part = np.concatenate([self.vertex_part, self.vertex_part[loose]])
        self.F[faces] = remap[self.F[faces]]
        self.defect[faces] = True
        rl, tl, zl = self.cyl(copy)
        return copy, rl * _wrap(tl - angle), angle, rl, zl

    def flap(self, part: int, angle: float):
        half_w = 2.5 * self.edge
        copy, d, angle, r, z = self._tongue(part, angle, half_w, 3.0 * self.edge)
        folded_t = angle - d / np.maximum(r, 1e-9)  # turned over the hinge onto the neighbour: a hole is left
        self.V[copy] = np.stack([r * np.cos(folded_t), r * np.sin(folded_t), z], axis=1)
        self.V[copy] += (SHEET_GAP_MM * (1.0 + d / (2 * half_w)))[:, None] * self.normal_offset(copy, part)

    def sheet(self, part: int, angle: float):
        half_w = 4.0 * self.edge
        copy, d, angle, r, z = self._tongue(part, angle, half_w, 3.0 * self.edge)
        # slid along the wall by up to half its length, off the wall: its far half lies over
        # the wall beyond its cut end (a second pass fused on misregistered), orientation kept
        slide = half_w * np.clip(d / half_w, 0.0, 1.0)
        t = angle + (d + slide) / np.maximum(r, 1e-9)
        self.V[copy] = np.stack([r * np.cos(t), r * np.sin(t), z], axis=1)
        self.V[copy] += (SHEET_GAP_MM * 1.25 * np.clip(d / half_w, 0.0, 1.0))[:, None] * self.normal_offset(copy, part)

    def spikes(self, part: int, angle: float, count: int = 4):
        idx = self.wall_vertices(part)
        r, t, z = self.cyl(idx)
        _, height = self.site(part, angle, 2.0 * self.edge)
        near = np.argsort(np.abs(r * _wrap(t - angle)) + np.abs(z - height))[: 20 * count]
        pick = idx[near[:: 20]][:count]
        sign = np.where(np.arange(len(pick)) % 2 == 0, 1.0, -1.0)
        self.V[pick] += (3.0 * self.edge * sign)[:, None] * self.normal_offset(pick, part)
        self._mark_vertices(pick)

    def nonmanifold(self, part: int, angle: float, fins: int = 3):
        idx = self.wall_vertices(part)
        _, height = self.site(part, angle, 2.0 * self.edge)
        faces = np.flatnonzero(self.patch(part, angle, height, 4.0 * self.edge, 2.0 * self.edge))
        pick = faces[:: max(1, len(faces) // fins)][:fins]
        V_new, F_new = [], []
        base = len(self.V)
        for k, f in enumerate(pick):  # a fin: a third face on the edge (a, b), standing off the wall
            a, b = self.F[f, 0], self.F[f, 1]
            out = self.normal_offset(np.array([a]), part)[0]
            V_new.append(0.5 * (self.V[a] + self.V[b]) + self.edge * out)
            F_new.append([a, b, base + k])
        # a fan of two faces hanging on one vertex of the wall
        v = idx[np.argmin(np.abs(self.cyl(idx)[2] - height) + np.abs(_wrap(self.cyl(idx)[1] - angle - 0.2)))]
        out = self.normal_offset(np.array([v]), part)[0]
        tangent = np.cross([0.0, 0.0, 1.0], out)
        k = len(V_new)
        V_new += [self.V[v] + self.edge * (out + tangent), self.V[v] + self.edge * out * 1.5,
                  self.V[v] + self.edge * (out - tangent)]
        F_new += [[v, base + k, base + k + 1], [v, base + k + 1, base + k + 2]]
        tc = None if self.texcoords is None else self.texcoords[np.r_[pick, pick[:1], pick[:1]]]
        self.add(np.asarray(V_new), np.asarray(F_new, np.int64), part, tc, self.face_chart[np.r_[pick, pick[:1], pick[:1]]])
        self._mark_vertices(np.unique(self.F[pick]))

    def noise(self, part: int, rng: np.random.Generator):
        idx = self.wall_vertices(part)
        self.V[idx] += (NOISE_FRACTION * self.edge * rng.standard_normal(len(idx)))[:, None] * self.normal_offset(idx, part)

    # -- helpers --------------------------------------------------------------------
    def _radius(self, part: int, height: float) -> float:
        idx = self.wall_vertices(part)
        r, _, z = self.cyl(idx)
        return float(np.median(r[np.abs(z - height) <= 2 * self.edge]))

    def _mark_vertices(self, verts: np.ndarray):
        hit = np.zeros(len(self.V), bool)
        hit[verts] = True
        self.defect |= hit[self.F].any(axis=1)

    def vessel_out(self) -> SyntheticVessel:
        R, t = self.vessel.pose[:3, :3], self.vessel.pose[:3, 3]
        mesh = Mesh(self.V @ R.T + t, self.F, texcoords=self.texcoords, units=self.vessel.mesh.units)
        return dataclasses.replace(self.vessel, mesh=mesh, face_part=self.face_part, vertex_part=self.vertex_part,
                                   face_chart=self.face_chart)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _mean_angle(t: np.ndarray) -> np.ndarray:
    """Mean of each row of angles (k, 3), radians."""
    return np.arctan2(np.sin(t).mean(axis=1), np.cos(t).mean(axis=1))


def add_defects(vessel: SyntheticVessel, defects, *, walls=("outer",), seed: int = 0) -> DefectScan:
    """A copy of ``vessel`` whose mesh has the scan ``defects`` on each of ``walls``.

    Parameters
    ----------
    vessel : SyntheticVessel
        From :func:`potflat_synthetic.vessels.make_vessel` (no ``sherd``).
    defects : str or sequence of str
        From :data:`DEFECTS`; each defect goes at its own angle (80 degrees apart), at
        mid-height of the wall.
    walls : sequence of str
        ``"outer"`` and/or ``"inner"`` (the vessel must have an inner wall: ``walls=2``).
    seed : int
        Seed of the noise.

    Returns
    -------
    DefectScan
    """
    defects = (defects,) if isinstance(defects, str) else tuple(defects)
    unknown = [d for d in defects if d not in DEFECTS] + [w for w in walls if w not in WALLS]
    if unknown:
        raise InvalidOptionError(f"unknown defect or wall {unknown}; use {', '.join(DEFECTS)} on {', '.join(WALLS)}")
    b = _Builder(vessel)
    rng = np.random.default_rng(seed)
    for w in walls:
        part = WALLS[w]
        if not (b.vertex_part == part).any():
            raise InvalidOptionError(f"the vessel has no {w} wall; make it with walls=2")
        for k, name in enumerate(defects):
            angle = math.radians(80.0 * k + (40.0 if w == "inner" else 0.0))
            if name == "noise":
                b.noise(part, rng)
            else:
                getattr(b, name)(part, angle)
    return DefectScan(vessel=b.vessel_out(), defect_faces=b.defect, defects=defects, walls=tuple(walls))
