"""Proxy surfaces around the axis and their exact developments (unrollings).

All heights ``h`` are measured along the axis from the foot (:attr:`AxisFit.point`), radii
``r`` from the axis, and angles ``theta`` (radians) counter-clockwise about the axis from the
seam, already unwrapped by the cut (so a cut region has no jump in ``theta``).

* **cylinder** (radius ``R``): ``u = R theta``, ``v = h``.
* **cone** (the line through the region's ``(h, r)`` points, total least squares; half-angle
  ``alpha`` between the generator and the axis): each vertex is projected on the generator
  (signed slant position ``s`` from the reference point ``(h_m, r_m)``, the proxy radius
  there is ``rho = r_m + s sin(alpha')`` with ``alpha'`` signed: positive when the cone
  widens towards the mouth), and placed on the isometric development: the sector angle is
  ``phi = (theta - theta_mid) sin(alpha')`` and the flat position is the point at distance
  ``rho / sin(alpha)`` from the apex, turned by ``phi``; the sector's bisector
  (``theta_mid``, the middle of the region's angle range) is vertical, so the image stands
  upright with ``v`` towards the mouth whether the apex is below (widening cone) or above
  (narrowing cone). Written stably (no apex far away): ``u = r_m theta_mid +
  rho t sinc(phi)``, ``v = h_m + s - rho t sinc(phi / 2) sin(phi / 2)`` with
  ``t = theta - theta_mid``; ``alpha' = 0`` is exactly the cylinder.
* **sphere** (centre on the axis at height ``h_c``, radius ``R``): equirectangular, as
  GigaMesh does: ``u = R theta``, ``v = h_c + R lat`` with ``lat = atan2(h - h_c, r)``. It is
  not a development: horizontal lengths are stretched by ``R / r`` (1 / cos(lat) on the
  sphere itself), which the distortion figures show.
* **ortho**: orthographic projection onto the plane perpendicular to ``view`` (the
  direction from the vessel towards the viewer), ``v`` along the axis projected on that
  plane, ``u = v x view`` to the right. For small cutouts seen face-on.

The flattened faces keep their counter-clockwise orientation (u right, v up, seen from
outside).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from potflat.mesh.distortion import DistortionSummary, SurfaceReference
from potflat.mesh.tolerances import DEGENERATE
from potflat.rollout.options import DEVELOPABLE

#: ``auto`` keeps the simplest candidate whose edge-length RMS is within this factor of the best.
AUTO_TOLERANCE = 1.01


@dataclass(frozen=True, eq=False)
class Proxy:
    """A fitted proxy surface.

    Attributes
    ----------
    kind : str
        ``"cylinder"``, ``"cone"``, ``"sphere"`` or ``"ortho"``.
    params : dict
        JSON-ready parameters (scan units, degrees; heights from the foot), see
        ``docs/formats.md``.
    candidates : dict
        For ``auto``: each candidate kind to its distortion figures.
    reason : str
        Why this proxy was used.
    """

    kind: str
    params: dict
    candidates: dict = field(default_factory=dict)
    reason: str = ""

    def as_dict(self) -> dict:
        """JSON-ready description."""
        return {"type": self.kind, "params": self.params, "candidates": self.candidates,
                "reason": self.reason}


def _weights(w, n):
    w = np.ones(n) if w is None else np.asarray(w, float)
    return w / w.sum() if w.sum() > 0 else np.full(n, 1.0 / n)


def fit_cylinder(h: np.ndarray, r: np.ndarray, weights: np.ndarray | None = None) -> Proxy:
    """Cylinder about the axis: the weighted mean radius.

    Parameters
    ----------
    h, r : (k,) float64
        Heights and radii of the region's vertices.
    weights : (k,) float64, optional
        Vertex areas.
    """
    w = _weights(weights, len(r))
    return Proxy("cylinder", {"radius": float(w @ r)})


def fit_cone(h: np.ndarray, r: np.ndarray, theta: np.ndarray, weights: np.ndarray | None = None) -> Proxy:
    """Cone (frustum) about the axis: total-least-squares line through the ``(h, r)`` points.

    Parameters
    ----------
    h, r, theta : (k,) float64
        Heights, radii and unwrapped angles of the region's vertices.
    weights : (k,) float64, optional
        Vertex areas.
    """
    w = _weights(weights, len(r))
    h_m, r_m = float(w @ h), float(w @ r)
    dh, dr = h - h_m, r - r_m
    cov = np.array([[w @ (dh * dh), w @ (dh * dr)], [w @ (dh * dr), w @ (dr * dr)]])
    evals, evecs = np.linalg.eigh(cov)
    g = evecs[:, 1] if evals[1] > 0 else np.array([1.0, 0.0])
    if g[0] < 0 or (g[0] == 0 and g[1] < 0):
        g = -g
    sin_signed = float(g[1])
    apex = h_m - r_m * g[0] / g[1] if g[1] != 0 else None
    return Proxy("cone", {
        "half_angle_deg": float(np.degrees(np.arcsin(min(abs(sin_signed), 1.0)))),
        "widens_towards_mouth": bool(sin_signed > 0),
        "apex_height": None if apex is None or not np.isfinite(apex) else float(apex),
        "reference_height": h_m, "reference_radius": r_m,
        "generator": [float(g[0]), float(g[1])],
        "bisector_deg": float(np.degrees(0.5 * (theta.min() + theta.max()))),
    })


def fit_sphere(h: np.ndarray, r: np.ndarray, weights: np.ndarray | None = None) -> Proxy:
    """Sphere with its centre on the axis: algebraic circle fit in the ``(h, r)`` half-plane.

    Parameters
    ----------
    h, r : (k,) float64
        Heights and radii of the region's vertices.
    weights : (k,) float64, optional
        Vertex areas.
    """
    w = np.sqrt(_weights(weights, len(r)))
    # h^2 + r^2 = 2 h_c h + K, K = R^2 - h_c^2
    A = np.stack([2.0 * h, np.ones_like(h)], axis=1) * w[:, None]
    b = (h * h + r * r) * w
    (h_c, K), *_ = np.linalg.lstsq(A, b, rcond=None)
    radius = float(np.sqrt(max(K + h_c * h_c, 0.0)))
    return Proxy("sphere", {"centre_height": float(h_c), "radius": radius})


def ortho_proxy(direction: np.ndarray, reference: np.ndarray, view: np.ndarray) -> Proxy:
    """Orthographic projection seen from ``view`` (unit vector from the vessel to the viewer).

    Parameters
    ----------
    direction, reference : (3,) float64
        The axis direction and its reference direction (used as "up" when the view is
        along the axis).
    view : (3,) float64
        Direction towards the viewer (normalised here).
    """
    view = np.asarray(view, float) / np.linalg.norm(view)
    up = direction - (direction @ view) * view
    if np.linalg.norm(up) < 1e-6:
        up = reference - (reference @ view) * view
    up = up / np.linalg.norm(up)
    right = np.cross(up, view)
    return Proxy("ortho", {"view": view.tolist(), "up": up.tolist(), "right": right.tolist()})


def fit(kind: str, h, r, theta, weights=None) -> Proxy:
    """Fit a developable proxy of ``kind`` (``cylinder``, ``cone`` or ``sphere``); see the ``fit_*`` functions."""
    if kind == "cylinder":
        return fit_cylinder(h, r, weights)
    if kind == "cone":
        return fit_cone(h, r, theta, weights)
    if kind == "sphere":
        return fit_sphere(h, r, weights)
    raise ValueError(f"no fit for proxy kind {kind!r}")


def develop(proxy: Proxy, h: np.ndarray, r: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Flatten vertices on a developable proxy (see module docs).

    Parameters
    ----------
    proxy : Proxy
        A cylinder, cone or sphere.
    h, r, theta : (k,) float64
        Height above the foot, radius and unwrapped angle of each vertex (on the scan).

    Returns
    -------
    (k, 2) float64
        ``(u, v)``.
    """
    p = proxy.params
    if proxy.kind == "cylinder":
        return np.stack([p["radius"] * theta, h], axis=1)
    if proxy.kind == "sphere":
        lat = np.arctan2(h - p["centre_height"], r)
        return np.stack([p["radius"] * theta, p["centre_height"] + p["radius"] * lat], axis=1)
    if proxy.kind == "cone":
        g_h, g_r = p["generator"]
        h_m, r_m = p["reference_height"], p["reference_radius"]
        mid = np.radians(p["bisector_deg"])
        s = (h - h_m) * g_h + (r - r_m) * g_r
        rho = r_m + s * g_r
        t = theta - mid
        phi = t * g_r
        u = r_m * mid + rho * t * np.sinc(phi / np.pi)
        v = h_m + s - rho * t * np.sinc(phi / (2.0 * np.pi)) * np.sin(0.5 * phi)
        return np.stack([u, v], axis=1)
    raise ValueError(f"proxy {proxy.kind!r} is not a development around the axis")


def project_ortho(proxy: Proxy, points: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Orthographic ``(u, v)`` of ``points`` (k, 3) relative to ``origin`` (3,). Shape (k, 2)."""
    d = points - origin
    return np.stack([d @ np.asarray(proxy.params["right"]), d @ np.asarray(proxy.params["up"])], axis=1)


def _figures(s: DistortionSummary) -> dict:
    return {"edge_rms": s.edge_rms, "area_mean_abs_log": s.area_mean_abs_log,
            "anisotropy_mean": s.anisotropy_mean, "flipped": s.flipped}


def choose(vertices: np.ndarray, faces: np.ndarray, h: np.ndarray, r: np.ndarray, theta: np.ndarray,
           weights: np.ndarray | None = None, kinds: tuple[str, ...] = DEVELOPABLE, *, edges: np.ndarray | None = None
           ) -> tuple[Proxy, np.ndarray, DistortionSummary]:
    """Fit every candidate proxy, unroll with each, and keep the least distorted.

    The candidates are ranked by edge-length RMS (:meth:`potflat.mesh.distortion.SurfaceReference.summarize`):
    among those within :data:`AUTO_TOLERANCE` of the best, the simplest (cylinder, cone,
    sphere, in that order) wins. Flipped triangles are reported with each candidate; they
    come from the scan (an inner wall, overhangs), not from the choice of a development.

    Parameters
    ----------
    vertices : (k, 3) float64
        The cut region's vertices (3D).
    faces : (m, 3) int64
        Its faces.
    h, r, theta : (k,) float64
        Cylindrical coordinates of ``vertices`` (``theta`` unwrapped by the cut).
    weights : (k,) float64, optional
        Vertex areas for the fits.
    kinds : tuple of str
        Candidate kinds, simplest first.
    edges : (e, 2) int64, optional
        The undirected edges of ``faces`` (:func:`potflat.mesh.distortion.unique_edges`) when
        the caller has them.

    Returns
    -------
    proxy : Proxy
        With ``candidates`` and ``reason`` filled in.
    uv : (k, 2) float64
    summary : DistortionSummary
    """
    results = {}
    reference = SurfaceReference(vertices, faces, edges=edges)  # the 3D side once for every candidate
    for kind in kinds:
        prox = fit(kind, h, r, theta, weights)
        uv = develop(prox, h, r, theta)
        if not np.isfinite(uv).all():
            continue
        results[kind] = (prox, uv, reference.summarize(uv))
    best = min(s.edge_rms for _, _, s in results.values())
    pick = next(k for k in results if results[k][2].edge_rms <= AUTO_TOLERANCE * best + DEGENERATE)
    prox, uv, summ = results[pick]
    others = ", ".join(f"{k} {results[k][2].edge_rms:.3g}" + (f" ({results[k][2].flipped} flipped)"
                                                           if results[k][2].flipped else "")
                       for k in results if k != pick)
    reason = (f"auto: least unrolling distortion, edge-length RMS {summ.edge_rms:.3g}"
              + (f" with {summ.flipped} flipped" if summ.flipped else "")
              + (f" (vs {others})" if others else ""))
    cands = {k: _figures(s) for k, (_, _, s) in results.items()}
    return Proxy(prox.kind, prox.params, cands, reason), uv, summ
