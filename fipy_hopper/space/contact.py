"""Wall contact of the 3D model as data, and its numpy reference.

Constraints (:func:`contact_table`): every node that touches an open cell and lies within half a
cell in front of a wall segment's surface (or behind it) is held by it
(:meth:`fipy_hopper.space.boundary.SiloBoundary.contacts`: the surface's normal, its segment's
friction ``mu_w = tan(phi_w)``, tubes frictionless, nodes round the outlet lip by the direction
to it; a rectangular plan's faces likewise, :meth:`fipy_hopper.space.rectangular.
RectangularSilo.contacts`); while the outlet plate is closed, the nodes of the outlet plane in
the outlet (its rim included, ``boundary.outlet_plate``) are held by it (normal ``-e_z``, the
wall's friction).  Mirror planes are
not constraints: the model sets ``v_x = 0`` on ``x = 0`` and ``v_y = 0`` on ``y = 0``.

The contact of a node with all its constraints (:func:`contact_nodes`, the reference of the
compiled :func:`fipy_hopper.space.stepping.contact_node`) gives the velocity closest to the
free one that presses into none: unchanged if it presses into none; else the one-wall impulse
Coulomb contact (the normal part removed, the tangential speed reduced by ``mu`` times the
removed normal speed, not below zero) against the wall whose frictionless projection is the
closest of those that then press into no other; else, at an edge (a concave corner pressed
from both sides), the projection onto the edge of the pair of walls (normal speeds ``a, b >=
0`` removed; the speed along the edge reduced by ``mu_1 a + mu_2 b``) closest among the
feasible pairs; else rest.  Each constraint's impulse ``m dv`` (kg m/s) is added to its entry:
the wall's force on the material times ``dt``.
"""

from __future__ import annotations

import numpy as np


def contact_table(boundary, grid, candidates, plate_friction: float):
    """The constraints grouped by node: ``(nodes (Q, 3) k, j, i; ptr (Q + 1,); normal (K, 3);
    mu (K,); kind (K,) 0 wall / 1 plate; entry (K,) index in its list; segment (n_wall,) the
    profile's segment of each wall entry (-1 tube, -2 convex corner); (n_wall, n_plate);
    face (n_wall,) the face of each wall entry (a rectangular silo's,
    :attr:`fipy_hopper.space.rectangular.RectangularSilo.faces`; a circular silo's: its
    segment))``; nodes in C order, a node's constraints in list order (walls, then the
    plate)."""
    Z, Y, X = np.meshgrid(grid.z_nodes, grid.y_nodes, grid.x_nodes, indexing="ij")
    flat, normals, mus, segs, faces = [], [], [], [], []
    for item in boundary.contacts(X, Y, Z, 0.5 * grid.h, candidates):
        mask, n, mu, seg = item[:4]
        idx = np.flatnonzero(mask)
        flat.append(idx)
        normals.append(n.reshape(3, -1)[:, idx].T)
        mus.append(np.full(len(idx), mu))
        segs.append(np.full(len(idx), seg))
        faces.append(np.full(len(idx), item[4] if len(item) > 4 else seg))
    wall_flat = np.concatenate(flat) if flat else np.zeros(0, np.int64)
    plate = (np.abs(Z) < 1e-12) & boundary.outlet_plate(X, Y) & candidates
    plate_flat = np.flatnonzero(plate)
    node = np.concatenate([wall_flat, plate_flat]).astype(np.int64)
    normal = np.concatenate(normals + [np.tile([0.0, 0.0, -1.0], (len(plate_flat), 1))])
    mu = np.concatenate(mus + [np.full(len(plate_flat), plate_friction)])
    kind = np.concatenate([np.zeros(len(wall_flat), np.int8), np.ones(len(plate_flat), np.int8)])
    entry = np.concatenate([np.arange(len(wall_flat)), np.arange(len(plate_flat))]).astype(
        np.int64)
    order = np.argsort(node, kind="stable")
    node, normal, mu, kind, entry = node[order], normal[order], mu[order], kind[order], \
        entry[order]
    first = np.concatenate([[True], node[1:] != node[:-1]]) if len(node) else np.zeros(0, bool)
    starts = np.flatnonzero(first)
    ptr = np.concatenate([starts, [len(node)]]).astype(np.int64)
    k, j, i = np.unravel_index(node[starts], X.shape)
    nodes = np.stack([k, j, i], axis=1).astype(np.int64)
    return (nodes, ptr, np.ascontiguousarray(normal), mu, kind, entry,
            np.concatenate(segs) if segs else np.zeros(0, np.int64),
            (len(wall_flat), len(plate_flat)),
            np.concatenate(faces) if faces else np.zeros(0, np.int64))


def _dot(a, b):
    """``a . b`` over the last axis, added in the compiled kernel's order."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def contact_nodes(v, mass, table, plate_closed, wall_impulse, plate_impulse):
    """The contact of every node of ``table`` (:func:`contact_table`) with all its constraints,
    vectorised over the nodes, in place (module docstring); the impulses are added."""
    nodes, ptr, normal, mu, kind, entry = table[:6]
    q = len(nodes)
    if q == 0:
        return v
    count = np.diff(ptr)
    kmax = int(count.max())
    slot = np.arange(kmax)
    present = slot[None, :] < count[:, None]
    index = np.where(present, ptr[:-1, None] + slot[None, :], 0)
    active = present & ((kind[index] == 0) | bool(plate_closed))
    n = normal[index]                                          # (Q, K, 3)
    vel = v[:, nodes[:, 0], nodes[:, 1], nodes[:, 2]].T         # (Q, 3)
    m = mass[nodes[:, 0], nodes[:, 1], nodes[:, 2]]
    tol = 1e-14 * np.abs(vel).sum(axis=1)
    vn = _dot(n, vel[:, None, :])
    pressing = active & (vn > 0.0)
    any_pressing = pressing.any(axis=1)
    # one wall
    proj = vel[:, None, :] - vn[..., None] * n
    other = _dot(proj[:, :, None, :], n[:, None, :, :])
    off = active[:, None, :] & ~np.eye(kmax, dtype=bool)[None]
    feasible = ~np.any(off & (other > tol[:, None, None]), axis=2)
    gap = np.where(pressing & feasible, vn, np.inf)
    best = np.argmin(gap, axis=1)
    rows = np.arange(q)
    single = any_pressing & np.isfinite(gap[rows, best])
    bn, bvn, bmu = n[rows, best], vn[rows, best], mu[index[rows, best]]
    t = vel - bvn[:, None] * bn
    speed = np.sqrt(_dot(t, t))
    scale = np.where(speed > 0.0, np.maximum(0.0, 1.0 - bmu * bvn / np.where(speed > 0.0, speed,
                                                                               1.0)), 0.0)
    new = vel.copy()
    new[single] = (scale[:, None] * t)[single]
    _add(single, index[rows, best], m[:, None] * (new - vel), kind, entry, wall_impulse,
         plate_impulse)
    # edges of two walls
    rest = any_pressing & ~single
    edge_best = np.full(q, np.inf)
    edge = np.zeros((q, 2), np.int64)
    edge_ab = np.zeros((q, 2))
    for a_k in range(kmax):
        for b_k in range(a_k + 1, kmax):
            na, nb = n[:, a_k], n[:, b_k]
            g = _dot(na, nb)
            det = 1.0 - g * g
            ok = rest & active[:, a_k] & active[:, b_k] & (det >= 1e-12)
            sdet = np.where(ok, det, 1.0)
            va, vb = vn[:, a_k], vn[:, b_k]
            a = (va - g * vb) / sdet
            b = (vb - g * va) / sdet
            ok &= (a >= -tol) & (b >= -tol)
            p = vel - a[:, None] * na - b[:, None] * nb
            press = _dot(n, p[:, None, :]) > tol[:, None]
            press[:, [a_k, b_k]] = False
            ok &= ~np.any(press & active, axis=1)
            diff = vel - p
            dist = (diff[:, 0] ** 2 + diff[:, 1] ** 2) + diff[:, 2] ** 2
            better = ok & (dist < edge_best)
            edge_best = np.where(better, dist, edge_best)
            edge[better] = (a_k, b_k)
            edge_ab[better] = np.stack([a, b], axis=1)[better]
    on_edge = rest & np.isfinite(edge_best)
    if on_edge.any():
        e = np.flatnonzero(on_edge)
        ca, cb = index[e, edge[e, 0]], index[e, edge[e, 1]]
        a, b = np.maximum(edge_ab[e, 0], 0.0), np.maximum(edge_ab[e, 1], 0.0)
        na, nb = normal[ca], normal[cb]
        p = vel[e] - a[:, None] * na - b[:, None] * nb
        speed = np.sqrt(_dot(p, p))
        fa, fb = mu[ca] * a, mu[cb] * b
        drop = np.minimum(fa + fb, speed)
        scale = np.where(speed > 0.0, 1.0 - drop / np.where(speed > 0.0, speed, 1.0), 0.0)
        w = scale[:, None] * p
        new[e] = w
        share = np.where(fa + fb > 0.0, fa / np.where(fa + fb > 0.0, fa + fb, 1.0), 0.5)
        every = np.ones(len(e), bool)
        _add(every, ca, m[e, None] * (-a[:, None] * na + share[:, None] * (w - p)), kind, entry,
             wall_impulse, plate_impulse)
        _add(every, cb, m[e, None] * (-b[:, None] * nb + (1.0 - share)[:, None] * (w - p)),
             kind, entry, wall_impulse, plate_impulse)
    stop = rest & ~on_edge
    if stop.any():
        hardest = np.argmax(np.where(active, vn, -np.inf), axis=1)
        new[stop] = 0.0
        _add(stop, index[rows, hardest], -m[:, None] * vel, kind, entry, wall_impulse,
             plate_impulse)
    v[:, nodes[:, 0], nodes[:, 1], nodes[:, 2]] = new.T
    return v


def _add(mask, constraint, impulse, kind, entry, wall_impulse, plate_impulse):
    """Add ``impulse[mask]`` to the entries of the constraints ``constraint[mask]``."""
    c = constraint[mask]
    wall = kind[c] == 0
    np.add.at(wall_impulse, entry[c[wall]], impulse[mask][wall])
    np.add.at(plate_impulse, entry[c[~wall]], impulse[mask][~wall])
