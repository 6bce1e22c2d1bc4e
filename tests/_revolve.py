"""Small posed surfaces of revolution with irregular triangles, for the axis/proxy/rollout tests."""
from __future__ import annotations

import numpy as np

from potflat.types import Mesh


def random_rotation(rng) -> np.ndarray:
    """A random proper rotation matrix (3, 3)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def revolve(radius, height, *, n_theta=64, n_t=24, theta_range=None, seed=0, pose=True,
            jitter=0.2, colors=False, holes=(), cap=False):
    """A surface of revolution ``r = radius(t), z = height(t)``, t in [0, 1], foot at t=0.

    Irregular triangles (jittered grid, random diagonals); faces CCW seen from outside;
    a random rigid pose unless ``pose=False``. ``theta_range`` (radians) makes a sherd.
    ``holes`` lists (theta0, theta1, t0, t1) boxes whose faces are removed; ``cap`` closes
    the foot with a fan around a centre vertex on the axis.

    Returns
    -------
    mesh : Mesh
    R : (3, 3), shift : (3,)
        The pose: world = R @ local + shift; the local axis is +z through the origin.
    local : (n, 3)
        Vertex positions before posing.
    """
    rng = np.random.default_rng(seed)
    full = theta_range is None
    cols = n_theta if full else n_theta + 1
    t0, t1 = (0.0, 2 * np.pi) if full else theta_range
    dth = (t1 - t0) / n_theta
    ti = np.arange(n_t + 1) / n_t
    th = t0 + np.arange(cols) * dth
    TH, T = np.meshgrid(th, ti)
    jt = rng.uniform(-jitter, jitter, T.shape) / n_t
    jt[0], jt[-1] = 0, 0
    jth = rng.uniform(-jitter, jitter, TH.shape) * dth
    if not full:
        jth[:, [0, -1]] = 0
    T = np.clip(T + jt, 0, 1)
    TH = TH + jth
    r = radius(T)
    z = height(T)
    local = np.stack([r * np.cos(TH), r * np.sin(TH), z], axis=-1).reshape(-1, 3)
    idx = np.arange((n_t + 1) * cols).reshape(n_t + 1, cols)
    faces = []
    quads = n_theta
    for j in range(n_t):
        for i in range(quads):
            a, b = idx[j, i], idx[j, (i + 1) % cols]
            c, d = idx[j + 1, (i + 1) % cols], idx[j + 1, i]
            cth = t0 + (i + 0.5) * dth
            ct = (j + 0.5) / n_t
            if any(h0 <= cth <= h1 and s0 <= ct <= s1 for h0, h1, s0, s1 in holes):
                continue
            if rng.random() < 0.5:
                faces += [[a, b, c], [a, c, d]]
            else:
                faces += [[a, b, d], [b, c, d]]
    if cap:
        centre = len(local)
        local = np.vstack([local, [0.0, 0.0, float(height(np.zeros(1))[0])]])
        faces += [[centre, idx[0, (i + 1) % cols], idx[0, i]] for i in range(quads)]
    faces = np.array(faces)
    R, shift = np.eye(3), np.zeros(3)
    if pose:
        R = random_rotation(rng)
        shift = rng.uniform(-100, 100, 3)
    world = local @ R.T + shift
    vc = None
    if colors:
        vc = rng.integers(0, 255, (len(world), 3))
    return Mesh(world, faces, vertex_colors=vc), R, shift, local


def cylinder(R=30.0, H=80.0, **kw):
    return revolve(lambda t: np.full_like(t, R), lambda t: H * t, **kw)


def cone(r0=40.0, r1=20.0, H=60.0, **kw):
    return revolve(lambda t: r0 + (r1 - r0) * t, lambda t: H * t, **kw)


def vase(**kw):
    return revolve(lambda t: 25 + 12 * np.sin(np.pi * t * 1.3) - 6 * t, lambda t: 90 * t, **kw)
