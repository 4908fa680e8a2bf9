"""The silo's boundary as data: named chains of straight wall segments in a section.

Coordinates ``(x, z)`` in m, ``z`` up, the outlet plane ``z = 0``; ``x`` is the radius ``r`` of
an axisymmetric half-section (the axis at ``x = 0``) or the horizontal position in a plane
section.  A :class:`Boundary` holds

- its :class:`Section`: an axisymmetric half-section, a plane half-section or a full plane
  section (both walls);
- named :class:`Chain` s of straight segments: ``wall`` from its outlet lip up to its top
  (``left_wall`` too in a full section), the frictionless free-fall ``tube`` below each lip
  (``left_tube``), and the inserts ``insert_1``, ... (closed polygons; in a half-section an
  edge on the axis is no wall, so an insert on the axis is an open chain);
- the outlet, the span ``[x_left, x_right]`` of the plane ``z = 0`` between the lips (the axis
  and the lip in a half-section), and the fill level.

The material region is ``X_left(z) < x < X_right(z)`` (``X_left = 0``, the axis, in a
half-section), outside every insert.  ``X(z)`` is the wall's ``x`` at height ``z``: the lip's
below the outlet plane (the tube), the first segment's (from the lip) whose heights hold ``z``
(at a horizontal segment its start: a floor or ledge belongs to the solid), and above the top
the wall goes on straight up.  Each tube starts at ``z = -FAR`` and each wall's top is carried
on to ``z = FAR``.  The conical and wedge shorthands are boundaries of three points (the
lip, the transition, the top): the one geometry of the code.

Arc length ``s`` (m) runs along each chain from its lowest point: a wall's lip, the lowest
vertex of a closed insert (counter-clockwise), the lower axis end of an insert on the axis.
Normals point from the material into the solid; the pressure on a wall is ``p_n = -n.sigma.n``.
The compiled marker and Lagrangian code take :meth:`Boundary.kernel_arrays` and
:func:`in_solid_point` / :func:`nearest_point`, which a test holds to the numpy methods.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Optional, Sequence

import numpy as np
from numba import njit

#: Tubes start at ``z = -FAR`` and wall tops are carried on to ``z = FAR`` (m), as the
#: ``r_far``/``z_far`` of :mod:`fipy_hopper.geometry`.
FAR = 1e3
SYMMETRIES = ("axisymmetric", "plane")
SECTIONS = ("half", "full")
#: Angles (deg) below which two consecutive segments count as one straight line.
STRAIGHT_DEG = 1e-9
#: A wall describes a cone (a wedge, a flat floor) under a bin (:func:`hopper_shape`) when,
#: below its top vertical stretch, the segments within ``SAME_SLOPE_DEG`` of the longest one's
#: slope make up at least ``SAME_SLOPE_SHARE`` of the length: a sliver of another slope (a
#: 1 um segment at the lip) does not make another hopper, a second slope of any length does.
SAME_SLOPE_DEG, SAME_SLOPE_SHARE = 0.5, 0.99


@dataclass(frozen=True)
class Section:
    """The computed section of the silo and its symmetry.

    - ``axisymmetric`` half-section: ``x`` is the radius, the axis ``x = 0`` carries
      ``v_x = 0``; areas weigh ``x`` (volumes per radian), the silo is ``2 pi`` of them;
    - ``plane`` half-section: a long silo, symmetric about its mid-plane ``x = 0`` (the axis
      condition there too); per metre of length, the silo is both halves (factor 2);
    - ``plane`` full section (``half = False``): both walls, no axis, factor 1.

    A half-section is mirrored (markers reflect at the axis, pictures draw the other half);
    ``centreline`` is the ``x`` the diagnostics measure from: the axis, or the outlet's centre
    in a full section.
    """

    symmetry: str = "axisymmetric"
    half: bool = True
    centreline: float = 0.0

    def __post_init__(self):
        if self.symmetry not in SYMMETRIES:
            raise ValueError(f"symmetry = {self.symmetry!r}: expected one of {SYMMETRIES}")
        if self.symmetry == "axisymmetric" and not self.half:
            raise ValueError("an axisymmetric section is a half-section (half = True)")

    @property
    def axisymmetric(self) -> bool:
        return self.symmetry == "axisymmetric"

    @property
    def has_axis(self) -> bool:
        """True when ``x = 0`` is an axis or mirror plane (``v_x = 0`` on it)."""
        return self.half

    @property
    def mirror(self) -> bool:
        """True when markers and pictures reflect about ``x = 0``."""
        return self.half

    @property
    def factor(self) -> float:
        """The computed section to the silo: ``2 pi`` (per radian), 2 (a plane half-section,
        per metre of length) or 1 (a full plane section, per metre)."""
        return 2.0 * math.pi if self.axisymmetric else (2.0 if self.half else 1.0)

    @property
    def name(self) -> str:
        return {(True, True): "axisymmetric half-section", (False, True): "plane half-section",
                (False, False): "full plane section"}[(self.axisymmetric, self.half)]

    @property
    def per(self) -> str:
        """The unit of the section's areas and volumes."""
        return "per radian" if self.axisymmetric else "per metre of length"

    def weight(self, x):
        """Radial weight of areas and volumes: ``x`` (axisymmetric) or 1 (plane)."""
        return x if self.axisymmetric else np.ones_like(x)

    def reflect(self, x):
        """Positions brought back into the section: ``|x|`` in a half-section."""
        return np.abs(x) if self.mirror else x


@dataclass(frozen=True)
class Segment:
    """A straight wall segment from ``a`` to ``b`` (m), the arc length ``s`` (m) running from
    ``s_start`` at ``a``: segment ``index`` of the chain named ``chain``, with the solid on
    its right (``side`` +1: a wall followed up from its lip) or left (-1: a left wall, an
    insert followed counter-clockwise), its wall friction, and whether its areas are per
    radian of an axisymmetric wall (``c = r``) or per metre of a plane one (``c = 1``).  The
    wall loads' stretches are segments too (:func:`fipy_hopper.diagnostics.wall_stretches`)."""

    a: tuple
    b: tuple
    friction_deg: float = math.nan
    s_start: float = 0.0
    chain: str = "wall"
    index: int = 0
    side: int = 1
    axisymmetric: bool = True

    @property
    def length(self) -> float:
        return math.hypot(self.b[0] - self.a[0], self.b[1] - self.a[1])

    @property
    def s_end(self) -> float:
        return self.s_start + self.length

    @property
    def angle_deg(self) -> float:
        """Angle of the segment's line from the vertical, in ``[0, 90]`` deg."""
        return math.degrees(math.atan2(abs(self.b[0] - self.a[0]), abs(self.b[1] - self.a[1])))

    @property
    def tangent(self) -> np.ndarray:
        """Unit tangent from ``a`` to ``b``."""
        d = np.subtract(self.b, self.a, dtype=float)
        return d / np.hypot(*d)

    @property
    def normal(self) -> np.ndarray:
        """Unit normal into the solid: the tangent turned clockwise, or anticlockwise for
        ``side = -1``."""
        t = self.tangent
        return self.side * np.array([t[1], -t[0]])

    def point(self, s):
        """``(x, z)`` of the point at arc length ``s`` (m)."""
        u = np.asarray(s, float) - self.s_start
        t = self.tangent
        return self.a[0] + u * t[0], self.a[1] + u * t[1]

    def weight(self, s):
        """The area weight ``c(s)``: the radius ``r(s)`` (m) per radian, or 1 (plane)."""
        s = np.asarray(s, float)
        return self.point(s)[0] if self.axisymmetric else np.ones_like(s)

    def area(self, s1, s2):
        """Wall area ``int_s1^s2 c ds`` (m^2 per radian; m^2 per metre of a plane wall),
        0 where ``s2 <= s1``."""
        s1, s2 = np.asarray(s1, float), np.asarray(s2, float)
        return np.where(s2 > s1, (s2 - s1) * self.weight(0.5 * (s1 + s2)), 0.0)


@dataclass(frozen=True)
class Corner:
    """A corner between consecutive segments ``segment - 1`` and ``segment`` of a chain: at
    ``point`` (m), arc length ``s`` (m), turning by ``turn_deg``; concave seen from the
    material (the material fills the corner, e.g. a hopper-bin transition) or convex."""

    chain: str
    segment: int
    point: tuple
    s: float
    turn_deg: float
    concave: bool


def _turn(d1, d2, side: int):
    """``(turn_deg, concave)`` from direction ``d1`` to ``d2`` of a chain with its solid on
    the right (``side = 1``) or left (-1): concave when it turns towards the material."""
    cross = d1[0] * d2[1] - d1[1] * d2[0]
    dot = d1[0] * d2[0] + d1[1] * d2[1]
    return math.degrees(math.atan2(abs(cross), dot)), side * cross > 0.0


@dataclass(frozen=True)
class Chain:
    """Named straight segments joining ``points`` (m) in the order of ``s``.

    ``kind``: ``"wall"``, ``"tube"`` or ``"insert"``; ``side``: +1 when the solid lies on the
    right of the direction of travel (``wall``, ``tube``), -1 on the left (``left_wall``,
    inserts, counter-clockwise); ``closed``: the last point joins the first; ``friction_deg``:
    the wall friction angle of each segment (nan: not given yet, see
    :meth:`Boundary.with_friction`); ``polygon``: an insert's whole outline (its solid, with
    an edge on the axis that is no wall).
    """

    name: str
    kind: str
    points: tuple
    side: int = 1
    closed: bool = False
    friction_deg: tuple = ()
    polygon: tuple = ()

    @property
    def n_segments(self) -> int:
        return len(self.points) - (0 if self.closed else 1)

    def ends(self) -> tuple:
        """``(a, b)``: start and end points ``(n, 2)`` of the segments, in order."""
        p = np.asarray(self.points, dtype=float)
        return p[:self.n_segments], np.roll(p, -1, axis=0)[:self.n_segments]

    @cached_property
    def s_vertices(self) -> np.ndarray:
        """Arc length (m) at the start of each segment, then at the chain's end."""
        a, b = self.ends()
        return np.concatenate([[0.0], np.cumsum(np.hypot(*(b - a).T))])

    @property
    def length(self) -> float:
        return float(self.s_vertices[-1])

    @cached_property
    def normals(self) -> np.ndarray:
        """Unit normal ``(n, 2)`` of each segment into the solid."""
        a, b = self.ends()
        d = b - a
        d = d / np.linalg.norm(d, axis=1)[:, None]
        n = np.stack([d[:, 1], -d[:, 0]], axis=1)
        return -n if self.side < 0 else n

    @property
    def segments(self) -> tuple:
        a, b = self.ends()
        return tuple(Segment(tuple(a[k]), tuple(b[k]), self.friction_deg[k]
                             if self.friction_deg else math.nan, float(self.s_vertices[k]),
                             self.name, k, self.side)
                     for k in range(self.n_segments))

    @property
    def corners(self) -> tuple:
        """The corners between consecutive segments (a closed chain's at its first point
        too); straight joints are none."""
        a, b = self.ends()
        d = b - a
        out = []
        for k in range(0 if self.closed else 1, self.n_segments):
            turn, concave = _turn(d[k - 1], d[k], self.side)
            if turn > STRAIGHT_DEG:
                out.append(Corner(self.name, k, tuple(a[k]), float(self.s_vertices[k]), turn,
                                  concave))
        return tuple(out)


@dataclass(frozen=True)
class SegmentTable:
    """Every segment of a boundary in flat arrays (``n`` rows: a tube, then its wall from the
    lip up, its top carried on to ``FAR``; the left tube and wall; the inserts).

    ``a, b`` (n, 2) end points (m); ``normal`` (n, 2) unit normal into the solid; ``chain``
    index into :attr:`Boundary.chains`, ``segment`` index in the chain (a wall's carried-on
    top has the last segment's); ``s0`` arc length at ``a``; ``friction_deg``; ``tube``;
    ``concave`` (n, 2): the corner at ``a`` / ``b`` is concave seen from the material (contact
    sets reach past it, :meth:`Boundary.segment_contacts`).
    """

    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray
    chain: np.ndarray
    segment: np.ndarray
    s0: np.ndarray
    friction_deg: np.ndarray
    tube: np.ndarray
    side: np.ndarray
    concave: np.ndarray

    def __len__(self) -> int:
        return len(self.a)


def profile_rows(points: np.ndarray, far: float = FAR) -> np.ndarray:
    """The rows ``(za, zb, xa, slope, x_lo, x_hi)`` (n, 6) of a wall rising from its lip,
    its top carried on to ``far``, for the wall's ``x`` at a height (:func:`wall_x`)."""
    p = np.asarray(points, dtype=float)
    a, b = _carried_on(p, far)
    dz = b[:, 1] - a[:, 1]
    safe = np.where(dz > 0.0, dz, 1.0)
    slope = np.where(dz > 0.0, (b[:, 0] - a[:, 0]) / safe, 0.0)
    return np.column_stack([a[:, 1], b[:, 1], a[:, 0], slope, np.minimum(a[:, 0], b[:, 0]),
                            np.maximum(a[:, 0], b[:, 0])])


def _carried_on(p: np.ndarray, far: float):
    """Segment ends of a wall ``p`` (k, 2) with its top carried straight up to ``far``: the
    last segment lengthened when vertical, else a segment added."""
    a, b = p[:-1].copy(), p[1:].copy()
    top = p[-1]
    if top[1] < far:
        if b[-1, 0] == a[-1, 0]:
            b[-1, 1] = max(far, top[1])
        else:
            a = np.vstack([a, top])
            b = np.vstack([b, [top[0], far]])
    return a, b


def wall_x(z, rows: np.ndarray, x_below: float):
    """The wall's ``x`` (m) at heights ``z`` (array): ``x_lo <= xa + (z - za) slope <= x_hi``
    of the first row with ``za <= z <= zb``, ``x_below`` below the lip."""
    z = np.asarray(z, dtype=float)
    rows = np.asarray(rows, dtype=float)
    if len(rows) and np.all(rows[1:, 0] == rows[:-1, 1]) and np.all(rows[1:, 1] >= rows[:-1, 1]):
        # a wall from its lip up (each row starts where the last ends, the heights never
        # fall): the first row holding z is the first whose top reaches it (a binary search,
        # the same arithmetic on the same row)
        k = np.searchsorted(rows[:, 1], z, side="left")
        r = rows[np.minimum(k, len(rows) - 1)]
        za, zb, xa, slope, lo, hi = (r[..., c] for c in range(6))
        inside = (k < len(rows)) & (z >= za) & (z <= zb)
        return np.where(inside, np.clip(xa + (z - za) * slope, lo, hi), x_below)
    x = np.full(z.shape, x_below)
    for za, zb, xa, slope, lo, hi in rows[::-1]:
        x = np.where((z >= za) & (z <= zb), np.clip(xa + (z - za) * slope, lo, hi), x)
    return x


@dataclass(frozen=True)
class HopperShape:
    """What a wall of one slope under a vertical bin wall is, in the shorthand's sizes (m,
    deg): ``half_angle_deg`` the hopper's slope from the vertical (90: a flat floor),
    ``outlet_x`` the lip's ``x``, ``bin_x`` the bin wall's, ``transition_height`` the height of
    the junction (:meth:`Boundary.transition`)."""

    half_angle_deg: float
    outlet_x: float
    bin_x: float
    transition_height: float


def hopper_shape(wall) -> Optional[HopperShape]:
    """The :class:`HopperShape` of a wall ``[(x, z), ...]`` from its lip up, or None when it
    describes no cone (wedge, flat floor) under a bin: a top segment that is not vertical, or
    below the top vertical stretch more than one slope by length (``SAME_SLOPE_DEG``,
    ``SAME_SLOPE_SHARE``; the segments of that slope rising outwards).  The half-angle is the
    length-weighted mean slope of the segments of that slope (the longest one's to round-off
    when there is one), to 1e-9 deg."""
    p = [tuple(map(float, q)) for q in wall]
    k = len(p) - 1
    while k > 0 and p[k - 1][0] == p[k][0]:
        k -= 1
    if k in (0, len(p) - 1):
        return None
    dx = np.array([b[0] - a[0] for a, b in zip(p[:k], p[1:k + 1])])
    dz = np.array([b[1] - a[1] for a, b in zip(p[:k], p[1:k + 1])])
    length = np.hypot(dx, dz)
    angle = np.degrees(np.arctan2(np.abs(dx), dz))
    longest = int(np.argmax(length))
    same = np.abs(angle - angle[longest]) <= SAME_SLOPE_DEG
    if length[same].sum() < SAME_SLOPE_SHARE * length.sum() or np.any(dx[same] <= 0.0):
        return None
    theta = angle[longest] + float(np.sum(length[same] * (angle[same] - angle[longest]))
                                   / np.sum(length[same]))
    return HopperShape(round(float(theta), 9), p[0][0], p[k][0], p[k][1])


def nearest_on_segments(x, z, a, b) -> tuple:
    """The nearest point ``(px, pz)`` of points ``(x, z)`` on the segments ``a[k] -> b[k]``
    (``(n, 2)`` each), the index of that segment (the first nearest) and ``t`` in ``[0, 1]``
    along it; vectorised over the points."""
    x = np.asarray(x, dtype=float)
    z = np.asarray(z, dtype=float)
    best_d2 = np.full(np.broadcast(x, z).shape, np.inf)
    best_x = np.zeros_like(best_d2)
    best_z = np.zeros_like(best_d2)
    best_t = np.zeros_like(best_d2)
    best_row = np.zeros(best_d2.shape, dtype=int)
    for k in range(len(a)):
        ab = b[k] - a[k]
        t = ((x - a[k][0]) * ab[0] + (z - a[k][1]) * ab[1]) / (ab @ ab)
        t = np.clip(t, 0.0, 1.0)
        px, pz = a[k][0] + t * ab[0], a[k][1] + t * ab[1]
        d2 = (x - px) ** 2 + (z - pz) ** 2
        closer = d2 < best_d2
        best_d2 = np.where(closer, d2, best_d2)
        best_x = np.where(closer, px, best_x)
        best_z = np.where(closer, pz, best_z)
        best_t = np.where(closer, t, best_t)
        best_row = np.where(closer, k, best_row)
    return best_x, best_z, best_row, best_t


def inside_polygon(x, z, polygon: np.ndarray):
    """Crossing-number test: True inside the polygon ``(k, 2)`` (points on it either way)."""
    x = np.asarray(x, dtype=float)
    z = np.asarray(z, dtype=float)
    inside = np.zeros(np.broadcast(x, z).shape, dtype=bool)
    for i in range(len(polygon)):
        xi, zi = polygon[i]
        xj, zj = polygon[i - 1]
        if zi == zj:
            continue
        crosses = (zi > z) != (zj > z)
        inside ^= crosses & (x < xi + (z - zi) * (xj - xi) / (zj - zi))
    return inside


def polygon_integrals(p: np.ndarray) -> tuple:
    """``(A, Q)``: the signed area ``A = 1/2 sum(x_i z_j - x_j z_i)`` (m^2, positive
    counter-clockwise) and first moment ``Q = int x dA = 1/6 sum (x_i + x_j)(x_i z_j - x_j
    z_i)`` (m^3) of a polygon ``(k, 2)``, ``j = i + 1``."""
    p = np.asarray(p, dtype=float)
    if len(p) < 3:
        return 0.0, 0.0
    q = np.roll(p, -1, axis=0)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    return float(0.5 * cross.sum()), float(((p[:, 0] + q[:, 0]) * cross).sum() / 6.0)


def clip_below(p: np.ndarray, level: float) -> np.ndarray:
    """The part ``z <= level`` of a polygon (Sutherland-Hodgman against one line)."""
    out = []
    for i in range(len(p)):
        cur, prev = p[i], p[i - 1]
        if (cur[1] <= level) != (prev[1] <= level):
            t = (level - prev[1]) / (cur[1] - prev[1])
            out.append((prev[0] + t * (cur[0] - prev[0]), level))
        if cur[1] <= level:
            out.append((cur[0], cur[1]))
    return np.asarray(out, dtype=float).reshape(-1, 2)


def segments_meet(p1, p2, q1, q2) -> bool:
    """True when the closed segments ``p1 p2`` and ``q1 q2`` share a point."""
    def orient(a, b, c):
        v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return (v > 0) - (v < 0)

    def within(a, b, c):          # c on the line of a b: inside its bounding box
        return (min(a[0], b[0]) <= c[0] <= max(a[0], b[0])
                and min(a[1], b[1]) <= c[1] <= max(a[1], b[1]))

    o1, o2 = orient(p1, p2, q1), orient(p1, p2, q2)
    o3, o4 = orient(q1, q2, p1), orient(q1, q2, p2)
    if o1 != o2 and o3 != o4 and o1 * o2 <= 0 and o3 * o4 <= 0:
        return True
    return ((o1 == 0 and within(p1, p2, q1)) or (o2 == 0 and within(p1, p2, q2))
            or (o3 == 0 and within(q1, q2, p1)) or (o4 == 0 and within(q1, q2, p2)))


def _orient_many(a, b, c) -> np.ndarray:
    """The sign of the turn ``a -> b -> c`` (points ``(k, 2)``): the arithmetic of
    :func:`segments_meet`'s, element by element."""
    v = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    return np.sign(v)


def _within_many(a, b, c) -> np.ndarray:
    return ((np.minimum(a[:, 0], b[:, 0]) <= c[:, 0]) & (c[:, 0] <= np.maximum(a[:, 0], b[:, 0]))
            & (np.minimum(a[:, 1], b[:, 1]) <= c[:, 1])
            & (c[:, 1] <= np.maximum(a[:, 1], b[:, 1])))


def segments_meet_many(p1, p2, q1, q2) -> np.ndarray:
    """:func:`segments_meet` of the segments ``p1[k] p2[k]`` and ``q1[k] q2[k]`` (arrays
    ``(n, 2)``), vectorised: the same decisions from the same arithmetic."""
    o1, o2 = _orient_many(p1, p2, q1), _orient_many(p1, p2, q2)
    o3, o4 = _orient_many(q1, q2, p1), _orient_many(q1, q2, p2)
    cross = (o1 != o2) & (o3 != o4) & (o1 * o2 <= 0) & (o3 * o4 <= 0)
    return cross | ((o1 == 0) & _within_many(p1, p2, q1)) | \
        ((o2 == 0) & _within_many(p1, p2, q2)) | ((o3 == 0) & _within_many(q1, q2, p1)) | \
        ((o4 == 0) & _within_many(q1, q2, p2))


#: pairs of segments tested at once by :func:`first_meeting` (bounds its memory)
_PAIRS_AT_ONCE = 2_000_000


def first_meeting(a1, b1, a2, b2, same: bool = False, closed: bool = False) -> Optional[tuple]:
    """The first pair ``(i, j)`` (by ``i``, then ``j``) of a segment ``a1[i] b1[i]`` and a
    segment ``a2[j] b2[j]`` that share a point (:func:`segments_meet`), or None; with
    ``same`` (both sets one chain's segments) only the pairs ``j > i + 1`` that are not the
    first and last of a ``closed`` chain.

    Near-linear for the shapes of silos: only segments whose heights overlap are compared
    (a binary search among the others sorted by their lower end, the few segments much
    taller than the rest compared with every one), then their boxes, then exactly."""
    a1, b1, a2, b2 = (np.asarray(v, dtype=float).reshape(-1, 2) for v in (a1, b1, a2, b2))
    n1, n2 = len(a1), len(a2)
    if not n1 or not n2:
        return None
    lo1, hi1 = np.minimum(a1[:, 1], b1[:, 1]), np.maximum(a1[:, 1], b1[:, 1])
    lo2, hi2 = np.minimum(a2[:, 1], b2[:, 1]), np.maximum(a2[:, 1], b2[:, 1])
    span = hi2 - lo2
    tall = span > 8.0 * max(float(np.median(span)), float(span.mean()))
    short, tall = np.flatnonzero(~tall), np.flatnonzero(tall)
    order = short[np.argsort(lo2[short], kind="stable")]
    reach = float(span[order].max()) if len(order) else 0.0
    start = np.searchsorted(lo2[order], lo1 - reach, side="left")
    count = np.maximum(np.searchsorted(lo2[order], hi1, side="right") - start, 0) + len(tall)
    xlo1, xhi1 = np.minimum(a1[:, 0], b1[:, 0]), np.maximum(a1[:, 0], b1[:, 0])
    xlo2, xhi2 = np.minimum(a2[:, 0], b2[:, 0]), np.maximum(a2[:, 0], b2[:, 0])
    first = 0
    while first < n1:            # chunks of the first set, in order: stop at the first hit
        last = first + max(1, int(np.searchsorted(np.cumsum(count[first:]), _PAIRS_AT_ONCE)))
        rows = np.arange(first, min(last, n1))
        k = np.maximum(count[rows] - len(tall), 0)
        i = np.repeat(rows, k)
        j = order[np.repeat(start[rows], k) + np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)]
        if len(tall):
            i = np.concatenate([i, np.repeat(rows, len(tall))])
            j = np.concatenate([j, np.tile(tall, len(rows))])
        keep = (lo2[j] <= hi1[i]) & (hi2[j] >= lo1[i]) & (xlo2[j] <= xhi1[i]) & \
            (xhi2[j] >= xlo1[i])
        if same:
            keep &= (j > i + 1) & ~(closed & (i == 0) & (j == n1 - 1))
        i, j = i[keep], j[keep]
        hit = segments_meet_many(a1[i], b1[i], a2[j], b2[j])
        if hit.any():
            i, j = i[hit], j[hit]
            best = np.lexsort((j, i))[0]
            return int(i[best]), int(j[best])
        first = int(rows[-1]) + 1
    return None


def self_crossing(points, closed: bool) -> Optional[tuple]:
    """The first pair ``(i, j)`` of segments of a polyline (a polygon when ``closed``) that
    cross, touch or fold back on each other, or None (vectorised: :func:`first_meeting` for
    the segments apart, the joints of neighbours element by element)."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    n = len(p) if closed else len(p) - 1
    if n < 2:
        return None
    a, b = p[:n], np.roll(p, -1, axis=0)[:n]
    found = []
    # neighbours (i, i + 1), and a closed chain's (0, n - 1) with its last segment first
    i = np.arange(n - 1)
    pairs = [(i, i + 1, i, i + 1)]
    if closed and n > 2:
        pairs.append((np.array([0]), np.array([n - 1]), np.array([n - 1]), np.array([0])))
    for i, j, first, second in pairs:
        pa, pb, pc, pd = a[first], b[first], a[second], b[second]
        d1, d2 = pb - pa, pd - pc
        folds = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] == 0) & \
            (d1[:, 0] * d2[:, 0] + d1[:, 1] * d2[:, 1] < 0)
        touch = (segments_meet_many(pa, pa, pc, pd) | segments_meet_many(pa, pb, pd, pd)) \
            if n > 2 else np.zeros(len(i), dtype=bool)
        bad = np.flatnonzero(folds | touch)
        if len(bad):
            found.append((int(i[bad[0]]), int(j[bad[0]])))
    apart = first_meeting(a, b, a, b, same=True, closed=closed)
    if apart is not None:
        found.append(apart)
    return min(found) if found else None


def insert_chain_points(outline, half: bool) -> tuple:
    """``(points, closed)`` of an insert's wall chain from its outline: counter-clockwise
    from the lowest vertex; in a half-section without its edge on the axis (then open, from
    the lower axis end)."""
    p = np.asarray(outline, dtype=float)
    if polygon_integrals(p)[0] < 0.0:
        p = p[::-1]
    k = len(p)
    if half:
        on_axis = [i for i in range(k) if p[i, 0] == 0.0 and p[(i + 1) % k, 0] == 0.0]
        if on_axis:
            start = (on_axis[0] + 1) % k
            order = [(start + m) % k for m in range(k)]
            return tuple(map(tuple, p[order])), False
    low = min(range(k), key=lambda i: (p[i, 1], p[i, 0]))
    return tuple(map(tuple, np.roll(p, -low, axis=0))), True


@dataclass(frozen=True)
class Boundary:
    """The silo's boundary (see the module docstring): ``section``, ``chains`` (tube, wall,
    [left_tube, left_wall], insert_1, ...), ``fill_level`` (m above the outlet plane),
    ``outlet`` = ``(x_left, x_right)`` (m) and ``far`` (m)."""

    section: Section
    chains: tuple
    fill_level: float
    outlet: tuple
    far: float = FAR

    # ------------------------------------------------------------------ the chains
    def chain(self, name) -> Chain:
        """The chain of this name (or index)."""
        if isinstance(name, (int, np.integer)):
            return self.chains[name]
        for c in self.chains:
            if c.name == name:
                return c
        raise KeyError(f"no chain {name!r}; the chains are "
                       f"{', '.join(c.name for c in self.chains)}")

    def chain_index(self, name: str) -> int:
        return self.chains.index(self.chain(name))

    @property
    def walls(self) -> tuple:
        return tuple(c for c in self.chains if c.kind == "wall")

    @property
    def inserts(self) -> tuple:
        return tuple(c for c in self.chains if c.kind == "insert")

    @property
    def corners(self) -> tuple:
        return tuple(k for c in self.chains for k in c.corners)

    @property
    def top(self) -> float:
        """Height of the highest wall point (m)."""
        return max(p[1] for c in self.walls for p in c.points)

    # ------------------------------------------------------------------ sizes of the section
    @property
    def x_extent(self) -> tuple:
        """``(x_min, x_max)`` (m) of the section: the axis (a half-section) or the left wall's
        leftmost point, and the (right) wall's rightmost point."""
        right = max(p[0] for p in self.chain("wall").points)
        if self.section.half:
            return 0.0, right
        return min(p[0] for p in self.chain("left_wall").points), right

    @property
    def width(self) -> float:
        """The silo's widest span (m): twice the wall's largest ``x`` of a half-section (the
        diameter, or the width of a plane silo), or from wall to wall of a full section."""
        x_min, x_max = self.x_extent
        return 2.0 * x_max if self.section.half else x_max - x_min

    def wall_x(self, z, chain="wall"):
        """A wall's ``x`` (m) at heights ``z`` (:func:`wall_x`: the lip's below the outlet
        plane, a floor's start, straight up above the top)."""
        rows, below, _ = self._profiles[[c.name for c in self.walls].index(
            self.chain(chain).name)]
        return wall_x(z, rows, below)

    def span_at(self, z: float) -> float:
        """The silo's width (m) at height ``z``: from wall to wall (twice the wall's ``x`` in a
        half-section: the diameter, or the plane silo's width)."""
        right = float(self.wall_x(z))
        if self.section.half:
            return 2.0 * right
        return right - float(self.wall_x(z, "left_wall"))

    @cached_property
    def hopper_shape(self) -> Optional[HopperShape]:
        """The wall's :class:`HopperShape` in a half-section (:func:`hopper_shape`): a cone, a
        wedge or a flat floor under a bin, with its sizes; None for any other wall and for a
        full section."""
        return hopper_shape(self.chain("wall").points) if self.section.half else None

    def transition(self, chain="wall") -> Optional[Corner]:
        """The corner of a wall where its top vertical stretch begins (a hopper's or a flat
        floor's junction with the bin wall above it), or None when the wall's top segment is
        not vertical (no bin wall stands on the rest)."""
        c = self.chain(chain)
        p = c.points
        k = len(p) - 1
        while k > 0 and p[k - 1][0] == p[k][0]:
            k -= 1
        if k in (0, len(p) - 1):
            return None
        return next((q for q in c.corners if q.segment == k), None)

    def transition_height(self, chain="wall") -> float:
        """The height (m) of a wall's :meth:`transition`: below it the wall hangs from it, above
        it the bin wall stands on it; the wall's top when it has none (all of it hangs)."""
        corner = self.transition(chain)
        return float(corner.point[1]) if corner is not None else \
            float(self.chain(chain).points[-1][1])

    def transition_s(self, chain="wall") -> float:
        """The arc length (m) of a wall's :meth:`transition` along it (the wall's length when
        it has none)."""
        corner = self.transition(chain)
        return float(corner.s) if corner is not None else self.chain(chain).length

    def with_friction(self, wall_deg: float, segment_deg: Sequence[float] = None) -> "Boundary":
        """A copy whose walls have friction ``segment_deg`` (one per segment of ``wall``) or
        ``wall_deg``, and inserts without an angle of their own ``wall_deg`` (deg)."""
        chains = []
        for c in self.chains:
            if c.kind == "tube":
                fr = (0.0,) * c.n_segments
            elif c.name == "wall" and segment_deg is not None:
                fr = tuple(float(f) for f in segment_deg)
            else:
                fr = tuple(wall_deg if math.isnan(f) else f for f in c.friction_deg)
            chains.append(replace(c, friction_deg=fr))
        return replace(self, chains=tuple(chains))

    # ------------------------------------------------------------------ flat tables
    @cached_property
    def table(self) -> SegmentTable:
        """The flat table of every segment (:class:`SegmentTable`)."""
        rows = []              # (a, b, chain, segment, s0, friction, tube, side, group)
        for ci, c in enumerate(self.chains):
            a, b = c.ends()
            if c.kind == "wall":
                a, b = _carried_on(np.asarray(c.points, dtype=float), self.far)
            group = ci - 1 if c.kind == "wall" else ci       # a wall joins its tube
            s_v = c.s_vertices
            for k in range(len(a)):
                seg = min(k, c.n_segments - 1)
                s0 = s_v[k] if k < c.n_segments else s_v[-1]
                rows.append((a[k], b[k], ci, seg, s0, c.friction_deg[seg] if c.friction_deg
                             else math.nan, c.kind == "tube", c.side, group))
        a = np.array([r[0] for r in rows], dtype=float)
        b = np.array([r[1] for r in rows], dtype=float)
        side = np.array([r[7] for r in rows])
        d = b - a
        d = d / np.linalg.norm(d, axis=1)[:, None]
        normal = np.stack([d[:, 1], -d[:, 0]], axis=1)
        normal[side < 0] *= -1.0
        group = np.array([r[8] for r in rows])
        concave = np.zeros((len(rows), 2), dtype=bool)
        for g in np.unique(group):
            idx = np.flatnonzero(group == g)
            closed = self.chains[g].closed
            pairs = list(zip(idx[:-1], idx[1:])) + ([(idx[-1], idx[0])] if closed else [])
            for i, j in pairs:
                _, concave[i, 1] = _turn(b[i] - a[i], b[j] - a[j], side[i])
                concave[j, 0] = concave[i, 1]
        return SegmentTable(a=a, b=b, normal=normal,
                            chain=np.array([r[2] for r in rows], dtype=np.int64),
                            segment=np.array([r[3] for r in rows], dtype=np.int64),
                            s0=np.array([r[4] for r in rows], dtype=float),
                            friction_deg=np.array([r[5] for r in rows], dtype=float),
                            tube=np.array([r[6] for r in rows]), side=side, concave=concave)

    @cached_property
    def _profiles(self) -> tuple:
        """``(rows, x_below, right)`` of each wall for :func:`wall_x`."""
        return tuple((profile_rows(c.points, self.far), float(c.points[0][0]), c.side > 0)
                     for c in self.walls)

    @cached_property
    def _polygons(self) -> tuple:
        return tuple(np.asarray(c.polygon, dtype=float) for c in self.inserts)

    def kernel_arrays(self) -> tuple:
        """The arguments after ``(x, z)`` of :func:`in_solid_point` and, first two,
        :func:`nearest_point`: ``(a, b, right_rows, right_below, left_rows, left_below,
        has_left, polygon_points, polygon_start)``, contiguous float64 / int64 arrays."""
        (right, r_below, _), *rest = self._profiles
        left, l_below = (rest[0][0], rest[0][1]) if rest else (np.zeros((0, 6)), 0.0)
        polys = self._polygons
        start = np.concatenate([[0], np.cumsum([len(p) for p in polys])]).astype(np.int64)
        pts = np.concatenate(polys) if polys else np.zeros((0, 2))
        c = np.ascontiguousarray
        return (c(self.table.a), c(self.table.b), c(right), r_below, c(left), l_below,
                bool(rest), c(pts, dtype=float), start)

    # ------------------------------------------------------------------ geometry
    def in_solid(self, x, z):
        """True where ``(x, z)`` lies in the solid: beyond a wall or inside an insert."""
        x = np.asarray(x, dtype=float)
        solid = None
        for rows, below, right in self._profiles:
            beyond = x >= wall_x(z, rows, below) if right else x <= wall_x(z, rows, below)
            solid = beyond if solid is None else solid | beyond
        for poly in self._polygons:
            solid = solid | inside_polygon(x, z, poly)
        return solid

    def _nearest_rows(self, x, z):
        """Nearest point ``(px, pz)``, its table row and ``t`` in ``[0, 1]`` along the row
        (the first nearest row: :func:`nearest_on_segments`)."""
        return nearest_on_segments(x, z, self.table.a, self.table.b)

    def nearest(self, x, z) -> tuple:
        """The nearest wall point of ``(x, z)``: ``(px, pz, chain, segment, s)`` (m, chain
        index, segment index, arc length along the chain in m)."""
        px, pz, row, t = self._nearest_rows(x, z)
        tab = self.table
        length = np.hypot(*(tab.b - tab.a).T)
        return px, pz, tab.chain[row], tab.segment[row], tab.s0[row] + t * length[row]

    @cached_property
    def _offsets(self) -> tuple:
        """Each chain's start along all the chains (m): the walls' and inserts' lengths one
        after the other, a metre apart (tubes: 0)."""
        out, at = [], 0.0
        for c in self.chains:
            out.append(0.0 if c.kind == "tube" else at)
            if c.kind != "tube":
                at += c.length + 1.0
        return tuple(out)

    def chain_offset(self, chain) -> float:
        """Where a chain starts along all the chains (m): :meth:`position` of its ``s = 0``."""
        return self._offsets[self.chain_index(chain) if isinstance(chain, str) else chain]

    def position(self, chain, s):
        """One coordinate along every wall and insert (m): a chain's offset
        (:meth:`chain_offset`) plus the arc length ``s`` along it, clipped to the chain."""
        chain = np.asarray(chain)
        offsets = np.asarray(self._offsets)[chain]
        lengths = np.array([c.length for c in self.chains])[chain]
        return offsets + np.clip(np.asarray(s, float), 0.0, lengths)

    def load_row(self, x, z) -> np.ndarray:
        """The table row whose load a contact at ``(x, z)`` is: the nearest segment's, or for
        a tube's the first segment of the wall above it (a lip's load is the wall's)."""
        _, _, row, _ = self._nearest_rows(x, z)
        return np.where(self.table.tube[row], row + 1, row)

    def signed_distance(self, x, z):
        """Signed distance to the boundary (m): positive in the open region, negative in the
        solid."""
        px, pz, _, _ = self._nearest_rows(x, z)
        d = np.hypot(np.asarray(x, dtype=float) - px, np.asarray(z, dtype=float) - pz)
        return np.where(self.in_solid(x, z), -d, d)

    def wall_normal(self, x, z):
        """Unit normal ``(n_x, n_z)`` from the open region into the solid at the nearest
        point: the segment's, or where that point is a vertex (a lip, a convex corner) the
        direction to it (the exact gradient of the distance)."""
        x = np.asarray(x, dtype=float)
        z = np.asarray(z, dtype=float)
        px, pz, seg, _ = self._nearest_rows(x, z)
        tab = self.table
        nx, nz = tab.normal[seg, 0], tab.normal[seg, 1]
        dx, dz = px - x, pz - z
        dist = np.hypot(dx, dz)
        at_vertex = np.isclose(px, tab.a[seg, 0]) & np.isclose(pz, tab.a[seg, 1]) | \
            np.isclose(px, tab.b[seg, 0]) & np.isclose(pz, tab.b[seg, 1])
        use_direction = at_vertex & (dist > 1e-12)
        sign = np.where(self.in_solid(x, z), -1.0, 1.0)
        safe = np.where(dist > 0, dist, 1.0)
        nx = np.where(use_direction, sign * dx / safe, nx)
        nz = np.where(use_direction, sign * dz / safe, nz)
        return nx, nz

    def segment_contacts(self, x, z, reach: float) -> list:
        """Contact sets ``[(row, mask, n_x, n_z), ...]`` of the table's segments.

        A point is in contact with a segment when its projection falls on it (``0 <= t <=
        1``, extended by ``reach`` past a concave corner, where the segment's line runs into
        the solid) and it lies less than ``reach`` in front of it, less than ``reach`` behind
        it, or further behind it inside the solid it bounds (a wall's: anywhere behind it; an
        insert's: inside the insert).  Near a concave corner a point is in
        contact with both segments; near a convex corner (a lip) a point projecting beyond
        both belongs to none (:meth:`wall_normal` gives its normal).

        "Behind" stops where the insert does: behind a wall's segment everything is its
        solid, but behind an insert's face lies, past the insert, the material again (the
        strip under an insert's top face runs down through the hopper to the outlet).  Held
        by the top face's normal there, every node of that column was stopped from falling:
        an insert 3.5 cells above the fill held up the material under it (at 1 cm, a box
        insert on the axis stopped the discharge and carried 70 N of it).
        """
        x = np.asarray(x, dtype=float)
        z = np.asarray(z, dtype=float)
        tab = self.table
        out = []
        for k in range(len(tab)):
            a, b = tab.a[k], tab.b[k]
            ab = b - a
            length = float(np.hypot(*ab))
            if length == 0.0:
                continue
            t = ((x - a[0]) * ab[0] + (z - a[1]) * ab[1]) / length ** 2
            normal = np.array([ab[1], -ab[0]]) / length
            if tab.side[k] < 0:
                normal = -normal
            front = -((x - a[0]) * normal[0] + (z - a[1]) * normal[1])
            ext = reach / length
            lo = -ext if tab.concave[k, 0] else 0.0
            hi = 1.0 + ext if tab.concave[k, 1] else 1.0
            mask = (t >= lo - 1e-12) & (t <= hi + 1e-12) & (front < reach)
            chain = self.chains[tab.chain[k]]
            far_behind = mask & (front <= -reach)
            if chain.kind == "insert" and np.any(far_behind):
                mask &= ~far_behind | inside_polygon(x, z, np.asarray(chain.polygon, float))
            out.append((k, mask, float(normal[0]), float(normal[1])))
        return out

    def wall_point(self, chain, s):
        """The point ``(x, z)`` at arc length ``s`` (m, clipped to the chain) along a chain
        and the normal ``(n_x, n_z)`` into the solid there (a vertex takes the segment below
        it)."""
        c = self.chain(chain)
        s = np.clip(np.asarray(s, dtype=float), 0.0, c.length)
        sv = c.s_vertices
        k = np.clip(np.searchsorted(sv, s, side="left") - 1, 0, c.n_segments - 1)
        a, b = c.ends()
        f = (s - sv[k]) / (sv[k + 1] - sv[k])
        x = a[k, 0] + f * (b[k, 0] - a[k, 0])
        z = a[k, 1] + f * (b[k, 1] - a[k, 1])
        return x, z, c.normals[k, 0], c.normals[k, 1]

    def arc_at_height(self, chain, z: float) -> float:
        """The arc length (m) along a wall chain where it first reaches height ``z`` (its top,
        carried on straight up, beyond its last point)."""
        c = self.chain(chain)
        a, b = c.ends()
        sv = c.s_vertices
        for k in range(c.n_segments):
            if b[k, 1] >= z:
                if b[k, 1] == a[k, 1] or z <= a[k, 1]:
                    return float(sv[k]) if z <= a[k, 1] else float(sv[k + 1])
                return float(sv[k] + (sv[k + 1] - sv[k]) * (z - a[k, 1]) / (b[k, 1] - a[k, 1]))
        return float(sv[-1] + z - b[-1, 1])

    def wall_area(self, chain, s1, s2):
        """Wall area between arc lengths ``s1 < s2`` of a chain, ``int w ds`` with the
        section's weight ``w`` (:meth:`Section.weight`): m^2 per radian (``int r ds``) or m^2
        per metre of length."""
        return self._weighted_length(chain, s2) - self._weighted_length(chain, s1)

    def _weighted_length(self, chain, s):
        """``int_0^s w ds`` along a chain (``w`` linear in ``s`` on a segment)."""
        c = self.chain(chain)
        s = np.clip(np.asarray(s, dtype=float), 0.0, c.length)
        if not self.section.axisymmetric:
            return s
        a, b = c.ends()
        sv = c.s_vertices
        whole = np.concatenate([[0.0], np.cumsum(np.diff(sv) * 0.5 * (a[:, 0] + b[:, 0]))])
        k = np.clip(np.searchsorted(sv, s, side="left") - 1, 0, c.n_segments - 1)
        x, _, _, _ = self.wall_point(chain, s)
        return whole[k] + (s - sv[k]) * 0.5 * (a[k, 0] + x)

    # ------------------------------------------------------------------ the fill
    def material_polygon(self, level: float = None) -> np.ndarray:
        """The material region below ``level`` (default: the fill level), inserts not taken
        out, as a counter-clockwise polygon ``(k, 2)`` (m)."""
        level = self.fill_level if level is None else float(level)
        sides = []
        for rows, below, right in self._profiles:
            pts = [tuple(p) for p in np.asarray(self.chain("wall" if right else "left_wall")
                                                .points) if p[1] < level]
            pts.append((float(wall_x(level, rows, below)), level))
            sides.append(pts)
        right = sides[0]
        left = sides[1][::-1] if len(sides) > 1 else [(0.0, level), (0.0, 0.0)]
        return np.asarray(right + left, dtype=float)

    def fill_volume(self, level: float = None) -> float:
        """Volume of the material below ``level`` (default: the fill level), inserts taken
        out: ``factor * int w dA`` (Pappus), m^3 for the silo (m^3 per metre of length in plane
        flow)."""
        level = self.fill_level if level is None else float(level)
        k = 1 if self.section.axisymmetric else 0
        total = polygon_integrals(self.material_polygon(level))[k]
        for poly in self._polygons:
            total -= abs(polygon_integrals(clip_below(poly, level))[k])
        return self.section.factor * total

    def fill_mass(self, density: float) -> float:
        """Mass of the fill (kg; kg per metre of length in plane flow) at ``density``
        (kg/m^3)."""
        return density * self.fill_volume()

    # ------------------------------------------------------------------ for people
    def describe(self, density: float = None) -> str:
        """The boundary in words: section, outlet, fill, chains, segments and corners."""
        sec = self.section
        unit = "m^3" + ("" if sec.axisymmetric else "/m")
        x0, x1 = self.outlet
        lines = [f"section      {sec.name}" + (
            f" (axis x = 0; the silo is {sec.factor:.4g} x the section, {sec.per})"
            if sec.half else f" (centreline x = {sec.centreline:g} m, {sec.per})"),
            f"outlet       x in [{x0:g}, {x1:g}] m on z = 0 (width {x1 - x0:g} m"
            + (" from the axis)" if sec.half else ")"),
            f"fill level   z = {self.fill_level:g} m: {self.fill_volume():.4g} {unit}"
            + (f", {self.fill_mass(density):.4g} kg{'' if sec.axisymmetric else '/m'} at "
               f"{density:g} kg/m3" if density else "")
            + (" (inserts taken out)" if self.inserts else "")]
        for c in self.chains:
            if c.kind == "tube":
                lines.append(f"{c.name:<12} free-fall tube below the lip at x = "
                             f"{c.points[-1][0]:g} m, frictionless")
                continue
            shape = ("closed" if c.closed else "open along the axis") \
                if c.kind == "insert" else "from the lip up"
            lines.append(f"{c.name:<12} {c.kind}, {shape}, {c.n_segments} segments, "
                         f"{c.length:.4g} m")
            for k, seg in enumerate(c.segments):
                fr = "from [wall]" if math.isnan(seg.friction_deg) else \
                    f"{seg.friction_deg:g} deg"
                lines.append(f"  segment {k}: ({seg.a[0]:.4g}, {seg.a[1]:.4g}) -> "
                             f"({seg.b[0]:.4g}, {seg.b[1]:.4g}) m, length {seg.length:.4g} m, "
                             f"{seg.angle_deg:.1f} deg from the vertical, s = "
                             f"{seg.s_start:.4g}-{seg.s_end:.4g} m, friction {fr}")
            for k in c.corners:
                lines.append(f"  corner at ({k.point[0]:.4g}, {k.point[1]:.4g}) m, s = "
                             f"{k.s:.4g} m: turns {k.turn_deg:.1f} deg, "
                             f"{'concave' if k.concave else 'convex'}")
        return "\n".join(lines)

    def draw(self, path) -> None:
        """Draw the boundary to ``path`` (PNG): walls coloured by chain, corners (filled:
        concave, open: convex), the outlet span, the fill, the axis and the mirrored half (a
        half-section) or the centreline (a full section)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        sec = self.section
        fig = Figure(figsize=(6.0, 7.0))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        fill = self.material_polygon()
        ax.fill(fill[:, 0], fill[:, 1], color="#e8d9a8", zorder=0,
                label=f"fill to z = {self.fill_level:g} m")
        depth = 0.15 * max(self.top, self.outlet[1] - self.outlet[0])
        colours = itertools.cycle(["C0", "C1", "C2", "C3", "C4", "C5", "C6", "C8", "C9"])
        for c in self.chains:
            p = np.asarray(c.points, dtype=float)
            if c.kind == "tube":
                ax.plot([p[-1, 0]] * 2, [-depth, 0.0], ":", color="0.4", lw=1.5,
                        label="free-fall tube" if c.name == "tube" else None)
                continue
            colour = next(colours)
            if c.kind == "insert":
                poly = np.asarray(c.polygon, dtype=float)
                ax.fill(poly[:, 0], poly[:, 1], color=colour, alpha=0.3, lw=0)
            q = np.vstack([p, p[:1]]) if c.closed else p
            ax.plot(q[:, 0], q[:, 1], "-", color=colour, lw=2.5, label=c.name)
            if sec.mirror:
                ax.plot(-q[:, 0], q[:, 1], "-", color="0.75", lw=1.5)
            for concave in (True, False):        # one call each: a wall may have 10,000
                points = np.array([k.point for k in c.corners if k.concave == concave])
                if len(points):
                    ax.plot(points[:, 0], points[:, 1], "o", ms=7, mec="k",
                            mfc="k" if concave else "w", zorder=5)
        x0, x1 = self.outlet
        ax.plot([x0, x1], [0.0, 0.0], "-", color="r", lw=4, solid_capstyle="butt",
                label=f"outlet, x in [{x0:g}, {x1:g}] m")
        ax.plot([], [], "o", mec="k", mfc="k", label="concave corner")
        ax.plot([], [], "o", mec="k", mfc="w", label="convex corner")
        if sec.has_axis:
            ax.axvline(0.0, color="k", ls="-.", lw=1, label="axis (mirror)")
            if sec.mirror:
                ax.fill(-fill[:, 0], fill[:, 1], color="#e8d9a8", alpha=0.4, zorder=0)
        else:
            ax.axvline(sec.centreline, color="k", ls=":", lw=1, label="outlet centreline")
        ax.set_aspect("equal")
        ax.set_xlabel("r (m)" if sec.axisymmetric else "x (m)")
        ax.set_ylabel("z (m)")
        ax.set_ylim(-depth, 1.05 * self.top)
        ax.set_title(f"{sec.name}: {len(self.inserts)} insert(s), "
                     f"{len(self.corners)} corner(s)")
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
        fig.savefig(path, dpi=110, bbox_inches="tight")


def build(wall, *, symmetry: str = "axisymmetric", left_wall=None, inserts=(),
          fill_level: float, far: float = FAR) -> Boundary:
    """The boundary of a wall profile ``[(x, z), ...]`` (m, the lip on ``z = 0`` up to the
    top), with ``left_wall`` a full plane section, and ``inserts`` a sequence of ``(outline,
    friction_deg or None)``.  Wall friction is left nan (:meth:`Boundary.with_friction`).
    The input is taken as valid (:class:`fipy_hopper.config.HopperGeometry` checks it)."""
    half = left_wall is None
    wall = tuple((float(x), float(z)) for x, z in wall)
    x_left = 0.0 if half else float(left_wall[0][0])
    section = Section(symmetry, half, 0.0 if half else 0.5 * (x_left + wall[0][0]))
    nan = math.nan

    def walls(name, points, side):
        tube = Chain(name.replace("wall", "tube"), "tube",
                     ((points[0][0], -far), points[0]), side, friction_deg=(0.0,))
        return [tube, Chain(name, "wall", points, side, friction_deg=(nan,) * (len(points) - 1))]

    chains = walls("wall", wall, 1)
    if not half:
        chains += walls("left_wall", tuple((float(x), float(z)) for x, z in left_wall), -1)
    for i, (outline, friction) in enumerate(inserts):
        outline = tuple((float(x), float(z)) for x, z in outline)
        points, closed = insert_chain_points(outline, half)
        n = len(points) - (0 if closed else 1)
        fr = nan if friction is None else float(friction)
        chains.append(Chain(f"insert_{i + 1}", "insert", points, -1, closed, (fr,) * n,
                            outline))
    return Boundary(section, tuple(chains), float(fill_level), (x_left, wall[0][0]), far)


# ------------------------------------------------------------------ compiled, one point
@njit(cache=True, error_model="numpy", inline="always")
def _wall_x_point(z, rows, x_below):
    """:func:`wall_x` of one height."""
    for k in range(rows.shape[0]):
        if z >= rows[k, 0] and z <= rows[k, 1]:
            return min(max(rows[k, 2] + (z - rows[k, 0]) * rows[k, 3], rows[k, 4]), rows[k, 5])
    return x_below


@njit(cache=True, error_model="numpy")
def in_solid_point(x, z, a, b, right, right_below, left, left_below, has_left, poly, start):
    """:meth:`Boundary.in_solid` of one point, with :meth:`Boundary.kernel_arrays`."""
    if x >= _wall_x_point(z, right, right_below):
        return True
    if has_left and x <= _wall_x_point(z, left, left_below):
        return True
    for m in range(start.shape[0] - 1):
        inside = False
        n = start[m + 1] - start[m]
        for i in range(n):
            j = i - 1 if i > 0 else n - 1
            xi, zi = poly[start[m] + i, 0], poly[start[m] + i, 1]
            xj, zj = poly[start[m] + j, 0], poly[start[m] + j, 1]
            if zi != zj and (zi > z) != (zj > z) and x < xi + (z - zi) * (xj - xi) / (zj - zi):
                inside = not inside
        if inside:
            return True
    return False


@njit(cache=True, error_model="numpy")
def nearest_point(x, z, a, b):
    """``(px, pz, row)``: the nearest point of one point on the segments ``a -> b`` (the
    first nearest, as :meth:`Boundary.nearest`)."""
    best = np.inf
    px = pz = 0.0
    row = 0
    for k in range(a.shape[0]):
        ab0, ab1 = b[k, 0] - a[k, 0], b[k, 1] - a[k, 1]
        t = ((x - a[k, 0]) * ab0 + (z - a[k, 1]) * ab1) / (ab0 * ab0 + ab1 * ab1)
        t = min(max(t, 0.0), 1.0)
        qx, qz = a[k, 0] + t * ab0, a[k, 1] + t * ab1
        d2 = (x - qx) ** 2 + (z - qz) ** 2
        if d2 < best:
            best, px, pz, row = d2, qx, qz, k
    return px, pz, row
