"""The rectangular silo in 3D as data: its plane faces, signed distance, normals and contact
entries (``[hopper] plan = "rectangular"``).

Coordinates as the circular silo's (:mod:`fipy_hopper.space.boundary`): ``z`` up, the outlet
plane ``z = 0``, the bin's axis ``x = y = 0``.  The bin is the box ``|x| <= B/2``, ``|y| <=
L/2`` (``B`` = ``bin_width`` along x, ``L`` = ``bin_length`` along y) from the transition
``z = H`` up to its top.  The outlet's centre is ``(ex, ey)`` (``outlet_offset``); the outlet
is a rectangle ``ox`` by ``oy`` (``outlet_width``, ``outlet_length``) or a circle of diameter
``D`` (``outlet_diameter``).  The hopper's *foot* is the outlet's rectangle, or the square
``D`` by ``D`` round a circular outlet.  Below the bin:

* a hopper (``H > 0``): four plane faces, each from an edge of the foot (on ``z = 0``) to the
  bin's edge on the same side (on ``z = H``): the convex hull of the foot and the bin's
  section, whose horizontal sections are rectangles with edges moving linearly from the
  foot's to the bin's (a pyramid under a square bin with a square outlet; a wedge-like
  hopper under a long bin with a slot).  ``H`` is set by ``half_angle_deg``, the half-angle
  from the vertical of the faces across x of the centred hopper, ``H = (B - ox) / (2 tan)``;
  an offset outlet makes the faces' slopes differ (the hopper sheared, as the circular
  silo's eccentric cone).  Round a circular outlet the foot's corners outside the circle are
  flat floor (``floor``);
* a flat floor (``H = 0``, ``half_angle_deg = 90``): the floor ``z = 0`` with the outlet a
  hole in it;
* below the outlet plane, the free-fall tube: the outlet's rectangle or circle extended
  down (frictionless, holding only nodes below ``z = 0``).

The material region is ``z >= 0`` inside the section at ``z`` (the foot's rectangle moving
linearly to the bin's, then the bin's) and ``z < 0`` inside the outlet: convex above the
outlet plane.

**Faces** (:class:`Face`): each a convex plane polygon with the unit normal into the solid,
its edges marked concave (the material's corner there is less than 180 deg: the bin's and the
hopper's corners, the hopper's or the bin's foot on a floor) or convex (the transition from the
hopper to the bin, the outlet's lip, the top); a floor may have a hole (the outlet), whose edge
is convex.  Names: ``x_plus``, ``x_minus``, ``y_plus``, ``y_minus`` the bin's faces (their
outward normal along ``+x``, ...), ``hopper_x_plus``, ... the hopper's, ``floor``, and
``tube_x_plus``, ... / ``tube`` below the outlet.

**Signed distance and normals** (:meth:`RectangularSilo.distance_normal`): exact, the distance
to the nearest face (to its plane where the point's projection falls on the face, else to its
nearest edge, vertex or the hole's rim), positive in the material; the normal into the solid
is the face's where the projection falls on it, else the direction from the point to its
nearest wall point (reversed in the solid): the round of a convex edge.

**Contact entries** (:meth:`RectangularSilo.contacts`): the sections' rule face by face (that of
:meth:`fipy_hopper.boundary.Boundary.segment_contacts`, as the circular silo's): a node is
held by a face when its projection on the face's plane falls on the face, extended by
``reach`` across the face's concave edges, and it lies less than ``reach`` in front of the
face or anywhere behind it, with the face's normal and friction; a node within ``reach`` of the
wall that no face holds (round a convex edge: the outlet's lip, the transition) is held by the
normal towards its nearest wall point.  So a node at a concave corner (two faces of the bin,
the bin's foot on a flat floor) is held by both faces and the contact resolves it against both
(the edge of two walls, :mod:`fipy_hopper.space.contact`: the 2D corner's rule).  The tube's
faces are frictionless and hold only nodes below the outlet plane.  Each entry carries its
face's index (:attr:`RectangularSilo.faces`), the wall profile's segment (0 the hopper or the
floor, 1 the bin, -1 the tube, -2 a convex edge) and its friction (``segment_friction_deg``:
the hopper's and the floor's, the bin's; the profile of the plan is
:attr:`fipy_hopper.config.HopperGeometry.wall_points`, the section across x).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: how far below the outlet plane the tube's faces reach (m, any depth below the grid)
_DEEP = 100.0
#: the bin's faces in the order of the wall loads (the outward axis and its sign)
BIN_FACES = (("x_plus", 0, 1.0), ("x_minus", 0, -1.0), ("y_plus", 1, 1.0),
             ("y_minus", 1, -1.0))
#: the bin's vertical corners: the two faces that meet there
CORNERS = (("x_plus_y_plus", "x_plus", "y_plus"), ("x_minus_y_plus", "x_minus", "y_plus"),
           ("x_minus_y_minus", "x_minus", "y_minus"), ("x_plus_y_minus", "x_plus", "y_minus"))


def outlet_offset_error(bin_width, bin_length, outlet_x, outlet_y, round_outlet,
                        offset) -> str:
    """Why an outlet at ``offset`` ``(ex, ey)`` (m) cannot be in a rectangular bin (one line
    naming ``outlet_offset``), or ``""``: the outlet (``outlet_x`` by ``outlet_y``, or a
    circle of diameter ``outlet_x``) must lie inside the floor or the hopper's top, not
    touching the bin's walls: ``|ex| + ox/2 < B/2`` and ``|ey| + oy/2 < L/2``."""
    ex, ey = offset
    hx, hy = 0.5 * bin_width - 0.5 * outlet_x, 0.5 * bin_length - 0.5 * outlet_y
    what = (f"diameter {outlet_x:g} m" if round_outlet
            else f"{outlet_x:g} m x {outlet_y:g} m")
    if abs(ex) >= hx or abs(ey) >= hy:
        return (f"outlet_offset = [{ex:g}, {ey:g}] m puts the outlet ({what}) outside the floor "
                f"or the hopper (bin {bin_width:g} m x {bin_length:g} m): allowed is "
                f"|ex| < {hx:g} m and |ey| < {hy:g} m")
    return ""


@dataclass(frozen=True)
class Face:
    """A plane face of the silo's wall (module docstring): ``vertices`` ``(m, 3)`` of a convex
    polygon in order, ``normal`` the unit normal into the solid, ``concave`` per edge ``i``
    (from vertex ``i`` to ``i + 1``), ``hole`` ``None``, ``("circle", cx, cy, r)`` or
    ``("rect", x_lo, x_hi, y_lo, y_hi)`` (a floor's outlet), ``kind`` ``"bin"``,
    ``"hopper"``, ``"floor"`` or ``"tube"``, ``segment`` the wall profile's (0 the hopper or
    the floor, 1 the bin, -1 the tube) and ``friction_deg``.  For the wall loads: a bin's or a
    hopper's face has an outward ``axis`` (0 x, 1 y) and ``side`` (+1, -1)."""

    name: str
    kind: str
    segment: int
    friction_deg: float
    vertices: np.ndarray
    normal: np.ndarray
    concave: tuple
    hole: tuple = None
    axis: int = -1
    side: float = 0.0
    edge_normal: np.ndarray = field(default=None, repr=False)

    @classmethod
    def make(cls, name, kind, segment, friction_deg, vertices, outward, concave, hole=None,
             axis=-1, side=0.0) -> "Face":
        """A face of ``vertices``, its normal oriented along ``outward`` (into the solid)."""
        v = np.asarray(vertices, float)
        n = np.cross(v[1] - v[0], v[-1] - v[0])
        n = n / np.linalg.norm(n)
        if np.dot(n, outward) < 0:
            n = -n
        centre = v.mean(axis=0)
        m = []
        for i in range(len(v)):
            e = v[(i + 1) % len(v)] - v[i]
            w = np.cross(n, e)
            w = w / np.linalg.norm(w)
            if np.dot(centre - v[i], w) < 0:
                w = -w
            m.append(w)
        return cls(name, kind, segment, float(friction_deg), v, n, tuple(bool(c) for c in concave),
                   hole, axis, side, np.array(m))

    def in_plane(self, p) -> tuple:
        """``(front, edges)`` of points ``p`` (3, ...): the distance in front of the face's
        plane (m, positive on the material's side) and the in-plane distance inside each edge
        ``(m, ...)`` (positive inside the polygon)."""
        p = np.asarray(p, float)
        rel = p - self.vertices[0].reshape((3,) + (1,) * (p.ndim - 1))
        front = -np.tensordot(self.normal, rel, axes=1)
        edges = np.stack([np.tensordot(self.edge_normal[i], p - self.vertices[i].reshape(
            (3,) + (1,) * (p.ndim - 1)), axes=1) for i in range(len(self.vertices))])
        return front, edges

    def outside_hole(self, p, grow: float = 0.0):
        """True where points ``p`` (3, ...) lie off the face's hole (its hole shrunk by
        ``grow``; everywhere for a face without one)."""
        if self.hole is None:
            return np.ones(np.shape(p)[1:], bool)
        if self.hole[0] == "circle":
            _, cx, cy, r = self.hole
            return np.hypot(p[0] - cx, p[1] - cy) >= r - grow
        _, x0, x1, y0, y1 = self.hole
        return np.maximum.reduce([x0 - p[0], p[0] - x1, y0 - p[1], p[1] - y1]) >= -grow

    def nearest(self, p) -> tuple:
        """``(distance, nearest point (3, ...), on the face's plane)`` of points ``p``
        (3, ...): the face's nearest point to each and whether it lies inside the face (not on
        an edge or the hole's rim)."""
        p = np.asarray(p, float)
        front, edges = self.in_plane(p)
        inside = np.all(edges >= 0.0, axis=0)
        free = inside & self.outside_hole(p)
        n = self.normal.reshape((3,) + (1,) * (p.ndim - 1))
        q_plane = p + front[None] * n
        best = np.where(free, np.abs(front), np.inf)
        q = np.where(free[None], q_plane, 0.0)
        segments = [(self.vertices[i], self.vertices[(i + 1) % len(self.vertices)])
                    for i in range(len(self.vertices))]
        if self.hole is not None and self.hole[0] == "rect":
            _, x0, x1, y0, y1 = self.hole
            z = self.vertices[0][2]
            corners = [np.array(c) for c in ((x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z))]
            segments += [(corners[i], corners[(i + 1) % 4]) for i in range(4)]
        for a, b in segments:
            d, qs = _segment_nearest(p, a, b)
            closer = d < best
            best = np.where(closer, d, best)
            q = np.where(closer[None], qs, q)
        if self.hole is not None and self.hole[0] == "circle":
            _, cx, cy, r = self.hole
            z = self.vertices[0][2]
            dx, dy = p[0] - cx, p[1] - cy
            rho = np.hypot(dx, dy)
            safe = np.where(rho > 0, rho, 1.0)
            ux, uy = np.where(rho > 0, dx / safe, 1.0), np.where(rho > 0, dy / safe, 0.0)
            qc = np.stack(np.broadcast_arrays(cx + r * ux, cy + r * uy, z + 0.0 * ux))
            d = np.sqrt(((p - qc) ** 2).sum(axis=0))
            closer = (d < best) & inside
            best = np.where(closer, d, best)
            q = np.where(closer[None], qc, q)
        return best, q, free


def _segment_nearest(p, a, b) -> tuple:
    """Distance and nearest point of points ``p`` (3, ...) on the segment ``a b``."""
    shape = (3,) + (1,) * (np.ndim(p) - 1)
    a, ab = a.reshape(shape), (b - a).reshape(shape)
    t = np.clip(((p - a) * ab).sum(axis=0) / float((ab * ab).sum()), 0.0, 1.0)
    q = a + t[None] * ab
    return np.sqrt(((p - q) ** 2).sum(axis=0)), q


@dataclass(frozen=True)
class RectangularSilo:
    """The rectangular silo (module docstring): ``bin_width`` (x), ``bin_length`` (y), the
    hopper's height ``hopper_height`` (0: a flat floor), the ``top`` of the bin, the
    ``fill_level`` (m), the outlet ``outlet_x`` by ``outlet_y`` (``round_outlet``: a circle of
    diameter ``outlet_x``) centred at ``outlet_offset`` ``(ex, ey)``, the wall profile across x
    ``wall`` (for the wall loads' bins) and ``segment_friction_deg`` (the hopper's or floor's,
    the bin's)."""

    bin_width: float
    bin_length: float
    hopper_height: float
    top: float
    fill_level: float
    outlet_x: float
    outlet_y: float
    round_outlet: bool
    outlet_offset: tuple
    wall: tuple
    segment_friction_deg: tuple
    faces: tuple = ()

    plan = "rectangular"

    @classmethod
    def from_geometry(cls, geom, friction_deg: float = 15.0,
                      segment_friction_deg=None) -> "RectangularSilo":
        """The silo of a rectangular :class:`fipy_hopper.config.HopperGeometry`; wall
        friction ``friction_deg`` or one angle per segment (the hopper or floor, the bin)."""
        if not getattr(geom, "rectangular", False):
            raise ValueError("RectangularSilo is made from a geometry with plan = "
                             "\"rectangular\"")
        ox, oy, round_outlet = geom.outlet_size
        fr = (tuple(float(f) for f in segment_friction_deg) if segment_friction_deg is not None
              else (float(friction_deg),) * 2)
        if len(fr) != 2:
            raise ValueError(f"segment_friction_deg has {len(fr)} values for 2 segments")
        error = outlet_offset_error(geom.bin_width, geom.bin_length, ox, oy, round_outlet,
                                    geom.offset_xy)
        if error:
            raise ValueError(error)
        silo = cls(float(geom.bin_width), float(geom.bin_length), float(geom.cone_height),
                   float(geom.top), float(geom.fill_level), float(ox), float(oy),
                   bool(round_outlet), tuple(float(e) for e in geom.offset_xy),
                   tuple(geom.wall_points), fr)
        object.__setattr__(silo, "faces", silo._build_faces())
        return silo

    # ------------------------------------------------------------------ sizes
    @property
    def radius(self) -> float:
        """Half the bin's larger side (m)."""
        return 0.5 * max(self.bin_width, self.bin_length)

    @property
    def half_extent(self) -> tuple:
        """``(B/2, L/2)`` (m): the grid's extent each way."""
        return 0.5 * self.bin_width, 0.5 * self.bin_length

    @property
    def outlet_radius(self) -> float:
        """Half the outlet's size along x (m): the lip of :attr:`wall` (the grid's free fall
        is counted in outlet diameters of it)."""
        return 0.5 * self.outlet_x

    @property
    def outlet_centre(self) -> tuple:
        return self.outlet_offset

    @property
    def bin_foot(self) -> float:
        """Height (m) of the bin's foot (the transition; 0 on a flat floor)."""
        return self.hopper_height

    @property
    def foot(self) -> tuple:
        """The hopper's foot ``(x_lo, x_hi, y_lo, y_hi)`` on ``z = 0`` (m): the outlet's
        rectangle, or the square round a circular outlet; on a flat floor the bin's."""
        if self.hopper_height <= 0.0:
            return -0.5 * self.bin_width, 0.5 * self.bin_width, -0.5 * self.bin_length, \
                0.5 * self.bin_length
        ex, ey = self.outlet_offset
        return (ex - 0.5 * self.outlet_x, ex + 0.5 * self.outlet_x, ey - 0.5 * self.outlet_y,
                ey + 0.5 * self.outlet_y)

    def section(self, z) -> tuple:
        """``(x_lo, x_hi, y_lo, y_hi)`` of the horizontal section at heights ``z >= 0``."""
        z = np.asarray(z, float)
        B, L = self.half_extent
        x0, x1, y0, y1 = self.foot
        if self.hopper_height <= 0.0:
            t = np.ones_like(z)
        else:
            t = np.clip(z / self.hopper_height, 0.0, 1.0)
        return x0 + (-B - x0) * t, x1 + (B - x1) * t, y0 + (-L - y0) * t, y1 + (L - y1) * t

    def section_centre(self, z) -> tuple:
        """``(cx, cy)`` (m) of the horizontal sections at heights ``z`` (the outlet's centre
        below the outlet plane)."""
        z = np.asarray(z, float)
        x0, x1, y0, y1 = self.section(np.maximum(z, 0.0))
        ex, ey = self.outlet_offset
        below = z < 0.0
        return np.where(below, ex, 0.5 * (x0 + x1)), np.where(below, ey, 0.5 * (y0 + y1))

    def fill_volume(self) -> float:
        """Volume of the material below the fill level (m^3): the hopper (a prismatoid) and the
        bin's box (a flat floor's box from z = 0)."""
        x0, x1, y0, y1 = self.foot
        a0, b0 = x1 - x0, y1 - y0
        a1, b1, h = self.bin_width, self.bin_length, self.hopper_height
        middle = 0.25 * (a0 + a1) * (b0 + b1)
        return h / 6.0 * (a0 * b0 + 4.0 * middle + a1 * b1) + a1 * b1 * (self.fill_level - h)

    # ------------------------------------------------------------------ faces
    def _build_faces(self) -> tuple:
        B, L = self.half_extent
        H, top = self.hopper_height, self.top
        f_low, f_bin = self.segment_friction_deg
        x0, x1, y0, y1 = self.foot
        ex, ey = self.outlet_offset
        faces = []
        hopper = H > 0.0
        # the bin's faces: vertices from its foot's (-u, +u) corners up
        for name, axis, side in BIN_FACES:
            if axis == 0:
                x = side * B
                v = ((x, -L, H), (x, L, H), (x, L, top), (x, -L, top))
            else:
                y = side * L
                v = ((-B, y, H), (B, y, H), (B, y, top), (-B, y, top))
            outward = np.eye(3)[axis] * side
            faces.append(Face.make(name, "bin", 1, f_bin, v, outward,
                                   (not hopper, True, False, True), axis=axis, side=side))
        if hopper:
            foot = {("x", 1.0): ((x1, y0, 0.0), (x1, y1, 0.0), (B, L, H), (B, -L, H)),
                    ("x", -1.0): ((x0, y0, 0.0), (x0, y1, 0.0), (-B, L, H), (-B, -L, H)),
                    ("y", 1.0): ((x0, y1, 0.0), (x1, y1, 0.0), (B, L, H), (-B, L, H)),
                    ("y", -1.0): ((x0, y0, 0.0), (x1, y0, 0.0), (B, -L, H), (-B, -L, H))}
            for name, axis, side in BIN_FACES:
                v = foot[("xy"[axis], side)]
                outward = np.eye(3)[axis] * side - 0.1 * np.eye(3)[2]
                faces.append(Face.make("hopper_" + name, "hopper", 0, f_low, v, outward,
                                       (self.round_outlet, True, False, True), axis=axis,
                                       side=side))
        floor_hole = (("circle", ex, ey, 0.5 * self.outlet_x) if self.round_outlet else
                      ("rect", ex - 0.5 * self.outlet_x, ex + 0.5 * self.outlet_x,
                       ey - 0.5 * self.outlet_y, ey + 0.5 * self.outlet_y))
        if not hopper or self.round_outlet:
            v = ((x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0))
            faces.append(Face.make("floor", "floor", 0, f_low, v, (0.0, 0.0, -1.0),
                                   (True, True, True, True), hole=floor_hole))
        if not self.round_outlet:
            ox0, ox1 = ex - 0.5 * self.outlet_x, ex + 0.5 * self.outlet_x
            oy0, oy1 = ey - 0.5 * self.outlet_y, ey + 0.5 * self.outlet_y
            d = -_DEEP
            tube = {("x", 1.0): ((ox1, oy0, d), (ox1, oy1, d), (ox1, oy1, 0.0), (ox1, oy0, 0.0)),
                    ("x", -1.0): ((ox0, oy0, d), (ox0, oy1, d), (ox0, oy1, 0.0), (ox0, oy0, 0.0)),
                    ("y", 1.0): ((ox0, oy1, d), (ox1, oy1, d), (ox1, oy1, 0.0), (ox0, oy1, 0.0)),
                    ("y", -1.0): ((ox0, oy0, d), (ox1, oy0, d), (ox1, oy0, 0.0), (ox0, oy0, 0.0))}
            for name, axis, side in BIN_FACES:
                faces.append(Face.make("tube_" + name, "tube", -1, 0.0,
                                       tube[("xy"[axis], side)], np.eye(3)[axis] * side,
                                       (False, True, False, True), axis=axis, side=side))
        return tuple(faces)

    def describe(self, density: float) -> str:
        """Lines describing the silo: the bin, the outlet, the fill, each face (its slope from
        the vertical and friction), for ``validate``."""
        ex, ey = self.outlet_offset
        outlet = (f"a circle {self.outlet_x:g} m across" if self.round_outlet
                  else f"{self.outlet_x:g} m x {self.outlet_y:g} m")
        volume = self.fill_volume()
        lines = [f"plan         rectangular: the bin {self.bin_width:g} m (x) x "
                 f"{self.bin_length:g} m (y), z = {self.hopper_height:.4g} to {self.top:.4g} m",
                 f"outlet       {outlet}, its centre at ({ex:g}, {ey:g}) m on z = 0",
                 f"fill level   z = {self.fill_level:g} m: {volume:.4g} m^3, "
                 f"{density * volume:.4g} kg at {density:g} kg/m3",
                 "tube         free-fall tube below the outlet, frictionless"]
        for face in self.faces:
            if face.kind == "tube":
                continue
            if face.kind == "floor":
                lines.append(f"face floor   z = 0 round the outlet, friction "
                             f"{face.friction_deg:g} deg")
                continue
            slope = math.degrees(math.acos(min(1.0, abs(face.normal[face.axis]))))
            lines.append(f"face {face.name:<14s} {slope:.1f} deg from the vertical, "
                         f"z = {face.vertices[:, 2].min():.4g} to "
                         f"{face.vertices[:, 2].max():.4g} m, friction "
                         f"{face.friction_deg:g} deg")
        return "\n".join(lines)

    def face_index(self, name: str) -> int:
        return [f.name for f in self.faces].index(name)

    @property
    def load_faces(self) -> tuple:
        """Indices of the faces the material loads (not the tube), in the wall loads' order:
        the floor, the hopper's faces, the bin's."""
        order = {"floor": 0, "hopper": 1, "bin": 2}
        idx = [k for k, f in enumerate(self.faces) if f.kind != "tube"]
        return tuple(sorted(idx, key=lambda k: order[self.faces[k].kind]))

    # ------------------------------------------------------------------ geometry
    def in_solid(self, x, y, z):
        """True where ``(x, y, z)`` lies in the solid (outside the material region)."""
        x, y, z = np.broadcast_arrays(*(np.asarray(a, float) for a in (x, y, z)))
        x0, x1, y0, y1 = self.section(np.maximum(z, 0.0))
        above = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        below = self.outlet_hole(x, y)
        return np.where(z >= 0.0, ~above, ~below)

    def outlet_hole(self, x, y):
        """True where ``(x, y)`` lies in the outlet."""
        ex, ey = self.outlet_offset
        x, y = np.asarray(x, float), np.asarray(y, float)
        if self.round_outlet:
            return np.hypot(x - ex, y - ey) < 0.5 * self.outlet_x
        return (np.abs(x - ex) < 0.5 * self.outlet_x) & (np.abs(y - ey) < 0.5 * self.outlet_y)

    def outlet_plate(self, x, y):
        """The nodes the closed outlet's plate holds: in the outlet or on its rim."""
        ex, ey = self.outlet_offset
        if self.round_outlet:
            return np.hypot(x - ex, y - ey) <= 0.5 * self.outlet_x + 1e-12
        return (np.abs(x - ex) <= 0.5 * self.outlet_x + 1e-12) & (
            np.abs(y - ey) <= 0.5 * self.outlet_y + 1e-12)

    def _round_tube(self, p) -> tuple:
        """Distance, nearest point and normal of the circular tube (below the outlet plane)."""
        ex, ey = self.outlet_offset
        r = 0.5 * self.outlet_x
        dx, dy = p[0] - ex, p[1] - ey
        rho = np.hypot(dx, dy)
        safe = np.where(rho > 0, rho, 1.0)
        ux, uy = np.where(rho > 0, dx / safe, 1.0), np.where(rho > 0, dy / safe, 0.0)
        zq = np.minimum(p[2], 0.0)
        q = np.stack([ex + r * ux, ey + r * uy, zq])
        d = np.sqrt(((p - q) ** 2).sum(axis=0))
        return d, q, np.stack([ux, uy, 0.0 * ux]), p[2] <= 0.0

    def distance_normal(self, x, y, z):
        """Signed distance (m, positive in the material) and the unit normal into the solid
        ``(3, ...)`` (module docstring)."""
        x, y, z = np.broadcast_arrays(*(np.asarray(a, float) for a in (x, y, z)))
        p = np.stack([x, y, z])
        best = np.full(x.shape, np.inf)
        q = np.zeros_like(p)
        plane_n = np.zeros_like(p)
        on_plane = np.zeros(x.shape, bool)
        for face in self.faces:            # ties (within 1e-12 m): the first face's
            d, qf, free = face.nearest(p)
            closer = d < best - 1e-12
            best = np.where(closer, d, best)
            q = np.where(closer[None], qf, q)
            plane_n = np.where(closer[None], face.normal.reshape(3, *([1] * x.ndim)), plane_n)
            on_plane = np.where(closer, free, on_plane)
        if self.round_outlet:
            d, qf, nf, free = self._round_tube(p)
            closer = d < best - 1e-12
            best = np.where(closer, d, best)
            q = np.where(closer[None], qf, q)
            plane_n = np.where(closer[None], nf, plane_n)
            on_plane = np.where(closer, free, on_plane)
        solid = self.in_solid(x, y, z)
        diff = q - p
        length = np.sqrt((diff * diff).sum(axis=0))
        safe = np.where(length > 0, length, 1.0)
        towards = diff / safe
        towards = np.where(solid[None], -towards, towards)
        normal = np.where((on_plane | (length <= 1e-14))[None], plane_n, towards)
        return np.where(solid, -best, best), normal

    def contacts(self, x, y, z, reach: float, candidates=None) -> list:
        """The contact entries of the points ``(x, y, z)`` (module docstring): ``[(mask,
        normal (3, ...), mu, segment, face), ...]``, one per face (the circular tube's face
        index is ``len(faces)``) and last the convex edges' (face -2); ``mu`` the friction
        coefficient (0 for the tube), ``segment`` the wall profile's (0 the hopper or floor,
        1 the bin, -1 the tube, -2 a convex edge)."""
        x, y, z = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x, y, z)))
        cand = np.ones(x.shape, bool) if candidates is None else np.asarray(candidates, bool)
        p = np.stack([x, y, z])
        out = []
        covered = np.zeros(x.shape, bool)
        for k, face in enumerate(self.faces):
            front, edges = face.in_plane(p)
            ext = np.array([reach if c else 0.0 for c in face.concave]).reshape(
                (-1,) + (1,) * x.ndim)
            mask = cand & np.all(edges >= -ext - 1e-12, axis=0) & (front < reach) & \
                face.outside_hole(p, 1e-12)
            if face.kind == "tube":
                mask &= z < -1e-12
            if not mask.any():
                continue
            n3 = np.broadcast_to(face.normal.reshape((3,) + (1,) * x.ndim), p.shape)
            mu = 0.0 if face.kind == "tube" else math.tan(math.radians(face.friction_deg))
            out.append((mask, n3, mu, face.segment, k))
            covered |= mask
        if self.round_outlet:
            ex, ey = self.outlet_offset
            rho = np.hypot(x - ex, y - ey)
            mask = cand & (rho > 0.5 * self.outlet_x - reach) & (z < -1e-12)
            if mask.any():
                _, _, n3, _ = self._round_tube(p)
                out.append((mask, n3, 0.0, -1, len(self.faces)))
                covered |= mask
        d, n = self.distance_normal(x, y, z)
        corner = cand & (d < reach) & ~covered
        if corner.any():
            out.append((corner, n, math.tan(math.radians(self.segment_friction_deg[0])), -2,
                        -2))
        return out
