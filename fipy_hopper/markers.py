"""Passive Lagrangian marker points: sharp layer pictures on the fixed Eulerian grid.

The layer tracer carried by the cell transport (upwind / van Leer) smears a layer interface
over a few cells within seconds of discharge, so the layers turn grey.  Marker points moved
with the nodal velocity field keep them sharp: they carry only their layer id and never feed
back into the physics.

A marker set is an ``(n, 3)`` array of rows ``(r, z, layer)``: position in m in the r-z plane
of the axisymmetric hopper and the layer id (an integer stored as float, 0 = bottom layer).

- :func:`seed` puts ``per_side x per_side`` markers on a regular sub-grid of every full cell
  of the hopper;
- :func:`interpolate` evaluates a nodal field at the markers (bilinear);
- :func:`advance` moves them by the displacement field of an interval (midpoint rule), then
  reflects them at the axis, pushes those that went into the wall back to its surface, and
  drops those that fell out of the bottom of the grid.

All functions are pure functions of arrays (no state); the per-marker loop of the midpoint
rule is compiled (numba) and held by a test to the numpy reference :func:`advance_reference`.

The markers follow the nodal velocities, the material fraction the face fluxes of the same
velocities; they agree as long as the velocity field is consistent with ``alpha`` (the model
takes the volumetric strain over the open volume of cut cells for that reason; before it
did, the markers drained faster than the material near a cone wall).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .boundary import in_solid_point, nearest_point

#: Markers pushed out of the wall end this far (fraction of the cell size) in the open region.
WALL_GAP = 1e-6

#: Passes of the wall push; a second one only matters within ``WALL_GAP`` of a wall corner.
WALL_PASSES = 3


def seed(grid, geom, alpha, layer, per_side: int = 2) -> np.ndarray:
    """Markers ``(n, 3)`` = ``(r, z, layer)`` in the full cells of the hopper.

    Every cell with ``alpha > 1/2`` and its centre at ``z >= 0`` (the hopper, above the outlet
    plane) gets the ``per_side x per_side`` points ``r = r_i + (k + 1/2) h_r / per_side``,
    ``z = z_j + (l + 1/2) h_z / per_side`` (m), ``k, l = 0 .. per_side - 1``; points inside the
    wall (:meth:`fipy_hopper.boundary.Boundary.in_solid`) are left out.  The layer id is the cell's layer
    tracer rounded to the nearest integer.  Deterministic: cells in row-major order ``(j, i)``,
    then ``l``, then ``k``.
    """
    if int(per_side) != per_side or per_side < 1:
        raise ValueError(f"per_side must be a positive integer, not {per_side!r}")
    per_side = int(per_side)
    alpha = np.asarray(alpha, dtype=float)
    full = (alpha > 0.5) & (np.asarray(grid.z_cells) >= 0.0)[:, None]
    j, i = np.nonzero(full)
    t = (np.arange(per_side) + 0.5) / per_side
    r_nodes, z_nodes = np.asarray(grid.r_nodes, float), np.asarray(grid.z_nodes, float)
    h_r, h_z = np.diff(r_nodes), np.diff(z_nodes)
    r = r_nodes[i, None, None] + h_r[i, None, None] * t[None, None, :]       # (m, 1, s)
    z = z_nodes[j, None, None] + h_z[j, None, None] * t[None, :, None]       # (m, s, 1)
    ids = np.round(np.asarray(layer, dtype=float)[j, i])[:, None, None]
    r, z, ids = np.broadcast_arrays(r, z, ids)
    keep = ~geom.boundary.in_solid(r, z)
    return np.column_stack([r[keep], z[keep], ids[keep]])


def interpolate(field, r_nodes, z_nodes, r, z) -> np.ndarray:
    """Bilinear interpolation of a nodal field at points ``(r, z)``.

    ``field`` has shape ``(k, nz + 1, nr + 1)`` (``k = 2``: ``(v_r, v_z)``), its node ``(j, i)``
    at ``(r_nodes[i], z_nodes[j])`` (the nodes may be non-uniform).  With the points clamped
    into the grid, ``s = (r - r_i) / (r_{i+1} - r_i)`` and ``t = (z - z_j) / (z_{j+1} - z_j)``
    in their cell,
    ``f = (1 - s)(1 - t) f_{j,i} + s (1 - t) f_{j,i+1} + (1 - s) t f_{j+1,i} + s t f_{j+1,i+1}``.
    Returns ``(k, n)`` in the field's units.
    """
    field = np.asarray(field, dtype=float)
    r_nodes, z_nodes = np.asarray(r_nodes, float), np.asarray(z_nodes, float)
    r = np.clip(np.asarray(r, dtype=float), r_nodes[0], r_nodes[-1])
    z = np.clip(np.asarray(z, dtype=float), z_nodes[0], z_nodes[-1])
    i = np.clip(np.searchsorted(r_nodes, r, side="right") - 1, 0, len(r_nodes) - 2)
    j = np.clip(np.searchsorted(z_nodes, z, side="right") - 1, 0, len(z_nodes) - 2)
    s = (r - r_nodes[i]) / (r_nodes[i + 1] - r_nodes[i])
    t = (z - z_nodes[j]) / (z_nodes[j + 1] - z_nodes[j])
    return ((1 - s) * (1 - t) * field[:, j, i] + s * (1 - t) * field[:, j, i + 1]
            + (1 - s) * t * field[:, j + 1, i] + s * t * field[:, j + 1, i + 1])


def _displacement_at(displacement, grid, r, z, mirror: bool = True) -> np.ndarray:
    """The nodal displacement ``(d_r, d_z)`` at points that may lie at ``r < 0``.

    In a half-section (``mirror``) the field continues across the axis as
    ``d_r(-r, z) = -d_r(r, z)``, ``d_z(-r, z) = d_z(r, z)``.
    """
    if not mirror:
        return interpolate(displacement, grid.r_nodes, grid.z_nodes, r, z)
    d = interpolate(displacement, grid.r_nodes, grid.z_nodes, np.abs(r), z)
    d[0] *= np.where(r < 0.0, -1.0, 1.0)
    return d


def _push_out_of_wall(r, z, geom, gap):
    """Move points inside the wall to the nearest wall point, plus ``gap`` (m) into the open.

    With the signed distance ``d < 0`` and the unit normal ``n`` into the wall
    (:meth:`Boundary.signed_distance`, :meth:`~Boundary.wall_normal`),
    ``x <- x + (d - gap) n``.  Repeated ``WALL_PASSES`` times for points that a corner of the
    wall leaves within ``gap`` of the other segment.
    """
    r, z = r.copy(), z.copy()
    bnd = geom.boundary
    for _ in range(WALL_PASSES):
        inside = np.nonzero(bnd.in_solid(r, z))[0]
        if inside.size == 0:
            break
        ri, zi = r[inside], z[inside]
        d = bnd.signed_distance(ri, zi)
        n_r, n_z = bnd.wall_normal(ri, zi)
        r[inside] = ri + (d - gap) * n_r
        z[inside] = zi + (d - gap) * n_z
    return r, z


def advance(markers, displacement, grid, geom) -> np.ndarray:
    """Markers moved by the nodal displacement field of an interval; returns a new array.

    ``displacement`` ``(2, nz + 1, nr + 1)`` is the integral of the nodal velocity over the
    interval, ``d = int v dt`` (m).  Midpoint (RK2) rule, second order in the interval:
    ``x_mid = x + d(x) / 2``, ``x_new = x + d(x_mid)``, with ``d`` interpolated bilinearly
    (:func:`interpolate`) and continued across the axis as an axisymmetric field.  Then
    ``r < 0`` is reflected to ``|r|`` (the axis), markers inside the wall are pushed back to
    its surface plus ``WALL_GAP h`` into the open region along the wall normal, and markers
    below the grid (``z < z_nodes[0]``) are removed, so the result may be shorter.  The layer
    column is kept.  The midpoint rule runs compiled (:func:`_midpoint_kernel`, the same
    arithmetic as :func:`advance_reference`, which a test holds it to).
    """
    markers = np.ascontiguousarray(markers, dtype=float).reshape(-1, 3)
    r_new = np.empty(len(markers))
    z_new = np.empty(len(markers))
    bnd = geom.boundary
    _midpoint_kernel(markers, np.ascontiguousarray(displacement, dtype=float),
                     np.asarray(grid.r_nodes, float), np.asarray(grid.z_nodes, float),
                     bnd.section.mirror, bnd.kernel_arrays(),
                     np.ascontiguousarray(bnd.table.normal), WALL_GAP * grid.h, WALL_PASSES,
                     r_new, z_new)
    return _kept_markers(markers, r_new, z_new, float(grid.z_nodes[0]))


@njit(cache=True)
def _kept_markers(markers, r_new, z_new, z_min):
    """The moved markers ``(r_new, z_new, layer)`` (n, 3) whose ``z_new >= z_min``, in order."""
    n = 0
    for k in range(markers.shape[0]):
        if z_new[k] >= z_min:
            n += 1
    out = np.empty((n, 3))
    q = 0
    for k in range(markers.shape[0]):
        if z_new[k] >= z_min:
            out[q, 0] = r_new[k]
            out[q, 1] = z_new[k]
            out[q, 2] = markers[k, 2]
            q += 1
    return out


def advance_reference(markers, displacement, grid, geom) -> np.ndarray:
    """:func:`advance` in plain numpy (the reference of the compiled midpoint rule)."""
    markers = np.asarray(markers, dtype=float).reshape(-1, 3)
    r, z = markers[:, 0], markers[:, 1]
    mirror = geom.boundary.section.mirror
    d0 = _displacement_at(displacement, grid, r, z, mirror)
    d_mid = _displacement_at(displacement, grid, r + 0.5 * d0[0], z + 0.5 * d0[1], mirror)
    r_new, z_new = r + d_mid[0], z + d_mid[1]
    if mirror:
        r_new = np.abs(r_new)
    r_new, z_new = _push_out_of_wall(r_new, z_new, geom, WALL_GAP * grid.h)
    keep = z_new >= grid.z_nodes[0]
    return np.column_stack([r_new[keep], z_new[keep], markers[keep, 2]])


@njit(cache=True, error_model="numpy", inline="always")
def _cell_of(x, nodes, inv_spacing):
    """Index ``i`` of the interval ``nodes[i] <= x < nodes[i + 1]`` of clamped ``x``, as
    ``clip(searchsorted(nodes, x, 'right') - 1, 0, n - 2)``: a guess from the mean spacing,
    corrected by comparisons (exact for any node positions)."""
    n = nodes.shape[0]
    i = min(max(int((x - nodes[0]) * inv_spacing), 0), n - 1)
    while i > 0 and nodes[i] > x:
        i -= 1
    while i < n - 1 and nodes[i + 1] <= x:
        i += 1
    return min(i, n - 2)


@njit(cache=True, error_model="numpy", inline="always")
def _interpolate_point(field, r_nodes, z_nodes, r, z):
    """:func:`interpolate` of the two components of ``field`` at one point, same arithmetic."""
    r = min(max(r, r_nodes[0]), r_nodes[-1])
    z = min(max(z, z_nodes[0]), z_nodes[-1])
    i = _cell_of(r, r_nodes, (r_nodes.shape[0] - 1) / (r_nodes[-1] - r_nodes[0]))
    j = _cell_of(z, z_nodes, (z_nodes.shape[0] - 1) / (z_nodes[-1] - z_nodes[0]))
    s = (r - r_nodes[i]) / (r_nodes[i + 1] - r_nodes[i])
    t = (z - z_nodes[j]) / (z_nodes[j + 1] - z_nodes[j])
    out0 = ((1 - s) * (1 - t) * field[0, j, i] + s * (1 - t) * field[0, j, i + 1]
            + (1 - s) * t * field[0, j + 1, i] + s * t * field[0, j + 1, i + 1])
    out1 = ((1 - s) * (1 - t) * field[1, j, i] + s * (1 - t) * field[1, j, i + 1]
            + (1 - s) * t * field[1, j + 1, i] + s * t * field[1, j + 1, i + 1])
    return out0, out1


@njit(cache=True, error_model="numpy", inline="always")
def _isclose(a, b):
    return abs(a - b) <= 1e-8 + 1e-5 * abs(b)


@njit(cache=True, error_model="numpy")
def _push_point(r, z, a, b, normals, gap, inside):
    """One pass of :func:`_push_out_of_wall` for one point inside the wall: the nearest wall
    point (first nearest segment of the boundary's table ``a -> b``), the signed distance and
    the normal as :meth:`Boundary.wall_normal` computes them, then ``x + (d - gap) n``."""
    pr, pz, seg = nearest_point(r, z, a, b)
    dr, dz = pr - r, pz - z
    dist = math.hypot(dr, dz)
    d = -dist if inside else dist
    n_r, n_z = normals[seg, 0], normals[seg, 1]
    at_vertex = ((_isclose(pr, a[seg, 0]) and _isclose(pz, a[seg, 1]))
                 or (_isclose(pr, b[seg, 0]) and _isclose(pz, b[seg, 1])))
    if at_vertex and dist > 1e-12:
        sign = -1.0 if inside else 1.0
        safe = dist if dist > 0 else 1.0
        n_r, n_z = sign * dr / safe, sign * dz / safe
    return r + (d - gap) * n_r, z + (d - gap) * n_z


@njit(cache=True, error_model="numpy", parallel=True)
def _midpoint_kernel(markers, displacement, r_nodes, z_nodes, mirror, solid, normals, gap,
                     passes, r_new, z_new):
    """:func:`advance` of every marker into ``r_new, z_new``: the midpoint rule (with the
    axis reflection in a half-section, ``mirror``), then up to ``passes`` pushes out of the
    wall (:func:`_push_point`; ``solid`` the boundary's :meth:`~Boundary.kernel_arrays`);
    the markers are shared out among numba's threads."""
    a, b = solid[0], solid[1]
    for k in prange(markers.shape[0]):
        r = markers[k, 0]
        z = markers[k, 1]
        d0r, d0z = _interpolate_point(displacement, r_nodes, z_nodes,
                                      abs(r) if mirror else r, z)
        if mirror and r < 0.0:
            d0r = -d0r
        rm = r + 0.5 * d0r
        zm = z + 0.5 * d0z
        dmr, dmz = _interpolate_point(displacement, r_nodes, z_nodes,
                                      abs(rm) if mirror else rm, zm)
        if mirror and rm < 0.0:
            dmr = -dmr
        rn = abs(r + dmr) if mirror else r + dmr
        zn = z + dmz
        for _ in range(passes):
            if not in_solid_point(rn, zn, *solid):
                break
            rn, zn = _push_point(rn, zn, a, b, normals, gap, True)
        r_new[k] = rn
        z_new[k] = zn
