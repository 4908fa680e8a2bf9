"""Compiled material steps of the 3D model (numba): many explicit steps in one call.

A step is the numpy reference's (:meth:`fipy_hopper.space.model.SpaceModel._step_numpy`, on
:mod:`fipy_hopper.space.momentum`), with the same arithmetic in the same order for the
forces, the node update, the contact and the faces:

1. per *carrying* cell (``alpha != 0``): its corner forces ``-w s . grad N_a + f_hg``
   (``s = alpha (sigma + 2 eta_I D' + eta_b tr(D) I)`` in loaded cells: the law's
   rate-dependent overstress where the cell is flowing, :mod:`fipy_hopper.space.rate3d`, and
   the bulk viscosity ``eta_b``);
   per moving node: the sum of its eight cells' corners in the order 0..7, ``v += dt (f / m -
   g e_z)`` (rest if no heavier than ``light_mass``), the wall and plate contact
   (:func:`contact_node`), the filling damping and the mirror planes;
2. per *loaded* cell (``alpha >= alpha_min``): velocity gradient, Jaumann rotation, the open
   divergence as volumetric strain, the closing of loose volume, then the law's 3D point update
   (:func:`fipy_hopper.material.principal3d.update6_points`: the law's principal-space return),
   the plastic and loose strains and the flowing flag (the return was plastic);
3. the face velocities of the node planes of the material added to the face-flux integral,
   and the transport rule.

The cell lists are made once per call (alpha is constant between transports); the work of a
step is on those cells and the nodes they move.  The stress update is not bit-identical to the
numpy reference's (the eigen-solves differ, :mod:`fipy_hopper.material.principal3d`).

Threads (numba ``prange``; the caller sets their number with ``numba.set_num_threads`` and
passes it): thread ``t`` of ``T`` takes the cells (nodes, blocks of the law's update, node
planes) ``t, t + T, ...`` of each list, so each has its share of the hopper and of the bin.
Every cell writes only its own corner forces and fields, every node only its own velocity and
its own constraints' impulses (a constraint belongs to one node), each node plane only its own
faces; the vertical budget's terms are written per node and summed afterwards in the node
list's order; the law's update runs on blocks of ``return_fast._BLOCK`` points aligned as in
one thread (a point's return does not depend on the others of its block).  So the results do
not depend on the number of threads, to the bit (tested).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from ..material import principal3d as p3
from ..material import return_fast as _fast
from ..material.mohr_coulomb import APEX, ELASTIC
from ..material.rate import overstress_factor
from ..stepping import read_cycles
from .rate3d import deviatoric_rate6

#: points per block of the law's update (the threads take whole blocks)
BLOCK = _fast._BLOCK

_jit = numba.njit(cache=True, error_model="numpy")
_jit_parallel = numba.njit(cache=True, error_model="numpy", parallel=True)

# corner offsets of a = di + 2 dj + 4 dk, and the hourglass vectors at the corners
_DK = np.array([(a >> 2) & 1 for a in range(8)], dtype=np.int64)
_DJ = np.array([(a >> 1) & 1 for a in range(8)], dtype=np.int64)
_DI = np.array([a & 1 for a in range(8)], dtype=np.int64)
_SX = 2.0 * _DI - 1.0
_SY = 2.0 * _DJ - 1.0
_SZ = 2.0 * _DK - 1.0
_HG = np.stack([_SX * _SY, _SY * _SZ, _SX * _SZ, _SX * _SY * _SZ])


@_jit
def _gradient(v, k, j, i, g, L):
    """``L[a, b] = dv_a / dx_b`` of cell (k, j, i) (corners in order 0..7, as the reference)."""
    for a in range(3):
        for b in range(3):
            L[a, b] = 0.0
    for c in range(8):
        kk, jj, ii = k + _DK[c], j + _DJ[c], i + _DI[c]
        sx, sy, sz = _SX[c] * g, _SY[c] * g, _SZ[c] * g
        for a in range(3):
            va = v[a, kk, jj, ii]
            L[a, 0] += sx * va
            L[a, 1] += sy * va
            L[a, 2] += sz * va


@_jit_parallel
def cell_forces(cells, n, alpha, sigma, v, open_volume, h, hg_base, alpha_min, bulk_viscosity,
                contrib, flowing, rate, threads=1):
    """Corner forces ``-f_int + f_hg`` of the cells ``cells[:n]`` (k, j, i) into ``contrib``
    (8, 3, nz, ny, nx), as ``momentum.corner_forces`` and ``hourglass_corner_forces``.  The
    stress of a loaded cell (``alpha >= alpha_min``) in them is ``sigma + 2 eta_I D' + eta_b
    tr(D) I``: the law's rate-dependent overstress where the cell is ``flowing`` (its last
    return was plastic; :mod:`fipy_hopper.space.rate3d` with the law's rate parameters
    ``rate``, none when ``rate[0]``, the grain size, is 0) and the bulk viscosity, added in
    this order."""
    for t in prange(threads):
        _cell_forces_of(t, threads, cells, n, alpha, sigma, v, open_volume, h, hg_base,
                        alpha_min, bulk_viscosity, contrib, flowing, rate)


@_jit
def _cell_forces_of(t, threads, cells, n, alpha, sigma, v, open_volume, h, hg_base, alpha_min,
                    bulk_viscosity, contrib, flowing, rate):
    """:func:`cell_forces` of the cells ``t, t + threads, ...``."""
    g = 1.0 / (4.0 * h)
    L = np.empty((3, 3))
    s = np.empty(6)
    modes = np.empty((4, 3))
    rated = rate[0] != 0.0
    for q in range(t, n, threads):
        k, j, i = cells[q, 0], cells[q, 1], cells[q, 2]
        a = alpha[k, j, i]
        w = open_volume[k, j, i]
        for c in range(6):
            s[c] = sigma[k, j, i, c]
        over = rated and a >= alpha_min and flowing[k, j, i] != 0.0
        if (bulk_viscosity > 0.0 and a >= alpha_min) or over:
            _gradient(v, k, j, i, g, L)
        if over:
            p = -(sigma[k, j, i, 0] + sigma[k, j, i, 1] + sigma[k, j, i, 2]) / 3.0
            d3 = 0.5 * (L[1, 2] + L[2, 1])
            d4 = 0.5 * (L[0, 2] + L[2, 0])
            d5 = 0.5 * (L[0, 1] + L[1, 0])
            e0, e1, e2, gamma_dot = deviatoric_rate6(L[0, 0], L[1, 1], L[2, 2], d3, d4, d5)
            f = overstress_factor(p, gamma_dot, rate)
            s[0] = s[0] + f * e0
            s[1] = s[1] + f * e1
            s[2] = s[2] + f * e2
            s[3] = s[3] + f * d3
            s[4] = s[4] + f * d4
            s[5] = s[5] + f * d5
        if bulk_viscosity > 0.0 and a >= alpha_min:
            p_b = bulk_viscosity * (L[0, 0] + L[1, 1] + L[2, 2])
            s[0] = s[0] + p_b
            s[1] = s[1] + p_b
            s[2] = s[2] + p_b
        for c in range(6):
            s[c] = (a * s[c]) * w
        for m in range(4):
            for d in range(3):
                modes[m, d] = 0.0
        for c in range(8):
            kk, jj, ii = k + _DK[c], j + _DJ[c], i + _DI[c]
            for m in range(4):
                for d in range(3):
                    modes[m, d] += _HG[m, c] * v[d, kk, jj, ii]
        coef = hg_base[k, j, i] * a
        for c in range(8):
            sx, sy, sz = _SX[c] * g, _SY[c] * g, _SZ[c] * g
            f0 = sx * s[0] + sy * s[5] + sz * s[4]
            f1 = sx * s[5] + sy * s[1] + sz * s[3]
            f2 = sx * s[4] + sy * s[3] + sz * s[2]
            h0 = ((_HG[0, c] * modes[0, 0] + _HG[1, c] * modes[1, 0]) + _HG[2, c] * modes[2, 0]) \
                + _HG[3, c] * modes[3, 0]
            h1 = ((_HG[0, c] * modes[0, 1] + _HG[1, c] * modes[1, 1]) + _HG[2, c] * modes[2, 1]) \
                + _HG[3, c] * modes[3, 1]
            h2 = ((_HG[0, c] * modes[0, 2] + _HG[1, c] * modes[1, 2]) + _HG[2, c] * modes[2, 2]) \
                + _HG[3, c] * modes[3, 2]
            contrib[c, 0, k, j, i] = -f0 + -coef * h0
            contrib[c, 1, k, j, i] = -f1 + -coef * h1
            contrib[c, 2, k, j, i] = -f2 + -coef * h2


@_jit
def _project(vx, vy, vz, nx_, ny_, nz_, mu):
    """The one-wall impulse Coulomb contact (normal part removed if pressing, the tangential
    speed reduced by ``mu`` times the removed normal speed, not below zero)."""
    vn = vx * nx_ + vy * ny_ + vz * nz_
    if not vn > 0.0:
        return vx, vy, vz
    tx, ty, tz = vx - vn * nx_, vy - vn * ny_, vz - vn * nz_
    speed = math.sqrt(tx * tx + ty * ty + tz * tz)
    scale = max(0.0, 1.0 - mu * vn / speed) if speed > 0.0 else 0.0
    return scale * tx, scale * ty, scale * tz


@_jit
def contact_node(v, k, j, i, m, k0, k1, normal, mu, kind, entry, plate_closed, wall_impulse,
                 plate_impulse):
    """Contact of node (k, j, i) with its walls ``k0 <= c < k1`` (a plate constraint, ``kind
    1``, only while ``plate_closed``), in place, and each constraint's impulse ``m dv`` added
    to its entry.  The velocity is the closest to the free one that presses into no wall:
    unchanged if it presses into none; else the one-wall contact against the wall whose
    frictionless projection is closest among those that then press into no other; else the
    projection onto the edge of a pair of walls (the normal speeds ``a, b >= 0`` removed, the
    speed along the edge reduced by ``mu_1 a + mu_2 b``) closest among the feasible pairs; else
    rest (given to the wall pressed hardest)."""
    vx, vy, vz = v[0, k, j, i], v[1, k, j, i], v[2, k, j, i]
    tol = 1e-14 * (abs(vx) + abs(vy) + abs(vz))
    best, best_gap, pressing = -1, np.inf, 0
    for c in range(k0, k1):
        if kind[c] == 1 and not plate_closed:
            continue
        vn = vx * normal[c, 0] + vy * normal[c, 1] + vz * normal[c, 2]
        if not vn > 0.0:
            continue
        pressing += 1
        px, py, pz = vx - vn * normal[c, 0], vy - vn * normal[c, 1], vz - vn * normal[c, 2]
        ok = True
        for d in range(k0, k1):
            if d == c or (kind[d] == 1 and not plate_closed):
                continue
            if px * normal[d, 0] + py * normal[d, 1] + pz * normal[d, 2] > tol:
                ok = False
                break
        if ok and vn < best_gap:
            best, best_gap = c, vn
    if pressing == 0:
        return
    if best >= 0:
        wx, wy, wz = _project(vx, vy, vz, normal[best, 0], normal[best, 1], normal[best, 2],
                              mu[best])
        v[0, k, j, i], v[1, k, j, i], v[2, k, j, i] = wx, wy, wz
        imp = plate_impulse if kind[best] == 1 else wall_impulse
        e = entry[best]
        imp[e, 0] += m * (wx - vx)
        imp[e, 1] += m * (wy - vy)
        imp[e, 2] += m * (wz - vz)
        return
    # the edge of two walls
    pa, pb, pa_n, pb_n, best_d = -1, -1, 0.0, 0.0, np.inf
    for c in range(k0, k1):
        if kind[c] == 1 and not plate_closed:
            continue
        for d in range(c + 1, k1):
            if kind[d] == 1 and not plate_closed:
                continue
            gcd = normal[c, 0] * normal[d, 0] + normal[c, 1] * normal[d, 1] \
                + normal[c, 2] * normal[d, 2]
            det = 1.0 - gcd * gcd
            if det < 1e-12:
                continue
            vc = vx * normal[c, 0] + vy * normal[c, 1] + vz * normal[c, 2]
            vd = vx * normal[d, 0] + vy * normal[d, 1] + vz * normal[d, 2]
            a = (vc - gcd * vd) / det
            b = (vd - gcd * vc) / det
            if a < -tol or b < -tol:
                continue
            px = vx - a * normal[c, 0] - b * normal[d, 0]
            py = vy - a * normal[c, 1] - b * normal[d, 1]
            pz = vz - a * normal[c, 2] - b * normal[d, 2]
            ok = True
            for e_ in range(k0, k1):
                if e_ == c or e_ == d or (kind[e_] == 1 and not plate_closed):
                    continue
                if px * normal[e_, 0] + py * normal[e_, 1] + pz * normal[e_, 2] > tol:
                    ok = False
                    break
            dist = (vx - px) ** 2 + (vy - py) ** 2 + (vz - pz) ** 2
            if ok and dist < best_d:
                pa, pb, pa_n, pb_n, best_d = c, d, a, b, dist
    if pa >= 0:
        a, b = max(pa_n, 0.0), max(pb_n, 0.0)
        px = vx - a * normal[pa, 0] - b * normal[pb, 0]
        py = vy - a * normal[pa, 1] - b * normal[pb, 1]
        pz = vz - a * normal[pa, 2] - b * normal[pb, 2]
        speed = math.sqrt(px * px + py * py + pz * pz)
        fa, fb = mu[pa] * a, mu[pb] * b
        drop = min(fa + fb, speed)
        scale = 1.0 - drop / speed if speed > 0.0 else 0.0
        wx, wy, wz = scale * px, scale * py, scale * pz
        v[0, k, j, i], v[1, k, j, i], v[2, k, j, i] = wx, wy, wz
        share = fa / (fa + fb) if fa + fb > 0.0 else 0.5
        for c, lam, sh in ((pa, a, share), (pb, b, 1.0 - share)):
            imp = plate_impulse if kind[c] == 1 else wall_impulse
            e = entry[c]
            imp[e, 0] += m * (-lam * normal[c, 0] + sh * (wx - px))
            imp[e, 1] += m * (-lam * normal[c, 1] + sh * (wy - py))
            imp[e, 2] += m * (-lam * normal[c, 2] + sh * (wz - pz))
        return
    # rest
    v[0, k, j, i], v[1, k, j, i], v[2, k, j, i] = 0.0, 0.0, 0.0
    hard, most = k0, -np.inf
    for c in range(k0, k1):
        if kind[c] == 1 and not plate_closed:
            continue
        vn = vx * normal[c, 0] + vy * normal[c, 1] + vz * normal[c, 2]
        if vn > most:
            hard, most = c, vn
    imp = plate_impulse if kind[hard] == 1 else wall_impulse
    e = entry[hard]
    imp[e, 0] -= m * vx
    imp[e, 1] -= m * vy
    imp[e, 2] -= m * vz


@_jit_parallel
def node_update(nodes, n_nodes, v, mass, contrib, gravity, dt, damping, light_mass, normal, mu,
                kind, entry, plate_closed, mirror_x, mirror_y, wall_impulse, plate_impulse,
                budget, node_budget, threads=1):
    """Velocities of the nodes ``nodes[:n_nodes]`` (k, j, i, first constraint, end): the sum
    of the eight cells' corner forces (order 0..7), ``v + dt (f / m - g e_z)`` (rest if no
    heavier than ``light_mass``), the mirror planes (``v_x = 0`` on ``i = 0``, ``v_y = 0`` on
    ``j = 0``: before the contact, whose friction must not see the unbalanced force across
    the plane, and again after it), the contact (:func:`contact_node`) and the damping
    ``v / (1 + c_d dt)``.  ``budget[0:3]`` gets the vertical impulses of gravity, damping and
    stopped nodes (each node's into ``node_budget[q]``, then added in the list's order)."""
    for t in prange(threads):
        _node_update_of(t, threads, nodes, n_nodes, v, mass, contrib, gravity, dt, damping,
                        light_mass, normal, mu, kind, entry, plate_closed, mirror_x, mirror_y,
                        wall_impulse, plate_impulse, node_budget)
    for c in range(3):
        total = 0.0
        for q in range(n_nodes):
            total += node_budget[q, c]
        budget[c] += total


@_jit
def _node_update_of(t, threads, nodes, n_nodes, v, mass, contrib, gravity, dt, damping,
                    light_mass, normal, mu, kind, entry, plate_closed, mirror_x, mirror_y,
                    wall_impulse, plate_impulse, node_budget):
    """:func:`node_update` of the nodes ``t, t + threads, ...``."""
    nz, ny, nx = contrib.shape[2], contrib.shape[3], contrib.shape[4]
    scale = 1.0 / (1.0 + damping * dt)
    for q in range(t, n_nodes, threads):
        node_budget[q, 0] = 0.0
        node_budget[q, 1] = 0.0
        node_budget[q, 2] = 0.0
        k, j, i = nodes[q, 0], nodes[q, 1], nodes[q, 2]
        m = mass[k, j, i]
        f0, f1, f2 = 0.0, 0.0, 0.0
        for c in range(8):
            kk, jj, ii = k - _DK[c], j - _DJ[c], i - _DI[c]
            if 0 <= kk < nz and 0 <= jj < ny and 0 <= ii < nx:
                f0 += contrib[c, 0, kk, jj, ii]
                f1 += contrib[c, 1, kk, jj, ii]
                f2 += contrib[c, 2, kk, jj, ii]
        if m > light_mass:
            node_budget[q, 0] = -(m * gravity * dt)
            v[0, k, j, i] = v[0, k, j, i] + dt * f0 / m
            v[1, k, j, i] = v[1, k, j, i] + dt * f1 / m
            v[2, k, j, i] = v[2, k, j, i] + dt * (f2 / m - gravity)
        else:
            node_budget[q, 2] = -(m * v[2, k, j, i])
            v[0, k, j, i] = 0.0
            v[1, k, j, i] = 0.0
            v[2, k, j, i] = 0.0
        if mirror_x and i == 0:
            v[0, k, j, i] = 0.0
        if mirror_y and j == 0:
            v[1, k, j, i] = 0.0
        c0, c1 = nodes[q, 3], nodes[q, 4]
        if c1 > c0:
            contact_node(v, k, j, i, m, c0, c1, normal, mu, kind, entry, plate_closed,
                         wall_impulse, plate_impulse)
        if damping > 0.0:
            vz = v[2, k, j, i]
            v[0, k, j, i] *= scale
            v[1, k, j, i] *= scale
            v[2, k, j, i] = vz * scale
            node_budget[q, 1] = m * (v[2, k, j, i] - vz)
        if mirror_x and i == 0:
            v[0, k, j, i] = 0.0
        if mirror_y and j == 0:
            v[1, k, j, i] = 0.0


@_jit_parallel
def stress_update(cells, n, v, sigma, loose, eps_p, flowing, kappa, aperture_z, aperture_y,
                  aperture_x, h, dt, prm, sig_in, dep_in, sig_out, dep_out, status, threads=1):
    """The stress update of the loaded cells ``cells[:n]`` in place: velocity gradient,
    Jaumann rotation, the open divergence as volumetric strain (shared equally by the three
    normal strains), the closing of loose volume, then the law's point update
    (``principal3d.update6_points``) of the gathered cells, the plastic and loose strains and
    ``flowing`` (1 where the return was plastic, else 0).  ``sig_in`` ... ``status``: work
    arrays of at least ``n`` rows.  Thread ``t``
    takes the blocks of :data:`BLOCK` points ``t, t + threads, ...``."""
    n_blocks = (n + BLOCK - 1) // BLOCK
    for t in prange(threads):
        for b in range(t, n_blocks, threads):
            b0 = b * BLOCK
            b1 = min(b0 + BLOCK, n)
            _stress_block(b0, b1, cells, v, sigma, loose, eps_p, flowing, kappa, aperture_z,
                          aperture_y, aperture_x, h, dt, prm, sig_in, dep_in, sig_out,
                          dep_out, status)


@_jit
def _stress_block(b0, b1, cells, v, sigma, loose, eps_p, flowing, kappa, aperture_z,
                  aperture_y, aperture_x, h, dt, prm, sig_in, dep_in, sig_out, dep_out,
                  status):
    """:func:`stress_update` of the points ``b0 <= q < b1``."""
    g = 1.0 / (4.0 * h)
    L = np.empty((3, 3))
    for q in range(b0, b1):
        k, j, i = cells[q, 0], cells[q, 1], cells[q, 2]
        _gradient(v, k, j, i, g, L)
        wyz = 0.5 * (L[1, 2] - L[2, 1]) * dt
        wxz = 0.5 * (L[0, 2] - L[2, 0]) * dt
        wxy = 0.5 * (L[0, 1] - L[1, 0]) * dt
        sxx, syy, szz = sigma[k, j, i, 0], sigma[k, j, i, 1], sigma[k, j, i, 2]
        syz, sxz, sxy = sigma[k, j, i, 3], sigma[k, j, i, 4], sigma[k, j, i, 5]
        # (W s - s W) with W = [[0, wxy, wxz], [-wxy, 0, wyz], [-wxz, -wyz, 0]]
        sig_in[q, 0] = sxx + (2.0 * (wxy * sxy + wxz * sxz))
        sig_in[q, 1] = syy + (2.0 * (-wxy * sxy + wyz * syz))
        sig_in[q, 2] = szz + (2.0 * (-wxz * sxz - wyz * syz))
        sig_in[q, 3] = syz + ((-wxy * sxz + wyz * szz) - (wxz * sxy + wyz * syy))
        sig_in[q, 4] = sxz + ((wxy * syz + wxz * szz) - (wxz * sxx + wyz * sxy))
        sig_in[q, 5] = sxy + ((wxy * syy + wxz * syz) - (wxy * sxx - wyz * sxz))
        d0, d1, d2 = L[0, 0] * dt, L[1, 1] * dt, L[2, 2] * dt
        d3 = 0.5 * (L[1, 2] + L[2, 1]) * dt
        d4 = 0.5 * (L[0, 2] + L[2, 0]) * dt
        d5 = 0.5 * (L[0, 1] + L[1, 0]) * dt
        # the open divergence of the face velocities (means of four nodes)
        wb = 0.25 * (v[2, k, j, i] + v[2, k, j, i + 1] + v[2, k, j + 1, i]
                     + v[2, k, j + 1, i + 1]) * aperture_z[k, j, i]
        wt = 0.25 * (v[2, k + 1, j, i] + v[2, k + 1, j, i + 1] + v[2, k + 1, j + 1, i]
                     + v[2, k + 1, j + 1, i + 1]) * aperture_z[k + 1, j, i]
        ys = 0.25 * (v[1, k, j, i] + v[1, k, j, i + 1] + v[1, k + 1, j, i]
                     + v[1, k + 1, j, i + 1]) * aperture_y[k, j, i]
        yn = 0.25 * (v[1, k, j + 1, i] + v[1, k, j + 1, i + 1] + v[1, k + 1, j + 1, i]
                     + v[1, k + 1, j + 1, i + 1]) * aperture_y[k, j + 1, i]
        xw = 0.25 * (v[0, k, j, i] + v[0, k, j + 1, i] + v[0, k + 1, j, i]
                     + v[0, k + 1, j + 1, i]) * aperture_x[k, j, i]
        xe = 0.25 * (v[0, k, j, i + 1] + v[0, k, j + 1, i + 1] + v[0, k + 1, j, i + 1]
                     + v[0, k + 1, j + 1, i + 1]) * aperture_x[k, j, i + 1]
        kap = kappa[k, j, i]
        div = (((wt - wb) + (yn - ys)) + (xe - xw)) / h / kap if kap > 0.0 else 0.0
        corr = (div * dt - (d0 + d1 + d2)) / 3.0
        d0 += corr
        d1 += corr
        d2 += corr
        compression = -(d0 + d1 + d2)
        old = loose[k, j, i]
        closed = min(old, max(compression, 0.0))
        share = 1.0 - closed / compression if closed > 0.0 else 1.0
        dep_in[q, 0], dep_in[q, 1], dep_in[q, 2] = d0 * share, d1 * share, d2 * share
        dep_in[q, 3], dep_in[q, 4], dep_in[q, 5] = d3 * share, d4 * share, d5 * share
        loose[k, j, i] = old - closed
    p3.update6_points(sig_in[b0:b1], dep_in[b0:b1], prm, sig_out[b0:b1], dep_out[b0:b1],
                      status[b0:b1])
    for q in range(b0, b1):
        k, j, i = cells[q, 0], cells[q, 1], cells[q, 2]
        for c in range(6):
            sigma[k, j, i, c] = sig_out[q, c]
        flowing[k, j, i] = 0.0 if status[q] == ELASTIC else 1.0
        e0, e1, e2 = dep_out[q, 0], dep_out[q, 1], dep_out[q, 2]
        e3, e4, e5 = dep_out[q, 3], dep_out[q, 4], dep_out[q, 5]
        if status[q] == APEX:
            loose[k, j, i] += max(e0 + e1 + e2, 0.0)
        eps_p[k, j, i] += math.sqrt(2.0 / 3.0 * (e0 ** 2 + e1 ** 2 + e2 ** 2
                                                 + 2.0 * (e3 ** 2 + e4 ** 2 + e5 ** 2)))


@_jit_parallel
def faces(k0, k1, v, dt, open_z, open_y, open_x, flux_z, flux_y, flux_x, plane_top,
          threads=1):
    """The face velocities of the node planes ``k0 <= k < k1`` (z-faces of the plane, y- and
    x-faces of the cell layer above it) added to the flux integrals (``u dt``, m); returns the
    largest open-face speed (m/s) (each plane's in ``plane_top[k]``)."""
    for t in prange(threads):
        for k in range(k0 + t, k1, threads):
            plane_top[k] = _faces_of(k, v, dt, open_z, open_y, open_x, flux_z, flux_y, flux_x)
    top = 0.0
    for k in range(k0, k1):
        top = max(top, plane_top[k])
    return top


@_jit
def _faces_of(k, v, dt, open_z, open_y, open_x, flux_z, flux_y, flux_x):
    """:func:`faces` of the node plane ``k``."""
    nz1, ny1, nx1 = v.shape[1], v.shape[2], v.shape[3]
    top = 0.0
    for j in range(ny1 - 1):
        for i in range(nx1 - 1):
            u = 0.25 * (v[2, k, j, i] + v[2, k, j, i + 1] + v[2, k, j + 1, i]
                        + v[2, k, j + 1, i + 1])
            flux_z[k, j, i] += u * dt
            if open_z[k, j, i]:
                top = max(top, abs(u))
    if k < nz1 - 1:
        for j in range(ny1):
            for i in range(nx1 - 1):
                u = 0.25 * (v[1, k, j, i] + v[1, k, j, i + 1] + v[1, k + 1, j, i]
                            + v[1, k + 1, j, i + 1])
                flux_y[k, j, i] += u * dt
                if open_y[k, j, i]:
                    top = max(top, abs(u))
        for j in range(ny1 - 1):
            for i in range(nx1):
                u = 0.25 * (v[0, k, j, i] + v[0, k, j + 1, i] + v[0, k + 1, j, i]
                            + v[0, k + 1, j + 1, i])
                flux_x[k, j, i] += u * dt
                if open_x[k, j, i]:
                    top = max(top, abs(u))
    return top


@_jit
def material_steps(max_steps, clock, v, mass, alpha, sigma, loose, eps_p, flowing, flux_z,
                   flux_y, flux_x, carry, n_carry, loaded, n_loaded, nodes, n_nodes, k0, k1,
                   open_volume, kappa, aperture_z, aperture_y, aperture_x, open_z, open_y,
                   open_x, h, hg_base, prm, dt, g_full, ramp_time, damping, light_mass,
                   alpha_min, bulk_viscosity, transport_cfl, max_transport_interval, normal,
                   mu, kind, entry, plate_closed, mirror_x, mirror_y, wall_impulse,
                   plate_impulse, budget, contrib, sig_in, dep_in, sig_out, dep_out, status,
                   node_budget, plane_top, rate, phase_cycles, threads=1):
    """Up to ``max_steps`` material steps in place (module docstring).  ``clock = [t, step,
    flux_time]``; gravity ``g_full`` ramped over ``ramp_time`` (0: none).  ``carry``/``loaded``
    (n, 3) cell lists, ``nodes`` (n, 5) node list with its contact constraints, ``k0 <= k <
    k1`` the node planes whose faces move.  ``phase_cycles``: empty, or counters of the phases
    ``fipy_hopper.stepping.PHASES`` (the sections' names) to which the cycles of forces, nodes,
    stress update and faces are added (:func:`fipy_hopper.stepping.read_cycles`; nothing else
    changes).  Returns ``(steps done, transport due)``."""
    timed = phase_cycles.size > 0
    for n in range(max_steps):
        t = clock[0]
        gravity = g_full * min(1.0, t / ramp_time) if ramp_time > 0.0 else g_full
        c0 = read_cycles() if timed else 0
        cell_forces(carry, n_carry, alpha, sigma, v, open_volume, h, hg_base, alpha_min,
                    bulk_viscosity, contrib, flowing, rate, threads)
        c1 = read_cycles() if timed else 0
        node_update(nodes, n_nodes, v, mass, contrib, gravity, dt, damping, light_mass, normal,
                    mu, kind, entry, plate_closed, mirror_x, mirror_y, wall_impulse,
                    plate_impulse, budget, node_budget, threads)
        c2 = read_cycles() if timed else 0
        stress_update(loaded, n_loaded, v, sigma, loose, eps_p, flowing, kappa, aperture_z,
                      aperture_y, aperture_x, h, dt, prm, sig_in, dep_in, sig_out, dep_out,
                      status, threads)
        c3 = read_cycles() if timed else 0
        speed = faces(k0, k1, v, dt, open_z, open_y, open_x, flux_z, flux_y, flux_x,
                      plane_top, threads)
        if timed:
            phase_cycles[1] += c1 - c0
            phase_cycles[2] += c2 - c1
            phase_cycles[3] += c3 - c2
            phase_cycles[4] += read_cycles() - c3
        clock[2] += dt
        clock[0] += dt
        clock[1] += 1.0
        if round(clock[2] / dt) >= max_transport_interval:
            return n + 1, True
        if (speed + 1e-30) * (clock[2] + dt) > transport_cfl * h:
            return n + 1, True
    return max_steps, False
