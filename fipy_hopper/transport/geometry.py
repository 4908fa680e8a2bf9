"""Geometry of the transport step: FiPy's mesh arrays and the wall data, precomputed once.

``V`` = ``mesh.cellVolumes`` = dr dz r_c (m^3 per radian), ``A`` = ``mesh._faceAreas`` = face
length times face radius (m^2 per radian, zero on the axis), ``kappa`` (-) the open fraction of a
cell, ``a`` (-) the aperture of a face, and the volume flux ``F = u_n a A`` (m^3/s per radian)
along FiPy's ``mesh.faceNormals`` (equations (1) and (2) of :mod:`fipy_hopper.transport`).  The
reconstruction geometry of each ``scheme`` is described in :mod:`fipy_hopper.transport.vanleer`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fipy_adapter

__all__ = ["TransportGeometry", "KAPPA_FLOOR"]

#: Floor of the open fraction used in the time derivative of (2) (``kappa_eff = max(kappa,
#: KAPPA_FLOOR)``) so closed cells keep a regular diagonal; they have closed faces, so nothing
#: changes there.
KAPPA_FLOOR = 1e-12


@dataclass(frozen=True)
class TransportGeometry:
    """FiPy's mesh arrays and the wall data used by (2), precomputed once (all float64/int64).

    Face arrays have length ``nFaces``; ``interior`` lists the interior faces (FiPy order) and
    ``outflow`` the opened exterior faces.  Cells with ``kappa < kappa_floor`` (1e-12) are
    solid: ``aperture`` is set to zero on every face touching one, so they never exchange
    anything (and ``kappa_eff = kappa_floor`` only keeps their diagonal regular).
    ``scheme`` selects the geometry of the face reconstruction
    (:mod:`fipy_hopper.transport.vanleer`).
    """

    n_cells: int
    n_faces: int
    cell_volume: np.ndarray          # V (nCells,), m^3/rad
    kappa: np.ndarray                # open fraction as given (nCells,)
    kappa_volume: np.ndarray         # kappa_eff V (nCells,)
    face_area: np.ndarray            # A (nFaces,), m^2/rad
    aperture: np.ndarray             # a (nFaces,)
    face_normal: np.ndarray          # FiPy faceNormals (2, nFaces)
    face_cell_1: np.ndarray          # FiPy _adjacentCellIDs[0] (nFaces,)
    face_cell_2: np.ndarray          # FiPy _adjacentCellIDs[1] (= cell 1 on exterior faces)
    face_ratio: np.ndarray           # FiPy _faceToCellDistanceRatio (arithmetic face value)
    cell_faces: np.ndarray           # FiPy cellFaceIDs (M, nCells)
    cell_face_sign: np.ndarray       # FiPy _cellToFaceOrientations (M, nCells), float
    interior: np.ndarray             # interior face ids (nInt,)
    interior_distance: np.ndarray    # FiPy _cellDistances on interior faces (nInt,)
    outflow: np.ndarray              # outflow face ids (nOut,)
    outflow_mask: np.ndarray         # bool (nFaces,)
    scheme: str                      # "fipy" or "axisymmetric" (see transport.vanleer)
    gradient_projection: np.ndarray  # (2, nFaces): n A ("fipy") or n L ("axisymmetric")
    gradient_volume: np.ndarray      # (nCells,): V ("fipy") or the planar area dr dz
    reach_1: np.ndarray              # (nInt,): A ("fipy") or V_1 / (2 d_1f), cell-1 side
    reach_2: np.ndarray              # (nInt,): A ("fipy") or V_2 / (2 d_2f), cell-2 side

    @classmethod
    def from_mesh(cls, mesh, kappa, aperture, outflow_faces, kappa_floor=KAPPA_FLOOR,
                  scheme="fipy"):
        """Read the geometry from a FiPy mesh (2D, e.g. ``CylindricalGrid2D``).

        ``kappa`` (nCells,), ``aperture`` (nFaces,) in [0, 1]; ``outflow_faces`` a bool mask
        (nFaces,) or None.  Outflow faces must be exterior faces.  ``scheme`` selects the
        gradient and face-extrapolation geometry (:mod:`fipy_hopper.transport.vanleer`).
        """
        if scheme not in ("fipy", "axisymmetric"):
            raise ValueError(f"scheme must be 'fipy' or 'axisymmetric', not {scheme!r}")
        n_cells, n_faces = mesh.numberOfCells, mesh.numberOfFaces
        kappa = np.clip(np.asarray(kappa, dtype=float).reshape(n_cells), 0.0, 1.0)
        aperture = np.clip(np.asarray(aperture, dtype=float).reshape(n_faces), 0.0, 1.0)
        id1, id2 = (np.asarray(ids, dtype=np.int64)
                    for ids in fipy_adapter.adjacent_cell_ids(mesh))
        solid = kappa < kappa_floor
        aperture = np.where(solid[id1] | solid[id2], 0.0, aperture)
        exterior = np.asarray(mesh.exteriorFaces.value, dtype=bool)
        if outflow_faces is None:
            outflow_mask = np.zeros(n_faces, dtype=bool)
        else:
            outflow_mask = np.asarray(outflow_faces, dtype=bool).reshape(n_faces)
        if np.any(outflow_mask & ~exterior):
            raise ValueError("outflow_faces must be exterior faces")
        interior = np.flatnonzero(~exterior).astype(np.int64)
        volume = np.asarray(mesh.cellVolumes, dtype=float)
        face_area = np.asarray(fipy_adapter.face_areas(mesh), dtype=float)
        normal = np.asarray(mesh.faceNormals, dtype=float)
        if scheme == "fipy":
            gradient_projection = np.asarray(fipy_adapter.area_projections(mesh), dtype=float)
            gradient_volume = volume
            reach_1 = reach_2 = face_area[interior]
        else:
            vertices = np.asarray(mesh.vertexCoords, dtype=float)
            ends = np.ma.filled(mesh.faceVertexIDs, 0)
            length = np.hypot(*(vertices[:, ends[1]] - vertices[:, ends[0]]))
            gradient_projection = normal * length
            gradient_volume = _planar_cell_areas(mesh)
            to_cell = np.ma.filled(fipy_adapter.face_to_cell_distances(mesh), 0.0)[:, interior]
            reach_1 = volume[id1[interior]] / (2.0 * to_cell[0])
            reach_2 = volume[id2[interior]] / (2.0 * to_cell[1])
        return cls(
            n_cells=n_cells,
            n_faces=n_faces,
            cell_volume=volume,
            kappa=kappa,
            kappa_volume=np.maximum(kappa, kappa_floor) * volume,
            face_area=face_area,
            aperture=aperture,
            face_normal=np.ascontiguousarray(normal),
            face_cell_1=id1,
            face_cell_2=id2,
            face_ratio=np.asarray(fipy_adapter.face_to_cell_distance_ratio(mesh), dtype=float),
            cell_faces=np.ascontiguousarray(np.ma.filled(mesh.cellFaceIDs, 0).astype(np.int64)),
            cell_face_sign=np.ascontiguousarray(
                np.ma.filled(fipy_adapter.cell_to_face_orientations(mesh), 0).astype(float)),
            interior=interior,
            interior_distance=np.asarray(fipy_adapter.cell_distances(mesh), dtype=float)[interior],
            outflow=np.flatnonzero(outflow_mask).astype(np.int64),
            outflow_mask=outflow_mask,
            scheme=scheme,
            gradient_projection=np.ascontiguousarray(gradient_projection),
            gradient_volume=np.ascontiguousarray(gradient_volume),
            reach_1=np.ascontiguousarray(reach_1),
            reach_2=np.ascontiguousarray(reach_2),
        )

    def outflow_velocity(self, u_n):
        """``u_n`` (nFaces,) with ``max(u_n, 0)`` on the outflow faces: there is no inflow."""
        u_n = np.array(u_n, dtype=float).reshape(self.n_faces)
        u_n[self.outflow] = np.maximum(u_n[self.outflow], 0.0)
        return u_n

    def volume_flux(self, u_n):
        """``F = u_n a A`` (m^3/s per radian) along the face normals, (nFaces,); no inflow
        through outflow faces (``outflow_velocity``); other exterior faces are never used.
        """
        return (self.outflow_velocity(u_n) * self.aperture) * self.face_area


def _planar_cell_areas(mesh):
    """Area of every cell in the (r, z) plane (shoelace over its ordered vertices), m^2."""
    vertices = np.asarray(mesh.vertexCoords, dtype=float)
    ids = np.ma.filled(fipy_adapter.ordered_cell_vertex_ids(mesh), -1)
    x, y = vertices[0][ids], vertices[1][ids]                   # (M, nCells)
    valid = ids >= 0
    x_next, y_next = np.roll(x, -1, axis=0), np.roll(y, -1, axis=0)
    return 0.5 * np.abs(np.sum(np.where(valid, x * y_next - x_next * y, 0.0), axis=0))
