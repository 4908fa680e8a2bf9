"""The closed-form cone of the shorthand sizes, as pure functions of ``(r, z)``: an independent
reference the tests hold :class:`fipy_hopper.boundary.Boundary` to (the code has one geometry,
the boundary; this is the cone written out by hand, as the code computed it before).

The wall is a rigid solid occupying ``{r >= r_wall(z)}`` with ``r_wall(z) = R0`` below the
outlet, ``R0 + z tan(theta)`` in the cone (``0 <= z <= h_c``) and ``R`` in the bin; its
boundary is the polyline ``(R0, -far) -> (R0, 0) -> (R, h_c) -> (R, far)``.  A half-angle of
90 degrees is a flat-bottomed bin.  Distances are exact (distance to the nearest segment).
"""

from __future__ import annotations

import numpy as np

from fipy_hopper.boundary import nearest_on_segments
from fipy_hopper.config import HopperGeometry


def wall_polyline(geom: HopperGeometry, r_far: float, z_far: float) -> np.ndarray:
    """Vertices (k, 2) of the wall boundary: free-fall tube, lip, cone (or floor), bin, top.

    Segment 0 is the free-fall tube, 1 the cone (the floor of a flat bin), 2 the bin wall.
    """
    R, R0, hc = geom.bin_radius, geom.outlet_radius, geom.cone_height
    return np.array([[R0, -abs(z_far)], [R0, 0.0], [R, hc], [R, max(z_far, hc)]])


def _nearest_on_polyline(r, z, vertices):
    """Nearest point (pr, pz) on the polyline and the index of its segment, vectorised
    (:func:`fipy_hopper.boundary.nearest_on_segments`)."""
    vertices = np.asarray(vertices, dtype=float)
    pr, pz, seg, _ = nearest_on_segments(r, z, vertices[:-1], vertices[1:])
    return pr, pz, seg


def wall_radius(z, geom: HopperGeometry):
    """Radius of the wall at height ``z`` (m): ``R0`` below the outlet, cone, then bin."""
    z = np.asarray(z, dtype=float)
    if geom.cone_height == 0.0:
        cone = np.where(z > 0.0, geom.bin_radius, geom.outlet_radius)
    else:
        cone = geom.outlet_radius + np.maximum(z, 0.0) * np.tan(geom.half_angle)
    return np.minimum(cone, geom.bin_radius)


def in_solid(r, z, geom: HopperGeometry):
    """True where ``(r, z)`` lies inside the wall body."""
    return np.asarray(r, dtype=float) >= wall_radius(z, geom)


def signed_distance(r, z, geom: HopperGeometry, r_far: float = 1e3, z_far: float = 1e3):
    """Signed distance to the wall (m): positive in the open region, negative inside the wall."""
    vertices = wall_polyline(geom, r_far, z_far)
    pr, pz, _ = _nearest_on_polyline(r, z, vertices)
    d = np.hypot(np.asarray(r, dtype=float) - pr, np.asarray(z, dtype=float) - pz)
    return np.where(in_solid(r, z, geom), -d, d)


def wall_normal(r, z, geom: HopperGeometry, r_far: float = 1e3, z_far: float = 1e3):
    """Unit normal pointing from the open region into the wall, at the nearest wall point.

    Returns ``(n_r, n_z)``; for points on a segment's interior this is the segment's normal; at the
    lip it is the direction from the point to the lip (exact gradient of the distance).
    """
    vertices = wall_polyline(geom, r_far, z_far)
    r = np.asarray(r, dtype=float)
    z = np.asarray(z, dtype=float)
    pr, pz, seg = _nearest_on_polyline(r, z, vertices)
    seg_dir = vertices[1:] - vertices[:-1]
    seg_dir = seg_dir / np.linalg.norm(seg_dir, axis=1)[:, None]
    # a normal of each segment, then oriented into the solid by a probe point
    normals = np.stack([seg_dir[:, 1], -seg_dir[:, 0]], axis=1)
    # orient every segment normal into the solid: probe a point a little along it from the middle
    mid = 0.5 * (vertices[1:] + vertices[:-1])
    probe = mid + 1e-9 * normals
    flip = ~in_solid(probe[:, 0], probe[:, 1], geom)
    normals[flip] *= -1.0
    nr, nz = normals[seg, 0], normals[seg, 1]
    dr, dz = pr - r, pz - z
    dist = np.hypot(dr, dz)
    at_vertex = np.isclose(pr, vertices[seg, 0]) & np.isclose(pz, vertices[seg, 1]) | \
        np.isclose(pr, vertices[seg + 1, 0]) & np.isclose(pz, vertices[seg + 1, 1])
    use_direction = at_vertex & (dist > 1e-12)
    sign = np.where(in_solid(r, z, geom), -1.0, 1.0)
    safe = np.where(dist > 0, dist, 1.0)
    nr = np.where(use_direction, sign * dr / safe, nr)
    nz = np.where(use_direction, sign * dz / safe, nz)
    return nr, nz


def arc_length(z, geom: HopperGeometry):
    """Arc length ``s`` (m) along the wall from the outlet lip up to the bin-wall or cone point
    at height ``z`` (for a flat bin, heights above the floor are on the bin wall)."""
    z = np.asarray(z, dtype=float)
    hc = geom.cone_height
    s_cone = np.minimum(z, hc) / np.cos(geom.half_angle) if hc > 0 else 0.0 * z
    return s_cone + (transition_arc_length(geom) if hc == 0 else 0.0) + np.maximum(z - hc, 0.0)


def arc_length_of_point(r, z, geom: HopperGeometry):
    """Arc length (m) of a wall point ``(r, z)`` on the cone/floor or the bin wall."""
    r = np.asarray(r, dtype=float)
    z = np.asarray(z, dtype=float)
    s_t = transition_arc_length(geom)
    on_cone = (z <= geom.cone_height) & (r < geom.bin_radius - 1e-12) if geom.cone_height > 0 \
        else (z <= 0.0)
    s_cone = np.clip(r - geom.outlet_radius, 0.0, None) / np.sin(geom.half_angle)
    return np.where(on_cone, s_cone, s_t + (z - geom.cone_height))


def wall_point(s, geom: HopperGeometry):
    """The wall point ``(r, z)`` at arc length ``s`` from the lip and the normal into the wall.

    The normal ``(n_r, n_z)`` points from the material into the wall, so ``p_n = -n.sigma.n``.
    """
    s = np.asarray(s, dtype=float)
    hc = geom.cone_height
    s_t = transition_arc_length(geom)
    in_cone = s <= s_t
    th = geom.half_angle
    z = np.where(in_cone, s * np.cos(th) if hc > 0 else 0.0 * s, hc + (s - s_t))
    r = np.where(in_cone, geom.outlet_radius + s * np.sin(th), geom.bin_radius)
    nr = np.where(in_cone, np.cos(th) if hc > 0 else 0.0, 1.0)
    nz = np.where(in_cone, -np.sin(th), 0.0)
    return r, z, nr, nz


def transition_arc_length(geom: HopperGeometry) -> float:
    """Arc length of the cone-cylinder transition from the outlet lip (m): the cone's slant
    length ``(R - R0) / sin(theta)`` (the floor's width for a flat bin)."""
    return (geom.bin_radius - geom.outlet_radius) / np.sin(geom.half_angle)


def segment_contacts(r, z, geom: HopperGeometry, reach: float, r_far: float = 1e3,
                     z_far: float = 1e3):
    """Contact sets of the wall segments: ``[(index, mask, n_r, n_z), ...]``.

    A point is in contact with segment ``k`` when its projection falls on the segment
    (``0 <= t <= 1``, extended by ``reach`` past a concave corner) and it lies less than
    ``reach`` in front of the segment or anywhere behind it (inside the wall).  A point near a
    concave corner (the floor and the bin wall, the cone and the bin) is in contact with both
    segments, so both normals constrain it, also a node just beyond the corner (behind one wall,
    on the line of the other: the corner of a cut cell, which one normal alone let slide along
    the wall); points near
    the convex lip that project beyond both segments belong to none (see
    :func:`wall_normal` for their nearest-point normal).  ``n`` points into the wall.
    """
    vertices = wall_polyline(geom, r_far, z_far)
    r = np.asarray(r, dtype=float)
    z = np.asarray(z, dtype=float)
    out = []
    last = len(vertices) - 2
    for k in range(len(vertices) - 1):
        a, b = vertices[k], vertices[k + 1]
        ab = b - a
        length = float(np.hypot(*ab))
        if length == 0.0:
            continue
        t = ((r - a[0]) * ab[0] + (z - a[1]) * ab[1]) / length ** 2
        normal = np.array([ab[1], -ab[0]]) / length
        mid = 0.5 * (a + b)
        if not in_solid(mid[0] + 1e-9 * normal[0], mid[1] + 1e-9 * normal[1], geom):
            normal = -normal
        # signed distance in front of the segment (positive on the material side)
        front = -((r - a[0]) * normal[0] + (z - a[1]) * normal[1])
        # at a concave corner the segment's line continues into the solid: the nodes within
        # reach beyond the corner (behind the other wall, corners of cut cells on this one)
        # are held by this segment too; at the convex lip it continues into the material
        ext = reach / length
        step = 1e-6 * ab / length
        lo = -ext if k > 0 and in_solid(*(a - step), geom) else 0.0
        hi = 1.0 + ext if k < last and in_solid(*(b + step), geom) else 1.0
        mask = (t >= lo - 1e-12) & (t <= hi + 1e-12) & (front < reach)
        out.append((k, mask, float(normal[0]), float(normal[1])))
    return out
