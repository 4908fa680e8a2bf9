"""The circular silo in 3D as data: signed distance, normals and contact entries.

Coordinates ``(x, y, z)`` (m), ``z`` up, the outlet plane ``z = 0``, the silo's axis
``x = y = 0``.  The wall is the sections' profile ``[(r, z), ...]`` (the lip on ``z = 0`` up to
the top: :attr:`fipy_hopper.config.HopperGeometry.wall_points`, the conical shorthand or a
``profile``) revolved about a vertical axis, with the outlet ``outlet_offset`` ``e`` (m) off
the silo's axis along ``+x``:

* a hopper (the profile's top vertical stretch starts at ``z_b > 0``, the foot of the bin
  wall): each horizontal section from the outlet plane up to ``z_b`` is the circle of the
  profile's radius ``r(z)`` centred at ``(c(z), 0)``, ``c(z) = e (1 - z / z_b)``: an eccentric
  cone (the free-fall tube below the outlet keeps ``c = e``, the bin above ``z_b`` is centred,
  ``c = 0``).  It is the centred silo sheared horizontally, ``x' = x - c(z)``: a point's
  local radius is ``rho = |(x - c(z), y)|`` and every query goes to the sections' boundary
  (:class:`fipy_hopper.boundary.Boundary`) at ``(rho, z)``;
* a flat floor (``z_b = 0``): the bin, centred, stands on the floor ``z = 0``, in which the
  outlet is a hole of the lip's radius centred at ``(e, 0)``.  The material region is the
  intersection of two bodies of revolution: the floor with its hole and tube (about
  ``(e, 0)``) and the bin's cylinder (about the axis).

In general the material region is the intersection of *parts*, each a sections' boundary
revolved about a vertical axis through ``(c(z), 0)``.  For a part, with ``d_2`` and ``n_2 =
(n_rho, n_z)`` the distance and the normal into the solid of the sections' boundary at
``(rho, z)`` and ``u = (x - c, y) / rho`` the horizontal unit vector (``(1, 0)`` on the axis),
the 3D normal into the solid is ``n = (n_rho u_x, n_rho u_y, n_z - c'(z) n_rho u_x) / L`` (the
gradient of ``d_2(rho(x), z)``, ``L`` its length) and the distance ``d_2 / L``: exact for a
centred silo (the nearest point of a body of revolution lies in the point's meridian plane),
first order in the distance from the wall for a sheared one (exact on the wall itself).  The
silo's signed distance (positive in the material) is the smallest of the parts' (exact in the
material region); its normal the nearest part's.

Contact entries (:meth:`SiloBoundary.contacts`) follow the sections' rule segment by segment
(:meth:`fipy_hopper.boundary.Boundary.segment_contacts`): a node is held by a wall segment's
surface of revolution when its projection in its meridian plane falls on the segment
(extended by ``reach`` past a concave corner) and it lies less than ``reach`` in front of it
(3D distance) or anywhere behind it (an insert's face: behind it only inside the insert, past
which lies material again), with that surface's normal at the node; a node within
``reach`` of the wall that no segment holds (round a convex corner, the outlet lip) is held
by the normal towards its nearest wall point.  A tube (the free fall below the outlet) holds
only nodes below the outlet plane: the plane itself is the floor's or the plate's (with the
sections' rule a node of a flat floor at ``z = 0`` was also held by the tube's surface behind
it, a frictionless wall with a normal about the outlet's centre, which took a share of the
bin wall's reaction at the floor's corner: 10 % of the lowest bin's pressure on the near side
of an off-centre outlet at rest, none on the far side).  Each entry carries the wall friction
of its segment (tubes frictionless) and the profile's segment index (-1 a tube, -2 a convex
corner, ``-3 - i`` the ``i``-th insert).

**Inserts** (``[[hopper.inserts]]``, a centred outlet only): each insert's outline in the
section revolved about the silo's axis, a body of revolution (a cone or a disc on the axis, a
ring off it) that is part of the section's boundary (:func:`fipy_hopper.boundary.build`), with
its own friction; the material region is the revolved section's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..boundary import Boundary, build, inside_polygon

#: how far below the outlet plane the bin cylinder of a flat-floored silo's second part
#: starts (m, any depth below the grid)
_DEEP = 100.0


#: the contact ``segment`` code of the first insert's entries (the ``i``-th: ``INSERT - i``)
INSERT = -3


def insert_code(index: int) -> int:
    """The contact entries' ``segment`` code of insert ``index`` (0-based)."""
    return INSERT - int(index)


def outlet_offset_error(wall, outlet_offset) -> str:
    """Why an outlet ``outlet_offset`` (m) off the axis of the silo of profile ``wall``
    ``[(r, z), ...]`` cannot be (one line, naming ``outlet_offset``), or ``""``: a negative or
    non-finite distance, or an outlet (of the lip's radius ``R_0``) outside the floor or the
    hopper, ``e + R_0 >= R`` (``R`` the widest radius of the wall)."""
    try:
        e = float(outlet_offset)
    except (TypeError, ValueError):
        return f"outlet_offset = {outlet_offset!r}: expected a distance in m >= 0"
    r0 = float(wall[0][0])
    radius = max(float(r) for r, _ in wall)
    if not (math.isfinite(e) and e >= 0.0):
        return f"outlet_offset = {outlet_offset!r} m: expected a distance >= 0"
    if e > 0.0 and e + r0 >= radius:
        return (f"outlet_offset = {e:g} m puts the outlet (radius {r0:g} m) outside the floor "
                f"or the hopper (bin radius {radius:g} m): allowed range is "
                f"[0, {radius - r0:g}) m")
    return ""


@dataclass(frozen=True)
class Part:
    """A sections' boundary revolved about the vertical line through ``(c(z), 0)``,
    ``c(z) = offset * clip(1 - z / z_shear, 0, 1)`` (``z_shear = 0``: ``c = offset`` at every
    height).  ``segment`` maps the boundary's table rows to the profile's segment index (-1
    for a tube)."""

    boundary: Boundary
    offset: float = 0.0
    z_shear: float = 0.0
    segment: tuple = ()

    def centre(self, z):
        """``c(z)`` (m)."""
        z = np.asarray(z, dtype=float)
        if self.offset == 0.0:
            return np.zeros_like(z)
        if self.z_shear <= 0.0:
            return np.full_like(z, self.offset)
        return self.offset * np.clip(1.0 - z / self.z_shear, 0.0, 1.0)

    def slope(self, z):
        """``dc/dz`` (-): ``-offset / z_shear`` inside ``0 < z < z_shear``, else 0."""
        z = np.asarray(z, dtype=float)
        if self.offset == 0.0 or self.z_shear <= 0.0:
            return np.zeros_like(z)
        return np.where((z > 0.0) & (z < self.z_shear), -self.offset / self.z_shear, 0.0)

    def local(self, x, y, z):
        """``(rho, u_x, u_y)``: the local radius and the horizontal unit vector from the part's
        axis (``(1, 0)`` on it)."""
        xs = np.asarray(x, dtype=float) - self.centre(z)
        y = np.asarray(y, dtype=float)
        rho = np.hypot(xs, y)
        on_axis = rho == 0.0
        safe = np.where(on_axis, 1.0, rho)
        return rho, np.where(on_axis, 1.0, xs / safe), np.where(on_axis, 0.0, y / safe)

    def lift(self, n_rho, n_z, u_x, u_y, z):
        """The 3D normal ``(3, ...)`` of a sections' normal ``(n_rho, n_z)`` and its length
        ``L`` before normalising (module docstring)."""
        n = np.stack(np.broadcast_arrays(n_rho * u_x, n_rho * u_y,
                                         n_z - self.slope(z) * n_rho * u_x))
        length = np.sqrt((n * n).sum(axis=0))
        return n / length, length

    def in_solid(self, x, y, z):
        rho, _, _ = self.local(x, y, z)
        return self.boundary.in_solid(rho, np.asarray(z, dtype=float))

    def distance_normal(self, x, y, z):
        """Signed distance (m, positive in the part's material) and the unit normal into the
        solid ``(3, ...)``."""
        z = np.asarray(z, dtype=float)
        rho, ux, uy = self.local(x, y, z)
        d2 = self.boundary.signed_distance(rho, z)
        n_rho, n_z = self.boundary.wall_normal(rho, z)
        n, length = self.lift(n_rho, n_z, ux, uy, z)
        return d2 / length, n


def silo_boundary(cfg):
    """The silo of a :class:`~fipy_hopper.space.config.SpaceConfig` as data: a
    :class:`SiloBoundary` (a circular plan) or a
    :class:`~fipy_hopper.space.rectangular.RectangularSilo` (``plan = "rectangular"``), with
    the walls' friction."""
    if getattr(cfg.hopper, "rectangular", False):
        from .rectangular import RectangularSilo
        return RectangularSilo.from_geometry(cfg.hopper, cfg.wall.friction_angle_deg,
                                             cfg.wall.segment_friction_deg)
    return SiloBoundary.from_geometry(cfg.hopper, cfg.outlet_offset,
                                      cfg.wall.friction_angle_deg,
                                      cfg.wall.segment_friction_deg)


@dataclass(frozen=True)
class SiloBoundary:
    """The silo in 3D (module docstring): its ``parts``, the profile ``wall`` (m), the
    ``outlet_offset`` (m), the outlet radius and the fill level (m)."""

    parts: tuple
    wall: tuple
    outlet_offset: float
    outlet_radius: float
    fill_level: float
    segment_friction_deg: tuple = field(default=())
    n_inserts: int = 0

    plan = "circular"

    @classmethod
    def from_profile(cls, wall, fill_level: float, outlet_offset: float = 0.0,
                     friction_deg: float = 15.0, segment_friction_deg=None,
                     inserts=()) -> "SiloBoundary":
        """The silo of a profile ``wall`` ``[(r, z), ...]`` (m; the lip on ``z = 0``, never
        descending, the top a vertical stretch), filled to ``fill_level`` (m), with the outlet
        ``outlet_offset`` (m) off the axis along ``+x``; wall friction ``friction_deg`` or one
        angle per segment (deg); ``inserts`` ``[(outline, friction_deg or None), ...]`` revolved
        about the axis (module docstring; a centred outlet only).  Refuses an offset that puts
        the outlet outside the floor or the hopper (``e + R_0 >= R``), and inserts beside an
        off-centre outlet."""
        wall = tuple((float(r), float(z)) for r, z in wall)
        error = outlet_offset_error(wall, outlet_offset)
        if error:
            raise ValueError(error)
        inserts = tuple(inserts)
        if inserts and outlet_offset != 0.0:
            raise ValueError(f"outlet_offset = {outlet_offset:g} m with {len(inserts)} "
                             "insert(s): inserts in 3D need a centred outlet (offset 0)")
        e = float(outlet_offset)
        r0 = wall[0][0]
        radius = max(r for r, _ in wall)
        n_seg = len(wall) - 1
        fr = (tuple(float(f) for f in segment_friction_deg) if segment_friction_deg is not None
              else (float(friction_deg),) * n_seg)
        if len(fr) != n_seg:
            raise ValueError(f"segment_friction_deg has {len(fr)} values for {n_seg} segments")

        def part(points, seg_of, friction, offset, z_shear, inserts=()):
            b = build(points, symmetry="axisymmetric", fill_level=fill_level,
                      inserts=inserts).with_friction(float(friction_deg), friction)
            tab = b.table
            insert_of = {ci: i for i, ci in enumerate(
                ci for ci, c in enumerate(b.chains) if c.kind == "insert")}
            segment = tuple(-1 if tab.tube[k] else
                            insert_code(insert_of[tab.chain[k]]) if tab.chain[k] in insert_of
                            else seg_of[tab.segment[k]] for k in range(len(tab)))
            return Part(b, offset, z_shear, segment)

        top = wall[-1][1]
        if e > 0.0 and _bin_foot(wall) == 0.0:
            # the floor with its hole (about (e, 0)); its far wall lies beyond any grid
            far = 10.0 * radius + 10.0 * top + 1.0
            floor_z = wall[1][1]
            floor = part(((r0, 0.0), (far, floor_z), (far, top)), (0, n_seg - 1),
                         (fr[0], fr[-1]), e, 0.0)
            bin_wall = part(((radius, -_DEEP), (radius, top)), (n_seg - 1,), (fr[-1],),
                            0.0, 0.0)
            parts = (floor, bin_wall)
        else:
            z_b = _bin_foot(wall)
            parts = (part(wall, tuple(range(n_seg)), fr, e, z_b, inserts),)
        return cls(parts, wall, e, r0, float(fill_level), fr, len(inserts))

    @classmethod
    def from_geometry(cls, geom, outlet_offset: float = 0.0, friction_deg: float = 15.0,
                      segment_friction_deg=None) -> "SiloBoundary":
        """The silo of a :class:`fipy_hopper.config.HopperGeometry` (axisymmetric): its wall
        points, inserts and fill level."""
        if not geom.axisymmetric:
            raise ValueError("the 3D silo is an axisymmetric profile")
        return cls.from_profile(geom.wall_points, geom.fill_level, outlet_offset, friction_deg,
                                segment_friction_deg,
                                [(i.outline, i.friction_angle_deg) for i in geom.inserts])

    # ------------------------------------------------------------------ sizes
    @property
    def radius(self) -> float:
        """The bin's radius (m)."""
        return max(r for r, _ in self.wall)

    @property
    def half_extent(self) -> tuple:
        """``(R, R)`` (m): the grid's extent each way."""
        return self.radius, self.radius

    @property
    def outlet_centre(self) -> tuple:
        """The outlet's centre ``(e, 0)`` (m)."""
        return self.outlet_offset, 0.0

    @property
    def top(self) -> float:
        return self.wall[-1][1]

    @property
    def bin_foot(self) -> float:
        """Height (m) of the foot of the vertical bin wall (0 for a flat floor)."""
        return _bin_foot(self.wall)

    def fill_volume(self) -> float:
        """Volume of the material below the fill level (m^3): the centred silo's (a shear and
        the hole's position change no volume)."""
        return self.parts[0].boundary.fill_volume() if len(self.parts) == 1 else \
            build(self.wall, fill_level=self.fill_level).fill_volume()

    # ------------------------------------------------------------------ geometry
    def in_solid(self, x, y, z):
        """True where ``(x, y, z)`` lies in the solid (outside the material region)."""
        solid = None
        for p in self.parts:
            s = p.in_solid(x, y, z)
            solid = s if solid is None else solid | s
        return solid

    def distance_normal(self, x, y, z):
        """Signed distance (m, positive in the material) and the unit normal into the solid
        ``(3, ...)`` of the nearest part."""
        d, n = self.parts[0].distance_normal(x, y, z)
        for p in self.parts[1:]:
            dp, npart = p.distance_normal(x, y, z)
            closer = dp < d
            d = np.where(closer, dp, d)
            n = np.where(closer[None], npart, n)
        return d, n

    def outlet_plate(self, x, y):
        """The nodes the closed outlet's plate holds: in the outlet's circle or on its rim."""
        return np.hypot(x - self.outlet_offset, y) <= self.outlet_radius + 1e-12

    def outlet_hole(self, x, y):
        """True where ``(x, y)`` lies in the outlet (the lip's circle centred at
        ``(e, 0)``)."""
        return np.hypot(np.asarray(x, float) - self.outlet_offset, y) < self.outlet_radius

    def contacts(self, x, y, z, reach: float, candidates=None) -> list:
        """The contact entries of the points ``(x, y, z)`` (module docstring):
        ``[(mask, normal (3, ...), mu, segment), ...]``, one per wall segment of each part
        and last the convex corners; ``mu`` the friction coefficient (0 for a tube),
        ``segment`` the profile's segment index (-1 tube, -2 convex corner).  Only points
        where ``candidates`` (default: all) are considered."""
        x, y, z = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x, y, z)))
        cand = np.ones(x.shape, bool) if candidates is None else np.asarray(candidates, bool)
        out = []
        covered = np.zeros(x.shape, bool)
        for p in self.parts:
            tab = p.boundary.table
            rho, ux, uy = p.local(x, y, z)
            for k in range(len(tab)):
                a, b = tab.a[k], tab.b[k]
                ab = b - a
                length = float(np.hypot(*ab))
                if length == 0.0:
                    continue
                t = ((rho - a[0]) * ab[0] + (z - a[1]) * ab[1]) / length ** 2
                n2 = tab.normal[k]
                n3, lift = p.lift(n2[0], n2[1], ux, uy, z)
                front = -((rho - a[0]) * n2[0] + (z - a[1]) * n2[1]) / lift
                ext = reach / length
                lo = -ext if tab.concave[k, 0] else 0.0
                hi = 1.0 + ext if tab.concave[k, 1] else 1.0
                if tab.tube[k]:             # the outlet plane is the floor's or the plate's
                    hi -= 1e-9
                mask = cand & (t >= lo - 1e-12) & (t <= hi + 1e-12) & (front < reach)
                chain = p.boundary.chains[tab.chain[k]]
                if chain.kind == "insert":        # behind an insert's face: only inside it
                    far_behind = mask & (front <= -reach)
                    if far_behind.any():
                        mask &= ~far_behind | inside_polygon(
                            rho, z, np.asarray(chain.polygon, float))
                if not mask.any():
                    continue
                mu = 0.0 if tab.tube[k] else math.tan(math.radians(tab.friction_deg[k]))
                out.append((mask, n3, mu, p.segment[k]))
                covered |= mask
        d, n = self.distance_normal(x, y, z)
        corner = cand & (d < reach) & ~covered
        if corner.any():
            out.append((corner, n, math.tan(math.radians(self.segment_friction_deg[0])), -2))
        return out


def _bin_foot(wall) -> float:
    """Height (m) where the profile's top vertical stretch starts."""
    k = len(wall) - 1
    while k > 0 and wall[k - 1][0] == wall[k][0]:
        k -= 1
    return wall[k][1]
