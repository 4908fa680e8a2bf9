"""The explicit van Leer step (2) of :mod:`fipy_hopper.transport`, plain numpy and compiled.

``vanleer_step_numpy`` works on the unstructured face lists (gather, ``bincount`` scatter);
``vanleer_step_grid`` runs the numba kernel on the (z, r) index grid of FiPy's 2D grid numbering
(``GridArrays``), all fields stacked as ``(nFields, nCells)``; both return the new fields and
the face fluxes ``dt F phi_f`` (field x m^3 per radian).

What FiPy's van Leer scheme does (read from ``fipy/terms/vanLeerConvectionTerm.py``), per
interior face between cells 1 and 2 with unit normal n (1 -> 2) and centre distance d::

    g_up   = (phi_2 - phi_1) / d
    g_uu   = 2 (grad phi)_1 . n - g_up          (grad phi: FiPy's Gauss cell gradient)
    g      = 0 if g_up g_uu < 0 else sign(g_uu) min(2|g_up|, 2|g_uu|, (|g_up| + |g_uu|) / 2)
             (despite the name, the monotonised-central limiter)
    phi_1f = phi_1 + g (V_1 - |F| dt) / (2 A)   (and the mirror value from cell 2)
    phi_f  = phi_1f if F > 0 else phi_2f

On a cylindrical grid two geometric factors of this reconstruction include r:

* ``V_1 / A`` is ``dr r_c / r_f`` on r-normal faces, not the planar cell width ``dr``: on the
  face nearer the axis the extrapolation reaches ``r_c / r_f`` (1.5 for the second cell) times
  too far and can overshoot the downstream neighbour;
* FiPy's Gauss gradient sums ``n A phi_f`` with r-weighted areas over ``V``; on a uniform
  grid its radial component is ``(phi_E - phi_W) / (2 dr) + (phi_E + 2 phi_P + phi_W) /
  (4 r_c)``: even a uniform field has a radial "gradient" ``phi / r_c``, which lets the
  limiter extrapolate where the true upwind slope is flat.

So FiPy's scheme is *not* bounded on a cylindrical grid even for a discretely divergence-free
velocity (a blob in a Stokes-stream-function rotation reaches alpha 1.14 and -0.002 at CFL 0.5;
smaller CFL is worse), although it is on a Cartesian grid.  ``scheme="axisymmetric"`` (what the
model runs, and the default of ``Transport`` and ``FiPyTransport``, whose equations then use
``AxisymmetricVanLeerConvectionTerm``, a FiPy term) keeps FiPy's limiter, upwinding, CFL
correction and conservative update but
reconstructs with planar geometry: gradient ``sum n L phi_f / (dr dz)`` (``L`` the face length)
and reach ``2 d_Pf (1 - |F| dt / V)`` (``d_Pf`` the centre-to-face distance).  Then face values
of an outflow face lie in ``[0, 2 phi_P]`` for non-negative fields, the update is positive for
any velocity at ``cfl <= 0.5``, and the divergence-free blob stays in ``[0, 1]`` to round-off.
``scheme="fipy"`` is FiPy's own term, unchanged; ``redistribute_overshoot`` makes either bounded.

Cut cells enter only through ``F`` (the aperture) and ``kappa`` in the time derivative; the
CFL correction ``V - |F| dt`` uses the full cell volume, as in FiPy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

__all__ = ["cell_gradient", "vanleer_step_numpy", "GridArrays", "grid_shape",
           "vanleer_step_grid", "material_rows"]


# --------------------------------------------------------------------------------------------
# The kernels: plain numpy and numba, same arithmetic as FiPy
# --------------------------------------------------------------------------------------------

def _mc_limited_gradient(normal_grad, g_up):
    """FiPy's ``VanLeerConvectionTerm._getGradient`` (monotonised-central limiter), 1/m.

    ``normal_grad`` is ``(grad phi)_P . n`` of the donor cell (n pointing to the face),
    ``g_up`` the face difference quotient; ``g_uu = 2 normal_grad - g_up``.
    """
    g_uu = -g_up + 2 * normal_grad
    avg = 0.5 * (np.abs(g_up) + np.abs(g_uu))
    min3 = np.minimum(np.minimum(np.abs(2 * g_up), np.abs(2 * g_uu)), avg)
    return np.where(g_up * g_uu < 0.0, 0.0, np.where(g_uu > 0.0, min3, -min3))


def cell_gradient(geom, phi):
    """Gauss cell gradient with arithmetic face values, stacked fields (nF, nCells).

    ``grad_P = (1/W_P) sum_faces s P_f phi_f``, ``phi_f = phi_1 + (phi_2 - phi_1) w_f``
    (``phi_f = phi_P`` on exterior faces: no value constraints), ``s`` = +-1 the outward
    orientation.  ``scheme="fipy"``: ``P = n A``, ``W = V`` (FiPy's ``phi.grad``, which on a
    cylindrical grid equals grad phi + phi/r_c e_r); ``"axisymmetric"``: ``P = n L`` (face
    length), ``W = dr dz`` (the planar gradient).  Returns (2, nF, nCells).
    """
    phi1 = phi[:, geom.face_cell_1]
    phi_face = (phi[:, geom.face_cell_2] - phi1) * geom.face_ratio + phi1
    contributions = geom.gradient_projection[:, None, :] * phi_face[None]    # (2, nF, nFaces)
    per_cell = contributions[:, :, geom.cell_faces]                         # (2, nF, M, nC)
    return (geom.cell_face_sign[None, None] * per_cell).sum(-2) / geom.gradient_volume


def vanleer_step_numpy(geom, phi, u_n, dt):
    """One explicit step (2) for stacked fields ``phi`` (nF, nCells), plain numpy.

    Returns ``(phi_new, face_flux)`` with ``face_flux`` (nF, nFaces) = ``dt F phi_f``.
    """
    phi = np.asarray(phi, dtype=float)
    volume_flux = geom.volume_flux(u_n)
    faces = geom.interior
    id1, id2 = geom.face_cell_1[faces], geom.face_cell_2[faces]
    normal = geom.face_normal[:, faces]
    f_int = volume_flux[faces]
    cfl_volume = np.abs(f_int) * dt

    grad = cell_gradient(geom, phi)
    phi1, phi2 = phi[:, id1], phi[:, id2]
    g_up = (phi2 - phi1) / geom.interior_distance
    normal_grad_1 = (grad[:, :, id1] * normal[:, None, :]).sum(0)
    normal_grad_2 = (grad[:, :, id2] * -normal[:, None, :]).sum(0)
    phi1_face = phi1 + 0.5 * _mc_limited_gradient(normal_grad_1, g_up) \
        * (geom.cell_volume[id1] - cfl_volume) / geom.reach_1
    phi2_face = phi2 + 0.5 * _mc_limited_gradient(normal_grad_2, -g_up) \
        * (geom.cell_volume[id2] - cfl_volume) / geom.reach_2
    flux_int = f_int * np.where(f_int > 0.0, phi1_face, phi2_face)            # (nF, nInt)

    n_fields, n_cells = phi.shape
    net_out = np.empty_like(phi)
    for k in range(n_fields):   # loop over the few fields only
        net_out[k] = (np.bincount(id1, flux_int[k], n_cells)
                      - np.bincount(id2, flux_int[k], n_cells))
    out = geom.outflow
    out_cells = geom.face_cell_1[out]
    outflow_coeff = np.bincount(out_cells, volume_flux[out], n_cells)
    transient = geom.kappa_volume / dt
    phi_new = (transient * phi - net_out) / (transient + outflow_coeff)

    face_flux = np.zeros((n_fields, geom.n_faces))
    face_flux[:, faces] = dt * flux_int
    face_flux[:, out] = dt * volume_flux[out] * phi_new[:, out_cells]
    return phi_new, face_flux


@dataclass(frozen=True)
class GridArrays:
    """``TransportGeometry`` laid out on the (z, r) index grid of FiPy's 2D grid meshes.

    FiPy numbers cells ``c = i + j nr`` and faces z-normal first: face ``i + j nr`` is the
    bottom of cell (j, i) (j = 0..nz), face ``nr (nz+1) + i + j (nr+1)`` its left side
    (i = 0..nr).  ``from_geometry`` checks this numbering against ``faceCellIDs``.  Arrays:
    ``*_h`` on z-normal faces (nz+1, nr), ``*_v`` on r-normal faces (nz, nr+1), cell arrays
    (nz, nr).
    """

    nr: int
    nz: int
    cell_volume: np.ndarray
    gradient_volume: np.ndarray
    kappa_volume: np.ndarray
    projection_h: np.ndarray      # |gradient_projection| on z-normal faces
    projection_v: np.ndarray      # |gradient_projection| on r-normal faces
    ratio_h: np.ndarray           # arithmetic face weight (cell 2) on interior faces
    ratio_v: np.ndarray
    distance_h: np.ndarray        # cell-centre distance on interior faces
    distance_v: np.ndarray
    reach_h: np.ndarray           # (2, nz+1, nr) divisors of the cell-1 / cell-2 extrapolation
    reach_v: np.ndarray           # (2, nz, nr+1)

    @classmethod
    def from_geometry(cls, geom, nr, nz):
        """Reshape ``geom`` (checked to be an nr x nz FiPy grid) to index-grid arrays."""
        n_h = nr * (nz + 1)
        i_h, j_h = np.meshgrid(np.arange(nr), np.arange(nz + 1))
        i_v, j_v = np.meshgrid(np.arange(nr + 1), np.arange(nz))
        cell_1 = np.concatenate([(i_h + np.maximum(j_h - 1, 0) * nr).ravel(),
                                 (np.maximum(i_v - 1, 0) + j_v * nr).ravel()])
        cell_2 = np.concatenate([(i_h + np.minimum(j_h, nz - 1) * nr).ravel(),
                                 (np.minimum(i_v, nr - 1) + j_v * nr).ravel()])
        interior = np.zeros(geom.n_faces, dtype=bool)
        interior[geom.interior] = True
        if (geom.n_cells != nr * nz or geom.n_faces != n_h + (nr + 1) * nz
                or not np.array_equal(geom.face_cell_1[interior], cell_1[interior])
                or not np.array_equal(geom.face_cell_2[interior], cell_2[interior])
                or interior[:n_h].reshape(nz + 1, nr)[[0, -1]].any()
                or interior[n_h:].reshape(nz, nr + 1)[:, [0, -1]].any()):
            raise ValueError("mesh is not a FiPy 2D grid with the standard numbering")

        def on_faces(values):
            values = np.asarray(values, dtype=float)
            lead = values.shape[:-1]
            return (np.ascontiguousarray(values[..., :n_h].reshape(lead + (nz + 1, nr))),
                    np.ascontiguousarray(values[..., n_h:].reshape(lead + (nz, nr + 1))))

        def interior_to_faces(values):
            full = np.ones(geom.n_faces)
            full[geom.interior] = values
            return full

        projection_h, _ = on_faces(np.abs(geom.gradient_projection[1]))
        _, projection_v = on_faces(np.abs(geom.gradient_projection[0]))
        ratio_h, ratio_v = on_faces(geom.face_ratio)
        distance_h, distance_v = on_faces(interior_to_faces(geom.interior_distance))
        reach_h, reach_v = on_faces(np.stack([interior_to_faces(geom.reach_1),
                                              interior_to_faces(geom.reach_2)]))
        cells = (nz, nr)
        return cls(nr=nr, nz=nz,
                   cell_volume=geom.cell_volume.reshape(cells),
                   gradient_volume=geom.gradient_volume.reshape(cells),
                   kappa_volume=geom.kappa_volume.reshape(cells),
                   projection_h=projection_h, projection_v=projection_v,
                   ratio_h=ratio_h, ratio_v=ratio_v,
                   distance_h=distance_h, distance_v=distance_v,
                   reach_h=reach_h, reach_v=reach_v)


def grid_shape(mesh):
    """``(nr, nz)`` of a FiPy 2D grid mesh (``CylindricalGrid2D``, ``Grid2D``)."""
    nr, nz = mesh.shape if hasattr(mesh, "shape") else (mesh.nx, mesh.ny)
    return int(nr), int(nz)


@njit(cache=True, inline="always", error_model="numpy")
def _mc_limit(normal_grad, g_up):
    """Scalar form of ``_mc_limited_gradient`` (FiPy's arithmetic, same operation order)."""
    g_uu = -g_up + 2 * normal_grad
    avg = 0.5 * (abs(g_up) + abs(g_uu))
    min3 = min(min(abs(2 * g_up), abs(2 * g_uu)), avg)
    if g_up * g_uu < 0.0:
        return 0.0
    return min3 if g_uu > 0.0 else -min3


@njit(cache=True, inline="always", error_model="numpy")
def _face_flux(flux, dt, p1, p2, normal_grad_1, normal_grad_2, distance, volume_1, volume_2,
               reach_1, reach_2):
    """``F phi_f`` on one interior face: the donor's limited, CFL-corrected face value."""
    g_up = (p2 - p1) / distance
    cfl_volume = abs(flux) * dt
    if flux > 0.0:
        limited = _mc_limit(normal_grad_1, g_up)
        return flux * (p1 + 0.5 * limited * (volume_1 - cfl_volume) / reach_1)
    limited = _mc_limit(normal_grad_2, -g_up)
    return flux * (p2 + 0.5 * limited * (volume_2 - cfl_volume) / reach_2)


@njit(cache=True, error_model="numpy", parallel=True)
def _grid_step_kernel(phi, flux_h, flux_v, dt, volume, gradient_volume, kappa_volume,
                      projection_h, projection_v, ratio_h, ratio_v, distance_h, distance_v,
                      reach_h, reach_v, outflow_coeff, j0, j1, phi_new, face_flux):
    """Compiled step (2) on the cell rows ``j0 <= j < j1`` of the index grid, as on a grid of
    their own; fields ``phi`` (nF, nz, nr).

    Writes ``phi_new`` (nF, nz, nr; rows outside the range keep ``phi``) and ``dt F phi_f`` on
    the interior faces of the range into ``face_flux`` (nF, nFaces; every other entry zero: the
    end faces of the range are closed by the grid's boundary rule); the fields are shared out
    among numba's threads.  Per field: arithmetic face values, Gauss gradient (only the two
    faces whose normal has the component contribute; the other two add FiPy's exact zeros),
    limited face fluxes, divergence and the diagonal solve.  ``error_model="numpy"`` lets LLVM
    vectorise the divisions (no Python zero-division checks; no interior face has zero area).
    """
    n_fields, nz, nr = phi.shape
    n_h = (nz + 1) * nr
    m = j1 - j0
    for k in prange(n_fields):              # the fields are independent: shared out to threads
        p = phi[k]
        ff = face_flux[k]
        pn = phi_new[k]
        for f in range(ff.shape[0]):
            ff[f] = 0.0
        for j in range(nz):
            if j < j0 or j >= j1:
                for i in range(nr):
                    pn[j, i] = p[j, i]
        if m <= 0:
            continue
        face_h = np.empty((m + 1, nr))       # local row jj is grid row j0 + jj
        face_v = np.empty((m, nr + 1))
        grad_r = np.empty((m, nr))
        grad_z = np.empty((m, nr))
        for i in range(nr):
            face_h[0, i] = p[j0, i]
            face_h[m, i] = p[j1 - 1, i]
        for jj in range(1, m):
            j = j0 + jj
            for i in range(nr):
                p1 = p[j - 1, i]
                face_h[jj, i] = (p[j, i] - p1) * ratio_h[j, i] + p1
        for jj in range(m):
            j = j0 + jj
            face_v[jj, 0] = p[j, 0]
            face_v[jj, nr] = p[j, nr - 1]
            for i in range(1, nr):
                p1 = p[j, i - 1]
                face_v[jj, i] = (p[j, i] - p1) * ratio_v[j, i] + p1
        for jj in range(m):
            j = j0 + jj
            for i in range(nr):
                grad_r[jj, i] = (projection_v[j, i + 1] * face_v[jj, i + 1]
                                 - projection_v[j, i] * face_v[jj, i]) / gradient_volume[j, i]
                grad_z[jj, i] = (-(projection_h[j, i] * face_h[jj, i])
                                 + projection_h[j + 1, i] * face_h[jj + 1, i]) \
                    / gradient_volume[j, i]
        # F phi_f on z-normal faces (index j nr + i), then r-normal faces (n_h + j (nr+1) + i)
        for jj in range(1, m):
            j = j0 + jj
            for i in range(nr):
                ff[j * nr + i] = _face_flux(
                    flux_h[j, i], dt, p[j - 1, i], p[j, i], grad_z[jj - 1, i], -grad_z[jj, i],
                    distance_h[j, i], volume[j - 1, i], volume[j, i], reach_h[0, j, i],
                    reach_h[1, j, i])
        for jj in range(m):
            j = j0 + jj
            row = n_h + j * (nr + 1)
            for i in range(1, nr):
                ff[row + i] = _face_flux(
                    flux_v[j, i], dt, p[j, i - 1], p[j, i], grad_r[jj, i - 1], -grad_r[jj, i],
                    distance_v[j, i], volume[j, i - 1], volume[j, i], reach_v[0, j, i],
                    reach_v[1, j, i])
        for j in range(j0, j1):
            row = n_h + j * (nr + 1)
            for i in range(nr):
                net_out = (ff[(j + 1) * nr + i] - ff[j * nr + i]
                           + ff[row + i + 1] - ff[row + i])
                transient = kappa_volume[j, i] / dt
                pn[j, i] = ((transient * p[j, i] - net_out)
                            / (transient + outflow_coeff[j, i]))
        for j in range(j0 + 1, j1):
            for i in range(nr):
                ff[j * nr + i] *= dt
        for f in range(n_h + j0 * (nr + 1), n_h + j1 * (nr + 1)):
            ff[f] *= dt


def vanleer_step_grid(geom, grid, phi, u_n, dt, out=None, rows=None):
    """One explicit step (2) for stacked fields ``phi`` (nF, nCells), compiled (numba) on the
    index grid ``grid`` (``GridArrays``); same result as ``vanleer_step_numpy``.

    ``out=(phi_new, face_flux)`` reuses caller-owned C-contiguous arrays (nF, nCells) and
    (nF, nFaces) instead of allocating (large fresh arrays cost page faults every call).
    ``rows=(j0, j1)``: only the cell rows ``j0 <= j < j1`` hold material, every field is zero
    in the three rows beyond each end of the range and no velocity crosses its end faces
    (:func:`material_rows` finds such a range).  The kernel then runs on those rows alone, as
    on a grid of their own: the end faces, closed by its boundary rule, carry nothing, as
    they would in the whole grid, and the cells next to them see the same (zero) face values
    and gradients, so the numbers are those of the whole-grid step.
    """
    nr, nz = grid.nr, grid.nz
    n_h = nr * (nz + 1)
    phi = np.ascontiguousarray(phi, dtype=float)
    n_fields = phi.shape[0]
    if out is None:
        phi_new, face_flux = np.empty_like(phi), np.empty((n_fields, geom.n_faces))
    else:
        phi_new, face_flux = out
        if not (phi_new.flags.c_contiguous and face_flux.flags.c_contiguous
                and phi_new.shape == phi.shape and face_flux.shape == (n_fields, geom.n_faces)):
            raise ValueError("out arrays must be C-contiguous (nF, nCells) and (nF, nFaces)")
    volume_flux = geom.volume_flux(u_n)
    out_faces = geom.outflow
    out_cells = geom.face_cell_1[out_faces]
    outflow_coeff = np.zeros(geom.n_cells)
    np.add.at(outflow_coeff, out_cells, volume_flux[out_faces])
    j0, j1 = (0, nz) if rows is None else (int(rows[0]), int(rows[1]))
    _grid_step_kernel(phi.reshape(n_fields, nz, nr), volume_flux[:n_h].reshape(nz + 1, nr),
                      volume_flux[n_h:].reshape(nz, nr + 1), float(dt), grid.cell_volume,
                      grid.gradient_volume, grid.kappa_volume, grid.projection_h,
                      grid.projection_v, grid.ratio_h, grid.ratio_v, grid.distance_h,
                      grid.distance_v, grid.reach_h, grid.reach_v,
                      outflow_coeff.reshape(nz, nr), j0, j1,
                      phi_new.reshape(n_fields, nz, nr), face_flux)
    face_flux[:, out_faces] = dt * volume_flux[out_faces] * phi_new[:, out_cells]
    return phi_new, face_flux


def material_rows(alpha, margin=3):
    """Cell rows ``(j0, j1)`` that hold every nonzero ``alpha`` (nz, nr) with ``margin`` empty
    rows beyond each end (clipped to the grid); ``(0, 0)`` when there is none."""
    lowest, highest = _nonzero_rows(np.ascontiguousarray(alpha, dtype=float))
    if lowest < 0:
        return 0, 0
    return max(int(lowest) - margin, 0), min(int(highest) + margin + 1, alpha.shape[0])


@njit(cache=True)
def _nonzero_rows(alpha):
    """The lowest and the highest row of ``alpha`` (nz, nr) with a nonzero entry (-1, -1: none);
    a compiled scan that stops at the first nonzero entry of a row."""
    nz, nr = alpha.shape
    lowest = -1
    highest = -1
    for j in range(nz):
        for i in range(nr):
            if alpha[j, i] != 0.0:
                if lowest < 0:
                    lowest = j
                highest = j
                break
    return lowest, highest
