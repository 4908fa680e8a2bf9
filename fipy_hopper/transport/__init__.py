"""Conservative, bounded transport of cell fields on the fixed cylindrical grid.

The Eulerian step (docs/physics_and_numerics.md, section 5) carries every cell field ``phi`` (a
density per *open* volume: the material fraction ``alpha`` and alpha-weighted quantities such as
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

One explicit step of (1) is therefore, per cell P (``F = u_n a A`` the volume flux in m^3/s
per radian, counted positive out of P; sums over P's interior faces and its outflow faces)::

    (kappa V / dt + sum_out F) phi_P^new = kappa V / dt phi_P^old - sum_int F phi_f^old    (2)

Implementations of (2):

``FiPyTransport``
    the definition: one FiPy equation ``TransientTerm(kappa_eff) + VanLeerConvectionTerm(
    u a) == 0`` per field, built once, velocity updated with ``setValue``.  Slow (FiPy spends
    milliseconds per solve in Python); it is the readable reference the tests hold the
    kernels to.
``Transport`` (``backend="numba"``, the default)
    the same arithmetic on FiPy's own mesh arrays (``_adjacentCellIDs``, ``_faceAreas``,
    ``cellVolumes``, ``_cellDistances``, ``faceNormals``, ``_areaProjections``,
    ``_faceToCellDistanceRatio``), precomputed once and laid out on the (z, r) index grid of
    FiPy's 2D grid numbering (checked against ``faceCellIDs``), compiled with numba
    (``@njit(cache=True, error_model="numpy")``), all fields stacked as ``(nFields, nCells)``.
    Numba because (2) is a gather / limiter / scatter over faces whose numpy form needs some
    forty temporaries of size ``nFields x nFaces`` and scattered sums: the compiled loops run
    each face once, in cache (measured for six fields on 5,000 cells: 0.15 ms, against 3.5 ms
    for the numpy form and 70 ms for FiPy's own solves).
``Transport(backend="numpy")``
    plain vectorised numpy of the same arithmetic written on the unstructured face lists
    (gather, ``bincount`` scatter), the independent reference the compiled kernel is held to by
    a test (no per-cell Python loops either).

Support functions: ``max_stable_dt`` (the CFL rule of the step), ``redistribute_overshoot``
(the conservative boundedness rule for alpha) and ``Redistribution.apply`` (moves the
alpha-weighted fields with the same ratios); ``Transport.redistribute_fields`` does both on
the stacked fields in one call, in place.

Modules:

* ``geometry``: :class:`TransportGeometry`, FiPy's mesh arrays and the wall data of (2);
* ``fipy_term``: :class:`FiPyTransport` and ``AxisymmetricVanLeerConvectionTerm``, the FiPy
  definition;
* ``vanleer``: the step (2) in plain numpy and compiled on the index grid, the reconstruction of
  each ``scheme`` and ``material_rows``;
* ``time_step``: :func:`max_stable_dt`, the CFL rule;
* ``redistribution``: :func:`redistribute_overshoot` and :class:`Redistribution`, the
  boundedness rule.

:class:`Transport`, the facade over them that the model uses, is defined here.
"""

from __future__ import annotations

import numpy as np

from .fipy_term import FiPyTransport
from .geometry import KAPPA_FLOOR, TransportGeometry
from .redistribution import (NeighbourGraph, Redistribution, _redistribute_compiled,
                             open_neighbour_pairs, redistribute_overshoot)
from .time_step import KAPPA_CFL_MIN, max_stable_dt, outgoing_volume_flux
from .vanleer import (GridArrays, cell_gradient, grid_shape, material_rows, vanleer_step_grid,
                      vanleer_step_numpy)

__all__ = [
    "TransportGeometry",
    "FiPyTransport",
    "Transport",
    "max_stable_dt",
    "outgoing_volume_flux",
    "open_neighbour_pairs",
    "NeighbourGraph",
    "Redistribution",
    "redistribute_overshoot",
    "material_rows",
    "KAPPA_FLOOR",
    "KAPPA_CFL_MIN",
    "GridArrays",
    "grid_shape",
    "cell_gradient",
    "vanleer_step_numpy",
    "vanleer_step_grid",
]


class Transport:
    """Fast transport: FiPy's van Leer update (2) on FiPy's mesh arrays, all fields at once.

    Same constructor and ``step`` as ``FiPyTransport``, plus ``backend`` (``"numba"``, compiled,
    for FiPy 2D grid meshes; ``"numpy"``, any 2D mesh) and ``scheme`` (``"axisymmetric"``, the
    default: planar reconstruction geometry, bounded on cylindrical grids, see
    :mod:`fipy_hopper.transport.vanleer`; ``"fipy"``: FiPy's own arithmetic); each is held by
    a test to ``FiPyTransport`` of the same scheme.  ``step_stacked`` works on
    ``(nFields, nCells)`` arrays without dicts.
    """

    def __init__(self, mesh, kappa, aperture, outflow_faces, field_names, backend="numba",
                 scheme="axisymmetric"):
        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', not {backend!r}")
        self.mesh = mesh
        self.geometry = TransportGeometry.from_mesh(mesh, kappa, aperture, outflow_faces,
                                                    scheme=scheme)
        self.field_names = tuple(field_names)
        self.backend = backend
        self.scheme = scheme
        self.grid = (GridArrays.from_geometry(self.geometry, *grid_shape(mesh))
                     if backend == "numba" else None)
        self._neighbours = None
        self._kappa_volume = None

    def step_stacked(self, phi, u_n, dt, out=None, rows=None):
        """Advance stacked fields ``phi`` (nF, nCells) by ``dt``; returns (phi_new, face_flux).

        ``out=(phi_new, face_flux)``: optional arrays to write into; ``rows=(j0, j1)``: only
        these cell rows hold material (:func:`vanleer_step_grid`; numba backend).
        """
        if not dt > 0.0:
            raise ValueError(f"dt must be positive, not {dt!r}")
        if self.grid is None:
            return vanleer_step_numpy(self.geometry, phi, u_n, dt)
        return vanleer_step_grid(self.geometry, self.grid, phi, u_n, dt, out=out, rows=rows)

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

    def neighbours(self):
        """The ``NeighbourGraph`` of this geometry's open faces (built once)."""
        if self._neighbours is None:
            geom = self.geometry
            pairs, faces = open_neighbour_pairs(geom)
            self._neighbours = NeighbourGraph(pairs, geom.n_cells, faces, geom.n_faces)
        return self._neighbours

    def redistribute_overshoot(self, alpha, alpha_max=1.0, **options):
        """``redistribute_overshoot`` of ``alpha`` (nCells,) on this geometry, with the face
        transfers (``redistribution.face_flux``).  Returns ``(alpha_new, redistribution)``.
        """
        geom = self.geometry
        return redistribute_overshoot(alpha, geom.kappa, geom.cell_volume, self.neighbours(),
                                      alpha_max=alpha_max, **options)

    def apply_redistribution(self, fields, redistribution, out=None):
        """Move alpha-weighted ``fields`` (nCells,) or (nF, nCells) as ``redistribution``
        moved alpha (``Redistribution.apply`` with this geometry's ``kappa V``; ``out`` may
        be ``fields`` to move them in place).
        """
        return redistribution.apply(fields, self._open_volume(), out=out)

    def redistribute_fields(self, fields, alpha_max=1.0, sweeps=50, tol=1e-14, room_min=1e-6):
        """``redistribute_overshoot`` and ``apply_redistribution`` in one compiled call, in
        place: ``fields`` (nF, nCells), a writeable C-contiguous float64 array whose row 0 is
        alpha and whose other rows are alpha-weighted fields (same numbers as the two calls).
        Returns the ``Redistribution`` (``face_flux``: alpha moved across the faces;
        ``moved == 0``: nothing was changed).  Options as ``redistribute_overshoot``.
        """
        if not (isinstance(fields, np.ndarray) and fields.dtype == float and fields.ndim == 2
                and fields.shape[1] == self.geometry.n_cells and fields.flags.c_contiguous
                and fields.flags.writeable):
            raise ValueError("fields must be a writeable C-contiguous float64 (nF, nCells) "
                             "array")
        if self.backend == "numpy":              # the reference: whole-array passes
            geom = self.geometry
            alpha_new, record = redistribute_overshoot(
                fields[0], geom.kappa, geom.cell_volume, self.neighbours(), alpha_max=alpha_max,
                sweeps=sweeps, tol=tol, room_min=room_min, fields=fields[1:], backend="numpy")
            fields[0] = alpha_new
            return record
        return _redistribute_compiled(fields[0], fields[1:], self._open_volume(),
                                      self.neighbours(), alpha_max, sweeps, tol, room_min)

    def _open_volume(self):
        """``kappa V`` (nCells,): the open volume the redistribution counts contents in."""
        if self._kappa_volume is None:
            geom = self.geometry
            self._kappa_volume = np.ascontiguousarray(geom.kappa * geom.cell_volume)
        return self._kappa_volume
