"""The flow channel measured in horizontal slices of a velocity field, in the terms of
EN 1991-4's eccentric discharge model: per height the channel's outline, its area, its
equivalent radius and centre, and its contact with the silo's wall (the contact half-angle
``theta_c``) with the circle of radius ``r_c`` that EN 1991-4 would draw for it.  Pure functions
of arrays; :func:`model_channel` reads a 3D model's grid and state and changes neither.

**A slice** is the downward speed ``down`` (m/s, positive downwards) on the nodes of a regular
(or monotone) grid ``x`` (nx,), ``y`` (ny,), ``down`` (ny, nx), and the section of the silo at
that height, a circle of radius ``radius`` about ``centre`` (the silo's axis for the bin).
``NaN`` marks a node without material: it does not flow, and the wall reading leaves it out.

**The channel** is where the downward speed is at least ``fraction`` (default
:data:`DEFAULT_FRACTION` = 1/10) of the largest downward speed in the section at that height.
Its **outline** is the zero contour of ``min(down - threshold, s (R - rho) / h)`` (``rho`` the
distance from the section's centre, ``h`` the grid spacing, ``s`` the largest speed): the
boundary of the flowing region inside the section, which follows the wall where the channel
touches it; contours by :mod:`contourpy` (matplotlib's), the bilinear interpolation of the nodal
values.  Its **area** and **centroid** are the contour polygons' (holes subtracted); with
several disconnected flowing regions the channel is the largest (``n_regions`` counts them).
The **equivalent radius** is ``sqrt(area / pi)``.

**The contact** is read on the wall itself: the speed interpolated bilinearly on the circle of
radius ``radius - wall_inset`` (default: the wall) at ``8`` points a cell along it, the arcs
where it reaches the threshold (their ends interpolated linearly between the points), and the
longest of them; ``theta_c`` is half its angle (deg), ``contact_angle`` its middle (deg, about
the section's centre, 0 towards ``+x``, ``+y`` positive: the package's wall angle, 0 towards
the outlet's offset).  No arc: ``theta_c = 0``; the whole wall: ``theta_c = 180`` (the channel
is the whole section there, mass flow).  The nodes round the wall must carry the speed there:
a 3D model's contact nodes (within half a cell behind the wall) do; a field known only inside
the section (``NaN`` outside) is read from the inside nodes, a one-sided reading whose ends
move by up to about a cell.

**EN 1991-4's circle** (``r_c``, ``e_c``): the circle through the two ends of the contact arc
(on the wall at ``contact_angle +- theta_c``) whose overlap with the section has the measured
area.  The two ends fix the circle's centre on the line through the section's centre and the
arc's middle; the overlap area falls monotonically as the centre moves out along it, so the
area fixes it (solved by bisection, :func:`fipy_hopper.theory.eccentric_channel_geometry`).
``e_c`` is the centre's distance from the section's centre along ``contact_angle`` (negative
beyond the axis).  Why area and contact, not a fitted circle: they are the two measures
EN 1991-4's loads rest on (``A_c`` and ``U_wc = 2 theta_c r`` make the channel's Janssen depth
``z_oc``), both integral or read on the wall, so they converge with the grid and do not depend
on the outline's shape; a measured channel is not a circle, and a fit to its outline depends
on which part of it is fitted.  The fitted circle is given beside it (``fit_r``,
``fit_centre`` and the RMS distance of the fitted points from it, ``fit_rms``: a measure of how
circular the channel is): a least-squares (Kasa) circle through the outline's points that lie
more than a cell inside the wall (the corners where the outline leaves the wall are not the
channel's edge).  Without contact ``r_c`` is the equivalent
radius and ``e_c`` the centroid's distance from the section's centre; with the whole wall in
contact, or an area that no circle through the arc's ends gives, NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: the fraction of the section's largest downward speed that bounds the channel
DEFAULT_FRACTION = 0.1

#: wall reading: points per grid spacing along the wall circle
WALL_POINTS_PER_CELL = 8


@dataclass(frozen=True)
class SliceChannel:
    """The channel in one horizontal slice (module docstring).  Lengths in m, areas in m^2,
    angles in degrees, speeds in m/s."""

    threshold: float
    max_speed: float
    area: float
    r_eq: float
    centroid: tuple
    theta_c: float
    contact_angle: float
    r_c: float
    e_c: float
    fit_r: float
    fit_centre: tuple
    fit_rms: float
    n_regions: int
    outline: np.ndarray = field(repr=False)

    @property
    def extent(self) -> tuple:
        """The outline's extent ``(x_min, x_max, y_min, y_max)`` (m): how far the channel
        reaches across the section each way; NaN without a channel."""
        if not len(self.outline):
            return (math.nan,) * 4
        return (float(self.outline[:, 0].min()), float(self.outline[:, 0].max()),
                float(self.outline[:, 1].min()), float(self.outline[:, 1].max()))

    @property
    def touches_wall(self) -> bool:
        return self.theta_c > 0.0


def _empty(max_speed: float, threshold: float) -> SliceChannel:
    nan = math.nan
    return SliceChannel(threshold, max_speed, 0.0, 0.0, (nan, nan), 0.0, nan, nan, nan, nan,
                        (nan, nan), nan, 0, np.zeros((0, 2)))


def unfold(x, y, field_, mirror_x: bool = False, mirror_y: bool = False) -> tuple:
    """The whole plane ``(x, y, field)`` of a part computed beside mirror planes ``x = 0``
    and/or ``y = 0`` (each the part's first node plane): the field's images across them (the
    downward speed is even in both).  ``field_`` is ``(..., ny, nx)``."""
    x, y, f = np.asarray(x, float), np.asarray(y, float), np.asarray(field_, float)
    if mirror_x:
        if x[0] != 0.0:
            raise ValueError("a mirror plane x = 0 must be the first node plane")
        x = np.concatenate([-x[:0:-1], x])
        f = np.concatenate([f[..., :0:-1], f], axis=-1)
    if mirror_y:
        if y[0] != 0.0:
            raise ValueError("a mirror plane y = 0 must be the first node plane")
        y = np.concatenate([-y[:0:-1], y])
        f = np.concatenate([f[..., :0:-1, :], f], axis=-2)
    return x, y, f


def _bilinear(x, y, f, px, py):
    """Bilinear interpolation of ``f (ny, nx)`` at the points ``(px, py)``; NaN nodes left
    out (the weights of the others renormalised), NaN where all four are."""
    i = np.clip(np.searchsorted(x, px) - 1, 0, len(x) - 2)
    j = np.clip(np.searchsorted(y, py) - 1, 0, len(y) - 2)
    tx = np.clip((px - x[i]) / (x[i + 1] - x[i]), 0.0, 1.0)
    ty = np.clip((py - y[j]) / (y[j + 1] - y[j]), 0.0, 1.0)
    num = np.zeros(np.shape(px))
    den = np.zeros(np.shape(px))
    for dj, wy in ((0, 1.0 - ty), (1, ty)):
        for di, wx in ((0, 1.0 - tx), (1, tx)):
            v = f[j + dj, i + di]
            w = np.where(np.isnan(v), 0.0, wx * wy)
            num += w * np.nan_to_num(v)
            den += w
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.0, num / den, np.nan)


def _ring_area_moments(ring):
    """Signed area and first moments ``(A, A x_c, A y_c)`` of a closed ring (n, 2)."""
    xa, ya = ring[:-1, 0], ring[:-1, 1]
    xb, yb = ring[1:, 0], ring[1:, 1]
    cross = xa * yb - xb * ya
    return 0.5 * cross.sum(), (xa + xb).dot(cross) / 6.0, (ya + yb).dot(cross) / 6.0


def _regions(x, y, g):
    """The regions ``g >= 0`` as contour polygons: ``[(area, mx, my, outer ring, rings)]``."""
    import contourpy

    cg = contourpy.contour_generator(x, y, g, fill_type=contourpy.FillType.OuterOffset)
    points, offsets = cg.filled(0.0, np.inf)
    out = []
    for pts, offs in zip(points, offsets):
        rings = [pts[a:b] for a, b in zip(offs[:-1], offs[1:])]
        area = mx = my = 0.0
        for ring in rings:                # outer anticlockwise, holes clockwise
            a, ax, ay = _ring_area_moments(ring)
            area, mx, my = area + a, mx + ax, my + ay
        out.append((area, mx, my, rings[0], rings))
    return out


def _contact(x, y, down, threshold, radius, centre, inset, h):
    """``(theta_c, contact_angle)`` (deg) of the longest wall arc at or above ``threshold``
    (module docstring)."""
    rw = radius - inset
    n = max(720, int(math.ceil(2.0 * math.pi * rw * WALL_POINTS_PER_CELL / h)))
    phi = 2.0 * math.pi * np.arange(n) / n
    s = _bilinear(x, y, down, centre[0] + rw * np.cos(phi), centre[1] + rw * np.sin(phi))
    s = s - threshold
    on = s >= 0.0                         # NaN: no reading, not in contact
    if not on.any():
        return 0.0, math.nan
    if on.all():
        return 180.0, math.nan
    start = int(np.flatnonzero(~on)[0])   # roll so the sequence starts off the arc
    on_r, s_r = np.roll(on, -start), np.roll(s, -start)
    edges = np.diff(on_r.astype(np.int8))
    begins = np.flatnonzero(edges == 1) + 1
    ends = np.flatnonzero(edges == -1)    # last index on the arc
    if len(ends) < len(begins):
        ends = np.append(ends, n - 1)
    step = 2.0 * math.pi / n
    best = (-1.0, 0.0, 0.0)
    for b, e in zip(begins, ends):
        # ends interpolated linearly between the last point off and the first point on
        s0, s1 = s_r[b - 1], s_r[b]
        lo = (b - 1) + (-s0 / (s1 - s0) if np.isfinite(s0) and s1 != s0 else 1.0)
        s0, s1 = s_r[e], s_r[(e + 1) % n]
        hi = e + (s0 / (s0 - s1) if np.isfinite(s1) and s0 != s1 else 0.0)
        if hi - lo > best[0]:
            best = (hi - lo, lo, hi)
    length, lo, hi = best
    mid = (0.5 * (lo + hi) + start) * step
    angle = (math.degrees(mid) + 180.0) % 360.0 - 180.0
    return 0.5 * math.degrees(length * step), angle


def _circle_through_arc(radius, theta_c, area):
    """``(r_c, e_c)`` of the circle through the wall points at ``+-theta_c`` (deg) whose
    overlap with the section (radius ``radius``) is ``area``; NaN when none is.

    With ``c = R sin theta_c`` half the chord, ``d = R cos theta_c`` its distance from the
    section's centre and ``beta`` in (0, pi) the half-angle the chord subtends at the circle's
    centre: ``r_c = c / sin beta``, ``e_c = d - c cot beta``.  The overlap is the section's part
    on one side of the chord and the circle's segment on the other [D]: for ``beta >= theta_c``
    (the circle's far arc inside the section) ``R^2 (t - sin t cos t) + r_c^2 (pi - beta +
    sin beta cos beta)``, for ``beta < theta_c`` ``pi R^2 - R^2 (t - sin t cos t) + r_c^2 (beta
    - sin beta cos beta)`` (``t = theta_c``), equal at ``beta = theta_c`` (the section itself),
    falling from ``pi R^2 - R^2 (t - sin t cos t)`` to ``R^2 (t - sin t cos t)`` as ``beta``
    goes from 0 to pi, without the cancellations of the general formula for huge circles."""
    from scipy.optimize import brentq

    t = math.radians(theta_c)
    c = radius * math.sin(t)
    d = radius * math.cos(t)
    small = radius * radius * (t - math.sin(t) * math.cos(t))

    def overlap(beta):
        sb, cb = math.sin(beta), math.cos(beta)
        r2 = (c / sb) ** 2
        if beta >= t:
            return small + r2 * (math.pi - beta + sb * cb)
        return math.pi * radius * radius - small + r2 * (beta - sb * cb)

    if not small < area < math.pi * radius * radius - small:
        return math.nan, math.nan
    lo, hi = 1e-12, math.pi - 1e-12
    beta = brentq(lambda b: overlap(b) - area, lo, hi, xtol=1e-15, rtol=1e-14, maxiter=400)
    return c / math.sin(beta), d - c / math.tan(beta)


def _fit_circle(points):
    """Least-squares (Kasa) circle ``(r, cx, cy, rms)`` through points (n, 2)."""
    if len(points) < 3:
        return math.nan, math.nan, math.nan, math.nan
    px, py = points[:, 0], points[:, 1]
    A = np.column_stack([px, py, np.ones_like(px)])
    b = px * px + py * py
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    cx, cy = 0.5 * sol[0], 0.5 * sol[1]
    r2 = sol[2] + cx * cx + cy * cy
    if not r2 > 0.0:
        return math.nan, math.nan, math.nan, math.nan
    r = math.sqrt(r2)
    rms = float(np.sqrt(np.mean((np.hypot(px - cx, py - cy) - r) ** 2)))
    return r, float(cx), float(cy), rms


def slice_channel(x, y, down, radius: float, centre=(0.0, 0.0),
                  fraction: float = DEFAULT_FRACTION, wall_inset: float = 0.0) -> SliceChannel:
    """The channel in one horizontal slice (module docstring).

    Parameters
    ----------
    x, y : node coordinates (m), increasing, (nx,) and (ny,).
    down : the downward speed (m/s) on the nodes, (ny, nx); NaN where there is no material.
    radius : the section's radius (m); centre: its centre ``(x, y)`` (m).
    fraction : the channel's edge as a fraction of the section's largest downward speed, in
        (0, 1).
    wall_inset : read the contact this far inside the wall (m), >= 0.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    down = np.asarray(down, float)
    if down.shape != (len(y), len(x)):
        raise ValueError(f"down must be (ny, nx) = ({len(y)}, {len(x)}); got {down.shape}")
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction must lie in (0, 1); got {fraction:g}")
    if not radius > 0.0 or not 0.0 <= wall_inset < radius:
        raise ValueError(f"radius must be > 0 and wall_inset in [0, radius); got {radius:g}, "
                         f"{wall_inset:g}")
    cx, cy = float(centre[0]), float(centre[1])
    h = float(min(np.min(np.diff(x)), np.min(np.diff(y))))
    X, Y = np.meshgrid(x, y)
    rho = np.hypot(X - cx, Y - cy)
    inside = (rho <= radius) & np.isfinite(down)
    max_speed = float(np.max(down[inside])) if inside.any() else 0.0
    if not max_speed > 0.0:
        return _empty(max_speed, math.nan)
    threshold = fraction * max_speed
    wall_term = max_speed * (radius - rho) / h
    g = np.minimum(np.where(np.isfinite(down), down - threshold, -threshold), wall_term)
    regions = _regions(x, y, g)
    regions = [r for r in regions if r[0] > 0.0]
    if not regions:
        return _empty(max_speed, threshold)
    area, mx, my, outer, _ = max(regions, key=lambda r: r[0])
    centroid = (mx / area, my / area)
    theta_c, angle = _contact(x, y, down, threshold, radius, (cx, cy), wall_inset, h)
    r_eq = math.sqrt(area / math.pi)
    if theta_c == 0.0:
        r_c, e_c = r_eq, math.hypot(centroid[0] - cx, centroid[1] - cy)
    elif theta_c >= 180.0:
        r_c = e_c = math.nan
    else:
        r_c, e_c = _circle_through_arc(radius, theta_c, area)
    off_wall = np.hypot(outer[:-1, 0] - cx, outer[:-1, 1] - cy) < radius - h
    fit_r, fit_x, fit_y, fit_rms = _fit_circle(outer[:-1][off_wall])
    return SliceChannel(threshold, max_speed, float(area), r_eq,
                        (float(centroid[0]), float(centroid[1])), float(theta_c),
                        float(angle), float(r_c), float(e_c), fit_r, (fit_x, fit_y),
                        fit_rms, len(regions), outer)


@dataclass(frozen=True)
class ChannelProfile:
    """:func:`slice_channel` at each height ``z`` (m): arrays over the heights (NaN where
    nothing flows), and each slice's outline."""

    z: np.ndarray
    area: np.ndarray
    r_eq: np.ndarray
    centroid_x: np.ndarray
    centroid_y: np.ndarray
    theta_c: np.ndarray
    contact_angle: np.ndarray
    r_c: np.ndarray
    e_c: np.ndarray
    fit_r: np.ndarray
    fit_rms: np.ndarray
    threshold: np.ndarray
    radius: np.ndarray
    x_min: np.ndarray
    x_max: np.ndarray
    y_min: np.ndarray
    y_max: np.ndarray
    outlines: list = field(repr=False)

    def G(self) -> np.ndarray:
        """``r_c / r`` at each height: EN 1991-4's ``G`` of the measured channel."""
        return self.r_c / self.radius


def channel_profile(x, y, z, down, radius, centre=(0.0, 0.0),
                    fraction: float = DEFAULT_FRACTION, wall_inset: float = 0.0
                    ) -> ChannelProfile:
    """:func:`slice_channel` of every horizontal slice ``down[k]`` ((nz, ny, nx), at heights
    ``z`` (nz,)); ``radius`` a number or one per slice, ``centre`` a pair or one per slice
    ((nz, 2))."""
    down = np.asarray(down, float)
    z = np.asarray(z, float)
    if down.ndim != 3 or down.shape[0] != len(z):
        raise ValueError(f"down must be (nz, ny, nx) with nz = len(z) = {len(z)}; "
                         f"got {down.shape}")
    radii = np.broadcast_to(np.asarray(radius, float), z.shape)
    centres = np.broadcast_to(np.asarray(centre, float), z.shape + (2,))
    rows = [slice_channel(x, y, down[k], float(radii[k]), centres[k], fraction, wall_inset)
            for k in range(len(z))]

    def col(get):
        return np.array([get(s) if s.area > 0.0 else math.nan for s in rows])

    return ChannelProfile(
        z=z.copy(), area=np.array([s.area for s in rows]), r_eq=col(lambda s: s.r_eq),
        centroid_x=col(lambda s: s.centroid[0]), centroid_y=col(lambda s: s.centroid[1]),
        theta_c=col(lambda s: s.theta_c), contact_angle=col(lambda s: s.contact_angle),
        r_c=col(lambda s: s.r_c), e_c=col(lambda s: s.e_c), fit_r=col(lambda s: s.fit_r),
        fit_rms=col(lambda s: s.fit_rms), threshold=np.array([s.threshold for s in rows]),
        radius=np.array(radii, float), x_min=col(lambda s: s.extent[0]),
        x_max=col(lambda s: s.extent[1]), y_min=col(lambda s: s.extent[2]),
        y_max=col(lambda s: s.extent[3]), outlines=[s.outline for s in rows])


def node_material(alpha, kappa) -> np.ndarray:
    """The material fraction at the nodes: the mean ``alpha`` of the open cells round each node
    (``kappa > 0``), NaN at nodes with no open cell.  ``alpha``, ``kappa`` (nz, ny, nx); the
    result (nz + 1, ny + 1, nx + 1)."""
    alpha, kappa = np.asarray(alpha, float), np.asarray(kappa, float)
    open_ = (kappa > 0.0).astype(float)
    shape = tuple(n + 1 for n in alpha.shape)
    total, count = np.zeros(shape), np.zeros(shape)
    for dk in (0, 1):
        for dj in (0, 1):
            for di in (0, 1):
                sl = (slice(dk, dk + alpha.shape[0]), slice(dj, dj + alpha.shape[1]),
                      slice(di, di + alpha.shape[2]))
                total[sl] += alpha * open_
                count[sl] += open_
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0.0, total / count, np.nan)


def model_channel(model, state, fraction: float = DEFAULT_FRACTION,
                  wall_inset: float = 0.0, full: float = 0.5) -> ChannelProfile:
    """The channel at every node plane of a 3D model's bin (``z >= bin_foot``, above the
    outlet plane) in a state: :func:`field_channel` of the nodes' vertical velocity
    ``state.v[2]`` and the cells' material fraction ``state.alpha``.  Changes nothing."""
    return field_channel(model, state.v[2], state.alpha, fraction, wall_inset, full)


def field_channel(model, v_z, alpha, fraction: float = DEFAULT_FRACTION,
                  wall_inset: float = 0.0, full: float = 0.5) -> ChannelProfile:
    """The channel at every node plane of a 3D model's bin (``z >= bin_foot``, above the
    outlet plane) in a field: the nodes' downward speed ``-v_z`` (m/s, (nz + 1, ny + 1,
    nx + 1)), NaN at nodes whose open cells hold less than ``full`` material of ``alpha``
    ((nz, ny, nx), :func:`node_material`), unfolded across the grid's mirror planes
    (:func:`unfold`); the section the bin's circle about the silo's axis.  Planes without
    material are left out.  A state's field or a mean over a window of the discharge
    (:meth:`fipy_hopper.space.model.SpaceModel.channel_measures`).  Reads ``model.grid`` and
    ``model.boundary``.  EN 1991-4's model concerns the vertical walls, hence the bin only."""
    g = model.grid
    R = float(model.boundary.radius)
    z_b = float(model.boundary.bin_foot)
    material = node_material(alpha, g.kappa)
    down = np.where(material >= full, -np.asarray(v_z, float), np.nan)
    x, y, down = unfold(g.x_nodes, g.y_nodes, down, g.mirror_x, g.mirror_y)
    keep = (g.z_nodes > 0.0) & (g.z_nodes >= z_b - 1e-12) & np.isfinite(down).any(axis=(1, 2))
    return channel_profile(x, y, g.z_nodes[keep], down[keep], R, (0.0, 0.0), fraction,
                           wall_inset)


#: the measures of a channel profile, per height, in a window's rows
#: (:func:`profile_rows`, ``channel_windows.csv``) and their profile attributes
PROFILE_COLUMNS = (("z_m", "z"), ("area_m2", "area"), ("r_eq_m", "r_eq"),
                   ("centroid_x_m", "centroid_x"), ("centroid_y_m", "centroid_y"),
                   ("theta_c_deg", "theta_c"), ("contact_angle_deg", "contact_angle"),
                   ("r_c_m", "r_c"), ("e_c_m", "e_c"), ("fit_rms_m", "fit_rms"),
                   ("threshold_m_s", "threshold"), ("x_min_m", "x_min"),
                   ("x_max_m", "x_max"), ("y_min_m", "y_min"), ("y_max_m", "y_max"))


def profile_rows(profile: ChannelProfile) -> list:
    """One dict per height of a channel profile (:data:`PROFILE_COLUMNS`), plain floats."""
    columns = [(name, np.asarray(getattr(profile, attr), float))
               for name, attr in PROFILE_COLUMNS]
    return [{name: float(values[k]) for name, values in columns}
            for k in range(len(profile.z))]
