"""Conservative, bounded transport of cell fields on the fixed cylindrical grid.

The Eulerian step of method.md section 3 carries every cell field ``phi`` (a density per
*open* volume: the material fraction ``alpha`` and alpha-weighted quantities such as
``alpha*sigma_rr`` or ``alpha*tracer``) with the face normal velocity of the material step:

    d/dt (kappa V phi) + sum_faces (u_n a A) phi_f = 0                                  (1)

* ``V`` = ``mesh.cellVolumes`` = dr dz r_c (m^3 per radian), ``A`` = ``mesh._faceAreas`` =
  face length times face radius (m^2 per radian, zero on the axis), ``kappa`` (-) the open
  fraction of a cell, ``a`` (-) the aperture of a face, ``u_n`` (m/s) the velocity along FiPy's
  ``mesh.faceNormals`` (which point from ``faceCellIDs[0]`` to ``faceCellIDs[1]``, outward
  on exterior faces).  The conserved amount of a cell is ``phi kappa V``.
* ``phi_f`` is FiPy's ``VanLeerConvectionTerm`` face value (explicit, from the old field).
* Exterior faces carry no flux except the *outflow* faces, opened as in FiPy with
  ``phi.faceGrad.constrain(0., where=outflow)``: FiPy then treats them implicitly upwind,
  ``phi_f = phi_P^new``.  There is no inflow.

One explicit step of (1) is therefore, per cell P (``F = dt``-free volume flux ``u_n a A``,
positive out of P, sums over P's interior faces and its outflow faces)::

    (kappa V / dt + sum_out F) phi_P^new = kappa V / dt phi_P^old - sum_int F phi_f^old    (2)

Three implementations of (2) are given:

``FiPyTransport``
    the definition: one FiPy equation ``TransientTerm(kappa_eff) + VanLeerConvectionTerm(
    u a) == 0`` per field, built once, velocity updated with ``setValue``.  Slow (FiPy spends
    milliseconds per solve in Python); it is the readable reference the tests hold the
    kernels to.
``Transport`` (``backend="numba"``, the default)
    the same arithmetic on FiPy's own mesh arrays, precomputed once, compiled with numba
    (``@njit(cache=True)``): one pass over faces and cells for all fields stacked as
    ``(nFields, nCells)``.  Numba because (2) is a gather/limiter/scatter over faces whose
    numpy form needs ~40 temporaries of size ``nFields x nFaces`` and scattered ``bincount``
    sums; the compiled loop touches each face once and is ~10x faster.
``Transport(backend="numpy")``
    plain vectorised numpy of the same arithmetic, the reference the compiled kernel is held
    to by a test (no per-cell Python loops either).

What FiPy's van Leer scheme does (read from ``fipy/terms/vanLeerConvectionTerm.py``), per
interior face between cells 1 and 2 with unit normal n (1 -> 2) and centre distance d::

    g_up   = (phi_2 - phi_1) / d
    g_uu   = 2 (grad phi)_1 . n - g_up          (grad phi: FiPy's Gauss cell gradient)
    g      = MC(g_up, g_uu) = 0 if g_up g_uu < 0 else sign(g_uu) min(2|g_up|, 2|g_uu|,
             (|g_up| + |g_uu|) / 2)         (the monotonised-central limiter)
    phi_1f = phi_1 + g (V_1 - |F| dt) / (2 A)   (and the mirror value from cell 2)
    phi_f  = phi_1f if F > 0 else phi_2f

On a cylindrical grid ``V_1 / A`` is ``dr r_c / r_f`` (not the half-width ``dr``), and the
Gauss gradient sums ``n A phi_f`` with r-weighted areas, so it carries an extra ``phi / r_c``
in the radial component.  Cut cells enter only through ``F`` (the aperture) and ``kappa`` in the
time derivative; the CFL correction ``V - |F| dt`` uses the full cell volume.

Support functions: ``max_stable_dt`` (the CFL rule of the step), ``redistribute_overshoot``
(the conservative boundedness rule for alpha) and ``Redistribution.apply`` (moves the
alpha-weighted fields with the same ratios).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

__all__ = [
    "TransportGeometry",
    "FiPyTransport",
    "Transport",
    "max_stable_dt",
    "outgoing_volume_flux",
    "open_neighbour_pairs",
    "Redistribution",
    "redistribute_overshoot",
]

#: Floor of the open fraction used in the time derivative of (2) (``kappa_eff = max(kappa,
#: KAPPA_FLOOR)``) so closed cells keep a regular diagonal; they have closed faces, so nothing
#: changes there.
KAPPA_FLOOR = 1e-12

#: Default guard of ``max_stable_dt``: a cell limits the time step as if it were at least this
#: open (see ``max_stable_dt``).
KAPPA_CFL_MIN = 0.1


# --------------------------------------------------------------------------------------------
# Geometry shared by all implementations
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TransportGeometry:
    """FiPy's mesh arrays and the wall data used by (2), precomputed once (all float64/int64).

    Face arrays have length ``nFaces``; ``interior`` lists the interior faces (FiPy order) and
    ``outflow`` the opened exterior faces.  ``aperture`` is zero on every face touching a solid
    cell (``kappa == 0``), so solid cells never exchange anything.
    """

    n_cells: int
    n_faces: int
    cell_volume: np.ndarray          # V (nCells,), m^3/rad
    kappa: np.ndarray                # open fraction as given (nCells,)
    kappa_volume: np.ndarray         # kappa_eff V (nCells,)
    face_area: np.ndarray            # A (nFaces,), m^2/rad
    aperture: np.ndarray             # a (nFaces,)
    face_normal: np.ndarray          # FiPy faceNormals (2, nFaces)
    area_projection: np.ndarray      # FiPy _areaProjections = n A (2, nFaces)
    face_cell_1: np.ndarray          # FiPy _adjacentCellIDs[0] (nFaces,)
    face_cell_2: np.ndarray          # FiPy _adjacentCellIDs[1] (= cell 1 on exterior faces)
    face_ratio: np.ndarray           # FiPy _faceToCellDistanceRatio (arithmetic face value)
    cell_faces: np.ndarray           # FiPy cellFaceIDs (M, nCells)
    cell_face_sign: np.ndarray       # FiPy _cellToFaceOrientations (M, nCells), float
    interior: np.ndarray             # interior face ids (nInt,)
    interior_distance: np.ndarray    # FiPy _cellDistances on interior faces (nInt,)
    outflow: np.ndarray              # outflow face ids (nOut,)
    outflow_mask: np.ndarray         # bool (nFaces,)

    @classmethod
    def from_mesh(cls, mesh, kappa, aperture, outflow_faces, kappa_floor=KAPPA_FLOOR):
        """Read the geometry from a FiPy mesh (2D, e.g. ``CylindricalGrid2D``).

        ``kappa`` (nCells,), ``aperture`` (nFaces,) in [0, 1]; ``outflow_faces`` a bool mask
        (nFaces,) or None.  Outflow faces must be exterior faces.
        """
        n_cells, n_faces = mesh.numberOfCells, mesh.numberOfFaces
        kappa = np.clip(np.asarray(kappa, dtype=float).reshape(n_cells), 0.0, 1.0)
        aperture = np.clip(np.asarray(aperture, dtype=float).reshape(n_faces), 0.0, 1.0)
        id1, id2 = (np.asarray(ids, dtype=np.int64) for ids in mesh._adjacentCellIDs)
        aperture = np.where((kappa[id1] == 0.0) | (kappa[id2] == 0.0), 0.0, aperture)
        exterior = np.asarray(mesh.exteriorFaces.value, dtype=bool)
        if outflow_faces is None:
            outflow_mask = np.zeros(n_faces, dtype=bool)
        else:
            outflow_mask = np.asarray(outflow_faces, dtype=bool).reshape(n_faces)
        if np.any(outflow_mask & ~exterior):
            raise ValueError("outflow_faces must be exterior faces")
        interior = np.flatnonzero(~exterior).astype(np.int64)
        volume = np.asarray(mesh.cellVolumes, dtype=float)
        return cls(
            n_cells=n_cells,
            n_faces=n_faces,
            cell_volume=volume,
            kappa=kappa,
            kappa_volume=np.maximum(kappa, kappa_floor) * volume,
            face_area=np.asarray(mesh._faceAreas, dtype=float),
            aperture=aperture,
            face_normal=np.ascontiguousarray(np.asarray(mesh.faceNormals, dtype=float)),
            area_projection=np.ascontiguousarray(np.asarray(mesh._areaProjections, dtype=float)),
            face_cell_1=id1,
            face_cell_2=id2,
            face_ratio=np.asarray(mesh._faceToCellDistanceRatio, dtype=float),
            cell_faces=np.ascontiguousarray(np.ma.filled(mesh.cellFaceIDs, 0).astype(np.int64)),
            cell_face_sign=np.ascontiguousarray(
                np.ma.filled(mesh._cellToFaceOrientations, 0).astype(float)),
            interior=interior,
            interior_distance=np.asarray(mesh._cellDistances, dtype=float)[interior],
            outflow=np.flatnonzero(outflow_mask).astype(np.int64),
            outflow_mask=outflow_mask,
        )

    def volume_flux(self, u_n):
        """``F = u_n a A`` (m^3/s per radian) along the face normals, (nFaces,)."""
        return (np.asarray(u_n, dtype=float) * self.aperture) * self.face_area


# --------------------------------------------------------------------------------------------
# 1. The definition: FiPy equations
# --------------------------------------------------------------------------------------------

class FiPyTransport:
    """Transport (1) as FiPy equations, one per field, built once (the reference).

    ``TransientTerm(coeff=kappa_eff, var=phi) + VanLeerConvectionTerm(coeff=u a, var=phi) == 0``
    with ``u = u_n * mesh.faceNormals`` (a rank-1 ``FaceVariable`` updated by ``setValue``) and
    ``phi.faceGrad.constrain(0., where=outflow)``; solved with FiPy's ``LinearLUSolver`` (the
    matrix is diagonal).
    """

    def __init__(self, mesh, kappa, aperture, outflow_faces, field_names):
        import fipy

        self.mesh = mesh
        self.geometry = geom = TransportGeometry.from_mesh(mesh, kappa, aperture, outflow_faces)
        self.field_names = tuple(field_names)
        self._velocity = fipy.FaceVariable(mesh=mesh, rank=1, value=0.0)
        self._aperture = fipy.FaceVariable(mesh=mesh, value=geom.aperture)
        kappa_eff = fipy.CellVariable(mesh=mesh, value=geom.kappa_volume / geom.cell_volume)
        coeff = self._velocity * self._aperture
        outflow = fipy.FaceVariable(mesh=mesh, value=geom.outflow_mask)
        self._solver = fipy.LinearLUSolver()
        self.variables, self.terms, self.equations = {}, {}, {}
        for name in self.field_names:
            phi = fipy.CellVariable(mesh=mesh, name=name, value=0.0, hasOld=True)
            if geom.outflow.size:
                phi.faceGrad.constrain(0.0, where=outflow)
            convection = fipy.VanLeerConvectionTerm(coeff=coeff, var=phi)
            self.variables[name] = phi
            self.terms[name] = convection
            self.equations[name] = (fipy.TransientTerm(coeff=kappa_eff, var=phi)
                                    + convection == 0)

    def step(self, fields, u_n, dt):
        """Advance every field by ``dt`` (s) with face normal velocity ``u_n`` (m/s, nFaces).

        Returns ``(new_fields, face_flux)``: dicts of (nCells,) and (nFaces,) arrays;
        ``face_flux = dt u_n a A phi_f`` (field x m^3 per radian) along the face normals.
        """
        geom = self.geometry
        u_n = np.asarray(u_n, dtype=float)
        self._velocity.setValue(u_n * geom.face_normal)
        volume_flux = geom.volume_flux(u_n)
        id1 = geom.face_cell_1[geom.interior]
        id2 = geom.face_cell_2[geom.interior]
        new_fields, face_flux = {}, {}
        for name in self.field_names:
            phi = self.variables[name]
            phi.setValue(np.asarray(fields[name], dtype=float))
            phi.updateOld()
            # FiPy's own face values (the term's explicit arithmetic), for the face fluxes
            phi1, phi2 = self.terms[name]._getOldAdjacentValues(phi.old, id1, id2, dt)
            self.equations[name].solve(var=phi, dt=dt, solver=self._solver)
            new = np.array(phi.value, dtype=float)
            flux = np.zeros(geom.n_faces)
            f_int = volume_flux[geom.interior]
            flux[geom.interior] = dt * f_int * np.where(f_int > 0.0, phi1, phi2)
            out = geom.outflow
            flux[out] = dt * volume_flux[out] * new[geom.face_cell_1[out]]
            new_fields[name], face_flux[name] = new, flux
        return new_fields, face_flux


# --------------------------------------------------------------------------------------------
# 2. The kernels: plain numpy and numba, same arithmetic as FiPy
# --------------------------------------------------------------------------------------------

def _mc_limited_gradient(g_uu_normal, g_up):
    """FiPy's ``VanLeerConvectionTerm._getGradient`` (monotonised-central limiter).

    ``g_uu_normal`` is ``(grad phi)_P . n`` of the donor cell, ``g_up`` the face difference
    quotient; ``g_uu = 2 g_uu_normal - g_up``.
    """
    g_uu = -g_up + 2 * g_uu_normal
    avg = 0.5 * (np.abs(g_up) + np.abs(g_uu))
    min3 = np.minimum(np.minimum(np.abs(2 * g_up), np.abs(2 * g_uu)), avg)
    return np.where(g_up * g_uu < 0.0, 0.0, np.where(g_uu > 0.0, min3, -min3))


def gauss_cell_gradient(geom, phi):
    """FiPy's ``phi.grad`` (Gauss, arithmetic face values) for stacked fields (nF, nCells).

    ``grad_P = (1/V_P) sum_faces s n A phi_f``, ``phi_f = phi_1 + (phi_2 - phi_1) w_f``; on
    exterior faces ``phi_f = phi_P`` (no value constraints).  Returns (2, nF, nCells).
    """
    phi1 = phi[:, geom.face_cell_1]
    phi_face = (phi[:, geom.face_cell_2] - phi1) * geom.face_ratio + phi1
    contributions = geom.area_projection[:, None, :] * phi_face[None]        # (2, nF, nFaces)
    per_cell = contributions[:, :, geom.cell_faces]                         # (2, nF, M, nC)
    return (geom.cell_face_sign[None, None] * per_cell).sum(-2) / geom.cell_volume


def vanleer_step_numpy(geom, phi, u_n, dt):
    """One explicit step (2) for stacked fields ``phi`` (nF, nCells), plain numpy.

    Returns ``(phi_new, face_flux)`` with ``face_flux`` (nF, nFaces) = ``dt F phi_f``.
    """
    phi = np.asarray(phi, dtype=float)
    volume_flux = geom.volume_flux(u_n)
    faces = geom.interior
    id1, id2 = geom.face_cell_1[faces], geom.face_cell_2[faces]
    area = geom.face_area[faces]
    normal = geom.face_normal[:, faces]
    f_int = volume_flux[faces]
    cfl_volume = np.abs(f_int) * dt

    grad = gauss_cell_gradient(geom, phi)
    phi1, phi2 = phi[:, id1], phi[:, id2]
    g_up = (phi2 - phi1) / geom.interior_distance
    normal_grad_1 = (grad[:, :, id1] * normal[:, None, :]).sum(0)
    normal_grad_2 = (grad[:, :, id2] * -normal[:, None, :]).sum(0)
    phi1_face = phi1 + 0.5 * _mc_limited_gradient(normal_grad_1, g_up) \
        * (geom.cell_volume[id1] - cfl_volume) / area
    phi2_face = phi2 + 0.5 * _mc_limited_gradient(normal_grad_2, -g_up) \
        * (geom.cell_volume[id2] - cfl_volume) / area
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


@njit(cache=True)
def _vanleer_step_kernel(phi, volume_flux, dt, face_cell_1, face_cell_2, face_ratio,
                         area_projection, cell_faces, cell_face_sign, cell_volume,
                         kappa_volume, face_area, face_normal, interior, interior_distance,
                         outflow, phi_new, face_flux):
    """Compiled form of ``vanleer_step_numpy``; writes ``phi_new`` and ``face_flux``."""
    n_fields, n_cells = phi.shape
    n_faces = face_ratio.shape[0]
    n_per_cell = cell_faces.shape[0]
    phi_face = np.empty(n_faces)
    grad_r = np.empty(n_cells)
    grad_z = np.empty(n_cells)
    net_out = np.empty(n_cells)
    outflow_coeff = np.zeros(n_cells)
    for j in range(outflow.shape[0]):
        outflow_coeff[face_cell_1[outflow[j]]] += volume_flux[outflow[j]]
    for k in range(n_fields):
        p = phi[k]
        # arithmetic face values and the Gauss cell gradient, as FiPy sums them
        for f in range(n_faces):
            p1 = p[face_cell_1[f]]
            phi_face[f] = (p[face_cell_2[f]] - p1) * face_ratio[f] + p1
        for c in range(n_cells):
            gr = 0.0
            gz = 0.0
            for m in range(n_per_cell):
                f = cell_faces[m, c]
                gr += cell_face_sign[m, c] * (area_projection[0, f] * phi_face[f])
                gz += cell_face_sign[m, c] * (area_projection[1, f] * phi_face[f])
            grad_r[c] = gr / cell_volume[c]
            grad_z[c] = gz / cell_volume[c]
            net_out[c] = 0.0
        # limited upwind face values and fluxes on interior faces
        for j in range(interior.shape[0]):
            f = interior[j]
            c1 = face_cell_1[f]
            c2 = face_cell_2[f]
            flux = volume_flux[f]
            nr = face_normal[0, f]
            nz = face_normal[1, f]
            g_up = (p[c2] - p[c1]) / interior_distance[j]
            if flux > 0.0:
                donor = c1
                normal_grad = grad_r[c1] * nr + grad_z[c1] * nz
                g_up_donor = g_up
            else:
                donor = c2
                normal_grad = grad_r[c2] * -nr + grad_z[c2] * -nz
                g_up_donor = -g_up
            g_uu = -g_up_donor + 2 * normal_grad
            if g_up_donor * g_uu < 0.0:
                limited = 0.0
            else:
                avg = 0.5 * (abs(g_up_donor) + abs(g_uu))
                min3 = min(min(abs(2 * g_up_donor), abs(2 * g_uu)), avg)
                limited = min3 if g_uu > 0.0 else -min3
            value = p[donor] + 0.5 * limited * (cell_volume[donor] - abs(flux) * dt) / face_area[f]
            face_value_flux = flux * value
            net_out[c1] += face_value_flux
            net_out[c2] -= face_value_flux
            face_flux[k, f] = dt * face_value_flux
        for c in range(n_cells):
            transient = kappa_volume[c] / dt
            phi_new[k, c] = (transient * p[c] - net_out[c]) / (transient + outflow_coeff[c])
        for j in range(outflow.shape[0]):
            f = outflow[j]
            face_flux[k, f] = dt * volume_flux[f] * phi_new[k, face_cell_1[f]]


def vanleer_step_numba(geom, phi, u_n, dt):
    """One explicit step (2) for stacked fields ``phi`` (nF, nCells), compiled (numba)."""
    phi = np.ascontiguousarray(phi, dtype=float)
    phi_new = np.empty_like(phi)
    face_flux = np.zeros((phi.shape[0], geom.n_faces))
    _vanleer_step_kernel(phi, geom.volume_flux(u_n), float(dt), geom.face_cell_1,
                         geom.face_cell_2, geom.face_ratio, geom.area_projection,
                         geom.cell_faces, geom.cell_face_sign, geom.cell_volume,
                         geom.kappa_volume, geom.face_area, geom.face_normal, geom.interior,
                         geom.interior_distance, geom.outflow, phi_new, face_flux)
    return phi_new, face_flux


_BACKENDS = {"numba": vanleer_step_numba, "numpy": vanleer_step_numpy}


class Transport:
    """Fast transport: FiPy's van Leer update (2) on FiPy's mesh arrays, all fields at once.

    Same constructor and ``step`` as ``FiPyTransport`` (plus ``backend``, ``"numba"`` or
    ``"numpy"``); ``step_stacked`` works on ``(nFields, nCells)`` arrays without dicts.
    """

    def __init__(self, mesh, kappa, aperture, outflow_faces, field_names, backend="numba"):
        self.mesh = mesh
        self.geometry = TransportGeometry.from_mesh(mesh, kappa, aperture, outflow_faces)
        self.field_names = tuple(field_names)
        self.backend = backend
        self._step = _BACKENDS[backend]

    def step_stacked(self, phi, u_n, dt):
        """Advance stacked fields ``phi`` (nF, nCells) by ``dt``; returns (phi_new, face_flux)."""
        return self._step(self.geometry, phi, u_n, dt)

    def step(self, fields, u_n, dt):
        """Advance every field by ``dt`` (s) with face normal velocity ``u_n`` (m/s, nFaces).

        Returns ``(new_fields, face_flux)`` as ``FiPyTransport.step``.
        """
        stacked = np.stack([np.asarray(fields[name], dtype=float) for name in self.field_names])
        new, flux = self.step_stacked(stacked, u_n, dt)
        names = self.field_names
        return ({n: new[k] for k, n in enumerate(names)},
                {n: flux[k] for k, n in enumerate(names)})

    def max_stable_dt(self, u_n, cfl=0.5, alpha=None, alpha_min=1e-3,
                      kappa_min=KAPPA_CFL_MIN):
        """``max_stable_dt`` on this geometry."""
        return max_stable_dt(self.geometry, u_n, cfl=cfl, alpha=alpha, alpha_min=alpha_min,
                             kappa_min=kappa_min)

    def neighbour_pairs(self):
        """``open_neighbour_pairs`` on this geometry."""
        return open_neighbour_pairs(self.geometry)


# --------------------------------------------------------------------------------------------
# 3. Time-step rule
# --------------------------------------------------------------------------------------------

def outgoing_volume_flux(geom, u_n):
    """Total outgoing volume flux ``sum_faces max(F_out, 0)`` of every cell (m^3/s per rad).

    Counts interior faces and outflow faces only (other exterior faces carry nothing).
    """
    volume_flux = geom.volume_flux(u_n)
    faces = geom.interior
    f_int = volume_flux[faces]
    n = geom.n_cells
    out = (np.bincount(geom.face_cell_1[faces], np.maximum(f_int, 0.0), n)
           + np.bincount(geom.face_cell_2[faces], np.maximum(-f_int, 0.0), n))
    f_out = volume_flux[geom.outflow]
    out += np.bincount(geom.face_cell_1[geom.outflow], np.maximum(f_out, 0.0), n)
    return out


def max_stable_dt(geom, u_n, cfl=0.5, alpha=None, alpha_min=1e-3, kappa_min=KAPPA_CFL_MIN):
    """Largest ``dt`` with ``dt sum_out F <= cfl max(kappa, kappa_min) V`` in every open cell.

    Guard for cut cells: a cell limits ``dt`` as if it were at least ``kappa_min`` open (default
    0.1), so slivers at the wall do not shrink the step; what such a sliver overdraws or
    overfills is put right by ``redistribute_overshoot``.  Solid cells (``kappa == 0``) have
    closed faces and never limit.

    Material-weighted variant: given ``alpha`` (nCells), only cells holding material
    (``alpha >= alpha_min``) limit ``dt``; empty cells move nothing, and light cells of a
    falling jet (fast, nearly empty) are left to the boundedness rule.

    Returns ``inf`` if nothing moves.
    """
    out = outgoing_volume_flux(geom, u_n)
    capacity = np.maximum(geom.kappa, kappa_min) * geom.cell_volume
    limiting = (out > 0.0) & (geom.kappa > 0.0)
    if alpha is not None:
        limiting &= np.asarray(alpha) >= alpha_min
    if not np.any(limiting):
        return np.inf
    return float(cfl * np.min(capacity[limiting] / out[limiting]))


# --------------------------------------------------------------------------------------------
# 4. Boundedness: conservative redistribution of overshoot (alpha > alpha_max) and deficit
# --------------------------------------------------------------------------------------------

def open_neighbour_pairs(geom):
    """Cell pairs ``(2, nPairs)`` sharing an interior face with a positive aperture."""
    faces = geom.interior[geom.aperture[geom.interior] > 0.0]
    return np.stack([geom.face_cell_1[faces], geom.face_cell_2[faces]])


@dataclass
class Redistribution:
    """What ``redistribute_overshoot`` moved: a list of passes, each ``(donor, receiver,
    fraction)`` arrays, ``fraction`` being the share of the donor's content (at that pass)
    handed to the receiver.  ``residual_excess`` / ``residual_deficit`` (field x m^3/rad) is
    what could not be placed.
    """

    passes: list = field(default_factory=list)
    residual_excess: float = 0.0
    residual_deficit: float = 0.0

    @property
    def moved(self):
        """Number of transfers made (0: the field was already within bounds)."""
        return sum(p[0].size for p in self.passes)

    def apply(self, fields, kappa_volume):
        """Move alpha-weighted fields (nCells,) or (nF, nCells) with the same ratios.

        Content ``Q = q kappa V`` of each field: every pass moves ``fraction Q_donor`` from
        donor to receiver, so ``q / alpha`` of the moved material is that of its donor and
        the total of every field is conserved.  Returns the new per-open-volume fields.
        """
        q = np.asarray(fields, dtype=float)
        content = q * kappa_volume
        flat = content.reshape(-1, content.shape[-1])
        n = flat.shape[-1]
        for donor, receiver, fraction in self.passes:
            for row in flat:
                moved = fraction * row[donor]
                row += np.bincount(receiver, moved, n) - np.bincount(donor, moved, n)
        return content / kappa_volume


def _transfer_pass(need, give_capacity, pairs_from, pairs_to, take_capacity):
    """Amounts of one redistribution pass along directed edges ``pairs_from -> pairs_to``.

    Every cell with ``need > 0`` wants to send ``need`` to neighbours with
    ``take_capacity > 0``, shared in proportion to that capacity; every receiver is capped at
    its capacity (all requests to it scaled down together).  Returns the edge amounts.
    """
    n = need.size
    sender = need[pairs_from] > 0.0
    room = np.where(sender, take_capacity[pairs_to], 0.0)
    room_sum = np.bincount(pairs_from, room, n)
    share = np.divide(room, room_sum[pairs_from], out=np.zeros_like(room),
                      where=room_sum[pairs_from] > 0.0)
    amount = need[pairs_from] * share
    incoming = np.bincount(pairs_to, amount, n)
    scale = np.minimum(1.0, np.divide(take_capacity, incoming, out=np.ones(n),
                                      where=incoming > 0.0))
    return amount * scale[pairs_to] * np.minimum(1.0, give_capacity[pairs_from] /
                                                 np.maximum(need[pairs_from], 1e-300))


def redistribute_overshoot(alpha, kappa, volume, pairs, alpha_max=1.0, sweeps=20, tol=1e-14):
    """Conservatively bring ``alpha`` into ``[0, alpha_max]``; never clips mass away.

    Rule (content ``c = alpha kappa V``, neighbours = cells sharing an open face, ``pairs``
    from ``open_neighbour_pairs``), repeated for at most ``sweeps`` sweeps until nothing is out
    of bounds by more than ``tol`` (relative):

    1. excess: an overfull cell sends ``(alpha - alpha_max) kappa V`` to its neighbours with
       room ``(alpha_max - alpha) kappa V``, in proportion to their room, no receiver past full;
    2. pass-through: an overfull cell whose neighbours are all full sends its excess to all its
       neighbours equally (they pass it on in the next sweep, so excess travels through packed
       material to where there is room);
    3. deficit: a cell with ``alpha < 0`` draws ``-alpha kappa V`` from its neighbours holding
       material, in proportion to their content, none below zero.

    Returns ``(alpha_new, redistribution)``; ``redistribution.apply(q, kappa V)`` moves the
    alpha-weighted fields ``q`` with the same ratios.  Solid cells (``kappa == 0``) are left
    alone.
    """
    kappa_volume = np.asarray(kappa, dtype=float) * np.asarray(volume, dtype=float)
    content = np.asarray(alpha, dtype=float) * kappa_volume
    pairs = np.asarray(pairs, dtype=np.int64)
    source = np.concatenate([pairs[0], pairs[1]])      # directed edges, both ways
    target = np.concatenate([pairs[1], pairs[0]])
    full = alpha_max * kappa_volume
    scale = tol * max(float(np.sum(np.abs(content))), 1e-300)
    record = Redistribution()

    def record_pass(amount, donor, receiver):
        keep = amount > 0.0
        if not np.any(keep):
            return
        donor, receiver, amount = donor[keep], receiver[keep], amount[keep]
        fraction = amount / content[donor]
        record.passes.append((donor, receiver, fraction))
        content[:] = (content + np.bincount(receiver, amount, content.size)
                      - np.bincount(donor, amount, content.size))

    for _ in range(sweeps):
        excess = np.maximum(content - full, 0.0)
        deficit = np.maximum(-content, 0.0)
        if excess.sum() <= scale and deficit.sum() <= scale:
            break
        if excess.sum() > scale:
            room = np.maximum(full - content, 0.0)
            amount = _transfer_pass(excess, excess, source, target, room)
            # cells whose neighbours have no room pass their excess through
            room_sum = np.bincount(source, np.where(excess[source] > 0, room[target], 0.0),
                                   content.size)
            boxed_in = (excess > 0.0) & (room_sum == 0.0)
            degree = np.bincount(source, minlength=content.size)
            through = np.where(boxed_in[source], excess[source] / np.maximum(degree[source], 1),
                               0.0)
            record_pass(amount + through, source, target)
        deficit = np.maximum(-content, 0.0)
        if deficit.sum() > scale:
            supply = np.maximum(content, 0.0)
            # a receiver (negative cell) draws from suppliers: edges target -> source reversed
            amount = _transfer_pass(deficit, deficit, source, target, supply)
            record_pass(amount, target, source)

    record.residual_excess = float(np.maximum(content - full, 0.0).sum())
    record.residual_deficit = float(np.maximum(-content, 0.0).sum())
    alpha_new = np.divide(content, kappa_volume, out=np.asarray(alpha, dtype=float).copy(),
                          where=kappa_volume > 0.0)
    return alpha_new, record
