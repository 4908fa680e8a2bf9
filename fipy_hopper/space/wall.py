"""Wall loads of the 3D silo: where each contact entry and each cell next to the wall lies on
the wall, the wall's patches (height bins along the meridian times sectors around the
circumference), the pressure and shear on them from the wall's reaction and from the stresses,
and the vertical balance.  Everything here reads a model and its states; nothing changes them.

**Coordinates on the wall.**  The silo's wall is a set of bodies of revolution (the *parts* of
:class:`fipy_hopper.space.boundary.SiloBoundary`: one for a centred silo or an eccentric cone,
two for a flat floor with an off-centre outlet).  A wall point is described in the coordinates
of its own part, as the sections describe theirs:

* ``s`` (m), the arc length along the wall profile's meridian from the outlet's lip, as the
  centred section's wall chain measures it (:attr:`SpaceConfig.boundary`): the 2D wall bins'
  coordinate, so that a 3D profile and the section's compare bin by bin;
* ``theta`` (deg), the angle around the part's axis at that height, 0 towards ``+x`` (the
  outlet's offset), positive towards ``+y``: the angle around the silo's axis on a centred
  silo and on the bin wall of any silo; around the section's own centre ``(c(z), 0)`` in an
  eccentric cone (its horizontal sections are circles about that centre); around the outlet's
  centre on the floor of a flat-bottomed silo with an off-centre outlet, whose floor stretch is
  then carried on from the bin's radius to ``R + e`` (the floor's farthest point from the
  outlet; its patches are clipped to the bin).

The *stretches* are the profile's segments that the material can load (the free-fall tube
left out; up to the fill level, the segment through it cut there, as
:func:`fipy_hopper.diagnostics.wall_stretches`), each divided into the sections' equal bins of
about ``wall_bin_width`` (:func:`fipy_hopper.wall_traction.bin_edges`); around the
circumference ``wall_sectors`` sectors of ``360 / n`` deg centred on ``theta_k = 360 k / n``
(sector 0 faces the outlet's offset, sector ``n / 2`` the far wall).  A *patch* is a bin times
a sector; its wall area is ``int int r J ds dtheta`` (``J = sqrt(z'^2 + (r' + c' z' cos
theta)^2)``, 1 on a centred body of revolution; ``c' = dc/dz`` the shear of an eccentric cone),
by midpoint quadrature.

**The whole silo from its computed part.**  A quarter or a half of the silo is computed
between mirror planes; every entry and every cell has one image per mirror (``theta -> -theta``
across ``y = 0``, ``theta -> 180 - theta`` across ``x = 0``), and a node or a cell on a plane
carries the computed part's share, its image the rest.  The maps are of the whole silo: every
image is binned, with its normal and meridional components as they are and its hoop component
reversed (a reflection reverses the direction of increasing ``theta``).

**A rectangular plan's faces** (:class:`FaceStretch`, :func:`face_patches`,
:func:`locate_faces`): the same patches, recovery, images and maps with each plane face
(:mod:`fipy_hopper.space.rectangular`) a stretch: ``s`` up its slope (from the outlet's edge on
its side, carried on from a hopper's face to the bin's above it; the floor's along x), and
across its width, in place of ``theta``, the fraction ``u`` of its width (0 at the ``-y`` end of
an x face or the floor, the ``-x`` end of a y face), ``wall_sectors`` equal parts of it; the
recovery's splines across are clamped cubic B-splines on ``u``; a mirror image may move to the
facing face (:func:`image_maps`); the frame is the face's: ``n`` its normal, ``t`` up its
slope, ``h`` along its width (``tau_theta`` is then the shear along the width).

**Directions on the wall.**  At a wall point: ``n`` the unit normal into the wall (the
surface's, :meth:`Part.lift`), ``t`` the unit tangent up the meridian (``d X / ds``), ``h`` the
unit tangent around the circumference (``d X / d theta`` with its ``t`` part taken out, for a
sheared wall).  Pressure ``p_n = -F . n / A`` (compression positive), meridional shear ``tau =
F . t / A`` (the wall's shear on the material, positive up the wall, the sections' sign) and
hoop shear ``tau_theta = F . h / A``, from the wall's force ``F`` on the material.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..diagnostics import KNOT_CELLS
from ..wall_traction import bin_edges
from .boundary import INSERT



@dataclass(frozen=True)
class Meridian:
    """A straight stretch of the wall's meridian from ``start`` to ``end`` (``(r, z)`` about
    its part's axis, m), the profile's arc length ``s_start`` at ``start`` (m) and the
    profile's ``segment``; the solid on its right (a wall followed up from its lip)."""

    start: tuple
    end: tuple
    s_start: float
    segment: int

    @property
    def length(self) -> float:
        return float(math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1]))

    @property
    def s_end(self) -> float:
        return self.s_start + self.length

    @property
    def tangent(self) -> np.ndarray:
        """Unit tangent from ``start`` to ``end`` (up the wall)."""
        d = np.subtract(self.end, self.start, dtype=float)
        return d / np.hypot(*d)

    @property
    def normal(self) -> np.ndarray:
        """Unit normal into the wall: the tangent turned clockwise."""
        t = self.tangent
        return np.array([t[1], -t[0]])

    def point(self, s):
        """``(r, z)`` of the meridian's point at arc length ``s`` (m)."""
        u = np.asarray(s, float) - self.s_start
        t = self.tangent
        return self.start[0] + u * t[0], self.start[1] + u * t[1]


@dataclass(frozen=True)
class WallStretch3:
    """A stretch of the wall of revolution: its meridian's straight ``stretch``
    (:class:`Meridian`), the index of the ``part`` it belongs to and whether its patches are
    clipped to the bin's cylinder (the carried-on floor of a flat-bottomed silo with an
    off-centre outlet)."""

    stretch: Meridian
    part: int
    clip_radius: float = math.inf


def wall_stretches(boundary, fill_level: float) -> list:
    """The :class:`WallStretch3` s of a :class:`~fipy_hopper.space.boundary.SiloBoundary`
    (module docstring)."""
    wall = boundary.wall
    radius, e = boundary.radius, boundary.outlet_offset
    two_parts = len(boundary.parts) > 1
    s_at = np.concatenate([[0.0], np.cumsum([math.hypot(b[0] - a[0], b[1] - a[1])
                                             for a, b in zip(wall[:-1], wall[1:])])])
    out = []
    for k, (a, b) in enumerate(zip(wall[:-1], wall[1:])):
        a, b = np.asarray(a, float), np.asarray(b, float)
        if a[1] >= fill_level and k > 0:
            break
        if b[1] > fill_level > a[1]:
            b = a + (b - a) * (fill_level - a[1]) / (b[1] - a[1])
        part, clip = 0, math.inf
        if two_parts:
            if k == 0:                       # the floor, about the outlet's centre
                b = np.array([radius + e, b[1]])
                clip = radius
            else:
                part = 1
        out.append(WallStretch3(Meridian(tuple(a), tuple(b), float(s_at[k]), k), part, clip))
    return out


@dataclass(frozen=True)
class WallPatches:
    """The wall's patches (module docstring): ``n_bins`` height bins (flattened over the
    stretches, each stretch's from its lowest point) times ``n_sectors`` sectors.

    Per bin: ``stretch`` (index into ``stretches``), ``segment`` (the profile's), ``s``,
    ``lo``, ``hi`` (m of arc length), ``r``, ``z`` (its centre on the meridian about the
    part's axis, m).  Per sector: ``theta_deg`` (its centre).  Per patch ``(n_bins,
    n_sectors)``: ``area`` (m^2, whole silo), ``centre`` (3, ...) (m), ``normal``, ``tangent``,
    ``hoop`` (3, ...)."""

    stretches: tuple
    stretch: np.ndarray
    segment: np.ndarray
    s: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    r: np.ndarray
    z: np.ndarray
    theta_deg: np.ndarray
    area: np.ndarray
    centre: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    hoop: np.ndarray
    #: "revolved" (a circular silo: sectors around the circumference) or "faces" (a
    #: rectangular plan: each stretch a plane face, its sectors equal parts of its width;
    #: ``theta_deg`` then holds each sector's centre as a fraction of the width)
    kind: str = "revolved"

    @property
    def n_bins(self) -> int:
        return len(self.s)

    @property
    def names(self) -> tuple:
        """The wall of each stretch: ``"wall"`` on a circular silo, the face's name on a
        rectangular plan (``x_plus``, ``hopper_x_plus``, ``floor``, ...)."""
        return tuple(getattr(st3, "name", "wall") for st3 in self.stretches)

    def sector_of_across(self, across) -> np.ndarray:
        """The sector of wall points at ``across``: their angle (rad) around a circular
        silo's part, or their fraction of a face's width (0 to 1)."""
        if self.kind == "revolved":
            return self.sector_of(np.degrees(across))
        n = self.n_sectors
        return np.clip(np.floor(np.asarray(across, float) * n).astype(np.int64), 0, n - 1)

    @property
    def n_sectors(self) -> int:
        return len(self.theta_deg)

    @property
    def sector_width_deg(self) -> float:
        return 360.0 / self.n_sectors

    def sector_of(self, theta_deg) -> np.ndarray:
        """The sector of angles (deg)."""
        n = self.n_sectors
        return np.mod(np.rint(np.asarray(theta_deg, float) / (360.0 / n)).astype(np.int64), n)

    def bin_of(self, stretch, s) -> np.ndarray:
        """The bin of points at arc length ``s`` (m) on their ``stretch`` (index): the bin that
        holds it, or the stretch's nearest (a point above the fill level: its top bin)."""
        stretch = np.asarray(stretch, np.int64)
        s = np.asarray(s, float)
        out = np.zeros(stretch.shape, np.int64)
        for k in range(len(self.stretches)):
            on = stretch == k
            if not on.any():
                continue
            rows = np.flatnonzero(self.stretch == k)
            edges = np.concatenate([self.lo[rows], self.hi[rows[-1:]]])
            out[on] = rows[np.clip(np.searchsorted(edges, s[on], side="right") - 1, 0,
                                   len(rows) - 1)]
        return out


def _surface(boundary, st3: WallStretch3, s, theta):
    """Point ``(3, ...)``, normal, meridional tangent, hoop tangent and the area factor
    ``r J`` of the stretch's surface at arc lengths ``s`` and angles ``theta`` (rad)."""
    st = st3.stretch
    part = boundary.parts[st3.part]
    r, z = st.point(s)
    tr, tz = st.tangent
    nr, nz = st.normal
    cos, sin = np.cos(theta), np.sin(theta)
    c, slope = part.centre(z), part.slope(z)
    point = np.stack(np.broadcast_arrays(c + r * cos, r * sin, z))
    normal, _ = part.lift(nr, nz, cos, sin, z)
    d_s = np.stack(np.broadcast_arrays(slope * tz + tr * cos, tr * sin, tz + 0.0 * cos))
    tangent = d_s / np.sqrt((d_s * d_s).sum(axis=0))
    d_t = np.stack(np.broadcast_arrays(-r * sin, r * cos, 0.0 * cos))
    hoop = d_t - (d_t * tangent).sum(axis=0) * tangent
    hoop = hoop / np.where(np.sqrt((hoop * hoop).sum(axis=0)) > 0,
                           np.sqrt((hoop * hoop).sum(axis=0)), 1.0)
    factor = r * np.sqrt(tz ** 2 + (tr + slope * tz * cos) ** 2)
    return point, normal, tangent, hoop, factor


def _gauss_pieces(cuts, order=3):
    """Gauss-Legendre points and weights on the pieces between sorted ``cuts``: ``(x, w,
    piece)`` (flat)."""
    lo, hi = cuts[:-1], cuts[1:]
    keep = hi > lo
    lo, hi = lo[keep], hi[keep]
    g, gw = np.polynomial.legendre.leggauss(order)
    x = (0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * g[None, :]).ravel()
    w = (0.5 * (hi - lo)[:, None] * gw[None, :]).ravel()
    return x, w, np.repeat(np.arange(len(lo)), order)


def periodic_cubic(theta, n: int) -> np.ndarray:
    """The ``n`` (>= 4) uniform periodic cubic B-splines around the circle at angles
    ``theta`` (rad): ``(len(theta), n)``, spline ``l`` rising from ``2 pi l / n`` (a partition
    of unity, each spanning four of the ``n`` spans)."""
    u = np.mod(np.asarray(theta, float)[:, None] * (n / (2.0 * math.pi))
               - np.arange(n)[None, :], n)
    out = np.zeros_like(u)
    a = u < 1.0
    out[a] = u[a] ** 3 / 6.0
    b = (u >= 1.0) & (u < 2.0)
    out[b] = (-3.0 * u[b] ** 3 + 12.0 * u[b] ** 2 - 12.0 * u[b] + 4.0) / 6.0
    c = (u >= 2.0) & (u < 3.0)
    out[c] = (3.0 * u[c] ** 3 - 24.0 * u[c] ** 2 + 60.0 * u[c] - 44.0) / 6.0
    d = (u >= 3.0) & (u < 4.0)
    out[d] = (4.0 - u[d]) ** 3 / 6.0
    return out


@dataclass
class StretchMap:
    """The linear maps of one stretch (module docstring, *recovery*): quadrature points on
    the stretch's surface (``s_q``, ``theta_q`` tensor grids; ``weight`` (n_s, n_theta) the
    area element ``r J ds dtheta``, 0 outside a clipped floor), the bin and sector of each
    point, the spline's knots along ``s`` and ``n_theta`` periodic splines around, the basis
    values at the points and the basis areas ``A`` (n_s_basis, n_theta)."""

    st3: WallStretch3
    bins: np.ndarray
    knot_vector: np.ndarray
    n_theta: int
    s_q: np.ndarray
    theta_q: np.ndarray
    weight: np.ndarray
    bin_q: np.ndarray
    sector_q: np.ndarray
    basis_s: np.ndarray
    basis_t: np.ndarray
    basis_area: np.ndarray
    #: a face's clamped knots across its width (fractions 0 to 1; None: the periodic
    #: splines around a circumference)
    across_knots: np.ndarray = None

    def across(self, theta) -> np.ndarray:
        """The basis across the stretch at ``theta`` (``(n, n_theta)``): the periodic cubic
        splines around (rad), or a face's clamped cubic B-splines across its width
        (fractions)."""
        if self.across_knots is None:
            return periodic_cubic(theta, self.n_theta)
        from ..wall_traction import design
        return design(self.across_knots, theta).toarray()

    def coefficients(self, s, theta, force) -> np.ndarray:
        """Spline coefficients ``(n_s_basis, n_theta, 3)`` (Pa) of forces ``force`` (n, 3)
        (N) at wall points ``(s, theta)`` (0 for a basis function with no wall under it: the
        part of a carried-on floor beyond the bin)."""
        from ..wall_traction import design
        bs = design(self.knot_vector, s).toarray()                    # (n, ks)
        bt = self.across(theta)                                        # (n, kt)
        shares = np.einsum("ek,el,ec->klc", bs, bt, np.asarray(force, float))
        area = self.basis_area[..., None]
        return np.where(area > 0, shares / np.where(area > 0, area, 1.0), 0.0)

    def patch_integrals(self, coefficients) -> np.ndarray:
        """``int int t r J ds dtheta`` of the traction over every (local bin, sector):
        ``(len(bins), n_sectors, 3)`` (N)."""
        t = np.einsum("ik,klc,jl->ijc", self.basis_s, coefficients, self.basis_t)
        return self.patch_sums(self.weight[..., None] * t)

    def patch_sums(self, values) -> np.ndarray:
        """Sums of quadrature values ``(n_s, n_theta, ...)`` over each (local bin, sector)."""
        nb, ns = len(self.bins), int(self.sector_q.max()) + 1
        rest = values.shape[2:]
        out = np.zeros((nb, ns) + rest)
        by_bin = np.zeros((nb,) + values.shape[1:])
        np.add.at(by_bin, self.bin_q, values)
        np.add.at(out, (slice(None), self.sector_q), by_bin)
        return out


def wall_patches(boundary, fill_level: float, width: float, n_sectors: int,
                 knot_spacing: float | None = None) -> tuple:
    """The :class:`WallPatches` of a silo (module docstring) for bins of about ``width`` m
    and ``n_sectors`` sectors, and each stretch's :class:`StretchMap` with knots about
    ``knot_spacing`` (default ``width``; not closer than ``width``) apart along the meridian
    and around the circumference (at the stretch's mean radius; at least 4 splines around)."""
    from ..wall_traction import DEGREE, design, knots

    spacing = max(width, knot_spacing or 0.0)
    stretches = tuple(wall_stretches(boundary, fill_level))
    cols = {k: [] for k in ("stretch", "segment", "s", "lo", "hi", "r", "z")}
    maps = []
    width_rad = 2.0 * math.pi / n_sectors
    theta = np.arange(n_sectors) * width_rad
    first = 0
    for k, st3 in enumerate(stretches):
        st = st3.stretch
        edges = bin_edges(st, width)
        centres = 0.5 * (edges[1:] + edges[:-1])
        r, z = st.point(centres)
        n = len(centres)
        cols["stretch"].append(np.full(n, k))
        cols["segment"].append(np.full(n, st.segment))
        cols["s"].append(centres)
        cols["lo"].append(edges[:-1])
        cols["hi"].append(edges[1:])
        cols["r"].append(np.asarray(r, float))
        cols["z"].append(np.asarray(z, float))
        kv = knots(st, spacing)
        r_mid = float(st.point(0.5 * (st.s_start + st.s_end))[0])
        n_t = max(4, int(round(2.0 * math.pi * r_mid / spacing)))
        s_q, ws, piece = _gauss_pieces(np.unique(np.concatenate(
            [kv[DEGREE:len(kv) - DEGREE], edges])))
        bin_q = np.clip(np.searchsorted(edges, s_q, side="right") - 1, 0, n - 1)
        t_cuts = np.unique(np.concatenate([theta - 0.5 * width_rad, [2 * math.pi
                                                                      - 0.5 * width_rad],
                                           np.arange(n_t) * 2 * math.pi / n_t]))
        t_cuts = t_cuts[(t_cuts >= -0.5 * width_rad - 1e-12)
                        & (t_cuts <= 2 * math.pi - 0.5 * width_rad + 1e-12)]
        t_q, wt, _ = _gauss_pieces(t_cuts)
        sector_q = np.mod(np.rint(t_q / width_rad).astype(np.int64), n_sectors)
        S, T = np.meshgrid(s_q, t_q, indexing="ij")
        point, _, _, _, factor = _surface(boundary, st3, S, T)
        inside = np.hypot(point[0], point[1]) <= st3.clip_radius * (1.0 + 1e-12)
        weight = np.where(inside, factor, 0.0) * ws[:, None] * wt[None, :]
        basis_s = design(kv, s_q).toarray()
        basis_t = periodic_cubic(t_q, n_t)
        area = np.einsum("ik,ij,jl->kl", basis_s, weight, basis_t)
        maps.append(StretchMap(st3, first + np.arange(n), kv, n_t, s_q, t_q, weight, bin_q,
                               sector_q, basis_s, basis_t, area))
        first += n
    cols = {k: np.concatenate(v) for k, v in cols.items()}
    nb = len(cols["s"])
    area = np.zeros((nb, n_sectors))
    for sm in maps:
        area[sm.bins] = sm.patch_sums(sm.weight)
    centre, normal, tangent, hoop = (np.zeros((3, nb, n_sectors)) for _ in range(4))
    for b in range(nb):
        st3 = stretches[cols["stretch"][b]]
        S, T = np.full(n_sectors, cols["s"][b]), theta
        centre[:, b], normal[:, b], tangent[:, b], hoop[:, b], _ = _surface(boundary, st3, S, T)
    theta_deg = 360.0 * np.arange(n_sectors) / n_sectors        # exact: 30.0, not 29.99...
    patches = WallPatches(stretches, cols["stretch"], cols["segment"], cols["s"], cols["lo"],
                          cols["hi"], cols["r"], cols["z"], theta_deg, area, centre, normal,
                          tangent, hoop)
    return patches, tuple(maps)


def locate(boundary, stretches, x, y, z, segment=None):
    """Where points ``(x, y, z)`` (m) lie on the wall: ``(stretch, s, theta (rad), normal (3,
    n), tangent, hoop)`` of the wall point of each, on the stretch of its profile
    ``segment`` (when given and >= 0) or else of its nearest wall segment that is not a tube
    (the load row of :meth:`fipy_hopper.boundary.Boundary.load_row` in its nearest part);
    ``stretch`` -1 for a point whose segment has no stretch (the free-fall tube, a segment
    above the fill level is given the top stretch)."""
    x, y, z = (np.atleast_1d(np.asarray(a, float)) for a in (x, y, z))
    n = len(x)
    parts = boundary.parts
    if len(parts) == 1:
        part_of = np.zeros(n, np.int64)
    else:
        dist = np.stack([p.distance_normal(x, y, z)[0] for p in parts])
        part_of = np.argmin(dist, axis=0)
    seg = np.full(n, -1, np.int64) if segment is None else np.asarray(segment, np.int64).copy()
    need = seg < 0
    for pi, p in enumerate(parts):
        on = need & (part_of == pi)
        if on.any():
            rho, _, _ = p.local(x[on], y[on], z[on])
            rows = p.boundary.load_row(rho, z[on])
            seg[on] = np.asarray(p.segment)[rows]
    if segment is not None:                  # a tube's and the inserts' entries stay off
        seg[(np.asarray(segment) == -1) | (np.asarray(segment) <= INSERT)] = -1   # the wall
    by_segment = {st3.stretch.segment: k for k, st3 in enumerate(stretches)}
    top = len(stretches) - 1
    stretch = np.array([by_segment.get(int(k), top if k > stretches[top].stretch.segment
                                       else -1) if k >= 0 else -1 for k in seg], np.int64)
    s = np.zeros(n)
    theta = np.zeros(n)
    normal, tangent, hoop = np.zeros((3, n)), np.zeros((3, n)), np.zeros((3, n))
    for k, st3 in enumerate(stretches):
        on = stretch == k
        if not on.any():
            continue
        p = parts[st3.part]
        rho, ux, uy = p.local(x[on], y[on], z[on])
        st = st3.stretch
        a, tv = np.asarray(st.start), st.tangent
        u = np.clip((rho - a[0]) * tv[0] + (z[on] - a[1]) * tv[1], 0.0, st.length)
        s[on] = st.s_start + u
        theta[on] = np.arctan2(uy, ux)
        _, normal[:, on], tangent[:, on], hoop[:, on], _ = _surface(boundary, st3, s[on],
                                                                    theta[on])
    return stretch, s, theta, normal, tangent, hoop


def entry_inserts(boundary, x, y, z, segment) -> np.ndarray:
    """The insert (0-based; -1 none) whose surface each contact entry at ``(x, y, z)`` (m)
    holds: from its ``segment`` code (:func:`fipy_hopper.space.boundary.insert_code`), and for
    a convex corner's entry (-2) the insert of its nearest segment (the load row of
    :meth:`fipy_hopper.boundary.Boundary.load_row`) if that is an insert's."""
    segment = np.asarray(segment, np.int64)
    out = np.full(len(segment), -1, np.int64)
    if not getattr(boundary, "n_inserts", 0):
        return out
    out = np.where(segment <= INSERT, INSERT - segment, -1)
    corner = np.flatnonzero(segment == -2)
    if corner.size:
        p = boundary.parts[0]
        rho, _, _ = p.local(x[corner], y[corner], z[corner])
        code = np.asarray(p.segment)[p.boundary.load_row(rho, z[corner])]
        out[corner] = np.where(code <= INSERT, INSERT - code, -1)
    return out


def images(mirror_x: bool, mirror_y: bool) -> list:
    """The mirror images of the computed part: ``[(theta map, hoop sign, force signs (3,)),
    ...]``, the identity first; ``theta map`` takes and gives radians."""
    out = [(lambda t: t, 1.0, np.array([1.0, 1.0, 1.0]))]
    if mirror_y:
        out.append((lambda t: -t, -1.0, np.array([1.0, -1.0, 1.0])))
    if mirror_x:
        out.append((lambda t: math.pi - t, -1.0, np.array([-1.0, 1.0, 1.0])))
    if mirror_x and mirror_y:
        out.append((lambda t: t + math.pi, 1.0, np.array([-1.0, -1.0, 1.0])))
    return out


def image_maps(patches, mirror_x: bool, mirror_y: bool) -> list:
    """The mirror images of the computed part as maps of wall points, in the order of
    :func:`images`: ``[f(stretch, s, across) -> (stretch, s, across, t_sign, h_sign), ...]``
    (the image's stretch, arc length and across-coordinate, and the signs of its meridional
    and hoop components).  Around a circular silo an image keeps its stretch and ``s``, maps
    its angle and reverses the hoop (:func:`images`); on a rectangular plan it may move to the
    facing face (``x_plus`` and ``x_minus`` across ``x = 0``, ``y_plus`` and ``y_minus``
    across ``y = 0``), its fraction of the width reversed where the reflection reverses the
    face's width (the hoop reversed with it), and the floor's ``s`` (along x) reversed across
    ``x = 0`` (its meridional component with it)."""
    if patches.kind == "revolved":
        return [(lambda tmap, hsign: (lambda st, s, a: (st, s, tmap(a), 1.0, hsign)))(tmap, hsign)
                for tmap, hsign, _ in images(mirror_x, mirror_y)]
    specs = [(1.0, 1.0)]
    if mirror_y:
        specs.append((1.0, -1.0))
    if mirror_x:
        specs.append((-1.0, 1.0))
    if mirror_x and mirror_y:
        specs.append((-1.0, -1.0))
    names = list(patches.names)
    out = []
    for rx, ry in specs:
        perm, flip, sflip, total = [], [], [], []
        for st3 in patches.stretches:
            name = st3.name
            if rx < 0:
                name = name.replace("x_plus", "@").replace("x_minus", "x_plus").replace(
                    "@", "x_minus")
            if ry < 0:
                name = name.replace("y_plus", "@").replace("y_minus", "y_plus").replace(
                    "@", "y_minus")
            perm.append(names.index(name))
            across_y = st3.axis in (0, 2)          # x faces and the floor: across y
            flip.append((ry < 0) if across_y else (rx < 0))
            sflip.append(st3.axis == 2 and rx < 0)
            total.append(st3.stretch.s_start + st3.stretch.s_end)
        perm, flip, sflip, total = (np.append(np.asarray(a), d) for a, d in
                                    ((perm, -1), (flip, False), (sflip, False), (total, 0.0)))

        def image(st, s, a, perm=perm, flip=flip, sflip=sflip, total=total):
            st = np.asarray(st, np.int64)
            f, sf = flip[st], sflip[st]
            return (perm[st], np.where(sf, total[st] - s, s), np.where(f, 1.0 - a, a),
                    np.where(sf, -1.0, 1.0), np.where(f, -1.0, 1.0))
        out.append(image)
    return out


# ---------------------------------------------------------------- a rectangular plan's faces
@dataclass(frozen=True)
class FaceStretch:
    """A plane face of a rectangular plan as a stretch of the wall loads: its meridian
    ``stretch`` (:class:`Meridian`: up the face's slope in ``(r, z)``, ``r`` the coordinate
    along the face's outward axis; the floor's along ``x`` at ``z = 0``), the ``face``'s
    index in :attr:`fipy_hopper.space.rectangular.RectangularSilo.faces`, its ``name``, its
    outward ``axis`` (0 x, 1 y; 2 the floor) and ``side`` (+1, -1)."""

    stretch: Meridian
    face: int
    name: str
    axis: int
    side: float
    part: int = -1
    clip_radius: float = math.inf


def face_stretches(boundary, fill_level: float) -> list:
    """The :class:`FaceStretch` es of a rectangular plan (the faces the material loads, up to
    the fill level): the floor (along x from its ``-x`` edge), the hopper's faces (from the
    foot's edge up their slope), the bin's faces (up from their foot; ``s`` carried on from
    the hopper's face below, or on a flat floor from the outlet's edge on that side, as the
    circular silo's meridian from the lip)."""
    H = boundary.hopper_height
    x0, x1, y0, y1 = boundary.foot
    ex, ey = boundary.outlet_offset
    half = boundary.half_extent
    edge = {(0, 1.0): x1, (0, -1.0): -x0, (1, 1.0): y1, (1, -1.0): -y0}
    if H <= 0.0:              # the outlet's edge on each side
        ox, oy = 0.5 * boundary.outlet_x, 0.5 * boundary.outlet_y
        edge = {(0, 1.0): ex + ox, (0, -1.0): -ex + ox, (1, 1.0): ey + oy,
                (1, -1.0): -ey + oy}
    out = []
    slant = {}
    for k in boundary.load_faces:
        face = boundary.faces[k]
        if face.kind == "floor":
            out.append(FaceStretch(Meridian((x0, 0.0), (x1, 0.0), 0.0, face.segment), k,
                                   face.name, 2, 1.0))
            continue
        key = (face.axis, face.side)
        r_top = half[face.axis]
        if face.kind == "hopper":
            a, b = np.array([edge[key], 0.0]), np.array([r_top, H])
            if fill_level < H:
                b = a + (b - a) * fill_level / H
            st = Meridian(tuple(a), tuple(b), 0.0, face.segment)
            slant[key] = st.s_end
        else:
            if fill_level <= H:
                continue
            start = slant.get(key, r_top - edge[key])
            st = Meridian((r_top, H), (r_top, min(fill_level, boundary.top)), float(start),
                          face.segment)
        out.append(FaceStretch(st, k, face.name, face.axis, face.side))
    return out


def _face_width(boundary, fs: FaceStretch, z) -> tuple:
    """``(lo, hi)`` of a face's across-coordinate (y for the x faces and the floor, x for the
    y faces) at heights ``z`` (m)."""
    if fs.axis == 2:
        _, _, y0, y1 = boundary.foot
        return np.full(np.shape(z), y0), np.full(np.shape(z), y1)
    x0, x1, y0, y1 = boundary.section(z)
    return (y0, y1) if fs.axis == 0 else (x0, x1)


def _face_surface(boundary, fs: FaceStretch, s, f):
    """Point ``(3, ...)``, normal, meridional tangent, hoop tangent (the horizontal along the
    face's width: ``+y`` on the x faces and the floor, ``+x`` on the y faces) and the area
    factor (the face's width there) at arc lengths ``s`` and width fractions ``f``."""
    st = fs.stretch
    r, z = st.point(s)
    r, z, f = np.broadcast_arrays(np.asarray(r, float), np.asarray(z, float),
                                  np.asarray(f, float))
    lo, hi = _face_width(boundary, fs, z)
    u = lo + f * (hi - lo)
    face = boundary.faces[fs.face]
    shape = (3,) + (1,) * r.ndim
    if fs.axis == 2:
        point = np.stack([r, u, z])
        tangent = np.array([1.0, 0.0, 0.0])
        hoop = np.array([0.0, 1.0, 0.0])
    else:
        a = fs.axis
        out = fs.side * r
        point = np.stack([out, u, z] if a == 0 else [u, out, z])
        tr, tz = st.tangent
        tangent = np.zeros(3)
        tangent[a], tangent[2] = fs.side * tr, tz
        hoop = np.eye(3)[1 - a]
    n = np.broadcast_to(face.normal.reshape(shape), point.shape)
    return (point, n, np.broadcast_to(tangent.reshape(shape), point.shape),
            np.broadcast_to(hoop.reshape(shape), point.shape), hi - lo)


def face_patches(boundary, fill_level: float, width: float, n_sectors: int,
                 knot_spacing: float | None = None) -> tuple:
    """The :class:`WallPatches` (``kind = "faces"``) of a rectangular plan and each face's
    :class:`StretchMap`: per face its bins of about ``width`` m up its slope (the floor's
    along x) times ``n_sectors`` equal parts of its width; areas by Gauss quadrature of the
    width along ``s`` (the floor's outlet left out); the recovery's clamped cubic splines
    along ``s`` and across the width, knots about ``knot_spacing`` (not closer than
    ``width``) apart (across: at the face's mean width)."""
    from ..wall_traction import DEGREE, design, knots

    spacing = max(width, knot_spacing or 0.0)
    stretches = tuple(face_stretches(boundary, fill_level))
    cols = {k: [] for k in ("stretch", "segment", "s", "lo", "hi", "r", "z")}
    maps = []
    f_edges = np.linspace(0.0, 1.0, n_sectors + 1)
    f_centre = 0.5 * (f_edges[1:] + f_edges[:-1])
    first = 0
    for k, fs in enumerate(stretches):
        st = fs.stretch
        edges = bin_edges(st, width)
        centres = 0.5 * (edges[1:] + edges[:-1])
        r, z = st.point(centres)
        n = len(centres)
        cols["stretch"].append(np.full(n, k))
        cols["segment"].append(np.full(n, st.segment))
        cols["s"].append(centres)
        cols["lo"].append(edges[:-1])
        cols["hi"].append(edges[1:])
        cols["r"].append(np.asarray(r, float))
        cols["z"].append(np.asarray(z, float))
        kv = knots(st, spacing)
        z_mid = float(st.point(0.5 * (st.s_start + st.s_end))[1])
        lo_m, hi_m = _face_width(boundary, fs, np.array(z_mid))
        n_f = max(1, int(round(float(hi_m - lo_m) / spacing)))
        inner = np.linspace(0.0, 1.0, n_f + 1)
        kf = np.concatenate([[0.0] * DEGREE, inner, [1.0] * DEGREE])
        s_q, ws, _ = _gauss_pieces(np.unique(np.concatenate(
            [kv[DEGREE:len(kv) - DEGREE], edges])))
        f_q, wf, _ = _gauss_pieces(np.unique(np.concatenate([inner, f_edges])))
        bin_q = np.clip(np.searchsorted(edges, s_q, side="right") - 1, 0, n - 1)
        sector_q = np.clip(np.searchsorted(f_edges, f_q, side="right") - 1, 0, n_sectors - 1)
        S, F = np.meshgrid(s_q, f_q, indexing="ij")
        point, _, _, _, factor = _face_surface(boundary, fs, S, F)
        open_ = boundary.faces[fs.face].outside_hole(point)
        weight = np.where(open_, factor, 0.0) * ws[:, None] * wf[None, :]
        basis_s = design(kv, s_q).toarray()
        basis_t = design(kf, f_q).toarray()
        area = np.einsum("ik,ij,jl->kl", basis_s, weight, basis_t)
        maps.append(StretchMap(fs, first + np.arange(n), kv, basis_t.shape[1], s_q, f_q, weight,
                               bin_q, sector_q, basis_s, basis_t, area, kf))
        first += n
    cols = {k: np.concatenate(v) for k, v in cols.items()}
    nb = len(cols["s"])
    area = np.zeros((nb, n_sectors))
    for sm in maps:
        area[sm.bins] = sm.patch_sums(sm.weight)
    centre, normal, tangent, hoop = (np.zeros((3, nb, n_sectors)) for _ in range(4))
    for b in range(nb):
        fs = stretches[cols["stretch"][b]]
        S = np.full(n_sectors, cols["s"][b])
        centre[:, b], normal[:, b], tangent[:, b], hoop[:, b], _ = _face_surface(
            boundary, fs, S, f_centre)
    patches = WallPatches(stretches, cols["stretch"], cols["segment"], cols["s"], cols["lo"],
                          cols["hi"], cols["r"], cols["z"], f_centre, area, centre, normal,
                          tangent, hoop, kind="faces")
    return patches, tuple(maps)


def locate_faces(boundary, stretches, x, y, z, face=None):
    """Where points ``(x, y, z)`` (m) lie on a rectangular plan's faces: ``(stretch, s, f,
    normal (3, n), tangent, hoop)``, ``f`` the fraction of the face's width (0 at its ``-y``
    end on the x faces and the floor, its ``-x`` end on the y faces).  A point's face is its
    entry's ``face`` (when given and a loaded face), else its nearest loaded face (a convex
    edge's entries, the cells next to the wall; of faces as near within 1e-9 m the first in
    :attr:`~fipy_hopper.space.rectangular.RectangularSilo.load_faces`' order, which a mirror
    image keeps); ``stretch`` -1 for the tube's entries and a
    face with no stretch (above the fill level)."""
    x, y, z = (np.atleast_1d(np.asarray(a, float)) for a in (x, y, z))
    n = len(x)
    p = np.stack([x, y, z])
    by_face = {fs.face: k for k, fs in enumerate(stretches)}
    loaded = boundary.load_faces
    if face is None:
        face = np.full(n, -2, np.int64)
    face = np.asarray(face, np.int64).copy()
    need = face == -2
    if need.any():
        best = np.full(int(need.sum()), np.inf)
        pick = np.full(int(need.sum()), -1, np.int64)
        for k in loaded:             # ties (within 1e-9 m) go to the first face, so that a
            d = boundary.faces[k].nearest(p[:, need])[0]     # mirror image goes to the image
            closer = d < best - 1e-9
            best = np.where(closer, d, best)
            pick = np.where(closer, k, pick)
        face[need] = pick
    stretch = np.array([by_face.get(int(k), -1) for k in face], np.int64)
    s, f = np.zeros(n), np.zeros(n)
    normal, tangent, hoop = np.zeros((3, n)), np.zeros((3, n)), np.zeros((3, n))
    for k, fs in enumerate(stretches):
        on = stretch == k
        if not on.any():
            continue
        st = fs.stretch
        a, tv = np.asarray(st.start), st.tangent
        r = x[on] if fs.axis == 2 else fs.side * p[fs.axis, on]
        u = np.clip((r - a[0]) * tv[0] + (z[on] - a[1]) * tv[1], 0.0, st.length)
        s[on] = st.s_start + u
        _, zq = st.point(s[on])
        lo, hi = _face_width(boundary, fs, np.asarray(zq, float))
        across = y[on] if fs.axis in (0, 2) else x[on]
        f[on] = np.clip((across - lo) / (hi - lo), 0.0, 1.0)
        _, normal[:, on], tangent[:, on], hoop[:, on], _ = _face_surface(boundary, fs, s[on],
                                                                          f[on])
    return stretch, s, f, normal, tangent, hoop


class SpaceWallLoads:
    """The wall loads of a :class:`~fipy_hopper.space.model.SpaceModel`: its contact entries
    and the cells next to its wall located on the wall's :class:`WallPatches`, the maps of the
    pressure and shear over a window between two :meth:`reading` s from the wall's reaction
    (recovered, :meth:`maps`, and plainly binned, :meth:`raw_maps`), the stress-sampled maps
    (the cells 0.5 to 2.5 cells from the wall) and the vertical balance.  The interface of
    :class:`fipy_hopper.diagnostics.WallLoads` where it has a 3D meaning.

    **Recovery** (the sections' :mod:`fipy_hopper.wall_traction` on a surface): on each
    stretch the traction is a tensor spline ``t(s, theta) = sum_kl t_kl B_k(s) P_l(theta)``,
    ``B_k`` the sections' clamped cubic B-splines along the meridian (knots about
    ``max(bin width, KNOT_CELLS h)`` apart), ``P_l`` uniform periodic cubic B-splines around
    the circumference (as many as fit that spacing at the stretch's mean radius, at least 4);
    each entry's force (every image) is shared by the basis values at its wall point,
    ``t_kl = sum_e B_k(s_e) P_l(theta_e) f_e / A_kl``, ``A_kl = int int B_k P_l r J ds
    dtheta``, so the traction carries the stretch's reaction exactly (each component), and a
    patch's value is its mean traction over its area.  The cut cells' pattern, which repeats
    around the circumference as along the meridian, is averaged over the spline's support (four
    knot spans) in both directions."""

    def __init__(self, model):
        self.model = model
        cfg, g = model.cfg, model.grid
        self.faces = model.boundary.plan == "rectangular"
        self.patches, self.stretch_maps = (face_patches if self.faces else wall_patches)(
            model.boundary, cfg.hopper.fill_level, cfg.wall_bin_width_at(g.h),
            cfg.wall_sectors, KNOT_CELLS * g.h)
        P = self.patches
        nodes, ptr, _, _, kind, entry, segment = model.contacts[:7]
        node_of = np.repeat(np.arange(len(nodes)), np.diff(ptr))
        wall = kind == 0
        where = np.empty((model.n_wall, 3), np.int64)
        where[entry[wall]] = nodes[node_of[wall]]
        x, y, z = g.x_nodes[where[:, 2]], g.y_nodes[where[:, 1]], g.z_nodes[where[:, 0]]
        #: each wall entry's node ``(k, j, i)`` and its position ``(3, n)`` (m)
        self.entry_node = where
        self.entry_xyz = np.stack([x, y, z])
        if self.faces:
            #: the face of each wall entry (a rectangular plan's, -2 a convex edge's)
            self.entry_face = np.asarray(model.contacts[8], np.int64)
            where = locate_faces(model.boundary, P.stretches, x, y, z, self.entry_face)
        else:
            where = locate(model.boundary, P.stretches, x, y, z, segment)
        (self.entry_stretch, self.entry_s, self.entry_theta, self.entry_normal,
         self.entry_tangent, self.entry_hoop) = where
        #: the insert whose surface each wall entry holds (0-based; -1 none)
        self.entry_insert = (np.full(len(x), -1, np.int64) if self.faces else
                             entry_inserts(model.boundary, x, y, z, segment))
        segment_of = np.array([st.stretch.segment for st in P.stretches] + [-1])
        #: the profile segment whose load each entry is (-1: the tube's, not a load)
        self.entry_segment = segment_of[self.entry_stretch]
        self.images = images(g.mirror_x, g.mirror_y)
        self.image_maps = image_maps(P, g.mirror_x, g.mirror_y)
        on = np.flatnonzero(self.entry_stretch >= 0)
        self._on = on
        #: per image, the entries' ``(stretch, s, across, t_sign, h_sign)`` on the wall
        self._image = [m(self.entry_stretch[on], self.entry_s[on], self.entry_theta[on])
                       for m in self.image_maps]
        self._bin_sector = [(P.bin_of(st, s), P.sector_of_across(a), hsign, tsign, st)
                            for st, s, a, tsign, hsign in self._image]
        self._band = None

    # ------------------------------------------------------------------ readings
    @staticmethod
    def reading(model, state) -> dict:
        """The cumulative measurements of ``state`` now (copies): the impulses, the momentum
        budget, the vertical momentum (computed part) and the time."""
        return {"t": state.t, "wall": state.wall_impulse.copy(),
                "plate": state.plate_impulse.copy(), "budget": state.momentum_budget.copy(),
                "momentum": model.vertical_momentum(state)}

    def entry_forces(self, start: dict, end: dict) -> np.ndarray:
        """Each wall entry's mean force on the material over the window in its wall point's
        frame, ``(f_n, f_t, f_h)`` (n_entries, 3) (N, computed part: ``f_n = -F . n``)."""
        duration = end["t"] - start["t"]
        if not duration > 0:
            raise ValueError("a wall-load window needs a positive duration")
        force = (end["wall"] - start["wall"]) / duration
        return np.stack([-np.einsum("ec,ce->e", force, self.entry_normal),
                         np.einsum("ec,ce->e", force, self.entry_tangent),
                         np.einsum("ec,ce->e", force, self.entry_hoop)], axis=1)

    def patch_sums(self, values) -> np.ndarray:
        """``values`` (n_entries, 3) as ``(f_n, f_t, f_h)`` summed over every image in each
        patch: (n_bins, n_sectors, 3), the hoop part of a reflected image reversed."""
        P = self.patches
        out = np.zeros((P.n_bins, P.n_sectors, 3))
        v = np.asarray(values, float)[self._on]
        for bins, sectors, hsign, tsign, _ in self._bin_sector:
            flat = bins * P.n_sectors + sectors
            for c, sign in ((0, 1.0), (1, tsign), (2, hsign)):
                out[..., c] += np.bincount(flat, sign * v[:, c],
                                           P.n_bins * P.n_sectors).reshape(P.n_bins, -1)
        return out

    def raw_maps(self, start: dict, end: dict) -> tuple:
        """``(p_n, tau, tau_theta)`` (n_bins, n_sectors) over a window by plain binning (Pa):
        each patch's entries' forces (every image) over its area, for checking the
        recovery."""
        sums = self.patch_sums(self.entry_forces(start, end))
        area = np.where(self.patches.area > 0, self.patches.area, np.nan)
        return sums[..., 0] / area, sums[..., 1] / area, sums[..., 2] / area

    def recovered_sums(self, forces) -> np.ndarray:
        """The recovered traction's integral over every patch (N, (n_bins, n_sectors, 3)) of
        the entries' ``forces`` ``(f_n, f_t, f_h)`` (n_entries, 3)."""
        P = self.patches
        f = np.asarray(forces, float)[self._on]
        out = np.zeros((P.n_bins, P.n_sectors, 3))
        for k, sm in enumerate(self.stretch_maps):
            ss, tt, ff = [], [], []
            for st, s, theta, tsign, hsign in self._image:
                on = st == k
                ss.append(s[on])
                tt.append(theta[on])
                ff.append(f[on] * _signs(tsign, hsign, on))
            coefficients = sm.coefficients(np.concatenate(ss), np.concatenate(tt),
                                           np.concatenate(ff))
            out[sm.bins] = sm.patch_integrals(coefficients)
        return out

    def maps(self, start: dict, end: dict) -> tuple:
        """``(p_n, tau, tau_theta)`` (n_bins, n_sectors) over a window (Pa): the recovered
        traction's mean over each patch (class docstring)."""
        sums = self.recovered_sums(self.entry_forces(start, end))
        area = np.where(self.patches.area > 0, self.patches.area, np.nan)
        return sums[..., 0] / area, sums[..., 1] / area, sums[..., 2] / area

    def height_profile(self, start: dict, end: dict, raw: bool = False) -> tuple:
        """``(p_n, tau)`` (n_bins,) around the whole circumference over a window (Pa): each
        bin's recovered traction (``raw``: its entries' forces) over its area, the sections'
        profile (:meth:`~fipy_hopper.diagnostics.WallLoads.profile`, ``raw_profile``) of the
        same bins."""
        forces = self.entry_forces(start, end)
        sums = (self.patch_sums(forces) if raw else self.recovered_sums(forces)).sum(axis=1)
        area = self.patches.area.sum(axis=1)
        area = np.where(area > 0, area, np.nan)
        return sums[:, 0] / area, sums[:, 1] / area

    # ------------------------------------------------------------------ stresses
    def _wall_band(self):
        """The cells whose centres lie 0.5 to 2.5 cells inside the material from a wall that
        is not a tube, their wall point on a stretch: ``(cells (flat), stretch, s, theta,
        normal, tangent, hoop)`` (cached)."""
        if self._band is None:
            g, m = self.model.grid, self.model
            Z, Y, X = np.meshgrid(g.centres(2), g.centres(1), g.centres(0), indexing="ij")
            d, _ = m.boundary.distance_normal(X, Y, Z)
            band = (d >= 0.5 * g.h) & (d <= 2.5 * g.h) & (g.kappa > 0) & (Z > 0.0) & (
                Z < m.cfg.hopper.fill_level)
            cells = np.flatnonzero(band.ravel())
            where = (locate_faces if self.faces else locate)(
                m.boundary, self.patches.stretches, X.ravel()[cells], Y.ravel()[cells],
                Z.ravel()[cells])
            keep = where[0] >= 0
            self._band = (cells[keep],) + tuple(w[..., keep] for w in where)
        return self._band

    def stress_maps(self, state) -> tuple:
        """``(p_n, tau, tau_theta)`` (n_bins, n_sectors) from the stresses of the cells next to
        the wall (Pa): each cell's traction on its wall point's frame, ``p_n = -n.sigma.n``,
        ``tau = t.sigma.n``, ``tau_theta = h.sigma.n`` (``h`` reversed on reflected images),
        averaged over the patch's cells (every image) weighted by ``alpha kappa V`` where
        ``alpha > 1/2``; NaN where a patch holds no material."""
        from ..material.principal3d import to_matrix
        cells, stretch, s, theta, n, t, hv = self._wall_band()
        sig = to_matrix(state.sigma.reshape(-1, 6)[cells])        # (m, 3, 3)
        trac = np.einsum("mij,jm->im", sig, n)
        vals = np.stack([-(trac * n).sum(axis=0), (trac * t).sum(axis=0),
                         (trac * hv).sum(axis=0)], axis=1)
        mean = self._patch_means(state, vals, "nth")
        return mean[..., 0], mean[..., 1], mean[..., 2]

    def vertical_stress_map(self, state) -> np.ndarray:
        """The mean vertical stress ``sigma_zz`` (Pa, tension positive) of the cells next to
        the wall of each patch (n_bins, n_sectors), weighted as :meth:`stress_maps`; NaN where
        a patch holds no material."""
        cells = self._wall_band()[0]
        return self._patch_means(state, state.sigma.reshape(-1, 6)[cells, 2:3], "n")[..., 0]

    def _patch_means(self, state, vals, kinds) -> np.ndarray:
        """The weighted means per patch (n_bins, n_sectors, k) of the band cells' values
        ``vals`` (m, k), over every image (``kinds``: each column a normal or scalar ``"n"``,
        meridional ``"t"`` or hoop ``"h"`` component, signed as the image's), weights ``alpha
        kappa V`` where ``alpha > 1/2``; NaN where there is none."""
        cells, stretch, s, theta = self._wall_band()[:4]
        P = self.patches
        alpha = state.alpha.ravel()[cells]
        w = np.where(alpha > 0.5, (state.alpha * self.model.open_volume).ravel()[cells], 0.0)
        k = vals.shape[1]
        total = np.zeros((P.n_bins, P.n_sectors, k))
        weight = np.zeros(P.n_bins * P.n_sectors)
        for image in self.image_maps:
            st, si, across, tsign, hsign = image(stretch, s, theta)
            flat = P.bin_of(st, si) * P.n_sectors + P.sector_of_across(across)
            weight += np.bincount(flat, w, len(weight))
            for c in range(k):
                sign = {"n": 1.0, "t": tsign, "h": hsign}[kinds[c]]
                total[..., c] += np.bincount(flat, sign * w * vals[:, c],
                                             len(weight)).reshape(P.n_bins, -1)
        weight = weight.reshape(P.n_bins, -1)
        return np.where(weight[..., None] > 0,
                        total / np.where(weight > 0, weight, 1.0)[..., None], np.nan)

    # ------------------------------------------------------------------ balances
    def balance(self, start: dict, end: dict) -> dict:
        """The vertical momentum balance over a window as mean forces (N, whole silo, upward
        positive), the sections' :meth:`~fipy_hopper.diagnostics.WallLoads.balance`:
        ``weight``, ``wall``, ``outlet`` (the plate), ``damping``, ``stopped``, ``outflow``,
        ``momentum_rate`` and the ``residual`` of ``dP/dt = wall + outlet + damping + stopped
        + outflow - weight`` (``relative_residual``: over the weight); each insert's push up
        on the material (``insert_1``, ...: its share of ``wall``)."""
        duration = end["t"] - start["t"]
        if not duration > 0:
            raise ValueError("a load window needs a positive duration")
        to_n = self.model.section_factor / duration
        budget = (end["budget"] - start["budget"]) * to_n
        out = {"weight": -budget[0],
               "wall": float(np.sum(end["wall"][:, 2] - start["wall"][:, 2])) * to_n,
               "outlet": float(np.sum(end["plate"][:, 2] - start["plate"][:, 2])) * to_n,
               "damping": budget[1], "stopped": budget[2], "outflow": budget[3],
               "momentum_rate": (end["momentum"] - start["momentum"]) * to_n}
        out["residual"] = (out["wall"] + out["outlet"] + out["damping"] + out["stopped"]
                           + out["outflow"] - out["weight"] - out["momentum_rate"])
        for i, f in self.insert_forces(start, end).items():   # the inserts' share of "wall"
            out[f"insert_{i + 1}"] = f[2]
        out["relative_residual"] = (abs(out["residual"]) / out["weight"]
                                    if out["weight"] > 0 else math.nan)
        return out

    def segment_forces(self, start: dict, end: dict) -> dict:
        """The mean force of each wall segment of the profile on the material over a window,
        ``{segment: (F_x, F_y, F_z)}`` (N, whole silo: every image; the tube's and the
        inserts' left out)."""
        return self._grouped_forces(self.entry_segment, start, end)

    def insert_forces(self, start: dict, end: dict) -> dict:
        """The mean force of each insert on the material over a window, ``{insert: (F_x,
        F_y, F_z)}`` (N, whole silo; insert 0-based; ``F_z`` its push up on the material,
        the load on it)."""
        return self._grouped_forces(self.entry_insert, start, end)

    def _grouped_forces(self, label, start: dict, end: dict) -> dict:
        """``{label: (F_x, F_y, F_z)}``: the summed mean force of the entries of each label
        ``>= 0`` over a window, every mirror image added (N, whole silo)."""
        duration = end["t"] - start["t"]
        force = (end["wall"] - start["wall"]) / duration
        out = {}
        for k in sorted(set(int(v) for v in label[label >= 0])):
            on = label == k
            total = np.zeros(3)
            for _, _, sign in self.images:
                total += sign * force[on].sum(axis=0)
            out[k] = tuple(float(v) for v in total)
        return out


def _signs(tsign, hsign, on) -> np.ndarray:
    """The component signs ``(1, t_sign, h_sign)`` of an image's entries ``on``: ``(3,)``
    for scalar signs, else ``(m, 3)``."""
    if np.ndim(tsign) == 0 and np.ndim(hsign) == 0:
        return np.array([1.0, tsign, hsign])
    t = np.broadcast_to(tsign, on.shape)[on]
    h = np.broadcast_to(hsign, on.shape)[on]
    return np.stack([np.ones(len(t)), t, h], axis=1)


def circumference_extremes(p) -> tuple:
    """``(largest, smallest, ratio)`` (n_bins,) of a map ``p`` (n_bins, n_sectors) around the
    circumference at each height bin (NaN where a bin has no finite sector; the ratio NaN
    where the smallest is not positive)."""
    p = np.asarray(p, float)
    finite = np.isfinite(p).any(axis=1)
    big = np.full(len(p), np.nan)
    small = np.full(len(p), np.nan)
    big[finite] = np.nanmax(p[finite], axis=1)
    small[finite] = np.nanmin(p[finite], axis=1)
    ratio = np.where(small > 0, big / np.where(small > 0, small, 1.0), np.nan)
    return big, small, ratio


@dataclass(frozen=True)
class _PatchNames:
    """The loop's ``sampler.bins.wall``: the wall each patch is on (all ``"wall"``)."""

    wall: np.ndarray


class PatchLoads:
    """The 3D wall loads as the shared loop (:class:`fipy_hopper.simulation.Simulation`) reads
    a model's (:class:`fipy_hopper.protocol.WallLoadsProtocol`), in both of its roles, the
    stress-sampled profile and the loads from the wall's reaction: the model's
    :class:`SpaceWallLoads` with each patch (height bin times sector, bin-major) as one of the
    loop's bins.  ``centres`` (the bins' ``s``), ``r``, ``z``, ``theta`` (deg, the sector's
    centre) and ``segment`` (the profile's) per patch.  What a shell of revolution has and a
    3D map has not (membrane forces, the corners' forces) is NaN or empty."""

    def __init__(self, model):
        self.model = model
        self.space = W = model.wall_loads
        P = self.patches = W.patches
        ns = P.n_sectors
        self.centres = np.repeat(P.s, ns)
        self.r = np.repeat(P.r, ns)
        self.z = np.repeat(P.z, ns)
        self.theta = np.tile(P.theta_deg, P.n_bins)
        self.segment = np.repeat(P.segment, ns)
        names = np.asarray(P.names, dtype=object)[P.stretch] if P.kind == "faces" else \
            np.full(P.n_bins, "wall", dtype=object)
        self.bins = _PatchNames(np.repeat(names, ns).astype(str))
        self.sampler = self

    # -------------------------------------------------------------- the loop's interface
    reading = staticmethod(SpaceWallLoads.reading)

    def balance(self, start: dict, end: dict) -> dict:
        return self.space.balance(start, end)

    def profile(self, start: dict, end: dict) -> tuple:
        """``(s, r, z, p_n, tau, tau_theta)`` per patch over a window: the recovered
        traction's means (:meth:`SpaceWallLoads.maps`)."""
        p, tau, hoop = self.space.maps(start, end)
        return self.centres, self.r, self.z, p.ravel(), tau.ravel(), hoop.ravel()

    def raw_profile(self, start: dict, end: dict) -> tuple:
        p, tau, _ = self.space.raw_maps(start, end)
        return self.centres, self.r, self.z, p.ravel(), tau.ravel()

    def profile_all(self, state) -> tuple:
        """``(s, r, z, p_n, tau)`` per patch from the stresses next to the wall."""
        p, tau, _ = self.space.stress_maps(state)
        return self.centres, self.r, self.z, p.ravel(), tau.ravel()

    def membrane_forces(self, start: dict, end: dict, p_n, tau=None) -> tuple:
        nan = np.full(len(self.centres), np.nan)
        return nan, nan.copy(), np.full(2, np.nan)

    def hoop_force(self, p_n) -> np.ndarray:
        return np.full(len(self.centres), np.nan)

    def chain_forces(self, start: dict, end: dict) -> dict:
        """``{"wall": [F_x, F_z]}``: the wall's mean force on the material over a window (N,
        whole silo; ``F_x`` towards the outlet's offset, the tube left out)."""
        forces = self.space.segment_forces(start, end).values()
        out = {"wall": [float(sum(f[0] for f in forces)), float(sum(f[2] for f in forces))]}
        for i, f in self.space.insert_forces(start, end).items():
            out[f"insert_{i + 1}"] = [f[0], f[2]]
        return out

    def corner_forces(self, p_n, tau) -> list:
        return []

    def wall_k(self, p_n, state) -> float:
        """The lateral pressure ratio at the bin wall: the median over the bin wall's patches
        (its vertical stretch, two bins clear of the transition and of the fill level, as the
        sections' :func:`fipy_hopper.diagnostics.wall_k`) of ``p_n / (-sigma_zz)`` of the
        cells next to it; NaN without a bin wall."""
        P = self.patches
        if P.kind == "faces":
            return self._face_wall_k(p_n, state)
        bnd = self.model.cfg.boundary
        if bnd.transition("wall") is None:
            return math.nan
        s_t = bnd.transition_s("wall")
        s_top = bnd.arc_at_height("wall", bnd.fill_level)
        width = np.repeat(P.hi - P.lo, P.n_sectors)
        vertical = np.repeat([abs(P.stretches[k].stretch.tangent[0]) < 1e-9
                              for k in P.stretch], P.n_sectors)
        szz = self.space.vertical_stress_map(state).ravel()
        keep = (vertical & (self.centres > s_t + 2 * width) & (self.centres < s_top - 2 * width)
                & np.isfinite(szz) & (szz < 0.0) & np.isfinite(p_n))
        if not keep.any():
            return math.nan
        return float(np.median(np.asarray(p_n)[keep] / -szz[keep]))

    def _face_wall_k(self, p_n, state) -> float:
        """:meth:`wall_k` of a rectangular plan: the median over the bin's faces' patches two
        bins clear of the transition and the fill level (by height) of ``p_n / (-sigma_zz)``
        of the cells next to them."""
        P = self.patches
        bnd = self.model.boundary
        width = np.repeat(P.hi - P.lo, P.n_sectors)
        on_bin = np.repeat([bnd.faces[P.stretches[k].face].kind == "bin" for k in P.stretch],
                           P.n_sectors)
        szz = self.space.vertical_stress_map(state).ravel()
        keep = (on_bin & (self.z > bnd.bin_foot + 2 * width)
                & (self.z < bnd.fill_level - 2 * width) & np.isfinite(szz) & (szz < 0.0)
                & np.isfinite(p_n))
        if not keep.any():
            return math.nan
        return float(np.median(np.asarray(p_n)[keep] / -szz[keep]))

    def summary(self, sim) -> dict:
        """The sections' wall-load numbers (:func:`fipy_hopper.diagnostics.load_summary`: the
        rest balance, the balance's residuals, ``wall_k_bin``, the largest overpressure over
        the patches, Janssen and Walker for the bin; the membrane and corner forces NaN) and
        the 3D ones (:func:`summary_3d`)."""
        from ..diagnostics import load_summary
        return {**load_summary(sim), **summary_3d(sim, self.patches)}


def stage_maps(record, n_sectors: int) -> dict:
    """``{stage: p_n (n_bins, n_sectors)}`` of a run's recorded wall stages (Pa)."""
    return {stage: np.asarray(values[4], float).reshape(-1, n_sectors)
            for stage, values in record.wall.items()}


def summary_3d(sim, patches) -> dict:
    """The 3D keys of ``summary.json``: the height bins (``wall_bins_s_m``, ``wall_bins_z_m``)
    and the sectors (``sector_theta_deg``); per recorded stage the largest and the smallest
    pressure around the circumference at each height bin and their ratio
    (``<stage>_wall_pressure_max_Pa``, ``..._min_Pa``, ``..._max_over_min``, and the largest
    ratio ``..._max_over_min_largest``; :func:`circumference_extremes`); the flow-mode call by
    wall slip per sector over the flow-mode window (``wall_slip_ratio_by_sector``, the
    smallest over the hopper stretches, and ``flow_mode_by_sector``,
    :func:`fipy_hopper.space.flow.flow_mode_by_sector`)."""
    from ..simulation import flow_mode_window
    from .flow import flow_mode_by_sector

    rec, P = sim.record, patches
    out = {"wall_bins_s_m": P.s.tolist(), "wall_bins_z_m": P.z.tolist(),
           "sector_theta_deg": P.theta_deg.tolist()}
    for stage, p in stage_maps(rec, P.n_sectors).items():
        big, small, ratio = circumference_extremes(p)
        out[f"{stage}_wall_pressure_max_Pa"] = big.tolist()
        out[f"{stage}_wall_pressure_min_Pa"] = small.tolist()
        out[f"{stage}_wall_pressure_max_over_min"] = ratio.tolist()
        out[f"{stage}_wall_pressure_max_over_min_largest"] = (
            float(np.nanmax(ratio)) if np.isfinite(ratio).any() else math.nan)
    samples = [s for s in rec.wall_slip_sectors]
    window, _ = flow_mode_window(rec.t, rec.mass_in_hopper, rec.initial_mass)
    ratio, calls = flow_mode_by_sector(samples, window=window, n_sectors=P.n_sectors,
                                       rule=sim.flow_rule)
    out["wall_slip_ratio_by_sector"] = [float(r) for r in ratio]
    out["flow_mode_by_sector"] = calls
    if P.kind == "faces":
        out.update(face_summary(rec, P))
    return out


def corner_pressures(p, patches) -> dict:
    """The pressure at each of the bin's vertical corners of a rectangular plan, per height
    bin of the bin's faces: ``{corner: (z (n,), p (n,))}`` (Pa), the mean of the two faces'
    patches in the sectors at the corner (the first or the last of each face's width), from a
    map ``p`` (n_bins, n_sectors); corners :data:`fipy_hopper.space.rectangular.CORNERS`.
    The corner's own end of a face is its ``+`` end (the last sector) for the ``_plus`` face
    across it, else its first."""
    from .rectangular import CORNERS

    p = np.asarray(p, float)
    names = patches.names
    rows = {name: np.flatnonzero(patches.stretch == names.index(name))
            for name in ("x_plus", "x_minus", "y_plus", "y_minus") if name in names}
    out = {}
    for corner, fx, fy in CORNERS:
        if fx not in rows or fy not in rows or len(rows[fx]) != len(rows[fy]):
            continue
        # the x face's sector at y = +-L/2, the y face's at x = +-B/2
        kx = -1 if fy == "y_plus" else 0
        ky = -1 if fx == "x_plus" else 0
        out[corner] = (patches.z[rows[fx]], 0.5 * (p[rows[fx], kx] + p[rows[fy], ky]))
    return out


def face_summary(rec, patches) -> dict:
    """The rectangular plan's keys of ``summary.json``: each height bin's face
    (``wall_bins_face``), and per recorded stage the pressure at the bin's corners per height
    bin of its faces, ``<stage>_corner_pressure_Pa`` ``{corner: [...]}``
    (:func:`corner_pressures`; their heights ``corner_z_m``)."""
    out = {"wall_bins_face": [patches.names[k] for k in patches.stretch]}
    for stage, p in stage_maps(rec, patches.n_sectors).items():
        corners = corner_pressures(p, patches)
        out[f"{stage}_corner_pressure_Pa"] = {c: [float(v) for v in pc]
                                              for c, (_, pc) in corners.items()}
        if corners and "corner_z_m" not in out:
            out["corner_z_m"] = [float(z) for z in next(iter(corners.values()))[0]]
    return out
