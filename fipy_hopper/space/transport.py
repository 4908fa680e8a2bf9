"""Bounded van Leer transport of the carried fields on the 3D grid.

The equation and its explicit step are the sections' (:mod:`fipy_hopper.transport`, equations
(1) and (2)): every field ``phi`` held per open volume is carried conservatively,
``(kappa V / dt + sum_out F) phi_P^new = kappa V / dt phi_P^old - sum_int F phi_f^old``, with
``F = u_n a A`` (m^3/s) along FiPy's face normals and ``phi_f`` FiPy's van Leer face value (the
monotonised-central limiter, the CFL-corrected donor extrapolation), outflow faces implicit
upwind, no inflow.  On a Cartesian grid FiPy's own reconstruction is bounded (the sections
needed a planar one only on their cylindrical grids), so the definition is FiPy's
``VanLeerConvectionTerm`` on the ``Grid3D`` itself (``FiPyTransport(..., scheme="fipy")``).

Implementations, each held by a test to the next:

* ``FiPyTransport`` (:mod:`fipy_hopper.transport.fipy_term`) on the ``Grid3D``: the definition;
* ``vanleer_step_numpy`` (:mod:`fipy_hopper.transport.vanleer`) on the same mesh's face lists:
  the plain-numpy reference (it is written for any FiPy mesh);
* :func:`vanleer_step_grid3`: the compiled kernel on the ``(nz, ny, nx)`` index grid with
  FiPy's own mesh arrays, the reference's arithmetic in the reference's order (bit for bit):
  the Gauss gradient adds a cell's west and east (south and north, bottom and top) face
  terms, its other four faces giving exact zeros; the net outflow of a cell is the sum of its
  top, north and east face fluxes less that of its bottom, south and west ones, each sum in
  face-number order, as ``np.bincount`` adds them.

The redistribution of ``alpha`` above 1 (and round-off below 0) is the sections'
(:mod:`fipy_hopper.transport.redistribution`), which works on the graph of open faces of any
mesh.
"""

from __future__ import annotations

import numpy as np
import numba
from numba import njit

from ..transport import (NeighbourGraph, TransportGeometry, open_neighbour_pairs,
                         redistribute_overshoot, vanleer_step_numpy)
from ..transport.redistribution import _redistribute_compiled

__all__ = ["SpaceTransport", "vanleer_step_grid3", "GridArrays3"]


class GridArrays3:
    """FiPy's mesh arrays of a ``Grid3D`` on the index grid: cell arrays ``(nz, ny, nx)``,
    face arrays per direction (z: ``(nz + 1, ny, nx)``, y: ``(nz, ny + 1, nx)``, x: ``(nz, ny,
    nx + 1)``).  Checks FiPy's numbering against ``faceCellIDs``."""

    def __init__(self, geom: TransportGeometry, nx: int, ny: int, nz: int):
        n_z, n_y = (nz + 1) * ny * nx, nz * (ny + 1) * nx
        shapes = ((nz + 1, ny, nx), (nz, ny + 1, nx), (nz, ny, nx + 1))
        self.shape = (nz, ny, nx)
        self.n_faces = (n_z, n_y, geom.n_faces - n_z - n_y)
        if geom.n_faces != n_z + n_y + nz * ny * (nx + 1) or geom.n_cells != nx * ny * nz:
            raise ValueError("mesh is not a FiPy Grid3D of this shape")
        cell = np.arange(geom.n_cells).reshape(nz, ny, nx)
        # the lower cell of every interior face in FiPy's numbering
        starts = np.concatenate([[0], np.cumsum(self.n_faces)])
        interior = np.zeros(geom.n_faces, bool)
        interior[geom.interior] = True
        lower = (cell[:-1], cell[:, :-1], cell[:, :, :-1])
        for d, (shape, low) in enumerate(zip(shapes, lower)):
            ids = np.arange(starts[d], starts[d + 1]).reshape(shape)
            inner = ids[(slice(1, -1),) if d == 0 else
                        ((slice(None), slice(1, -1)) if d == 1 else
                         (slice(None), slice(None), slice(1, -1)))]
            if not (interior[inner].all() and np.array_equal(geom.face_cell_1[inner], low)):
                raise ValueError("FiPy's face numbering is not the expected Grid3D numbering")

        def faces(values):
            values = np.asarray(values, float)
            return tuple(np.ascontiguousarray(values[starts[d]:starts[d + 1]].reshape(s))
                         for d, s in enumerate(shapes))

        def on_interior(values):
            full = np.ones(geom.n_faces)
            full[geom.interior] = values
            return full

        self.volume = geom.cell_volume.reshape(self.shape)
        self.kappa_volume = geom.kappa_volume.reshape(self.shape)
        proj = np.abs(geom.gradient_projection)
        self.proj = tuple(faces(proj[2 - d])[d] for d in range(3))   # n A of each direction
        self.ratio = faces(geom.face_ratio)
        self.distance = faces(on_interior(geom.interior_distance))
        self.reach1 = faces(on_interior(geom.reach_1))
        self.reach2 = faces(on_interior(geom.reach_2))
        self.starts = starts


@njit(cache=True, inline="always", error_model="numpy")
def _mc_limit(normal_grad, g_up):
    """FiPy's monotonised-central limited gradient (same operation order as the numpy one)."""
    g_uu = -g_up + 2 * normal_grad
    avg = 0.5 * (abs(g_up) + abs(g_uu))
    min3 = min(min(abs(2 * g_up), abs(2 * g_uu)), avg)
    if g_up * g_uu < 0.0:
        return 0.0
    return min3 if g_uu > 0.0 else -min3


@njit(cache=True, inline="always", error_model="numpy")
def _face_flux(flux, dt, p1, p2, ng1, ng2, distance, v1, v2, reach1, reach2):
    """``F phi_f`` on one interior face: the donor's limited, CFL-corrected face value."""
    g_up = (p2 - p1) / distance
    cfl_volume = abs(flux) * dt
    if flux > 0.0:
        return flux * (p1 + 0.5 * _mc_limit(ng1, g_up) * (v1 - cfl_volume) / reach1)
    return flux * (p2 + 0.5 * _mc_limit(ng2, -g_up) * (v2 - cfl_volume) / reach2)


@njit(cache=True, error_model="numpy")
def _step3(phi, fz, fy, fx, dt, volume, kappa_volume, pz, py, px, rz, ry, rx, dz, dy, dx,
           r1z, r1y, r1x, r2z, r2y, r2x, outflow, k0, k1, phi_new, ffz, ffy, ffx):
    """One field: step (2) on the cell layers ``k0 <= k < k1`` (the others copied), interior
    face fluxes ``dt F phi_f`` of the range into ``ff*`` (others zero)."""
    nz, ny, nx = phi.shape
    ffz[:] = 0.0
    ffy[:] = 0.0
    ffx[:] = 0.0
    phi_new[:] = phi
    if k1 <= k0:
        return
    gx = np.zeros((nz, ny, nx))
    gy = np.zeros((nz, ny, nx))
    gz = np.zeros((nz, ny, nx))
    for k in range(k0, k1):
        for j in range(ny):
            for i in range(nx):
                p = phi[k, j, i]
                w = p if i == 0 else (p - phi[k, j, i - 1]) * rx[k, j, i] + phi[k, j, i - 1]
                e = p if i == nx - 1 else (phi[k, j, i + 1] - p) * rx[k, j, i + 1] + p
                s = p if j == 0 else (p - phi[k, j - 1, i]) * ry[k, j, i] + phi[k, j - 1, i]
                n = p if j == ny - 1 else (phi[k, j + 1, i] - p) * ry[k, j + 1, i] + p
                b = p if k == k0 else (p - phi[k - 1, j, i]) * rz[k, j, i] + phi[k - 1, j, i]
                t = p if k == k1 - 1 else (phi[k + 1, j, i] - p) * rz[k + 1, j, i] + p
                vol = volume[k, j, i]
                gx[k, j, i] = (-(px[k, j, i] * w) + px[k, j, i + 1] * e) / vol
                gy[k, j, i] = (-(py[k, j, i] * s) + py[k, j + 1, i] * n) / vol
                gz[k, j, i] = (-(pz[k, j, i] * b) + pz[k + 1, j, i] * t) / vol
    for k in range(k0, k1):
        for j in range(ny):
            for i in range(nx):
                if k > k0:
                    ffz[k, j, i] = _face_flux(fz[k, j, i], dt, phi[k - 1, j, i], phi[k, j, i],
                                              gz[k - 1, j, i], -gz[k, j, i], dz[k, j, i],
                                              volume[k - 1, j, i], volume[k, j, i],
                                              r1z[k, j, i], r2z[k, j, i])
                if j > 0:
                    ffy[k, j, i] = _face_flux(fy[k, j, i], dt, phi[k, j - 1, i], phi[k, j, i],
                                              gy[k, j - 1, i], -gy[k, j, i], dy[k, j, i],
                                              volume[k, j - 1, i], volume[k, j, i],
                                              r1y[k, j, i], r2y[k, j, i])
                if i > 0:
                    ffx[k, j, i] = _face_flux(fx[k, j, i], dt, phi[k, j, i - 1], phi[k, j, i],
                                              gx[k, j, i - 1], -gx[k, j, i], dx[k, j, i],
                                              volume[k, j, i - 1], volume[k, j, i],
                                              r1x[k, j, i], r2x[k, j, i])
    for k in range(k0, k1):
        for j in range(ny):
            for i in range(nx):
                out_ = (ffz[k + 1, j, i] + ffy[k, j + 1, i]) + ffx[k, j, i + 1]
                in_ = (ffz[k, j, i] + ffy[k, j, i]) + ffx[k, j, i]
                net = out_ - in_
                transient = kappa_volume[k, j, i] / dt
                phi_new[k, j, i] = (transient * phi[k, j, i] - net) / (transient
                                                                      + outflow[k, j, i])
    for k in range(k0, k1 + 1):
        for j in range(ny):
            for i in range(nx):
                ffz[k, j, i] *= dt
    for k in range(k0, k1):
        for j in range(ny + 1):
            for i in range(nx):
                ffy[k, j, i] *= dt
        for j in range(ny):
            for i in range(nx + 1):
                ffx[k, j, i] *= dt


def vanleer_step_grid3(geom, grid: GridArrays3, phi, u_n, dt, rows=None):
    """One explicit step (2) for stacked fields ``phi`` (nF, nCells), compiled on the index
    grid; the same numbers as ``vanleer_step_numpy``.  ``rows = (k0, k1)``: only the cell
    layers ``k0 <= k < k1`` hold material, with three empty layers beyond each end and no
    velocity across the range's end faces (:func:`fipy_hopper.transport.material_rows` of
    alpha as ``(nz, ny nx)``); the kernel then runs on them alone (the end faces carry
    nothing in the whole-grid step either).  Returns ``(phi_new, face_flux)``."""
    nz, ny, nx = grid.shape
    phi = np.ascontiguousarray(phi, dtype=float)
    n_fields = phi.shape[0]
    volume_flux = geom.volume_flux(u_n)
    s = grid.starts
    fz = volume_flux[s[0]:s[1]].reshape(nz + 1, ny, nx)
    fy = volume_flux[s[1]:s[2]].reshape(nz, ny + 1, nx)
    fx = volume_flux[s[2]:s[3]].reshape(nz, ny, nx + 1)
    out_faces = geom.outflow
    out_cells = geom.face_cell_1[out_faces]
    outflow = np.bincount(out_cells, volume_flux[out_faces], geom.n_cells).reshape(nz, ny, nx)
    k0, k1 = (0, nz) if rows is None else (int(rows[0]), int(rows[1]))
    phi_new = np.empty_like(phi)
    face_flux = np.zeros((n_fields, geom.n_faces))
    for f in range(n_fields):
        ff = face_flux[f]
        _step3(phi[f].reshape(nz, ny, nx), fz, fy, fx, float(dt), grid.volume,
               grid.kappa_volume, *grid.proj, *grid.ratio, *grid.distance, *grid.reach1,
               *grid.reach2, outflow, k0, k1, phi_new[f].reshape(nz, ny, nx),
               ff[s[0]:s[1]].reshape(nz + 1, ny, nx), ff[s[1]:s[2]].reshape(nz, ny + 1, nx),
               ff[s[2]:s[3]].reshape(nz, ny, nx + 1))
    face_flux[:, out_faces] = dt * volume_flux[out_faces] * phi_new[:, out_cells]
    return phi_new, face_flux


class SpaceTransport:
    """The 3D grid's transport: ``step_stacked`` (van Leer, compiled or numpy) and
    ``redistribute_fields`` (the sections' redistribution), on a ``Grid3D`` ``mesh`` with
    open fractions ``kappa`` (nCells,), apertures (nFaces,) and outflow faces (bool
    nFaces,)."""

    def __init__(self, mesh, kappa, aperture, outflow_faces, backend="numba"):
        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', not {backend!r}")
        self.backend = backend
        self.geometry = TransportGeometry.from_mesh(mesh, kappa, aperture, outflow_faces,
                                                    scheme="fipy")
        nx, ny, nz = (int(n) for n in mesh.shape)
        self.grid = GridArrays3(self.geometry, nx, ny, nz)
        pairs, faces = open_neighbour_pairs(self.geometry)
        self.neighbours = NeighbourGraph(pairs, self.geometry.n_cells, faces,
                                         self.geometry.n_faces)
        self.kappa_volume = np.ascontiguousarray(self.geometry.kappa * self.geometry.cell_volume)

    def step_stacked(self, phi, u_n, dt, rows=None):
        """``(phi_new, face_flux)`` after one step of ``dt`` (s) with the face normal velocities
        ``u_n`` (m/s, FiPy's face order and normals)."""
        if self.backend == "numpy":
            return vanleer_step_numpy(self.geometry, phi, u_n, dt)
        return vanleer_step_grid3(self.geometry, self.grid, phi, u_n, dt, rows=rows)

    def redistribute_fields(self, fields, room_min=1e-6, alpha_max=1.0, sweeps=50, tol=1e-14):
        """Alpha (row 0 of ``fields``) into ``[0, alpha_max]`` conservatively, the other rows
        (alpha-weighted) moved with it, in place; returns the ``Redistribution``."""
        if self.backend == "numpy":
            geom = self.geometry
            alpha_new, record = redistribute_overshoot(
                fields[0], geom.kappa, geom.cell_volume, self.neighbours, alpha_max=alpha_max,
                sweeps=sweeps, tol=tol, room_min=room_min, fields=fields[1:], backend="numpy")
            fields[0] = alpha_new
            return record
        return _redistribute_compiled(fields[0], fields[1:], self.kappa_volume,
                                      self.neighbours, alpha_max, sweeps, tol, room_min)


# ---------------------------------------------------------------- momentum on the dual grid
@njit(cache=True, inline="always", error_model="numpy")
def _edge(rf_lo, rf_hi, ka, ja, ia, kb, jb, ib, kc, jc, ic, kd, jd, id_, n0, n1, n2):
    """The dual flux of one node edge: the sum of its (up to) four cells' ``(F_- + F_+) /
    8`` in the reference's order; a cell outside the grid adds nothing."""
    g = 0.0
    for (k, j, i) in ((ka, ja, ia), (kb, jb, ib), (kc, jc, ic), (kd, jd, id_)):
        if 0 <= k < n0 and 0 <= j < n1 and 0 <= i < n2:
            g += 0.125 * (rf_lo[k, j, i] + rf_hi[k, j, i])
    return g


@njit(cache=True, error_model="numpy")
def _dual_plane(k, v, mass_old, mass_new, rz, ry, rx, out_z, light_mass, v_new, plane):
    """:func:`dual_momentum_transport` at the node plane ``k``: ``v_new`` of its nodes and
    ``plane = (outflow, stopped)`` of the plane (added in node order)."""
    nz1, ny1, nx1 = mass_old.shape
    nz, ny, nx = nz1 - 1, ny1 - 1, nx1 - 1
    outflow = 0.0
    stopped = 0.0
    P = np.empty(3)
    for j in range(ny1):
        for i in range(nx1):
            m0 = mass_old[k, j, i]
            for c in range(3):
                P[c] = m0 * v[c, k, j, i]
            # z: the edge above (this node its lower end), then the edge below
            for axis in range(3):
                if axis == 0:
                    up = k < nz
                    down = k > 0
                    gu = _edge(rz[:-1], rz[1:], k, j, i, k, j, i - 1, k, j - 1, i, k, j - 1,
                               i - 1, nz, ny, nx) if up else 0.0
                    gd = _edge(rz[:-1], rz[1:], k - 1, j, i, k - 1, j, i - 1, k - 1, j - 1, i,
                               k - 1, j - 1, i - 1, nz, ny, nx) if down else 0.0
                    ku, ju, iu, kd, jd, id_ = k + 1, j, i, k - 1, j, i
                elif axis == 1:
                    up = j < ny
                    down = j > 0
                    gu = _edge(ry[:, :-1], ry[:, 1:], k, j, i, k, j, i - 1, k - 1, j, i, k - 1,
                               j, i - 1, nz, ny, nx) if up else 0.0
                    gd = _edge(ry[:, :-1], ry[:, 1:], k, j - 1, i, k, j - 1, i - 1, k - 1,
                               j - 1, i, k - 1, j - 1, i - 1, nz, ny, nx) if down else 0.0
                    ku, ju, iu, kd, jd, id_ = k, j + 1, i, k, j - 1, i
                else:
                    up = i < nx
                    down = i > 0
                    gu = _edge(rx[:, :, :-1], rx[:, :, 1:], k, j, i, k, j - 1, i, k - 1, j, i,
                               k - 1, j - 1, i, nz, ny, nx) if up else 0.0
                    gd = _edge(rx[:, :, :-1], rx[:, :, 1:], k, j, i - 1, k, j - 1, i - 1,
                               k - 1, j, i - 1, k - 1, j - 1, i - 1, nz, ny, nx) if down else 0.0
                    ku, ju, iu, kd, jd, id_ = k, j, i + 1, k, j, i - 1
                if up:
                    for c in range(3):
                        donor = v[c, k, j, i] if gu > 0 else v[c, ku, ju, iu]
                        P[c] = P[c] - gu * donor
                if down:
                    for c in range(3):
                        donor = v[c, kd, jd, id_] if gd > 0 else v[c, k, j, i]
                        P[c] = P[c] + gd * donor
            if k == 0:
                o = 0.0
                for (jj, ii) in ((j, i), (j, i - 1), (j - 1, i), (j - 1, i - 1)):
                    if 0 <= jj < ny and 0 <= ii < nx:
                        o += out_z[jj, ii]
                for c in range(3):
                    P[c] = P[c] + o * v[c, 0, j, i]
                outflow += o * v[2, 0, j, i]
            m = mass_new[k, j, i]
            for c in range(3):
                v_new[c, k, j, i] = P[c] / m if m > 0 else 0.0
            if m <= light_mass:
                stopped -= m * v_new[2, k, j, i]
                for c in range(3):
                    v_new[c, k, j, i] = 0.0
    plane[0] = outflow
    plane[1] = stopped


@njit(cache=True, error_model="numpy", parallel=True)
def _dual_kernel(k0, k1, v, mass_old, mass_new, rz, ry, rx, out_z, light_mass, v_new, planes,
                 threads):
    for t in numba.prange(threads):
        for k in range(k0 + t, k1, threads):
            _dual_plane(k, v, mass_old, mass_new, rz, ry, rx, out_z, light_mass, v_new,
                        planes[k])


def dual_momentum_transport_compiled(v, mass_old, mass_new, flux_z, flux_y, flux_x, rho,
                                     light_mass, rows=None, threads=1):
    """The compiled :func:`fipy_hopper.space.model.dual_momentum_transport`: the same
    velocities to the bit (the same sums in the same order, node by node), ``outflow`` and
    ``stopped`` added in node order (the reference's ``np.sum`` adds pairwise: the same to
    round-off).  ``rows = (k0, k1)``: only the node planes ``k0 <= k < k1`` can hold mass
    (old or new) or cross a flux; the others are left at rest.  Thread ``t`` takes the planes
    ``t, t + threads, ...``."""
    nz1 = v.shape[1]
    k0, k1 = (0, nz1) if rows is None else (max(int(rows[0]), 0), min(int(rows[1]), nz1))
    v_new = np.zeros_like(v)
    planes = np.zeros((nz1, 2))
    _dual_kernel(k0, k1, np.ascontiguousarray(v), mass_old, mass_new, rho * flux_z,
                 rho * flux_y, rho * flux_x, 0.25 * rho * flux_z[0], light_mass, v_new,
                 planes, threads)
    outflow = stopped = 0.0
    for k in range(k0, k1):
        outflow += planes[k, 0]
        stopped += planes[k, 1]
    return v_new, outflow, stopped
