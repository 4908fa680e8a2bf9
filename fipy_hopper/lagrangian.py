"""Updated-Lagrangian mode of the same physics: the mesh moves with the material.

:class:`LagrangianModel` solves the hopper problem of :class:`fipy_hopper.model.HopperModel` --
the same explicit Galerkin momentum step, Mohr-Coulomb update with Jaumann rotation, wall contact,
outlet plate, filling stage and discharge -- on a mesh of bilinear quadrilaterals that initially
fills the hopper's material and whose nodes move with the material (``x += v dt``).  There is no
transport step: elements never exchange material, so the lumped nodal masses are fixed and the
mass is conserved exactly.  It exists to show the method's headline claim: the Lagrangian mesh
distorts as the hopper discharges and the computation has to stop, where the Eulerian one empties
the hopper.  Choices (stated here, held by tests/test_lagrangian.py):

Mesh
    A structured mesh conforming to the wall: ``n_cols = max(2, round(R / h))`` columns of nodes
    spaced evenly between the axis and the wall radius of every node row, so the outer column lies
    on the wall.  The bin rows are ``~h`` apart; the cone rows are graded so that the elements are
    about square (``r_wall`` grows by ``1 + tan(theta) / n_cols`` per row, with a node row exactly
    at the cone-cylinder transition).  A uniform row spacing would start with elements of aspect
    ``R / R0`` at the outlet (5 in the reference hopper), half of the stop limit before anything
    moved; the graded mesh starts every element near aspect 1 and is the fairest start the
    Lagrangian method can get.  A flat-bottomed bin (90 degrees) puts a node column at the
    outlet's radius.  Elements are numbered row by row, nodes SW, SE, NE, NW (counter-clockwise).

Element
    One-point (centroid) quadrature of the general bilinear quadrilateral: the gradient at the
    centroid ``b_r = (z2-z4, z3-z1, z4-z2, z1-z3)/(2A)``,
    ``b_z = (r4-r2, r1-r3, r2-r4, r3-r1)/(2A)`` (nodes 1..4; equal to the element-mean gradient
    of Flanagan & Belytschko 1981), recomputed each step from the current node coordinates.
    Axisymmetric: the volume per radian is ``w = r_c A`` with ``r_c`` the mean node radius, the
    hoop strain rate ``D_tt = mean(v_r) / r_c`` and the hoop force ``w s_tt / (4 r_c)`` on every
    node.  On a rectangle this is exactly the Eulerian kernel of :mod:`fipy_hopper.momentum`
    (tested).  Internal force
    ``f_a = w [b_r,a s_rr + b_z,a s_rz + s_tt/(4 r_c), b_r,a s_rz + b_z,a s_zz]``.
    Viscous hourglass control with the Eulerian coefficient ``kappa_hg rho sqrt(g h_e) w / h_e``
    (``h_e = sqrt(A)``) on the Flanagan-Belytschko hourglass vector
    ``gamma = Gamma - (Gamma.r) b_r - (Gamma.z) b_z``, ``Gamma = (1, -1, 1, -1)`` (equal to
    ``Gamma`` on a rectangle, orthogonal to linear velocity fields on any quad).

Time step
    Central difference: ``v += dt (-f_int + f_hg + m g) / m`` (in ``f_int`` the stress of a
    flowing element carries the law's rate-dependent overstress, from the current velocities,
    as in the Eulerian forces), contact, then (during filling)
    the Eulerian model's mass-proportional damping, applied after the contact as there, so
    that the walls, not the damping, hold what rests on them; the axis; the strain increment
    ``D dt`` and spin from the new velocity on the mid-step configuration ``x + v dt/2``;
    Jaumann rotation and :func:`material.update`; then ``x += v dt``.
    ``dt = dt_safety L_min / c_p`` with ``L_min`` the smallest element length
    ``A / (longest edge)`` (``h`` for a square, so the Eulerian step on the same cell size),
    recomputed every step and never above its initial value.

Contact (the same impulse Coulomb rule as :func:`momentum.apply_wall_contact`)
    Predictive, node by node, against each wall segment (the frictionless free-fall tube below
    the outlet, the cone, the bin wall; the outlet plate ``z = 0, r <= R0`` while it is closed):
    if the node's position after the step, ``x + v dt``, would lie behind the segment (and
    project onto it), the normal velocity is reduced to what brings the node onto the wall,
    ``v_n = gap / dt`` (``v_n = 0`` for a node on the wall), and the tangential velocity by
    ``mu`` times the normal velocity removed (not below zero).  Two passes over the segments
    hold a node in a concave corner by both.  After the move, a node left inside the wall by
    round-off is projected onto it (measured: never needed on the coarse test hopper, fill and
    discharge).  ``v_r = 0`` and ``r = 0`` on the axis.

Stop rule (:class:`DistortionLimits`)
    After every step every active element is checked at its four corners: the corner Jacobian
    ``(x_{a+1} - x_a) x (x_{a-1} - x_a)`` must be positive (else "inverted"), the interior angle
    at least ``min_angle_deg`` (10 deg, else "min_angle"), and the aspect ratio, longest over
    shortest edge, at most ``max_aspect`` (10, else "aspect_ratio").  The step that breaks a limit
    is undone: the state kept is the last valid one, with ``halt = "mesh_distorted"``, and the
    simulation's ``halt`` stop rule ends the run there; the summary names the kind, the element
    and the time.  The limits only bring the stop forward a little: without them the coarse
    test hopper's mesh inverts 26 ms later (4.0% instead of 3.2% discharged).

The run
    :class:`~fipy_hopper.simulation.Simulation` drives it as it drives the Eulerian model (the
    protocol of :mod:`fipy_hopper.protocol`): the same fill to rest, stop rules, time series,
    summary and wall loads.  The wall's reaction is measured as in the Eulerian model: each
    step's contact velocity change times the node mass, the outlet plate's apart, the wall's
    collected at stations half a cell apart along the wall (the station of the node's nearest
    wall point), and the vertical impulses of gravity and of the fill's damping.  The
    stress-sampled estimate averages the elements whose centroids lie within 2.5 element sizes
    of the wall.  ``[numerics] formulation = "lagrangian"`` runs it from the command line and
    :func:`fipy_hopper.run`.

Discharged elements
    By default (``erode_discharged=True``) an element whose four nodes have all fallen below
    ``z = -erode_depth`` (default 0: below the outlet plane) has left the hopper: it is removed
    from the force and stress computation and from the distortion check (element erosion, as a
    Lagrangian code would do), its nodes keep their mass and fall freely.  This only helps the
    Lagrangian run -- without it, the sheared free-falling jet stops the run earlier (measured on
    the coarse test hopper: 0.121 s and 2.4% discharged instead of 0.151 s and 3.2%) -- and the
    run still stops by distortion where the material leaves the hopper.  The mass discharged is
    the mass of the nodes below ``z = 0``; the discharge rate its change per time.

Kernels: the per-step loops over elements and nodes are compiled (numba); each has a plain-numpy
reference (:func:`internal_force`, :func:`hourglass_force`, :func:`strain_rate`,
:func:`element_quality`, :func:`contact_reference`, :func:`project_reference`) that
tests/test_lagrangian.py holds it to.  Masses are reported for the full 3D hopper (``2 pi`` times
the per-radian values), in kg; masses per node are per radian (kg/rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from numba import njit

from .boundary import _wall_x_point, nearest_point
from .config import HopperConfig
from .dense_loose import close_loose_volume, separation_strain
from .material import ELASTIC, equivalent_plastic_strain
from .model import GRAVITY, InstabilityError, ramped_gravity, runaway_speed
from .protocol import SectionMeasures

__all__ = ["DistortionLimits", "LagrangianMesh", "LagrangianState",
           "LagrangianModel", "build_mesh", "element_gradients", "internal_force",
           "hourglass_force", "strain_rate", "element_quality", "contact_reference",
           "project_reference"]

#: Hourglass base vector of the nodes SW, SE, NE, NW
GAMMA = np.array([1.0, -1.0, 1.0, -1.0])


@dataclass(frozen=True)
class DistortionLimits:
    """The stated limits of the Lagrangian run: it stops when an element passes one of them.

    ``max_aspect``: longest over shortest edge; ``min_angle_deg``: smallest interior angle;
    a non-positive corner Jacobian (an inverted or degenerate corner) always stops the run.
    """

    max_aspect: float = 10.0
    min_angle_deg: float = 10.0


# ------------------------------------------------------------------------------------- mesh
@dataclass
class LagrangianMesh:
    """Structured quad mesh of the filled hopper.  ``x`` (n_nodes, 2) holds ``(r, z)`` in m."""

    x: np.ndarray
    conn: np.ndarray           # (n_el, 4) node indices SW, SE, NE, NW (counter-clockwise)
    n_cols: int                # elements per row
    n_rows: int                # element rows
    z_rows: np.ndarray         # (n_rows + 1,) initial node-row heights

    @property
    def n_nodes(self) -> int:
        return len(self.x)

    @property
    def n_elements(self) -> int:
        return len(self.conn)

    def node(self, j, i):
        """Index of the node in row ``j``, column ``i``."""
        return np.asarray(j) * (self.n_cols + 1) + np.asarray(i)


def build_mesh(boundary, h: float) -> LagrangianMesh:
    """The conforming structured mesh of the material filling a boundary (a cone or a flat
    floor under a bin: :attr:`~fipy_hopper.boundary.Boundary.hopper_shape`) to its fill level.

    See the module docstring: ``round(R / h)`` columns between the axis and the wall, bin rows
    about ``h`` apart, cone rows graded to square elements, a node row at the transition.
    """
    shape = boundary.hopper_shape
    R, R0, hc = shape.bin_x, shape.outlet_x, shape.transition_height
    fill = boundary.fill_level - hc
    n_cols = max(2, int(round(R / h)))
    rows = [0.0]
    if hc > 0.0:
        tan_t = (R - R0) / hc
        n_cone = max(1, int(math.ceil(math.log(R / R0) / math.log1p(tan_t / n_cols) - 1e-9)))
        q = (R / R0) ** (1.0 / n_cone)
        r_rows = R0 * q ** np.arange(1, n_cone + 1)
        z_cone = (r_rows - R0) / tan_t
        z_cone[-1] = hc
        rows.extend(z_cone.tolist())
    dz_bin = R / n_cols
    n_bin = max(1, int(round(fill / dz_bin)))
    rows.extend((hc + fill * np.arange(1, n_bin + 1) / n_bin).tolist())
    z_rows = np.asarray(rows)
    if hc > 0.0:
        frac = np.linspace(0.0, 1.0, n_cols + 1)
        r_wall = boundary.wall_x(z_rows)
        R_nodes = frac[None, :] * r_wall[:, None]
    else:  # flat bin: a node column at the outlet radius, the floor beyond it
        n_out = min(max(1, int(round(n_cols * R0 / R))), n_cols - 1)
        r_line = np.concatenate([np.linspace(0.0, R0, n_out + 1),
                                 np.linspace(R0, R, n_cols - n_out + 1)[1:]])
        R_nodes = np.repeat(r_line[None, :], len(z_rows), axis=0)
    Z_nodes = np.repeat(z_rows[:, None], n_cols + 1, axis=1)
    x = np.stack([R_nodes.ravel(), Z_nodes.ravel()], axis=1)
    n_rows = len(z_rows) - 1
    j, i = np.meshgrid(np.arange(n_rows), np.arange(n_cols), indexing="ij")
    sw = (j * (n_cols + 1) + i).ravel()
    conn = np.stack([sw, sw + 1, sw + n_cols + 2, sw + n_cols + 1], axis=1).astype(np.int64)
    return LagrangianMesh(x=x, conn=conn, n_cols=n_cols, n_rows=n_rows, z_rows=z_rows)


# ----------------------------------------------------------------- numpy reference kernels
def element_gradients(x: np.ndarray, conn: np.ndarray):
    """Centroid gradients ``b_r, b_z`` (n_el, 4), area ``A`` and centroid radius ``r_c``.

    ``b_r = (z2-z4, z3-z1, z4-z2, z1-z3) / (2A)``, ``b_z = (r4-r2, r1-r3, r2-r4, r3-r1) / (2A)``,
    ``A = ((r3-r1)(z4-z2) - (r4-r2)(z3-z1)) / 2``; ``r_c`` is the mean node radius.
    """
    r = x[conn, 0]
    z = x[conn, 1]
    A = 0.5 * ((r[:, 2] - r[:, 0]) * (z[:, 3] - z[:, 1])
               - (r[:, 3] - r[:, 1]) * (z[:, 2] - z[:, 0]))
    inv = 1.0 / (2.0 * A)
    b_r = np.stack([z[:, 1] - z[:, 3], z[:, 2] - z[:, 0], z[:, 3] - z[:, 1], z[:, 0] - z[:, 2]],
                   axis=1) * inv[:, None]
    b_z = np.stack([r[:, 3] - r[:, 1], r[:, 0] - r[:, 2], r[:, 1] - r[:, 3], r[:, 2] - r[:, 0]],
                   axis=1) * inv[:, None]
    return b_r, b_z, A, r.mean(axis=1)


def internal_force(x, conn, sigma, n_nodes=None):
    """Nodal internal force (n_nodes, 2), N/rad, of element stresses ``sigma`` (n_el, 4)."""
    b_r, b_z, A, r_c = element_gradients(x, conn)
    w = (r_c * A)[:, None]
    s_rr, s_zz, s_tt, s_rz = (sigma[:, k:k + 1] for k in range(4))
    f_r = w * (b_r * s_rr + b_z * s_rz) + w * s_tt / (4.0 * r_c[:, None])
    f_z = w * (b_r * s_rz + b_z * s_zz)
    n = len(x) if n_nodes is None else n_nodes
    f = np.zeros((n, 2))
    np.add.at(f[:, 0], conn, f_r)
    np.add.at(f[:, 1], conn, f_z)
    return f


def hourglass_force(x, conn, v, hg_scale):
    """Viscous hourglass force (n_nodes, 2): ``f_a = -C gamma_a (gamma . v)`` per element with
    ``gamma = Gamma - (Gamma.r) b_r - (Gamma.z) b_z`` and ``C = hg_scale sqrt(h_e) w / h_e``,
    ``h_e = sqrt(A)``, ``hg_scale = kappa_hg rho sqrt(g)``."""
    b_r, b_z, A, r_c = element_gradients(x, conn)
    gam = GAMMA[None, :] - (x[conn, 0] @ GAMMA)[:, None] * b_r \
        - (x[conn, 1] @ GAMMA)[:, None] * b_z
    he = np.sqrt(np.abs(A))
    c = hg_scale * np.sqrt(he) * r_c * A / he
    f = np.zeros((len(x), 2))
    for k in range(2):
        mode = np.sum(gam * v[conn, k], axis=1)
        np.add.at(f[:, k], conn, -(c * mode)[:, None] * gam)
    return f


def strain_rate(x, conn, v):
    """Element strain rate (n_el, 4) (rr, zz, tt, rz tensor components) and spin ``omega``."""
    b_r, b_z, A, r_c = element_gradients(x, conn)
    vr, vz = v[conn, 0], v[conn, 1]
    dvr_dr = np.sum(b_r * vr, axis=1)
    dvr_dz = np.sum(b_z * vr, axis=1)
    dvz_dr = np.sum(b_r * vz, axis=1)
    dvz_dz = np.sum(b_z * vz, axis=1)
    D = np.stack([dvr_dr, dvz_dz, vr.mean(axis=1) / r_c, 0.5 * (dvr_dz + dvz_dr)], axis=1)
    return D, 0.5 * (dvr_dz - dvz_dr)


def element_quality(x, conn):
    """Per element: smallest corner Jacobian ``e_next x e_prev`` (m^2), aspect ratio (longest over
    shortest edge), smallest interior angle (deg) and length ``A / longest edge`` (m)."""
    p = x[conn]                                        # (n_el, 4, 2)
    e_next = np.roll(p, -1, axis=1) - p
    e_prev = np.roll(p, 1, axis=1) - p
    cross = e_next[..., 0] * e_prev[..., 1] - e_next[..., 1] * e_prev[..., 0]
    dot = np.sum(e_next * e_prev, axis=-1)
    angle = np.degrees(np.arctan2(cross, dot))
    edges = np.linalg.norm(e_next, axis=-1)
    _, _, A, _ = element_gradients(x, conn)
    return cross.min(axis=1), edges.max(axis=1) / edges.min(axis=1), angle.min(axis=1), \
        A / edges.max(axis=1)


def coulomb(vr, vz, n_r, n_z, mu, dvn):
    """The velocity ``(vr, vz)`` after a contact that removes ``dvn`` of its normal part
    (``n`` into the wall) and reduces its tangential speed by ``mu dvn``, not below zero: the
    discrete form of ``|impulse_t| <= mu impulse_n``.  Scalars or arrays alike: the one
    Coulomb rule of the Lagrangian contact (:func:`_contact_kernel`, compiled, and
    :func:`contact_reference`); the Eulerian contact removes the whole normal speed the
    same way (``stepping._project``)."""
    vr = vr - dvn * n_r
    vz = vz - dvn * n_z
    vn = vr * n_r + vz * n_z
    t_r = vr - vn * n_r
    t_z = vz - vn * n_z
    speed = np.sqrt(t_r * t_r + t_z * t_z)
    scale = np.maximum(0.0, 1.0 - mu * dvn / (speed + (speed <= 0.0) * 1.0)) * (speed > 0.0)
    return vn * n_r + scale * t_r, vn * n_z + scale * t_z


_coulomb = njit(cache=True, error_model="numpy", inline="always")(coulomb)


def contact_reference(x, v, dt, segments, passes=2, plate_segment=-1):
    """Numpy reference of :func:`_contact_kernel`: returns the new velocities and the velocity
    changes made by segment ``plate_segment``.

    Within one segment's pass every node is independent, so the node loop vectorises exactly.
    """
    v = v.copy()
    dv_plate = np.zeros_like(v)
    for _ in range(passes):
        for k, (ar, az, br, bz, nr, nz, mu) in enumerate(segments):
            before = v
            ab = np.array([br - ar, bz - az])
            n = np.array([nr, nz])
            p = x + v * dt
            t = ((p - [ar, az]) @ ab) / (ab @ ab)
            behind = -((p - [ar, az]) @ n) < 0.0
            gap = np.maximum(0.0, -((x - [ar, az]) @ n))
            dvn = v @ n - gap / dt
            hit = (t >= -1e-9) & (t <= 1.0 + 1e-9) & behind & (dvn > 0.0)
            new = coulomb(v[:, 0], v[:, 1], nr, nz, mu, np.where(hit, dvn, 0.0))
            v = np.where(hit[:, None], np.stack(new, axis=1), v)
            if k == plate_segment:
                dv_plate += v - before
    return v, dv_plate


def project_reference(x, boundary, plate_closed):
    """Numpy reference of :func:`_project_kernel` (returns the new positions)."""
    x = x.copy()
    r, z = x[:, 0], x[:, 1]
    plate = plate_closed & (z < 0.0) & (r <= boundary.outlet[1])
    rw = boundary.wall_x(z)
    inside = ~plate & (r > rw + 1e-12 * np.maximum(1.0, rw))
    pr, pz, _, _, _ = boundary.nearest(r, z)
    x[inside, 0], x[inside, 1] = pr[inside], pz[inside]
    x[plate, 1] = 0.0
    return x


# ------------------------------------------------------------------- compiled step kernels
@njit(cache=True, error_model="numpy")
def _force_kernel(x, v, conn, sigma, active, hg_scale, force):
    """``force = -f_int + f_hg`` (n_nodes, 2) over the active elements (see module docstring).

    ``hg_scale = kappa_hg rho sqrt(g)``: the hourglass coefficient is
    ``hg_scale sqrt(h_e) w / h_e`` with ``h_e = sqrt(A)``.
    """
    force[:] = 0.0
    br = np.empty(4)
    bz = np.empty(4)
    gam = np.empty(4)
    for e in range(conn.shape[0]):
        if not active[e]:
            continue
        n0, n1, n2, n3 = conn[e, 0], conn[e, 1], conn[e, 2], conn[e, 3]
        r0, r1, r2, r3 = x[n0, 0], x[n1, 0], x[n2, 0], x[n3, 0]
        z0, z1, z2, z3 = x[n0, 1], x[n1, 1], x[n2, 1], x[n3, 1]
        A = 0.5 * ((r2 - r0) * (z3 - z1) - (r3 - r1) * (z2 - z0))
        inv = 1.0 / (2.0 * A)
        br[0] = (z1 - z3) * inv
        br[1] = (z2 - z0) * inv
        br[2] = (z3 - z1) * inv
        br[3] = (z0 - z2) * inv
        bz[0] = (r3 - r1) * inv
        bz[1] = (r0 - r2) * inv
        bz[2] = (r1 - r3) * inv
        bz[3] = (r2 - r0) * inv
        rc = 0.25 * (r0 + r1 + r2 + r3)
        w = rc * A
        s_rr = sigma[e, 0] * w
        s_zz = sigma[e, 1] * w
        s_tt = sigma[e, 2] * w
        s_rz = sigma[e, 3] * w
        hoop = s_tt / (4.0 * rc)
        # hourglass: gamma = Gamma - (Gamma.r) b_r - (Gamma.z) b_z
        gr = r0 - r1 + r2 - r3
        gz = z0 - z1 + z2 - z3
        he = math.sqrt(abs(A))
        c = hg_scale * math.sqrt(he) * w / he
        mode_r = 0.0
        mode_z = 0.0
        for a in range(4):
            sign = 1.0 if a % 2 == 0 else -1.0
            gam[a] = sign - gr * br[a] - gz * bz[a]
            na = conn[e, a]
            mode_r += gam[a] * v[na, 0]
            mode_z += gam[a] * v[na, 1]
        for a in range(4):
            na = conn[e, a]
            force[na, 0] += -(br[a] * s_rr + bz[a] * s_rz + hoop) - c * gam[a] * mode_r
            force[na, 1] += -(br[a] * s_rz + bz[a] * s_zz) - c * gam[a] * mode_z


@njit(cache=True, error_model="numpy")
def _strain_kernel(x, v, dt, conn, sigma, active, d_eps, sigma_rot):
    """Strain increment ``D dt`` (n_el, 4) on configuration ``x`` and the Jaumann-rotated stress
    (as :func:`momentum.strain_rate_jaumann_kernel` on a general quad)."""
    for e in range(conn.shape[0]):
        if not active[e]:
            for k in range(4):
                d_eps[e, k] = 0.0
                sigma_rot[e, k] = 0.0
            continue
        n0, n1, n2, n3 = conn[e, 0], conn[e, 1], conn[e, 2], conn[e, 3]
        r0, r1, r2, r3 = x[n0, 0], x[n1, 0], x[n2, 0], x[n3, 0]
        z0, z1, z2, z3 = x[n0, 1], x[n1, 1], x[n2, 1], x[n3, 1]
        A = 0.5 * ((r2 - r0) * (z3 - z1) - (r3 - r1) * (z2 - z0))
        inv = 1.0 / (2.0 * A)
        br0, br1, br2, br3 = (z1 - z3) * inv, (z2 - z0) * inv, (z3 - z1) * inv, (z0 - z2) * inv
        bz0, bz1, bz2, bz3 = (r3 - r1) * inv, (r0 - r2) * inv, (r1 - r3) * inv, (r2 - r0) * inv
        rc = 0.25 * (r0 + r1 + r2 + r3)
        vr0, vr1, vr2, vr3 = v[n0, 0], v[n1, 0], v[n2, 0], v[n3, 0]
        vz0, vz1, vz2, vz3 = v[n0, 1], v[n1, 1], v[n2, 1], v[n3, 1]
        dvr_dr = br0 * vr0 + br1 * vr1 + br2 * vr2 + br3 * vr3
        dvr_dz = bz0 * vr0 + bz1 * vr1 + bz2 * vr2 + bz3 * vr3
        dvz_dr = br0 * vz0 + br1 * vz1 + br2 * vz2 + br3 * vz3
        dvz_dz = bz0 * vz0 + bz1 * vz1 + bz2 * vz2 + bz3 * vz3
        d_eps[e, 0] = dvr_dr * dt
        d_eps[e, 1] = dvz_dz * dt
        d_eps[e, 2] = 0.25 * (vr0 + vr1 + vr2 + vr3) / rc * dt
        d_eps[e, 3] = 0.5 * (dvr_dz + dvz_dr) * dt
        w = 0.5 * (dvr_dz - dvz_dr) * dt
        s_rr = sigma[e, 0]
        s_zz = sigma[e, 1]
        s_rz = sigma[e, 3]
        sigma_rot[e, 0] = s_rr + 2.0 * w * s_rz
        sigma_rot[e, 1] = s_zz - 2.0 * w * s_rz
        sigma_rot[e, 2] = sigma[e, 2]
        sigma_rot[e, 3] = s_rz + w * (s_zz - s_rr)


@njit(cache=True, error_model="numpy")
def _quality_kernel(x, conn, active, out):
    """Per active element: ``out[e] = (min corner Jacobian, aspect, min angle (deg), A/l_max)``;
    inactive elements get harmless values."""
    for e in range(conn.shape[0]):
        if not active[e]:
            out[e, 0] = 1.0
            out[e, 1] = 1.0
            out[e, 2] = 90.0
            out[e, 3] = np.inf
            continue
        jmin = np.inf
        amin = np.inf          # the smallest angle of a corner with a negative Jacobian (deg)
        cmax = -1.0            # the largest cosine of a corner with a positive Jacobian
        lmax = 0.0
        lmin = np.inf
        for a in range(4):
            na = conn[e, a]
            nn = conn[e, (a + 1) % 4]
            npv = conn[e, (a + 3) % 4]
            e1r = x[nn, 0] - x[na, 0]
            e1z = x[nn, 1] - x[na, 1]
            e2r = x[npv, 0] - x[na, 0]
            e2z = x[npv, 1] - x[na, 1]
            cross = e1r * e2z - e1z * e2r
            dot = e1r * e2r + e1z * e2z
            jmin = min(jmin, cross)
            l1 = math.sqrt(e1r * e1r + e1z * e1z)
            l2 = math.sqrt(e2r * e2r + e2z * e2z)
            if cross > 0.0:
                if l1 > 0.0 and l2 > 0.0:
                    cmax = max(cmax, dot / (l1 * l2))
            else:
                amin = min(amin, math.degrees(math.atan2(cross, dot)))
            lmax = max(lmax, l1)
            lmin = min(lmin, l1)
        if cmax > -1.0:        # one acos per element: the angle falls as its cosine rises
            amin = min(amin, math.degrees(math.acos(min(1.0, cmax))))
        n0, n1, n2, n3 = conn[e, 0], conn[e, 1], conn[e, 2], conn[e, 3]
        A = 0.5 * ((x[n2, 0] - x[n0, 0]) * (x[n3, 1] - x[n1, 1])
                   - (x[n3, 0] - x[n1, 0]) * (x[n2, 1] - x[n0, 1]))
        out[e, 0] = jmin
        out[e, 1] = lmax / lmin if lmin > 0.0 else np.inf
        out[e, 2] = amin if amin < np.inf else 0.0
        out[e, 3] = A / lmax if lmax > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def _contact_kernel(x, v, dt, segments, n_segments, passes, plate_segment, dv_plate):
    """Predictive impulse Coulomb contact of every node against the segments, in place.

    ``segments`` rows ``(a_r, a_z, b_r, b_z, n_r, n_z, mu)``, ``n`` into the wall.  A node whose
    predicted position ``x + v dt`` lies behind a segment (projecting onto it) gets its normal
    velocity reduced to ``gap / dt`` and its tangential speed reduced by ``mu`` times the normal
    velocity removed (not below zero).  The velocity changes made by segment
    ``plate_segment`` (the outlet plate; -1 for none) are added to ``dv_plate`` (n_nodes, 2),
    so that the plate's reaction is told from the wall's.
    """
    for _ in range(passes):
        for k in range(n_segments):
            ar, az, bbr, bbz = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
            nr_, nz_, mu = segments[k, 4], segments[k, 5], segments[k, 6]
            abr = bbr - ar
            abz = bbz - az
            l2 = abr * abr + abz * abz
            for i in range(x.shape[0]):
                pr = x[i, 0] + v[i, 0] * dt
                pz = x[i, 1] + v[i, 1] * dt
                t = ((pr - ar) * abr + (pz - az) * abz) / l2
                if t < -1e-9 or t > 1.0 + 1e-9:
                    continue
                front_pred = -((pr - ar) * nr_ + (pz - az) * nz_)
                if front_pred >= 0.0:
                    continue
                gap = max(0.0, -((x[i, 0] - ar) * nr_ + (x[i, 1] - az) * nz_))
                vn = v[i, 0] * nr_ + v[i, 1] * nz_
                dvn = vn - gap / dt
                if dvn <= 0.0:
                    continue
                new_r, new_z = _coulomb(v[i, 0], v[i, 1], nr_, nz_, mu, dvn)
                if k == plate_segment:
                    dv_plate[i, 0] += new_r - v[i, 0]
                    dv_plate[i, 1] += new_z - v[i, 1]
                v[i, 0] = new_r
                v[i, 1] = new_z


@njit(cache=True, error_model="numpy")
def _project_kernel(x, a, b, rows, r0, plate_closed):
    """Move nodes left inside the wall (round-off) onto the nearest wall point (the
    boundary's segments ``a -> b``; the wall's ``x`` at a height from its ``rows``,
    :func:`fipy_hopper.boundary.wall_x`); nodes below a closed outlet plate (``r <= r0``) onto
    the plate.  Returns the number of nodes moved."""
    moved = 0
    for i in range(x.shape[0]):
        r = x[i, 0]
        z = x[i, 1]
        if plate_closed and z < 0.0 and r <= r0:
            x[i, 1] = 0.0
            moved += 1
            continue
        rw = _wall_x_point(z, rows, r0)
        if r <= rw + 1e-12 * max(1.0, rw):
            continue
        px, pz, _ = nearest_point(r, z, a, b)
        x[i, 0] = px
        x[i, 1] = pz
        moved += 1
    return moved


# ------------------------------------------------------------------------------------ state
@dataclass
class LagrangianState:
    """Everything that evolves in a Lagrangian run (the state of
    :class:`~fipy_hopper.protocol.HopperModelProtocol`)."""

    t: float
    step: int
    stage: str                     # "filling" or "discharge"
    x: np.ndarray                  # (n_nodes, 2) node positions (r, z), m
    v: np.ndarray                  # (n_nodes, 2) node velocities, m/s
    sigma: np.ndarray              # (n_el, 4) element stress (rr, zz, tt, rz), Pa
    eps_p: np.ndarray              # (n_el,) accumulated equivalent plastic strain
    active: np.ndarray             # (n_el,) bool: not eroded
    dt: float
    plate_closed: bool = True
    loose: np.ndarray = None       # (n_el,) loose strain (dense_loose.close_loose_volume)
    discharged: float = 0.0        # kg (3D) of the nodes below the outlet plane
    lost: float = 0.0              # nothing leaves a Lagrangian mesh
    # measurements, cumulative per radian (kg m/s), as in fipy_hopper.model.State: the wall's
    # impulse on the nodes per wall station (LagrangianModel.wall_entries), the plate's, and
    # the vertical momentum budget (gravity, damping, stopped, outflow)
    wall_impulse: np.ndarray = None
    plate_impulse: np.ndarray = None
    momentum_budget: np.ndarray = None
    halt: str = ""                 # "mesh_distorted" once an element broke a limit
    halt_detail: str = ""          # which element, how, when
    halt_kind: str = ""            # inverted | aspect_ratio | min_angle
    halt_element: int = -1
    flowing: np.ndarray = None     # (n_el,) bool: the last return was plastic (the overstress)

    def copy(self) -> "LagrangianState":
        return LagrangianState(**{k: (v.copy() if isinstance(v, np.ndarray) else v)
                                  for k, v in self.__dict__.items()})


# ------------------------------------------------------------------------------------ model
class LagrangianModel(SectionMeasures):
    """Updated-Lagrangian axisymmetric hopper of a :class:`HopperConfig` (module docstring).

    It implements :class:`~fipy_hopper.protocol.HopperModelProtocol`, so
    :class:`~fipy_hopper.simulation.Simulation` runs it exactly as the Eulerian model: the same
    fill to rest, stop rules, time series, wall loads from the wall's reaction and summary.
    """

    formulation = "lagrangian"

    def __init__(self, cfg: HopperConfig, limits: DistortionLimits = DistortionLimits(),
                 erode_discharged: bool = True, erode_depth: float = 0.0,
                 n_layers: int = 8):
        from .config import ConfigError

        if not cfg.hopper.axisymmetric:
            raise ConfigError("the Lagrangian mode models conical hoppers only "
                              "(hopper.shape = \"conical\"); run a wedge with the Eulerian model")
        self.cfg = cfg
        self.limits = limits
        self.erode_discharged = erode_discharged
        geom = cfg.hopper
        self.geom = geom
        self.boundary = bnd = cfg.boundary
        self.erode_depth = float(erode_depth)
        self.h = self.cell_size = cfg.numerics.cell_size
        self.mesh = build_mesh(bnd, self.h)
        self.n_cells = self.mesh.n_elements
        self.material = cfg.material.law()
        #: the law has a rate dependence (an overstress in flowing elements)
        self._rated = bool(self.material.rate_parameters()[0] != 0.0)
        self.rho = cfg.material.density
        self.c_p = self.material.p_wave_speed
        self.mu_wall = cfg.wall.friction_coefficient
        self.section_factor = 2.0 * math.pi
        self.ramp_time = cfg.ramp_time
        m = self.mesh
        _, _, A, r_c = element_gradients(m.x, m.conn)
        if np.any(A <= 0):
            raise ValueError("the Lagrangian mesh has an element of non-positive area")
        self.volume0 = r_c * A                                 # m^3/rad
        mass = np.zeros(m.n_nodes)
        np.add.at(mass, m.conn, 0.25 * self.rho * self.volume0[:, None])
        self.node_mass = mass                                  # kg/rad, fixed
        self._mass_sum = float(mass.sum())                     # kg/rad
        self.total_mass_kg = 2.0 * math.pi * self._mass_sum    # kg
        zc0 = m.x[m.conn, 1].mean(axis=1)
        self.layer = np.floor(np.clip(zc0 / geom.fill_level, 0, 0.999999) * n_layers)
        self.axis_nodes = np.flatnonzero(m.x[:, 0] == 0.0)
        self.hg_scale = cfg.numerics.hourglass_coefficient * self.rho * math.sqrt(GRAVITY)
        q = element_quality(m.x, m.conn)
        self.initial_quality = {"max_aspect": float(q[1].max()), "min_angle_deg": float(q[2].min())}
        self.dt0 = self.dt = self.material.stable_time_step(float(q[3].min()),
                                                            cfg.numerics.dt_safety)
        column = max(geom.fill_level, self.h)
        self.fill_damping = math.pi * self.c_p / (2.0 * column)
        # the boundary's segments (tube: frictionless; cone or floor; bin) and the outlet plate
        tab = bnd.table
        self._kernel = bnd.kernel_arrays()      # segments a, b and the wall's rows of x(z)
        self.outlet_radius = bnd.outlet[1]
        segs = [[*tab.a[k], *tab.b[k], *tab.normal[k], 0.0 if tab.tube[k] else self.mu_wall]
                for k in range(len(tab))]
        self.wall_segments = np.array(segs)
        plate = [0.0, 0.0, self.outlet_radius, 0.0, 0.0, -1.0, self.mu_wall]
        self.segments_closed = np.array(segs + [plate])
        self._stations()
        self._force = np.zeros((m.n_nodes, 2))
        self._d_eps = np.zeros((m.n_elements, 4))
        self._sig_rot = np.zeros((m.n_elements, 4))
        self._quality = np.zeros((m.n_elements, 4))
        self._dv_plate = np.zeros((m.n_nodes, 2))
        self.last_quality = None

    def _stations(self):
        """The wall stations that collect the wall's impulse: the free-fall tube (one), and
        the cone (or floor) and the bin wall divided into stretches of about half a cell;
        each station stands for its stretch (arc length ``s`` at its middle, normal into the
        wall there)."""
        bnd = self.boundary
        s_t = float(bnd.transition("wall").s)
        s_top = float(bnd.chain("wall").length)
        n_cone = max(1, int(math.ceil(s_t / (0.5 * self.h))))
        n_bin = max(1, int(math.ceil((s_top - s_t) / (0.5 * self.h))))
        self._s_t, self._ds_cone, self._ds_bin = s_t, s_t / n_cone, (s_top - s_t) / n_bin
        s = np.concatenate([[0.0], (np.arange(n_cone) + 0.5) * self._ds_cone,
                            s_t + (np.arange(n_bin) + 0.5) * self._ds_bin])
        _, _, n_r, n_z = bnd.wall_point("wall", s)
        normal = np.stack([n_r, n_z], axis=1)
        normal[0] = (-1.0, 0.0) if self.outlet_radius > 0 else (0.0, -1.0)   # the tube
        segment = np.concatenate([[0], np.ones(n_cone, int), np.full(n_bin, 2)])
        self._wall_stations = (s, normal, segment)
        self._n_cone = n_cone

    # ------------------------------------------------------------------ state
    def initial_state(self) -> LagrangianState:
        """The mesh filling the hopper at rest, stress free, outlet plate closed."""
        m = self.mesh
        return LagrangianState(t=0.0, step=0, stage="filling", x=m.x.copy(),
                               v=np.zeros((m.n_nodes, 2)), sigma=np.zeros((m.n_elements, 4)),
                               eps_p=np.zeros(m.n_elements),
                               active=np.ones(m.n_elements, dtype=bool), dt=self.dt0,
                               loose=np.zeros(m.n_elements),
                               wall_impulse=np.zeros((len(self._wall_stations[0]), 2)),
                               plate_impulse=np.zeros((1, 2)), momentum_budget=np.zeros(4),
                               flowing=np.zeros(m.n_elements, dtype=bool))

    def gravity(self, state: LagrangianState) -> float:
        """Gravity (m/s^2, downward) at this time (:func:`~fipy_hopper.model.ramped_gravity`)."""
        return ramped_gravity(state, self.ramp_time)

    def open_outlet(self, state: LagrangianState) -> None:
        """Remove the outlet plate: discharge starts."""
        state.plate_closed = False
        state.stage = "discharge"

    def transport_step(self, state: LagrangianState) -> None:
        """Nothing to carry: the mesh moves with the material."""

    def reset_caches(self) -> None:
        """Nothing is cached from a state."""

    def discharged_mass(self, state: LagrangianState) -> float:
        """Mass (kg, 3D) of the nodes below the outlet plane."""
        return 2.0 * math.pi * float(self.node_mass[state.x[:, 1] < 0.0].sum())

    def mass_in_hopper(self, state: LagrangianState) -> float:
        """Mass (kg, 3D) of the nodes at or above the outlet plane."""
        return 2.0 * math.pi * float(self.node_mass[state.x[:, 1] >= 0.0].sum())

    def total_mass(self, state: LagrangianState) -> float:
        """Mass (kg, 3D) of the mesh: fixed."""
        return self.total_mass_kg

    def kinetic_energy(self, state: LagrangianState) -> float:
        """Kinetic energy of the nodal velocities (J, 3D)."""
        return math.pi * float(np.sum(self.node_mass * (state.v[:, 0] ** 2 + state.v[:, 1] ** 2)))

    def vertical_momentum(self, state: LagrangianState) -> float:
        """``sum m v_z`` over the nodes (kg m/s per radian)."""
        return float(np.sum(self.node_mass * state.v[:, 1]))

    def quality(self, state: LagrangianState) -> np.ndarray:
        """(n_el, 4): min corner Jacobian, aspect, min angle (deg), length ``A / l_max``."""
        _quality_kernel(state.x, self.mesh.conn, state.active, self._quality)
        return self._quality

    def check_distortion(self, state: LagrangianState, q: Optional[np.ndarray] = None):
        """``None`` if every active element is within the limits, else ``(kind, element, text)``.

        ``q``: the element quality of this state if already computed (:meth:`step` leaves it in
        ``self.last_quality``)."""
        q = self.quality(state) if q is None else q
        lim = self.limits
        checks = (("inverted", q[:, 0] <= 0.0, "non-positive corner Jacobian {:.4g} m^2", 0),
                  ("min_angle", q[:, 2] < lim.min_angle_deg,
                   "smallest interior angle {:.4g} deg < %g deg" % lim.min_angle_deg, 2),
                  ("aspect_ratio", q[:, 1] > lim.max_aspect,
                   "aspect ratio {:.4g} > %g" % lim.max_aspect, 1))
        for kind, bad, text, col in checks:
            if bad.any():
                worst = np.flatnonzero(bad)
                e = int(worst[np.argmin(q[worst, col]) if col != 1 else np.argmax(q[worst, col])])
                rc, zc = state.x[self.mesh.conn[e]].mean(axis=0)
                return kind, e, (f"element {e} (centroid r = {rc:.4g} m, z = {zc:.4g} m): "
                                 + text.format(q[e, col]))
        return None

    def check_stable(self, state: LagrangianState) -> None:
        """Raise :class:`~fipy_hopper.model.InstabilityError` on a non-finite velocity or
        stress, or a runaway velocity (the Eulerian model's limit)."""
        speed = np.hypot(state.v[:, 0], state.v[:, 1])
        limit = runaway_speed(self.geom)
        bad = ~np.isfinite(speed) | (speed > limit)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InstabilityError(
                f"runaway velocity at step {state.step}, t = {state.t:.6g} s, node {k} at r = "
                f"{state.x[k, 0]:.4g} m, z = {state.x[k, 1]:.4g} m (|v| = {speed[k]:.3g} m/s)")
        if not np.all(np.isfinite(state.sigma)):
            e = int(np.flatnonzero(~np.isfinite(state.sigma).all(axis=1))[0])
            raise InstabilityError(f"non-finite stress in element {e} at step {state.step}, "
                                   f"t = {state.t:.6g} s")

    # ------------------------------------------------------------------ step
    def advance(self, state: LagrangianState, max_steps: int) -> int:
        """Up to ``max_steps`` steps (:meth:`step`).  A step after which an active element
        breaks a distortion limit is undone: the state stays the last valid one, with
        ``halt = "mesh_distorted"`` and the element, the kind (``halt_kind``: inverted,
        min_angle, aspect_ratio) and the time in ``halt_detail``.  Returns the steps kept."""
        taken = 0
        if state.halt:
            return 0
        for _ in range(int(max_steps)):
            previous = state.copy()
            self.step(state)
            bad = self.check_distortion(state, self.last_quality)
            if bad is not None:
                kind, element, text = bad
                step_broken, t_broken = state.step, state.t
                state.__dict__.update(previous.__dict__)
                state.halt, state.halt_kind, state.halt_element = "mesh_distorted", kind, element
                state.halt_detail = (f"{kind}: at step {step_broken} (t = {t_broken:.6g} s, "
                                     f"{state.stage}) {text}; the state kept is the last valid "
                                     f"step {state.step}")
                break
            taken += 1
        state.discharged = self.discharged_mass(state)
        return taken

    def step(self, state: LagrangianState) -> LagrangianState:
        """Advance by one explicit step ``state.dt`` (in place); see the module docstring.

        The loads are measured as in the Eulerian model: the vertical impulses of gravity and
        of the fill's damping, and the contact's velocity change times the node mass, the
        plate's apart, the wall's added to the station nearest to the node's wall point."""
        dt = state.dt
        x, v, conn = state.x, state.v, self.mesh.conn
        stress = state.sigma
        if self._rated and state.flowing is not None and state.flowing.any():
            # the law's rate-dependent overstress in the flowing elements, as in the
            # Eulerian forces (fipy_hopper.material.rate)
            D, _ = strain_rate(x, conn, v)
            stress = stress + self.material.overstress_reference(
                state.sigma, D, state.flowing & state.active)
        _force_kernel(x, v, conn, stress, state.active, self.hg_scale, self._force)
        damping = self.fill_damping if state.stage == "filling" else 0.0
        m = self.node_mass[:, None]
        v += dt * self._force / m
        g = self.gravity(state)
        v[:, 1] -= dt * g
        budget = state.momentum_budget
        budget[0] -= dt * g * self._mass_sum
        segments = self.segments_closed if state.plate_closed else self.wall_segments
        v_free = v.copy()
        self._dv_plate[:] = 0.0
        _contact_kernel(x, v, dt, segments, len(segments), 2,
                        len(segments) - 1 if state.plate_closed else -1, self._dv_plate)
        self._add_contact_impulse(state, v - v_free)
        if damping:           # after the contact, as in the Eulerian model: a wall, not the
            factor = 1.0 / (1.0 + damping * dt)      # damping, holds what rests on it
            budget[1] += (factor - 1.0) * self.vertical_momentum(state)
            v *= factor
        v[self.axis_nodes, 0] = 0.0
        x_mid = x + 0.5 * dt * v
        _strain_kernel(x_mid, v, dt, conn, state.sigma, state.active, self._d_eps, self._sig_rot)
        # the same dense/loose rule as the Eulerian model (dense_loose.close_loose_volume)
        d_skeleton, loose = close_loose_volume(self._d_eps, state.loose)
        sig_new, deps_p, status = self.material.update(self._sig_rot, d_skeleton,
                                                       return_status=True)
        sig_new[~state.active] = 0.0
        state.sigma = sig_new
        state.flowing = (status != ELASTIC) & state.active
        state.loose = np.where(state.active, loose + separation_strain(deps_p, status), 0.0)
        state.eps_p += equivalent_plastic_strain(deps_p)
        x += dt * v
        a, b, rows = self._kernel[:3]
        _project_kernel(x, a, b, rows, self.outlet_radius, state.plate_closed)
        x[self.axis_nodes, 0] = 0.0
        if self.erode_discharged and state.stage == "discharge":
            gone = np.all(x[conn, 1] < -self.erode_depth, axis=1) & state.active
            if gone.any():
                state.active &= ~gone
                state.sigma[gone] = 0.0
        state.t += dt
        state.step += 1
        q = self.quality(state)
        self.last_quality = q
        lengths = q[state.active, 3]
        if len(lengths):
            state.dt = min(self.dt0, self.material.stable_time_step(float(lengths.min()),
                                                                    self.cfg.numerics.dt_safety))
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(state.sigma))):
            raise InstabilityError(f"non-finite Lagrangian state at step {state.step}, "
                                   f"t = {state.t:.6g} s")
        return state

    def _add_contact_impulse(self, state: LagrangianState, dv: np.ndarray) -> None:
        """Add ``m dv`` of this step's contact to the plate's and the wall stations' impulse
        (per radian): the plate's from its own velocity changes, the rest to the station of
        the node's nearest wall point."""
        mass = self.node_mass[:, None]
        state.plate_impulse[0] += (mass * self._dv_plate).sum(axis=0)
        wall = mass * (dv - self._dv_plate)
        nodes = np.flatnonzero(np.any(wall != 0.0, axis=1))
        if not len(nodes):
            return
        np.add.at(state.wall_impulse, self._station(state.x[nodes]), wall[nodes])

    def _station(self, x: np.ndarray) -> np.ndarray:
        """The wall station (row of ``wall_impulse``) of the nearest wall point of each
        position ``x`` (n, 2)."""
        _, _, chain, _, s = self.boundary.nearest(x[:, 0], x[:, 1])
        cone = np.clip(np.floor(s / self._ds_cone), 0, self._n_cone - 1) + 1
        n_bin = len(self._wall_stations[0]) - 1 - self._n_cone
        above = np.clip(np.floor((s - self._s_t) / self._ds_bin), 0, n_bin - 1) \
            + 1 + self._n_cone
        tube = self.boundary.chain_index("tube")
        return np.where(chain == tube, 0, np.where(s < self._s_t, cone, above)).astype(int)

    # ------------------------------------------------------------------ measuring
    def wall_entries(self) -> tuple:
        """``(s, normal, segment)`` of the wall stations (rows of ``wall_impulse``)."""
        return self._wall_stations

    def wall_load_rows(self) -> np.ndarray:
        """The boundary's table row of each wall station: its segment (0 the tube, 1 the cone
        or floor, 2 the bin wall: the rows of a conical hopper's boundary)."""
        return self._wall_stations[2]

    def wall_stress_points(self, state: LagrangianState) -> tuple:
        """``(s, weight, sigma)`` of the active elements whose centroids lie within 2.5
        element sizes of the cone or bin wall, below the fill level (the outer column's
        centroids are half an element off the wall, so no inner bound): the arc length of
        the nearest wall point, the element volume ``r_c A`` and its stress."""
        bnd, h, conn = self.boundary, self.h, self.mesh.conn
        rc, zc = state.x[conn, 0].mean(axis=1), state.x[conn, 1].mean(axis=1)
        d = bnd.signed_distance(rc, zc)
        _, pz, chain, _, s = bnd.nearest(rc, zc)
        band = ((d <= 2.5 * h) & (chain != bnd.chain_index("tube")) & (pz >= 0)
                & (pz < bnd.fill_level) & state.active)
        idx = np.flatnonzero(band)
        _, _, A, r_el = element_gradients(state.x, conn)
        return s[idx], (A * r_el)[idx], state.sigma[idx]

    def contact_slip(self, state: LagrangianState) -> tuple:
        """``(slip, axis_speed)`` (m/s) per wall station: the mean slip speed down the wall of
        the mesh nodes on the wall (within a tenth of an element size of it) whose nearest
        wall point lies in the station's stretch (NaN where none does), and the downward
        speed at the axis at the station's height (linear between the axis nodes)."""
        from . import diagnostics
        s_w, normal, _ = self._wall_stations
        d = self.boundary.signed_distance(state.x[:, 0], state.x[:, 1])
        on = np.flatnonzero(np.abs(d) <= 0.1 * self.h)
        station = self._station(state.x[on])
        slip = diagnostics.entry_slip(state.v[on], normal[station])
        n = len(s_w)
        count = np.bincount(station, minlength=n)
        total = np.bincount(station, slip, minlength=n)
        mean = np.where(count > 0, total / np.maximum(count, 1), math.nan)
        _, z_w, _, _ = self.boundary.wall_point("wall", s_w)
        axis = self.axis_nodes[np.argsort(state.x[self.axis_nodes, 1])]
        axis_speed = np.interp(z_w, state.x[axis, 1], -state.v[axis, 1])
        return mean, axis_speed

    def flow_mode_measures(self, state: LagrangianState, rule) -> tuple:
        """The mass-flow index and the stagnant fraction of
        :class:`~fipy_hopper.diagnostics.FlowModeRule` on the elements (centroid velocity:
        the mean of its nodes'): at each height of the rule, the elements of the row within
        half a cell, 1 to 2.5 cells from the wall against those within 2 cells of the axis;
        the stagnant share by element volume in the cone."""
        bnd, h, conn = self.boundary, self.h, self.mesh.conn
        z_t = bnd.transition_height("wall")
        act = state.active
        rc, zc = state.x[conn, 0].mean(axis=1), state.x[conn, 1].mean(axis=1)
        down = -state.v[conn, 1].mean(axis=1)
        d = bnd.signed_distance(rc, zc)
        ratios = []
        for frac in rule.heights:
            row = act & (np.abs(zc - frac * z_t) <= 0.5 * h)
            near_wall = row & (d >= h) & (d <= 2.5 * h)
            axis = row & (rc < 2.0 * h)
            if near_wall.any() and axis.any():
                v_axis = float(np.mean(down[axis]))
                if v_axis > 1e-9:
                    ratios.append(float(np.mean(down[near_wall])) / v_axis)
        index = float(np.mean(ratios)) if ratios else math.nan
        cone = act & (zc > 0) & (zc < z_t)
        if not cone.any():
            return index, math.nan
        _, _, A, r_el = element_gradients(state.x, conn)
        w = (A * r_el)[cone]
        mean_down = float(np.sum(down[cone] * w) / np.sum(w))
        slow = down[cone] < rule.stagnant_speed * max(mean_down, 1e-12)
        return index, float(np.sum(w[slow]) / np.sum(w))

    def channel_fields(self, state) -> tuple:
        """None: a section has no eccentric flow channel to measure per window."""
        return ()

    def channel_measures(self, means: tuple) -> list:
        """None (:meth:`channel_fields`)."""
        return []

    def empty_channel(self, state: LagrangianState, rule) -> tuple:
        """Not measured: the mesh stops by distortion long before a channel could form."""
        return math.nan, math.nan

    def bin_lateral_stress_ratio(self, state: LagrangianState) -> float:
        """Not measured on the moving mesh (NaN)."""
        return math.nan

    def summary_extras(self, state: LagrangianState) -> dict:
        """``formulation``, the stop by distortion (``distortion_kind``, ``distortion``,
        ``distortion_element``; empty when the mesh stayed valid) and the worst element at
        the end (``max_aspect_ratio``, ``min_angle_deg``)."""
        q = self.quality(state)
        act = state.active
        return {"formulation": self.formulation, "distortion_kind": state.halt_kind,
                "distortion": state.halt_detail, "distortion_element": state.halt_element,
                "elements": self.mesh.n_elements,
                "max_aspect_ratio": float(q[act, 1].max()) if act.any() else math.nan,
                "min_angle_deg": float(q[act, 2].min()) if act.any() else math.nan}
