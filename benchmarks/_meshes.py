"""Benchmark and test meshes: bulgy vessels and developable patches, cut open and rolled out.

Irregular triangulations: a jittered (theta, height) lattice with randomly chosen quad
diagonals and uneven row spacing, so valences range from 3 to 9 and triangles vary in
shape and size like a decimated scan. The cut runs along theta = 0: its vertices are
duplicated (theta = 0 and theta = 2 pi), as the rollout stage does.
"""
from __future__ import annotations

import numpy as np

from potflat.types import FlatMesh, Mesh

#: Amphora/hydria-like profile: (height, radius) control points, foot to lip (units: dm).
PROFILE = np.array([[0.00, 0.42], [0.15, 0.45], [0.45, 0.80], [0.85, 1.00], [1.20, 0.92],
                    [1.50, 0.55], [1.70, 0.33], [1.85, 0.33], [2.00, 0.48]])


def profile_radius(h: np.ndarray) -> np.ndarray:
    """Smooth radius of the vessel profile at heights ``h`` (monotone cubic through :data:`PROFILE`)."""
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(PROFILE[:, 0], PROFILE[:, 1])(h)


def _lattice(nu: int, nv: int, rng: np.random.Generator, jitter: float):
    """Parameter points in [0, 1]^2 (columns 0 and nu shared by the cut) and CCW faces."""
    us = np.linspace(0.0, 1.0, nu + 1)
    vs = np.cumsum(np.concatenate([[0.0], rng.uniform(0.6, 1.4, nv)]))
    vs /= vs[-1]
    U, Vv = np.meshgrid(us, vs)
    du, dv = 1.0 / nu, np.diff(vs).min()
    ju = rng.uniform(-jitter, jitter, U.shape) * du
    jv = rng.uniform(-jitter, jitter, U.shape) * dv
    ju[:, 0] = ju[:, -1] = 0.0  # cut columns stay on the cut
    jv[0, :] = jv[-1, :] = 0.0  # rims stay on the rims
    ju[:, -1] = ju[:, 0]
    P = np.stack([(U + ju).ravel(), (Vv + jv).ravel()], axis=1)
    idx = np.arange((nv + 1) * (nu + 1)).reshape(nv + 1, nu + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    flip = rng.random(len(a)) < 0.5
    f1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    f2 = np.where(flip[:, None], np.stack([a, d, c], 1), np.stack([b, d, c], 1))
    return P, np.concatenate([f1, f2]).astype(np.int64)


def vessel_rollout(n_vertices: int, *, seed: int = 0, proxy: str = "cylinder", jitter: float = 0.3,
                   turn: float = 1.0) -> FlatMesh:
    """A bulgy amphora-like vessel (foot to lip) cut along one meridian and rolled out.

    Parameters
    ----------
    n_vertices : int
        Approximate vertex count.
    seed : int
        Seed of the triangulation's randomness.
    proxy : str
        ``cylinder`` (u = mean radius * theta, v = height) or ``sphere`` (equirectangular
        about the belly's centre): both distort the bulgy profile strongly, neither folds.
    jitter : float
        Vertex jitter in lattice cells (0 regular, < 0.5 keeps all triangles CCW).
    turn : float
        Fraction of the full turn covered (1: the whole vessel, cut open once).

    Returns
    -------
    FlatMesh
        Units mm (the vessel is 200 mm tall).
    """
    rng = np.random.default_rng(seed)
    H = PROFILE[-1, 0]
    # aspect: circumference ~ 2 pi * 0.7 vs height 2 -> about 2.2 : 1
    ratio = 2 * np.pi * 0.7 * turn / H
    nv = max(2, round(np.sqrt(n_vertices / ratio)))
    nu = max(2, round(n_vertices / nv))
    P, F = _lattice(nu, nv, rng, jitter)
    theta = P[:, 0] * 2 * np.pi * turn
    h = P[:, 1] * H
    r = profile_radius(h)
    X = np.stack([r * np.cos(theta), r * np.sin(theta), h], axis=1) * 100.0
    if proxy == "cylinder":
        R = float(np.mean(PROFILE[:, 1]))
        uv = np.stack([R * theta, h], axis=1) * 100.0
    elif proxy == "sphere":
        c = 0.9
        R = 1.0
        lat = np.arctan2(h - c, r)
        uv = np.stack([R * theta, R * lat], axis=1) * 100.0
    else:
        raise ValueError(f"unknown proxy {proxy!r}")
    return FlatMesh(Mesh(X, F, units="mm"), uv)


def cylinder_patch(nu: int = 24, nv: int = 16, *, radius: float = 1.0, angle: float = 2.0, height: float = 1.5,
                   seed: int = 0, start: str = "orthographic") -> tuple[FlatMesh, np.ndarray]:
    """A developable cylinder patch with a distorted start and its exact development.

    Parameters
    ----------
    nu, nv : int
        Lattice cells around and along.
    radius, angle, height : float
        Cylinder radius, patch angle (radians, < pi for the orthographic start), height.
    seed : int
    start : str
        ``orthographic`` (u = R sin theta) or ``sphere`` (u = R theta cos(latitude)).

    Returns
    -------
    flat : FlatMesh
        The patch with the distorted start as ``uv``.
    exact : (n, 2) float64
        The isometric development ``(R theta, h)``.
    """
    rng = np.random.default_rng(seed)
    P, F = _lattice(nu, nv, rng, 0.3)
    theta = (P[:, 0] - 0.5) * angle
    h = P[:, 1] * height
    X = np.stack([radius * np.cos(theta), radius * np.sin(theta), h], axis=1)
    exact = np.stack([radius * theta, h], axis=1)
    if start == "orthographic":
        uv = np.stack([radius * np.sin(theta), h], axis=1)
    elif start == "sphere":
        lat = (h - height / 2) / (2 * height)
        uv = np.stack([radius * theta * np.cos(lat), h + 0.1 * np.sin(3 * theta)], axis=1)
    else:
        raise ValueError(f"unknown start {start!r}")
    return FlatMesh(Mesh(X, F, units="mm"), uv), exact


def cone_patch(nu: int = 24, nv: int = 16, *, half_angle: float = 0.4, seed: int = 0) -> tuple[FlatMesh, np.ndarray]:
    """A developable cone frustum patch (a full turn, cut open) started from a cylinder rollout.

    Returns
    -------
    flat : FlatMesh
        Start: ``(r_mean * theta, height)`` (a cylinder proxy on a cone: distorted).
    exact : (n, 2) float64
        The cone's development (slant distance and sector angle ``theta sin(alpha)``).
    """
    rng = np.random.default_rng(seed)
    P, F = _lattice(nu, nv, rng, 0.3)
    theta = P[:, 0] * 2 * np.pi
    s = 1.0 + P[:, 1]  # slant distance from the apex
    r = s * np.sin(half_angle)
    h = s * np.cos(half_angle)
    X = np.stack([r * np.cos(theta), r * np.sin(theta), h], axis=1)
    phi = theta * np.sin(half_angle)
    # apex at the origin, sector opening upwards: u grows with theta, v with s (CCW kept)
    exact = np.stack([s * np.sin(phi), s * np.cos(phi)], axis=1)
    uv = np.stack([np.mean(r) * theta, h], axis=1)
    return FlatMesh(Mesh(X, F, units="mm"), uv), exact
