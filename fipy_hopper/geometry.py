"""The wall of a silo by the shorthand's names: thin calls of its
:class:`~fipy_hopper.boundary.Boundary` (``geom.boundary``), the one geometry of the code.

Kept for scripts written against the cone's functions of ``(r, z)``; each works for any
wall the boundary describes.  Nothing here computes a wall of its own.
"""

from __future__ import annotations

import numpy as np

from .config import HopperGeometry


def wall_polyline(geom: HopperGeometry, r_far: float = None, z_far: float = 1e3) -> np.ndarray:
    """Vertices (k, 2) of the (right) wall from its free-fall tube at ``-z_far`` up to
    ``z_far``: the tube's foot, the lip, the wall's points, its top carried straight up.
    (``r_far`` is not used: the wall is carried on vertically.)"""
    points = np.asarray(geom.boundary.chain("wall").points, dtype=float)
    lip, top = points[0], points[-1]
    return np.vstack([[lip[0], -abs(z_far)], points, [[top[0], max(z_far, top[1])]]])


def wall_radius(z, geom: HopperGeometry):
    """The wall's ``x`` (m) at heights ``z`` (:meth:`Boundary.wall_x`)."""
    return geom.boundary.wall_x(z)


def in_solid(r, z, geom: HopperGeometry):
    """True where ``(r, z)`` lies in the solid (:meth:`Boundary.in_solid`)."""
    return geom.boundary.in_solid(r, z)


def signed_distance(r, z, geom: HopperGeometry, r_far: float = None, z_far: float = None):
    """Signed distance to the boundary (m), positive in the open region
    (:meth:`Boundary.signed_distance`)."""
    return geom.boundary.signed_distance(r, z)


def wall_normal(r, z, geom: HopperGeometry, r_far: float = None, z_far: float = None):
    """Unit normal into the solid at the nearest wall point (:meth:`Boundary.wall_normal`)."""
    return geom.boundary.wall_normal(r, z)


def transition_arc_length(geom: HopperGeometry) -> float:
    """Arc length (m) along the wall from the lip to its transition
    (:meth:`Boundary.transition`; the wall's length when it has none)."""
    return geom.boundary.transition_s("wall")


def arc_length(z, geom: HopperGeometry):
    """Arc length (m) along the wall from the lip to its point at height ``z``: below the
    transition the first point of the wall at that height (:meth:`Boundary.arc_at_height`),
    from the transition up the bin wall's (a flat floor's height is the bin wall's foot)."""
    bnd = geom.boundary
    z = np.asarray(z, dtype=float)
    z_t, s_t = bnd.transition_height("wall"), transition_arc_length(geom)
    below = np.vectorize(lambda h: bnd.arc_at_height("wall", h))(np.minimum(z, z_t))
    return np.where(z >= z_t, s_t + (z - z_t), below)


def arc_length_of_point(r, z, geom: HopperGeometry):
    """Arc length (m) along its wall of the nearest wall point of ``(r, z)``
    (:meth:`Boundary.nearest`)."""
    return geom.boundary.nearest(r, z)[4]


def wall_point(s, geom: HopperGeometry):
    """The wall point ``(r, z)`` at arc length ``s`` from the lip and the normal into the wall
    (:meth:`Boundary.wall_point`)."""
    return geom.boundary.wall_point("wall", s)


def segment_contacts(r, z, geom: HopperGeometry, reach: float, r_far: float = None,
                     z_far: float = None):
    """Contact sets of the boundary's segments (:meth:`Boundary.segment_contacts`)."""
    return geom.boundary.segment_contacts(r, z, reach)
