"""The synthetic vessels' painting: its layout on the generatrix and its colour at a 3D point."""
from __future__ import annotations

import math

import numpy as np
from potflat_synthetic.geometry import (
    _Generatrix,
    _outer_polyline,
    _project_to_generatrix,
    _wall_polyline,
    _wrap,
)
from potflat_synthetic.spec import (
    BAR_WIDTH,
    BLACK,
    CIRCLE_RADIUS,
    CREAM,
    LATTICE_LINES_MM,
    LATTICE_PITCH,
    PANEL_WIDTHS_DEG,
    SHADING_NOISE,
    SHADING_RANGE,
    TERRACOTTA,
    ZONE_MARGIN,
    PaintedCircle,
    Painting,
    _Spec,
)


def _layout_painting(g: _Generatrix, spec: _Spec, walls: int, rng, painting: str = "frieze") -> Painting:
    """The painting of kind ``painting`` (:data:`PAINTINGS`); draws the same random numbers
    for every kind, so the mesh does not depend on the painting."""
    z_lo = float(np.interp(g.s_outer[0], g.s, g.z))
    z_hi = float(np.interp(g.s_outer[1], g.s, g.z))
    H = z_hi - z_lo
    _, prof_r, prof_z = _outer_polyline(g)
    rc = CIRCLE_RADIUS
    zf = z_lo + spec.frieze * H
    rf = float(np.interp(zf, prof_z, prof_r))
    n_c = int(np.clip(math.floor(2 * math.pi * rf / (3.2 * rc)), 3, 12))
    phase = float(rng.uniform(0.0, 2 * math.pi))
    circles = []
    for k in range(n_c):
        th = (phase + 2 * math.pi * k / n_c) % (2 * math.pi)
        centre = np.array([rf * math.cos(th), rf * math.sin(th), zf])
        circles.append(PaintedCircle(centre, rc, BLACK if k % 2 == 0 else CREAM, "outer", zf, th))
    foot_top = z_lo + 0.04 * H
    bands = [
        (-math.inf, foot_top, BLACK),
        (zf - rc - 7.0, zf - rc - 3.0, BLACK),
        (zf + rc + 3.0, zf + rc + 7.0, BLACK),
        (z_hi - 3.0, math.inf, BLACK),
    ]
    G = float(np.clip(0.15 * H, 10.0, 30.0))
    grid = None
    g0, g1 = zf + rc + 10.0, min(zf + rc + 10.0 + G, z_hi - 8.0)
    if g1 - g0 >= 5.0:
        r_mid = float(np.interp(0.5 * (g0 + g1), prof_z, prof_r))
        grid = (g0, g1, 5.0, max(8, int(round(2 * math.pi * r_mid / 5.0))), 1.0, BLACK)
    bars = []
    b1, b0 = zf - rc - 10.0, max(zf - rc - 10.0 - G, foot_top + 3.0)
    if b1 - b0 >= 5.0:
        for k in (0, n_c // 2):
            th = (phase + 2 * math.pi * (k + 0.5) / n_c) % (2 * math.pi)
            bars.append((th, BAR_WIDTH, b0, b1, BLACK))
    tondo = None
    if walls == 2:
        floor_r = float(np.interp(g.s_floor, g.s, g.r))
        rt = min(30.0, 0.9 * floor_r)
        tondo = (spec.floor, rt, TERRACOTTA)
        circles.append(PaintedCircle(np.array([0.0, 0.0, spec.floor]), rc, BLACK, "inner", spec.floor, 0.0))
    if painting == "frieze":
        return Painting(tuple(circles), tuple(bands), tuple(bars), grid, tondo)
    inner = [c for c in circles if c.side == "inner"]
    frieze = [c for c in circles if c.side == "outer"]
    if painting == "allover":
        n_mer = max(8, int(round(2 * math.pi * float(prof_r.max()) / LATTICE_LINES_MM)))
        lines = (foot_top, z_hi - 3.0, LATTICE_LINES_MM, n_mer, 1.0, BLACK)
        lattice = _lattice_circles(g, spec, phase)
        return Painting(tuple(lattice + inner), (bands[0], bands[-1]), (), lines, tondo, kind=painting)
    # belt: the frieze between its frame bands; panel: from the bars below to the grid above
    zone = (zf - rc - 7.0, zf + rc + 7.0, None, math.pi)
    if painting == "panel":
        zone = _panel_zone(g, spec, frieze, min(zone[0], b0 if bars else math.inf),
                           max(zone[1], g1 if grid is not None else -math.inf))
        frieze = [c for c in frieze if _circle_in_zone(g, zone, c)]
        frieze.sort(key=lambda c: abs(float(_wrap(c.angle - zone[2]))))  # the central one first
    return Painting(tuple(frieze + inner), tuple(bands), tuple(bars), grid, tondo, kind=painting, zone=zone)


def _handle_roots(g: _Generatrix, spec: _Spec) -> list:
    """Where the profile's handles meet the wall: (canonical point, tube radius) per end."""
    out = []
    for hd in spec.handles:
        for z, dth, inner in ((hd.z0, hd.dtheta0, False), (hd.z1, hd.dtheta1, hd.inner1)):
            pr, pz, _ = _wall_polyline(g, inner)
            order = np.argsort(pz)
            r, th = float(np.interp(z, pz[order], pr[order])), hd.theta + dth
            out.append((np.array([r * math.cos(th), r * math.sin(th), z]), hd.radius))
    return out


def _circle_outline(g: _Generatrix, c: PaintedCircle, k: int = 48) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(z, theta, r)`` of ``k`` points about the outline of an outer-wall circle (first order
    in its radius: arc length along the profile and along the parallel)."""
    sc = float(_project_to_generatrix(g, np.array([math.hypot(*c.centre[:2])]), np.array([c.centre[2]]))[0])
    a = np.linspace(0.0, 2 * math.pi, k, endpoint=False)
    s = sc + c.radius * np.sin(a)
    r = np.interp(s, g.s, g.r)
    return np.interp(s, g.s, g.z), c.angle + c.radius * np.cos(a) / r, r


def _circle_in_zone(g: _Generatrix, zone: tuple, c: PaintedCircle) -> bool:
    """Whether circle ``c`` lies in ``zone`` with :data:`ZONE_MARGIN` to spare."""
    z, th, r = _circle_outline(g, c)
    z_lo, z_hi, centre, half = zone
    ok = (z >= z_lo + ZONE_MARGIN) & (z <= z_hi - ZONE_MARGIN)
    if centre is not None:
        ok &= np.abs(_wrap(th - centre)) * r <= half * r - ZONE_MARGIN
    return bool(np.all(ok))


def _panel_zone(g: _Generatrix, spec: _Spec, circles: list, z_lo: float, z_hi: float) -> tuple:
    """A panel of one of :data:`PANEL_WIDTHS_DEG` centred on a frieze circle or between two,
    holding the most whole circles (then: far from the handles, the first width listed)."""
    roots = [math.atan2(p[1], p[0]) for p, _ in _handle_roots(g, spec)]
    angles = [c.angle for c in circles]
    n = len(angles)
    centres = angles + [a + 0.5 * float(_wrap(angles[(i + 1) % n] - a)) for i, a in enumerate(angles)]
    best, best_key = None, None
    for w_deg in PANEL_WIDTHS_DEG:
        for th in centres:
            zone = (z_lo, z_hi, th % (2 * math.pi), math.radians(w_deg) / 2)
            count = sum(_circle_in_zone(g, zone, c) for c in circles)
            clear = min((abs(float(_wrap(th - a))) for a in roots), default=math.pi)
            key = (count, round(clear, 6))
            if best_key is None or key > best_key:
                best, best_key = zone, key
    return best


def _lattice_circles(g: _Generatrix, spec: _Spec, phase: float) -> list:
    """Circles of radius :data:`CIRCLE_RADIUS` in staggered rows over the whole outer wall:
    rows :data:`LATTICE_PITCH` radii apart along the profile where the wall's radius is at
    least 2.5 circle radii, clear of the wall's ends and of the handle roots."""
    rc = CIRCLE_RADIUS
    pitch = LATTICE_PITCH * rc
    s0, s1 = g.s_outer
    n_rows = int((s1 - s0 - 2 * (rc + 4.0)) // pitch) + 1
    first = 0.5 * (s0 + s1) - 0.5 * (n_rows - 1) * pitch
    roots = _handle_roots(g, spec)
    out = []
    for k in range(max(n_rows, 0)):
        s = first + k * pitch
        r, z = float(np.interp(s, g.s, g.r)), float(np.interp(s, g.s, g.z))
        n = int(2 * math.pi * r // pitch)
        if r < 2.5 * rc or n < 3:
            continue
        for j in range(n):
            th = (phase + 2 * math.pi * (j + 0.5 * (k % 2)) / n) % (2 * math.pi)
            centre = np.array([r * math.cos(th), r * math.sin(th), z])
            if any(np.linalg.norm(centre - p) < rc + a + 8.0 for p, a in roots):
                continue
            out.append(PaintedCircle(centre, rc, BLACK if len(out) % 2 == 0 else CREAM, "outer", z, th))
    return out


def _in_zone(p: Painting, g: _Generatrix, P) -> np.ndarray:
    """Canonical points ``P`` in the painting's zone of the outer wall, ``(n,)`` bool."""
    P = np.asarray(P, float).reshape(-1, 3)
    if not math.isfinite(g.s_inner):
        return _zone_mask(p.zone, P)
    s = _project_to_generatrix(g, np.hypot(P[:, 0], P[:, 1]), P[:, 2])
    return (s <= 0.5 * (g.s_outer[1] + g.s_inner)) & _zone_mask(p.zone, P)


def _zone_mask(zone: tuple | None, P: np.ndarray) -> np.ndarray:
    """Canonical points ``P`` within the heights and angles of ``zone`` (:attr:`Painting.zone`)."""
    ok = np.ones(len(P), bool)
    if zone is not None:
        z_lo, z_hi, centre, half = zone
        ok &= (P[:, 2] >= z_lo) & (P[:, 2] <= z_hi)
        if centre is not None:
            ok &= np.abs(_wrap(np.arctan2(P[:, 1], P[:, 0]) - centre)) <= half
    return ok


def _shading_rng(seed: int, stream: int) -> np.random.Generator:
    """The random numbers of the lighting and noise of ``shading=True`` (apart from the mesh's)."""
    return np.random.default_rng([seed, 0x5EAD, stream])


def _shade(colours: np.ndarray, P, g: _Generatrix, rng) -> np.ndarray:
    """Colours lit by a smooth gradient (factor :data:`SHADING_RANGE` across the vessel: a side
    light about the axis and a vertical fall-off) plus per-sample noise (:data:`SHADING_NOISE`
    grey levels), as a scan's texture shows them. ``P`` canonical points, ``(n, 3)``."""
    light = float(rng.uniform(0.0, 2 * math.pi))
    P = np.asarray(P, float).reshape(-1, 3)
    z0, z1 = float(g.z.min()), float(g.z.max())
    t = 0.7 * np.cos(np.arctan2(P[:, 1], P[:, 0]) - light) \
        + 0.3 * np.clip(2.0 * (P[:, 2] - z0) / max(z1 - z0, 1e-9) - 1.0, -1.0, 1.0)
    lo, hi = SHADING_RANGE
    factor = 0.5 * (lo + hi) + 0.5 * (hi - lo) * t
    out = colours * factor[:, None] + rng.normal(0.0, SHADING_NOISE, colours.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _paint(p: Painting, g: _Generatrix, P) -> np.ndarray:
    """Colours ``(n, 3)`` uint8 of canonical points ``P`` on the body surface."""
    P = np.asarray(P, float).reshape(-1, 3)
    r = np.hypot(P[:, 0], P[:, 1])
    z = P[:, 2]
    theta = np.arctan2(P[:, 1], P[:, 0])
    s = _project_to_generatrix(g, r, z)
    inner = s > 0.5 * (g.s_outer[1] + g.s_inner) if math.isfinite(g.s_inner) else np.zeros(len(P), bool)
    outer = ~inner
    col = np.empty((len(P), 3), np.uint8)
    col[:] = TERRACOTTA
    if p.grid is not None:
        z0, z1, spacing, n_mer, width, rgb = p.grid
        zone = outer & (z >= z0) & (z <= z1)
        hz = np.abs((z - z0 + 0.5 * spacing) % spacing - 0.5 * spacing) <= 0.5 * width
        step = 2 * math.pi / n_mer
        ang = np.abs(((theta % step) + 0.5 * step) % step - 0.5 * step) * r
        col[zone & (hz | (ang <= 0.5 * width))] = rgb
    for z0, z1, rgb in p.bands:
        col[outer & (z >= z0) & (z <= z1)] = rgb
    for th, width, z0, z1, rgb in p.bars:
        col[outer & (z >= z0) & (z <= z1) & (np.abs(_wrap(theta - th)) * r <= 0.5 * width)] = rgb
    if p.tondo is not None:
        col[inner] = BLACK
        zc, rt, rgb = p.tondo
        d = np.linalg.norm(P - np.array([0.0, 0.0, zc]), axis=1)
        col[inner & (d <= rt)] = rgb
        col[inner & (d <= rt - 2.0) & (d >= rt - 4.0)] = BLACK
    for c in p.circles:
        side = outer if c.side == "outer" else inner
        col[side & (np.linalg.norm(P - c.centre, axis=1) <= c.radius)] = c.colour
    if p.zone is not None:
        col[outer & ~_zone_mask(p.zone, P)] = BLACK
    return col

