"""Compiled material steps of the Eulerian model: many explicit steps in one call.

:meth:`fipy_hopper.model.HopperModel.advance` runs the material part of the operator split
(stage 1 of :mod:`fipy_hopper.model`) for up to ``max_steps`` steps in one compiled call of
:func:`material_steps`, stopping after the step at which a transport is due.  A step is the
numpy reference's (``HopperModel(..., backend="numpy")``), with the same arithmetic in the
same order, so that each number is the same to the last bit as that of the sequence of
compiled kernels it replaces:

1. nodal forces ``-f_int(alpha (sigma + 2 eta D + 2 eta_I D' + eta_b tr(D) I)) + f_hg``
   (``eta``, ``eta_b``: the grid and the bulk viscosity; ``2 eta_I D'`` the law's
   rate-dependent overstress in the cells whose last return was plastic; ``tr(D)``, in every
   step of a call but its first, as the previous step's strain pass computed it from the same
   velocities): each cell's corner forces, then
   each node's sum of its four cells' in the order in which a cell-by-cell scatter adds them;
   velocity ``v += dt (f / m - g e_z)``, mass-proportional damping, light nodes at rest;
   then, node row by node row, the wall contacts in the order of the model's contact list,
   the outlet plate and the axis (``v_r = 0``);
2. per *loaded* cell (``alpha >= alpha_min``): the Q1 strain increment and spin, the Jaumann
   rotation, the open-volume divergence as volumetric strain, the closing of loose volume
   (first pass, over runs of cells along a row), then the law's compiled point update on a
   block of up to ``BLOCK`` cells (:func:`fipy_hopper.material.return_fast.update_points`: the
   elastic predictor and the Mohr-Coulomb return, the fast lockstep solve with the robust
   return for the points it does not accept; the step does not write the law out again) and
   the plastic and loose strains and the flowing flag (second pass);
3. face velocities, the face-flux integral of the transport, the nodal displacement of the
   markers and the transport rule (the material has crossed ``transport_cfl`` of a cell, or
   ``max_transport_interval`` steps have passed).

What is skipped changes nothing but the cost.  Cells that are not loaded carry no stress and
no loose strain (the reference zeroes them in every step); cells with ``alpha = 0`` push no
node, nor do round-off traces of material whose four nodes are all light (a node no heavier
than ``light_mass`` is set at rest whatever its force: over the reference's discharge about a
third of the cells with ``alpha != 0``, left on the wall); nodes outside the rows of material
have no mass and stay at rest, and their faces carry nothing.  In discharge about half of the
grid is empty or behind the wall.

Work is organised in *runs*, ``(j, i0, i1)``: the cells ``i0 <= i < i1`` of row ``j`` (no
integer division per cell, contiguous inner loops).  The loops over runs, node rows and
blocks are ``prange`` loops (numba threads; the caller sets their number with
``numba.set_num_threads`` and passes it: the runs of the forces and the blocks of the stress
update, which go up the hopper, are dealt to the threads in turn, so that each has its share
of short and long rows and of the plastic cone; one thread runs them in order).  Each sum has
a fixed order, no two threads write the same place and a return does not depend on which
points share its block, so the results do not depend on the number of threads.
"""

from __future__ import annotations

import math
import platform

import numba
import numpy as np
from llvmlite import ir
from numba import prange
from numba.core import types
from numba.extending import intrinsic

from .material import mohr_coulomb as mc
from .material import return_fast as fast
from .material import rate as rate_law
from .material import return_robust as robust

#: largest number of loaded cells in a block of the Mohr-Coulomb solve
BLOCK = fast._BLOCK

_ELASTIC, _PLASTIC, _APEX = mc.ELASTIC, mc.PLASTIC, mc.APEX

_jit = numba.njit(cache=True, error_model="numpy")
_jit_parallel = numba.njit(cache=True, error_model="numpy", parallel=True)

#: the processor has a cycle counter that :func:`read_cycles` reads (x86's time-stamp counter)
HAS_CYCLE_COUNTER = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686", "x86")

if HAS_CYCLE_COUNTER:
    @intrinsic
    def _cycle_counter(typingctx):
        """LLVM's ``readcyclecounter`` (``rdtsc`` on x86): a count rising at a constant rate."""
        def codegen(context, builder, signature, args):
            counter = builder.module.declare_intrinsic(
                "llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
            return builder.call(counter, [])
        return types.int64(), codegen

    @_jit
    def read_cycles():
        """The processor's cycle counter (an integer that rises at a constant rate; the
        profile of :mod:`fipy_hopper.profiling` converts it to seconds)."""
        return _cycle_counter()
else:
    @_jit
    def read_cycles():
        """0: no cycle counter that user code may read on this processor."""
        return 0


@_jit
def _runs(alpha, alpha_min, sigma, loose, v, contrib, carry_runs, load_runs, block_ptr,
          threads=1, mass=None, light_mass=0.0, flowing=None):
    """Runs of carrying (``alpha != 0``; given the node masses ``mass``, also a corner node
    heavier than ``light_mass``) and of loaded cells, the loaded runs cut into blocks
    of at most ``BLOCK`` cells (``block_ptr``: first run of each block, and the end), as
    many as a multiple of the number of threads and of nearly equal size, so that the
    threads' shares of the stress update are even (:func:`_stress_update`).  Zeroes
    stress, loose strain and ``flowing`` (if given) where not loaded, corner forces where
    nothing is carried and the velocity of node rows outside the material.  Returns ``(carry runs, load runs, blocks,
    first node row, end node row)``."""
    nz, nr = alpha.shape
    loaded = 0
    for j in range(nz):
        for i in range(nr):
            if alpha[j, i] >= alpha_min:
                loaded += 1
    blocks = -(-loaded // BLOCK)                     # ceil(loaded / BLOCK) blocks at least,
    blocks = -(-blocks // threads) * threads         # ... a multiple of the threads,
    block = max(-(-loaded // max(blocks, 1)), 1)     # ... of nearly equal size
    n_carry = 0
    n_load = 0
    n_blocks = 0
    in_block = block
    j_lo, j_hi = nz + 1, -1
    for j in range(nz):
        start_c = -1
        start_l = -1
        for i in range(nr + 1):
            a = alpha[j, i] if i < nr else 0.0
            carries = a != 0.0             # round-off traces below zero push the nodes too
            if carries and mass is not None:   # ... if a node they push can move
                carries = (mass[j, i] > light_mass or mass[j, i + 1] > light_mass
                           or mass[j + 1, i] > light_mass or mass[j + 1, i + 1] > light_mass)
            loads = a >= alpha_min
            if i < nr and not loads:
                sigma[j, i, 0] = 0.0
                sigma[j, i, 1] = 0.0
                sigma[j, i, 2] = 0.0
                sigma[j, i, 3] = 0.0
                loose[j, i] = 0.0
                if flowing is not None:
                    flowing[j, i] = 0.0
            if i < nr and not carries:
                for k in range(8):
                    contrib[k, j, i] = 0.0
            if carries and start_c < 0:
                start_c = i
            elif not carries and start_c >= 0:
                carry_runs[n_carry, 0], carry_runs[n_carry, 1] = j, start_c
                carry_runs[n_carry, 2] = i
                n_carry += 1
                start_c = -1
                j_lo, j_hi = min(j_lo, j), j
            if loads and start_l < 0:
                start_l = i
            elif not loads and start_l >= 0:
                while start_l < i:         # cut at block boundaries
                    if in_block == block:
                        block_ptr[n_blocks] = n_load
                        n_blocks += 1
                        in_block = 0
                    end = min(i, start_l + block - in_block)
                    load_runs[n_load, 0], load_runs[n_load, 1] = j, start_l
                    load_runs[n_load, 2] = end
                    n_load += 1
                    in_block += end - start_l
                    start_l = end
                start_l = -1
    block_ptr[n_blocks] = n_load
    if j_hi < 0:
        j_lo, j_hi = 0, -1
    for j in range(nz + 1):
        if j < j_lo or j > j_hi + 1:
            for i in range(nr + 1):
                v[0, j, i] = 0.0
                v[1, j, i] = 0.0
    return n_carry, n_load, n_blocks, j_lo, j_hi + 2


@_jit_parallel
def _cell_forces(carry_runs, n_carry, alpha, sigma, v, open_volume, r_c, h, hg_base, contrib,
                 viscosity, bulk_viscosity, alpha_min, rate_trace, trace_fresh, flowing, rate,
                 threads=1):
    """Corner forces ``-f_int + f_hg`` of the carrying cells into ``contrib`` (8, nz, nr):
    (r, z) at SW, SE, NE, NW, as ``momentum.internal_force`` and ``hourglass_force`` sum them.
    The stress of a loaded cell (``alpha >= alpha_min``) in them is ``sigma + 2 eta D + 2 eta_I
    D' + eta_b tr(D) I``, ``D`` its strain rate (``momentum.strain_rate``) and ``D'`` its
    deviator, with the grid viscosity ``eta`` and the bulk viscosity ``eta_b`` (Pa s; 0: none)
    and, where the cell is ``flowing`` (its last return was plastic), the law's rate-dependent
    overstress ``2 eta_I D'`` (:func:`fipy_hopper.material.rate.overstress_factor` with the
    law's rate parameters ``rate``; none when ``rate[0]``, the grain size, is 0), added in
    this order.  With ``trace_fresh`` (``v`` has not changed since the strain pass of
    :func:`_strain_run` wrote ``rate_trace``, (nz, nr), 1/s) and no grid viscosity or
    overstress in the cell, ``tr(D)`` is read from ``rate_trace``: the same number, computed
    once."""
    g = 1.0 / (2.0 * h)
    two_eta = 2.0 * viscosity
    rated = rate[0] != 0.0
    viscous = viscosity > 0.0 or bulk_viscosity > 0.0 or rated
    for t in prange(threads):       # thread t: runs t, t + T, ... (short and long rows alike)
        for run in range(t, n_carry, threads):
            j, i0, i1 = carry_runs[run, 0], carry_runs[run, 1], carry_runs[run, 2]
            for i in range(i0, i1):
                a = alpha[j, i]
                w = open_volume[j, i]
                t_rr = sigma[j, i, 0]
                t_zz = sigma[j, i, 1]
                t_tt = sigma[j, i, 2]
                t_rz = sigma[j, i, 3]
                if viscous and a >= alpha_min:
                    over = rated and flowing[j, i] != 0.0
                    if trace_fresh and viscosity == 0.0 and not over:
                        trace = rate_trace[j, i]
                    else:
                        vr_sw, vr_se = v[0, j, i], v[0, j, i + 1]
                        vr_ne, vr_nw = v[0, j + 1, i + 1], v[0, j + 1, i]
                        vz_sw, vz_se = v[1, j, i], v[1, j, i + 1]
                        vz_ne, vz_nw = v[1, j + 1, i + 1], v[1, j + 1, i]
                        d_rr = g * (vr_se + vr_ne - vr_sw - vr_nw)
                        d_zz = g * (vz_nw + vz_ne - vz_sw - vz_se)
                        d_tt = 0.25 * (vr_sw + vr_se + vr_ne + vr_nw) / r_c[i]
                        trace = (d_rr + d_zz) + d_tt
                        dvr_dz = g * (vr_nw + vr_ne - vr_sw - vr_se)
                        dvz_dr = g * (vz_se + vz_ne - vz_sw - vz_nw)
                        d_rz = 0.5 * (dvr_dz + dvz_dr)
                        if viscosity > 0.0:
                            t_rr = t_rr + two_eta * d_rr
                            t_zz = t_zz + two_eta * d_zz
                            t_tt = t_tt + two_eta * d_tt
                            t_rz = t_rz + two_eta * d_rz
                        if over:
                            p = -(sigma[j, i, 0] + sigma[j, i, 1] + sigma[j, i, 2]) / 3.0
                            e_rr, e_zz, e_tt, gamma_dot = rate_law.deviatoric_rate(
                                d_rr, d_zz, d_tt, d_rz)
                            f = rate_law.overstress_factor(p, gamma_dot, rate)
                            t_rr = t_rr + f * e_rr
                            t_zz = t_zz + f * e_zz
                            t_tt = t_tt + f * e_tt
                            t_rz = t_rz + f * d_rz
                    if bulk_viscosity > 0.0:
                        p_b = bulk_viscosity * trace
                        t_rr = t_rr + p_b
                        t_zz = t_zz + p_b
                        t_tt = t_tt + p_b
                s_rr = (a * t_rr) * w
                s_zz = (a * t_zz) * w
                s_tt = (a * t_tt) * w
                s_rz = (a * t_rz) * w
                hoop = s_tt / (4.0 * r_c[i])
                c = hg_base[j, i] * a
                mode_r = v[0, j, i] - v[0, j, i + 1] + v[0, j + 1, i + 1] - v[0, j + 1, i]
                mode_z = v[1, j, i] - v[1, j, i + 1] + v[1, j + 1, i + 1] - v[1, j + 1, i]
                contrib[0, j, i] = -(g * (-s_rr - s_rz) + hoop) - c * mode_r
                contrib[1, j, i] = -(g * (-s_rz - s_zz)) - c * mode_z
                contrib[2, j, i] = -(g * (s_rr - s_rz) + hoop) + c * mode_r
                contrib[3, j, i] = -(g * (s_rz - s_zz)) + c * mode_z
                contrib[4, j, i] = -(g * (s_rr + s_rz) + hoop) - c * mode_r
                contrib[5, j, i] = -(g * (s_rz + s_zz)) - c * mode_z
                contrib[6, j, i] = -(g * (-s_rr + s_rz) + hoop) + c * mode_r
                contrib[7, j, i] = -(g * (-s_rz + s_zz)) + c * mode_z


@numba.njit(cache=True, error_model="numpy", inline="always")
def _project(vr, vz, n_r, n_z, mu):
    """The velocity after an impulse Coulomb contact against one wall of normal (n_r, n_z)
    (into the wall): the normal part removed if pressing, the tangential speed reduced by
    ``mu`` times the removed normal speed (not below zero); ``momentum.apply_wall_contact``
    for one node and one wall."""
    vn = vr * n_r + vz * n_z
    if vn > 0.0:
        vr -= vn * n_r
        vz -= vn * n_z
        tn = vr * n_r + vz * n_z
        t_r = vr - tn * n_r
        t_z = vz - tn * n_z
        speed = math.sqrt(t_r * t_r + t_z * t_z)
        scale = 0.0
        if speed > 0.0:
            scale = max(0.0, 1.0 - mu * vn / speed)
        return (vr - t_r) + scale * t_r, (vz - t_z) + scale * t_z
    return vr, vz


@numba.njit(cache=True, error_model="numpy", inline="always")
def _book(k, kind, entry, contact_impulse, plate_impulse, jr, jz):
    """Add the impulse ``(jr, jz)`` to constraint ``k``'s entry (wall or plate)."""
    if kind[k] == 1:
        plate_impulse[entry[k], 0] += jr
        plate_impulse[entry[k], 1] += jz
    else:
        contact_impulse[entry[k], 0] += jr
        contact_impulse[entry[k], 1] += jz


@numba.njit(cache=True, error_model="numpy", inline="always")
def _book_shares(k0, k1, normal, mu, kind, entry, plate_closed, last, lam, lam_t, total_r,
                 total_z, contact_impulse, plate_impulse):
    """Book the compound contact's impulse: to every weighted wall ``k`` (``w_k > 0``) but
    ``last``, ``w_k (lam (-n_k) + lam_t mu_k t_k)``; to ``last`` the rest of ``(total_r,
    total_z)``, so that the shares add up to the node's impulse."""
    rest_r, rest_z = total_r, total_z
    for k in range(k0, k1):
        if (kind[k] == 1 and not plate_closed) or normal[k, 2] <= 0.0 or k == last:
            continue
        n_r, n_z, w = normal[k, 0], normal[k, 1], normal[k, 2]
        f = lam_t * mu[k]
        jr = w * (-(lam * n_r) - f * n_z)
        jz = w * (f * n_r - lam * n_z)
        _book(k, kind, entry, contact_impulse, plate_impulse, jr, jz)
        rest_r = rest_r - jr
        rest_z = rest_z - jz
    _book(last, kind, entry, contact_impulse, plate_impulse, rest_r, rest_z)


@numba.njit(cache=True, error_model="numpy", inline="always")
def _contact_node(v, j, i, mass, k0, k1, normal, mu, kind, entry, plate_closed,
                  contact_impulse, plate_impulse):
    """Contact of node (j, i) with all its walls (constraints ``k0 <= k < k1``; a plate
    constraint, ``kind == 1``, only while ``plate_closed``), in place, and the impulse ``m dv``
    of each constraint added to its entry.  ``normal[k] = (n_r, n_z, w)``: the unit normal
    into the wall and the wall's tributary length ``w`` at the node (the length of the wall in
    the node's dual cell; 0 for a tube, for a convex corner's own normal).

    One wall: :func:`_project`, the impulse Coulomb contact.  A node at a corner (two or more
    walls, e.g. the cone and the bin wall at the transition, a ledge, an insert's corner, the
    lip with the plate) is resolved against its walls together, as one patch of wall made of
    their tributary lengths.  With ``t_k = (-n_z, n_r)`` each wall's friction cone
    ``F_k = {lam (-n_k) + f t_k : |f| <= mu_k lam}``, the patch's normal and friction
    directions are

        N = sum_k w_k (-n_k),   T = sum_k w_k mu_k t_k    (the walls with w_k > 0),

    and its impulses ``J = A N + B T``, ``|B| <= A``, split into one per wall,

        J_k = w_k (A (-n_k) + B mu_k t_k)  in F_k:

    the normal impulses share the patch by the walls' lengths (the same mean pressure on
    both sides of the corner, as a continuous stress gives across a shallow corner) and the
    friction is mobilised alike on every wall (``|B| / A`` of Coulomb's limit on each, so
    ``|J_t,k| <= mu_k J_n,k`` holds on every wall, each in its own frame).  Then, with
    ``J0 = -m v`` the impulse that stops the node:

    1. no wall pressed (``v.n_k <= 0``): free;
    2. ``J0 = A N + B T`` with ``|B| <= A``: the patch holds the node, ``v' = 0``, ``J = J0``;
    3. else the node slides along the wall ``k*`` of the old rule (the closest frictionless
       projection that presses no other wall) with the impulse on the patch cone's edge
       that resists the slide, ``J = lam (N + s T)`` (``s`` the sign of ``B``), ``lam`` such
       that ``v'.n_k* = 0``: accepted when it presses no other wall and slows the slide
       without reversing it (``|v' . t_k*| <= |v . t_k*|``, so ``|v'| <= |v|``: it
       dissipates; where another wall's normal would push along the slide, e.g. sliding away
       from a 90 deg corner, it is refused);
    4. otherwise (one weighted wall, frictionless walls, or 3 refused), the rule the patch
       generalises: the one-wall contact against ``k*`` (all of the impulse to it), or, with
       no such wall, rest with the impulse split between the two walls whose normals span it.

    Why this split: a node at a corner stands for a patch of both walls, and at rest its
    impulse's split is statically indeterminate (any ``J_a in F_a``, ``J0 - J_a in F_b``).
    Giving the whole impulse to one wall (the rule before) left the bin wall's first cell
    above the transition without its share, and the first bin converged at first order;
    sharing the impulse vector by length broke Coulomb on the bin wall, because that node's
    impulse sat on the cone's limit (its friction cone's edge, where no share is
    admissible).  Here the patch's own cone (2) lies inside both walls' cones by construction
    and the node slides (3) when the patch, not the cone alone, cannot hold it: at rest the
    corner's impulse settles on the patch cone's edge, where both walls are at their limit
    and each carries its length's share.  (Projecting onto the walls one after the other is
    not a corner contact: at the outlet lip, with the plate closed, it turned the weight
    pressing on the cone and the plate into a steady inward slide of the lip's node, which
    squeezed the material out of the lip's cells during the fill; 4 keeps the lip's rest.)"""
    vr, vz = v[0, j, i], v[1, j, i]
    if k1 - k0 == 1 and (kind[k0] == 0 or plate_closed):     # one wall: the usual contact
        if vr * normal[k0, 0] + vz * normal[k0, 1] > 0.0:
            wr, wz = _project(vr, vz, normal[k0, 0], normal[k0, 1], mu[k0])
            v[0, j, i], v[1, j, i] = wr, wz
            m = mass[j, i]
            _book(k0, kind, entry, contact_impulse, plate_impulse, m * (wr - vr),
                  m * (wz - vz))
        return
    # the patch of the weighted walls, N and T
    pressing = 0
    weighted = 0
    last = -1
    big_r = 0.0
    big_z = 0.0
    fri_r = 0.0
    fri_z = 0.0
    for k in range(k0, k1):
        if kind[k] == 1 and not plate_closed:
            continue
        if vr * normal[k, 0] + vz * normal[k, 1] > 0.0:
            pressing += 1
        w = normal[k, 2]
        if w > 0.0:
            wm = w * mu[k]
            big_r = big_r - w * normal[k, 0]
            big_z = big_z - w * normal[k, 1]
            fri_r = fri_r - wm * normal[k, 1]
            fri_z = fri_z + wm * normal[k, 0]
            weighted += 1
            last = k
    if pressing == 0:
        return
    m = mass[j, i]
    j0r = -(m * vr)
    j0z = -(m * vz)
    det = big_r * fri_z - big_z * fri_r
    size = (abs(big_r) + abs(big_z)) * (abs(fri_r) + abs(fri_z))
    patch = weighted >= 2 and abs(det) > 1e-9 * size
    a = 0.0
    b = 0.0
    if patch:
        a = (j0r * fri_z - j0z * fri_r) / det
        b = (big_r * j0z - big_z * j0r) / det
        if a >= 0.0 and abs(b) <= a:                           # 2: the patch holds it
            v[0, j, i], v[1, j, i] = 0.0, 0.0
            _book_shares(k0, k1, normal, mu, kind, entry, plate_closed, last, a, b, j0r, j0z,
                         contact_impulse, plate_impulse)
            return
    best = -1
    best_gap = np.inf
    for k in range(k0, k1):
        if kind[k] == 1 and not plate_closed:
            continue
        vn = vr * normal[k, 0] + vz * normal[k, 1]
        if vn <= 0.0:
            continue
        fr, fz = vr - vn * normal[k, 0], vz - vn * normal[k, 1]
        tol = 1e-14 * (abs(vr) + abs(vz))
        feasible = True
        for q in range(k0, k1):
            if q == k or (kind[q] == 1 and not plate_closed):
                continue
            if fr * normal[q, 0] + fz * normal[q, 1] > tol:
                feasible = False
                break
        if feasible and vn < best_gap:
            best, best_gap = k, vn
    if patch and b != 0.0 and best >= 0 and normal[best, 2] > 0.0:    # 3: slide, the patch
        s = 1.0 if b > 0.0 else -1.0
        e_r = big_r + s * fri_r
        e_z = big_z + s * fri_z
        n_r, n_z = normal[best, 0], normal[best, 1]
        push = -(e_r * n_r + e_z * n_z)
        if push > 0.0:
            c = (vr * n_r + vz * n_z) / push
            wr = vr + c * e_r
            wz = vz + c * e_z
            u = vz * n_r - vr * n_z                  # v . t_k*, before and after
            u_new = wz * n_r - wr * n_z
            ok = u * u_new >= 0.0 and abs(u_new) <= abs(u)
            tol = 1e-14 * (abs(vr) + abs(vz))
            for q in range(k0, k1):
                if q == best or (kind[q] == 1 and not plate_closed):
                    continue
                if wr * normal[q, 0] + wz * normal[q, 1] > tol:
                    ok = False
            if ok:
                v[0, j, i], v[1, j, i] = wr, wz
                lam = m * c
                _book_shares(k0, k1, normal, mu, kind, entry, plate_closed, last, lam,
                             s * lam, m * (wr - vr), m * (wz - vz), contact_impulse,
                             plate_impulse)
                return
    if best >= 0:                                              # 4: one wall
        wr, wz = _project(vr, vz, normal[best, 0], normal[best, 1], mu[best])
        v[0, j, i], v[1, j, i] = wr, wz
        _book(best, kind, entry, contact_impulse, plate_impulse, m * (wr - vr), m * (wz - vz))
        return
    # ... or a corner pressed from both sides: rest, J0 split between two walls k, q as
    # J0 = l_k e_k + l_q e_q, l >= 0, e = -n + s mu t: both at the limit of their friction on
    # the side the impulse left the patch cone (s = sign B), else frictionless, else the
    # other side; the first pair that spans J0
    v[0, j, i], v[1, j, i] = 0.0, 0.0
    s_first = -1.0 if b < 0.0 else 1.0
    tol = -1e-12 * (abs(j0r) + abs(j0z))
    for p in range(3):
        s = s_first if p == 0 else (0.0 if p == 1 else -s_first)
        for a_k in range(k0, k1):
            if kind[a_k] == 1 and not plate_closed:
                continue
            fa = s * mu[a_k]
            ea_r = -normal[a_k, 0] - fa * normal[a_k, 1]
            ea_z = fa * normal[a_k, 0] - normal[a_k, 1]
            for b_k in range(a_k + 1, k1):
                if kind[b_k] == 1 and not plate_closed:
                    continue
                fb = s * mu[b_k]
                eb_r = -normal[b_k, 0] - fb * normal[b_k, 1]
                eb_z = fb * normal[b_k, 0] - normal[b_k, 1]
                det = ea_r * eb_z - ea_z * eb_r
                if abs(det) < 1e-12:
                    continue
                la = (j0r * eb_z - j0z * eb_r) / det
                lb = (ea_r * j0z - ea_z * j0r) / det
                if la >= tol and lb >= tol:
                    jr = la * ea_r
                    jz = la * ea_z
                    _book(a_k, kind, entry, contact_impulse, plate_impulse, jr, jz)
                    _book(b_k, kind, entry, contact_impulse, plate_impulse, j0r - jr,
                          j0z - jz)
                    return
    # no pair spans the stop (round-off): all of it to the wall pressed hardest
    k = k0
    most = -np.inf
    for q in range(k0, k1):
        if kind[q] == 1 and not plate_closed:
            continue
        vn = vr * normal[q, 0] + vz * normal[q, 1]
        if vn > most:
            k, most = q, vn
    _book(k, kind, entry, contact_impulse, plate_impulse, j0r, j0z)


@numba.njit(cache=True, error_model="numpy")
def opening_radius(t, opening):
    """Radius (m) inside which the outlet plate has let go at time ``t`` (s) of an opening
    ``opening = [t_open, duration, R_0]``: ``R_0 (t - t_open) / duration`` while it opens,
    infinite once ``t >= t_open + duration``, -1 when ``t_open < 0`` (not opening)."""
    t_open, duration, outlet_radius = opening[0], opening[1], opening[2]
    if t_open < 0.0:
        return -1.0
    if t >= t_open + duration:
        return np.inf
    return outlet_radius * (t - t_open) / duration


@numba.njit(cache=True, error_model="numpy", inline="always")
def _push_node(v, j, i, mass, contrib, gravity, dt, light_mass):
    """Node (j, i) of :func:`_node_update`: its force, the sum of its cells' corner forces
    from 0 in the scatter's order (NE of the cell below left, NW below, SE left, SW own), and
    its new velocity ``v + dt (f / m - g e_z)``, or rest if no heavier than ``light_mass``."""
    nz1, nr1 = mass.shape
    nz, nr = nz1 - 1, nr1 - 1
    fr = 0.0
    fz = 0.0
    if j > 0 and i > 0:
        fr += contrib[4, j - 1, i - 1]
        fz += contrib[5, j - 1, i - 1]
    if j > 0 and i < nr:
        fr += contrib[6, j - 1, i]
        fz += contrib[7, j - 1, i]
    if j < nz and i > 0:
        fr += contrib[2, j, i - 1]
        fz += contrib[3, j, i - 1]
    if j < nz and i < nr:
        fr += contrib[0, j, i]
        fz += contrib[1, j, i]
    m = mass[j, i]
    heavy = m > light_mass
    v[0, j, i] = v[0, j, i] + dt * fr / m if heavy else 0.0
    v[1, j, i] = v[1, j, i] + dt * (fz / m - gravity) if heavy else 0.0


@_jit_parallel
def _node_update(j0, j1, v, mass, contrib, gravity, dt, damping, light_mass, row_nodes,
                 node_i, node_ptr, normal, mu, kind, entry, plate_closed, r_open, node_r,
                 contact_impulse, plate_impulse, row_budget):
    """Velocities of the nodes of rows ``j0 <= j < j1`` from the corner forces (summed in the
    scatter's order: NE of the cell below left, NW below, SE left, SW own; the inner nodes of
    a row in a loop without branches, which the compiler vectorises); then, node by
    node, the contact with the walls and the plate (:func:`_contact_node`; the nodes of row
    ``j`` are ``row_nodes[j]:row_nodes[j + 1]``, node ``q`` at column ``node_i[q]`` with the
    constraints ``node_ptr[q]:node_ptr[q + 1]``; the plate holds a node only while
    ``plate_closed`` and its radius ``node_r[i] >= r_open``), the mass-proportional damping
    (after the contact, so that a wall, not the damping, holds what rests on it) and the axis.

    Measured on the way, without changing a velocity: the impulse ``m dv`` (kg m/s per radian)
    of every wall and plate constraint (:func:`_contact_node`), and each row's vertical
    impulses of gravity (``-m g dt``), of the damping and of stopping light nodes in
    ``row_budget[j, 0:3]``."""
    nz1, nr1 = mass.shape
    nz, nr = nz1 - 1, nr1 - 1
    scale = 1.0 / (1.0 + damping * dt)
    for j in prange(j0, j1):
        weight = 0.0
        damped = 0.0
        stopped = 0.0
        for i in range(nr1):           # the row's impulses, from the velocities before
            m = mass[j, i]
            if m > light_mass:
                weight -= m * gravity * dt
            else:
                stopped -= m * v[1, j, i]
        if 0 < j < nz:                 # inner columns without branches, in the same order
            _push_node(v, j, 0, mass, contrib, gravity, dt, light_mass)
            c0, c1, c2, c3 = contrib[0, j], contrib[1, j], contrib[2, j], contrib[3, j]
            c4, c5 = contrib[4, j - 1], contrib[5, j - 1]
            c6, c7 = contrib[6, j - 1], contrib[7, j - 1]
            v_r, v_z, m_j = v[0, j], v[1, j], mass[j]
            for i in range(1, nr):
                fr = (((0.0 + c4[i - 1]) + c6[i]) + c2[i - 1]) + c0[i]
                fz = (((0.0 + c5[i - 1]) + c7[i]) + c3[i - 1]) + c1[i]
                m = m_j[i]
                heavy = m > light_mass
                v_r[i] = v_r[i] + dt * fr / m if heavy else 0.0
                v_z[i] = v_z[i] + dt * (fz / m - gravity) if heavy else 0.0
            _push_node(v, j, nr, mass, contrib, gravity, dt, light_mass)
        else:
            for i in range(nr1):
                _push_node(v, j, i, mass, contrib, gravity, dt, light_mass)
        for q in range(row_nodes[j], row_nodes[j + 1]):
            i = node_i[q]
            _contact_node(v, j, i, mass, node_ptr[q], node_ptr[q + 1], normal, mu, kind, entry,
                          plate_closed and node_r[i] >= r_open, contact_impulse, plate_impulse)
        if damping > 0.0:
            for i in range(nr1):
                vz = v[1, j, i]
                v[0, j, i] *= scale
                v[1, j, i] = vz * scale
                damped += mass[j, i] * (v[1, j, i] - vz)
        v[0, j, 0] = 0.0
        row_budget[j, 0] = weight
        row_budget[j, 1] = damped
        row_budget[j, 2] = stopped


@_jit
def _strain_run(j, i0, i1, out, v, sigma, loose, r_c, r_nodes, strain_dims, h, dt, kappa,
                zface_aperture, rface_aperture, scratch, rate_trace):
    """First pass over the run ``(j, i0, i1)`` into ``scratch[:, out:out + i1 - i0]``: the
    rotated stress (rows 0-3), the strain increment that loads the skeleton (rows 4-7) and the
    loose strain left (row 8), as ``momentum.strain_rate``, ``jaumann_rotate`` and
    ``open_divergence`` and ``dense_loose.close_loose_volume``; and the trace of the strain
    rate into ``rate_trace[j, i]`` (1/s, for the bulk viscosity of the next step's forces)."""
    g = 1.0 / (2.0 * h)
    for i in range(i0, i1):
        q = out + i - i0
        vr_sw = v[0, j, i]
        vr_se = v[0, j, i + 1]
        vr_ne = v[0, j + 1, i + 1]
        vr_nw = v[0, j + 1, i]
        vz_sw = v[1, j, i]
        vz_se = v[1, j, i + 1]
        vz_ne = v[1, j + 1, i + 1]
        vz_nw = v[1, j + 1, i]
        dvr_dr = g * (vr_se + vr_ne - vr_sw - vr_nw)
        dvr_dz = g * (vr_nw + vr_ne - vr_sw - vr_se)
        dvz_dr = g * (vz_se + vz_ne - vz_sw - vz_nw)
        dvz_dz = g * (vz_nw + vz_ne - vz_sw - vz_se)
        hoop = 0.25 * (vr_sw + vr_se + vr_ne + vr_nw) / r_c[i]
        rate_trace[j, i] = (dvr_dr + dvz_dz) + hoop
        d0 = dvr_dr * dt
        d1 = dvz_dz * dt
        d2 = hoop * dt
        d3 = 0.5 * (dvr_dz + dvz_dr) * dt
        w = 0.5 * (dvr_dz - dvz_dr) * dt
        s_rr = sigma[j, i, 0]
        s_zz = sigma[j, i, 1]
        s_rz = sigma[j, i, 3]
        scratch[0, q] = s_rr + 2.0 * w * s_rz
        scratch[1, q] = s_zz - 2.0 * w * s_rz
        scratch[2, q] = sigma[j, i, 2]
        scratch[3, q] = s_rz + w * (s_zz - s_rr)
        # volumetric part: the net flux of the face velocities over the open volume
        kap = kappa[j, i]
        w_b = 0.5 * (vz_sw + vz_se) * zface_aperture[j, i]
        w_t = 0.5 * (vz_nw + vz_ne) * zface_aperture[j + 1, i]
        u_l = 0.5 * (vr_sw + vr_nw) * rface_aperture[j, i] * r_nodes[i]
        u_r = 0.5 * (vr_se + vr_ne) * rface_aperture[j, i + 1] * r_nodes[i + 1]
        r_mid = 0.5 * (r_nodes[i] + r_nodes[i + 1])
        div = ((w_t - w_b) / h + (u_r - u_l) / (r_mid * h)) / kap if kap > 0.0 else 0.0
        corr = (div * dt - (d0 + d1 + d2)) / strain_dims
        d0 += corr
        d1 += corr
        if strain_dims == 3.0:      # plane strain (2): no strain out of the plane
            d2 += corr
        # compression first closes loose volume
        compression = -(d0 + d1 + d2)
        old = loose[j, i]
        closed = min(old, max(compression, 0.0))
        share = 1.0 - closed / compression if closed > 0.0 else 1.0
        scratch[4, q] = d0 * share
        scratch[5, q] = d1 * share
        scratch[6, q] = d2 * share
        scratch[7, q] = d3 * share
        scratch[8, q] = old - closed


@_jit
def _stress_block(r0, r1, load_runs, v, sigma, loose, eps_p, flowing, r_c, r_nodes, strain_dims,
                  h, dt, kappa, zface_aperture, rface_aperture, prm, cst, rate_trace):
    """Stress update of the loaded cells of the runs ``r0 <= run < r1`` (one block), in place:
    :func:`_strain_run`, then the law's compiled point update
    (:func:`fipy_hopper.material.return_fast.update_points`: the elastic predictor and the
    Mohr–Coulomb return), then the model's closures around it: the loose strain of a return to
    the apex (``dense_loose.separation_strain``), the equivalent plastic strain and
    ``flowing`` (1 where the return was plastic, else 0: the cells in which the law's
    rate-dependent overstress acts in the next step's forces)."""
    E, nu, mu = prm[3], prm[4], prm[1]
    n = 0
    for run in range(r0, r1):
        n += load_runs[run, 2] - load_runs[run, 1]
    scratch = np.empty((9, n))
    cell_j = np.empty(n, dtype=np.int64)
    cell_i = np.empty(n, dtype=np.int64)
    q = 0
    for run in range(r0, r1):
        j, i0, i1 = load_runs[run, 0], load_runs[run, 1], load_runs[run, 2]
        _strain_run(j, i0, i1, q, v, sigma, loose, r_c, r_nodes, strain_dims, h, dt, kappa,
                    zface_aperture, rface_aperture, scratch, rate_trace)
        for i in range(i0, i1):
            cell_j[q] = j
            cell_i[q] = i
            q += 1
    out = np.empty((8, n))
    status = np.empty(n, dtype=np.int8)
    fast.update_points(scratch, n, prm, cst, out, status)
    for q in range(n):
        j, i = cell_j[q], cell_i[q]
        sigma[j, i, 0] = out[0, q]
        sigma[j, i, 1] = out[1, q]
        sigma[j, i, 2] = out[2, q]
        sigma[j, i, 3] = out[3, q]
        loose[j, i] = scratch[8, q]
        if status[q] == _ELASTIC:
            flowing[j, i] = 0.0
            continue
        flowing[j, i] = 1.0
        e0, e1, e2, e3 = out[4, q], out[5, q], out[6, q], out[7, q]
        if status[q] == _APEX:
            loose[j, i] += max(e0 + e1 + e2, 0.0)
        eps_p[j, i] += math.sqrt(2.0 / 3.0 * (e0 ** 2 + e1 ** 2 + e2 ** 2 + 2.0 * e3 ** 2))


@_jit_parallel
def _stress_update(block_ptr, n_blocks, load_runs, v, sigma, loose, eps_p, flowing, r_c,
                   r_nodes, strain_dims, h, dt, kappa, zface_aperture, rface_aperture, prm, cst,
                   rate_trace, threads=1):
    """:func:`_stress_block` for every block; thread ``t`` of ``T`` takes the blocks ``t, t +
    T, ...``: the blocks go up the hopper, so each thread has its share of the cone (where the
    plastic returns are) and of the bin."""
    for t in prange(threads):
        for b in range(t, n_blocks, threads):
            _stress_block(block_ptr[b], block_ptr[b + 1], load_runs, v, sigma, loose, eps_p,
                          flowing, r_c, r_nodes, strain_dims, h, dt, kappa, zface_aperture,
                          rface_aperture, prm, cst, rate_trace)


@_jit
def _moving_rows(j0, j1, mass, v, light_mass):
    """The node rows of ``j0 <= j < j1`` from the lowest to the highest that has a node
    heavier than ``light_mass`` or a node in motion; ``(j0, j0)`` if none.  The rows beyond
    hold only light nodes at rest (round-off traces of material left on the wall), which no
    step moves until the next transport (a light node gets no force, no gravity and no
    contact impulse, :func:`_node_update`) and whose faces carry nothing, so leaving them out
    of the node update and the faces changes nothing but the cost."""
    lowest, highest = -1, -1
    for j in range(j0, j1):
        for i in range(mass.shape[1]):
            if mass[j, i] > light_mass or v[0, j, i] != 0.0 or v[1, j, i] != 0.0:
                if lowest < 0:
                    lowest = j
                highest = j
                break
    if lowest < 0:
        return j0, j0
    return lowest, highest + 1


@_jit_parallel
def _faces(j0, j1, v, dt, face_sign, open_face, face_flux_sum, displacement, with_markers,
           row_speed):
    """For the node rows ``j0 <= j < j1``: the face normal velocities (edge means, FiPy's
    orientation) of the z-faces of the row and of the r-faces above it, added to the flux
    integral; the largest open-face speed per row (``open_face`` is 1 or 0); the markers'
    displacement."""
    nz1, nr1 = v.shape[1], v.shape[2]
    nz, nr = nz1 - 1, nr1 - 1
    n_h = nz1 * nr
    for j in prange(j0, j1):
        top = 0.0
        for i in range(nr):
            f = j * nr + i
            u = 0.5 * (v[1, j, i] + v[1, j, i + 1]) * face_sign[f]
            face_flux_sum[f] += u * dt
            top = max(top, abs(u) * open_face[f])
        if j < nz:
            for i in range(nr1):
                f = n_h + j * nr1 + i
                u = 0.5 * (v[0, j, i] + v[0, j + 1, i]) * face_sign[f]
                face_flux_sum[f] += u * dt
                top = max(top, abs(u) * open_face[f])
        row_speed[j] = top
        if with_markers:
            for i in range(nr1):
                displacement[0, j, i] += dt * v[0, j, i]
                displacement[1, j, i] += dt * v[1, j, i]


#: the phases of :func:`material_steps` in the order of its ``phase_cycles``
PHASES = ("step setup", "forces", "nodes", "stress update", "faces")


@_jit
def material_steps(max_steps, clock, v, mass, alpha, sigma, loose, eps_p, face_flux_sum,
                   displacement, with_markers, open_volume, r_c, r_nodes, strain_dims, h,
                   hg_base, kappa, zface_aperture, rface_aperture, face_sign, open_face, prm,
                   dt, g_full,
                   ramp_time, damping, light_mass, alpha_min, transport_cfl,
                   max_transport_interval, row_nodes, node_i, node_ptr, normal, mu, kind,
                   entry, plate_closed, opening, node_r, contact_impulse, plate_impulse, budget,
                   work, viscosity, bulk_viscosity, rate_trace, flowing, rate, threads,
                   phase_cycles):
    """Up to ``max_steps`` material steps, in place.

    The symmetry is data: ``r_c`` is the radius of the hoop terms (the cell-centre radius;
    infinite in plane strain, where they vanish), ``r_nodes`` the radial weights of the face
    fluxes (the node radius; 1 in plane strain) and ``strain_dims`` the normal strains that
    share the open-divergence correction (3; 2 in plane strain).
    ``clock = [t, step, flux_time]`` (s, -, s) is advanced; gravity is ``g_full`` ramped over
    ``ramp_time`` s (0: none).  The measurements of :func:`_node_update` accumulate in
    ``contact_impulse``, ``plate_impulse`` and ``budget[0:3]`` (vertical impulses of gravity,
    damping and stopped light nodes; kg m/s per radian).  While ``plate_closed`` the outlet
    opens as ``opening`` says (:func:`opening_radius`, each step) over the node radii
    ``node_r``.  ``work = (carry runs (n, 3), load
    runs (n, 3), block pointers (n + 1,), corner forces (8, nz, nr), row speeds (nz + 1,),
    row budgets (nz + 1, 3))``, sized by the model.  ``viscosity`` and ``bulk_viscosity``: the
    grid viscosity ``eta`` and the bulk viscosity ``eta_b`` (Pa s; 0: none) of
    :func:`_cell_forces`; ``rate_trace`` (nz, nr): the trace of each loaded cell's strain rate
    from the strain pass, which the next step's bulk viscosity reads (any contents: the
    first step of a call computes it).  ``flowing`` (nz, nr): 1 where the cell's last return
    was plastic (written by the stress update, read by the next step's forces) and ``rate``:
    the law's rate parameters (``law.rate_parameters()``; zeros: none) of the rate-dependent
    overstress of :func:`_cell_forces`.  ``threads``: the number of numba threads (``numba.
    get_num_threads()``; the work is shared out by it, the results do not depend on it).
    ``phase_cycles``: empty, or ``PHASES`` counters to which the cycles (:func:`read_cycles`)
    spent in each phase are added; reading the counter changes nothing else.
    Returns ``(steps done, transport due)``:
    the loop stops after the step at which a transport is due (the caller transports; alpha is
    constant until then).
    """
    timed = phase_cycles.size > 0
    start = read_cycles() if timed else 0
    carry_runs, load_runs, block_ptr, contrib, row_speed, row_budget = work
    cst = fast._fast_constants(prm)
    n_carry, n_load, n_blocks, j0, j1 = _runs(alpha, alpha_min, sigma, loose, v, contrib,
                                              carry_runs, load_runs, block_ptr, threads, mass,
                                              light_mass, flowing)
    j0, j1 = _moving_rows(j0, j1, mass, v, light_mass)
    jf = max(j0 - 1, 0)         # the r-faces below the lowest node row with material move too
    if timed:
        phase_cycles[0] += read_cycles() - start
    for n in range(max_steps):
        t = clock[0]
        gravity = g_full * min(1.0, t / ramp_time) if ramp_time > 0.0 else g_full
        c0 = read_cycles() if timed else 0
        _cell_forces(carry_runs, n_carry, alpha, sigma, v, open_volume, r_c, h, hg_base,
                     contrib, viscosity, bulk_viscosity, alpha_min, rate_trace, n > 0, flowing,
                     rate, threads)
        c1 = read_cycles() if timed else 0
        _node_update(j0, j1, v, mass, contrib, gravity, dt, damping, light_mass, row_nodes,
                     node_i, node_ptr, normal, mu, kind, entry, plate_closed,
                     opening_radius(t, opening), node_r, contact_impulse, plate_impulse,
                     row_budget)
        for j in range(j0, j1):           # in row order: the sums do not depend on threads
            budget[0] += row_budget[j, 0]
            budget[1] += row_budget[j, 1]
            budget[2] += row_budget[j, 2]
        c2 = read_cycles() if timed else 0
        _stress_update(block_ptr, n_blocks, load_runs, v, sigma, loose, eps_p, flowing, r_c,
                       r_nodes, strain_dims, h, dt, kappa, zface_aperture, rface_aperture, prm,
                       cst, rate_trace, threads)
        c3 = read_cycles() if timed else 0
        _faces(jf, j1, v, dt, face_sign, open_face, face_flux_sum, displacement, with_markers,
               row_speed)
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
        speed = 0.0
        for j in range(jf, j1):
            speed = max(speed, row_speed[j])
        if (speed + 1e-30) * (clock[2] + dt) > transport_cfl * h:
            return n + 1, True
    return max_steps, False


@_jit
def all_finite(a):
    """``np.all(np.isfinite(a))`` without the temporary: stops at the first NaN or inf."""
    for x in a.ravel():
        if not math.isfinite(x):
            return False
    return True


@_jit
def pack_fields(alpha, sigma, eps_p, layer, loose, out):
    """The transported fields ``(alpha, alpha sigma_rr, alpha sigma_zz, alpha sigma_tt,
    alpha sigma_rz, alpha eps_p, alpha layer, alpha e_l)`` of (nz, nr) cells into ``out``
    (8, nz nr), row-major (``model.TRANSPORTED``)."""
    nz, nr = alpha.shape
    for j in range(nz):
        for i in range(nr):
            c = j * nr + i
            a = alpha[j, i]
            out[0, c] = a
            out[1, c] = a * sigma[j, i, 0]
            out[2, c] = a * sigma[j, i, 1]
            out[3, c] = a * sigma[j, i, 2]
            out[4, c] = a * sigma[j, i, 3]
            out[5, c] = a * eps_p[j, i]
            out[6, c] = a * layer[j, i]
            out[7, c] = a * loose[j, i]


@_jit
def unpack_fields(carried, alpha_min, alpha, sigma, eps_p, layer, loose):
    """The cell fields from the transported ones (:func:`pack_fields`), into the outputs:
    each carried field over ``alpha`` where ``alpha >= 1e-12`` (else 0), no stress where
    ``alpha < alpha_min``, the loose strain not below 0."""
    nz, nr = alpha.shape
    for j in range(nz):
        for i in range(nr):
            c = j * nr + i
            a = carried[0, c]
            alpha[j, i] = a
            present = a >= 1e-12
            safe = a if present else 1.0
            stressed = present and a >= alpha_min
            for k in range(4):
                sigma[j, i, k] = carried[1 + k, c] / safe if stressed else 0.0
            eps_p[j, i] = carried[5, c] / safe if present else 0.0
            layer[j, i] = carried[6, c] / safe if present else 0.0
            loose[j, i] = max(carried[7, c] / safe, 0.0) if present else 0.0
