"""The fixed Eulerian grid: a ``fipy.CylindricalGrid2D`` over the hopper and a free-fall zone
(a ``fipy`` ``Grid2D`` of the half-section for a wedge: plane strain, per metre of length).

Layout (``x = r``, ``y = z``): ``nr`` square cells of size ``h`` from the axis to beyond the bin
wall, ``nz`` rows from ``z_bottom = -free_fall_depth`` (aligned so that the outlet plane
``z = 0`` is a grid line) to just above the bin top.  FiPy numbers cells ``i + nr j`` and faces
z-normal first (``i + nr j`` for the row of faces at ``z_j``), then r-normal
(``n_zfaces + i + (nr + 1) j``).  Nodes are ``(nz + 1, nr + 1)`` arrays.

Cut cells: the open fraction ``kappa`` of each cell (volume fraction outside the wall, r-weighted
as the axisymmetric volume) and the aperture of each face (open fraction of its area) are
computed by sub-sampling each cell and face with ``n_sub`` points per direction (error below
``1/n_sub`` of a cell).  Cells with ``kappa < min_open_fraction`` are closed with their faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fipy import CylindricalGrid2D

from .fipy_adapter import UniformGrid2D
from .config import HopperConfig, grid_columns, grid_rows


@dataclass
class HopperGrid:
    """The grid and its immersed-wall data (all lengths in m, volumes per radian; for a wedge,
    ``r`` is the distance from the mid-plane and volumes are per metre of length)."""

    mesh: CylindricalGrid2D | UniformGrid2D
    h: float
    nr: int
    nz: int
    z_bottom: float
    j_outlet: int                 # node row at z = 0
    r_nodes: np.ndarray           # (nr + 1,)
    z_nodes: np.ndarray           # (nz + 1,)
    kappa: np.ndarray             # (nz, nr) open fraction of cells
    face_aperture: np.ndarray     # (n_faces,) FiPy face order
    cell_volume: np.ndarray       # (nz, nr) r_c h^2 per radian, h^2 for a wedge (mesh.cellVolumes)
    node_distance: np.ndarray     # (nz + 1, nr + 1) signed distance to the wall
    node_normal: np.ndarray       # (2, nz + 1, nr + 1) unit normal into the wall
    outflow_faces: np.ndarray     # (n_faces,) bool: bottom boundary, material leaves
    outlet_faces: np.ndarray      # (n_faces,) bool: faces in the outlet plane, r < R0

    @property
    def n_cells(self) -> int:
        return self.nr * self.nz

    @property
    def r_cells(self) -> np.ndarray:
        return 0.5 * (self.r_nodes[1:] + self.r_nodes[:-1])

    @property
    def z_cells(self) -> np.ndarray:
        return 0.5 * (self.z_nodes[1:] + self.z_nodes[:-1])

    @property
    def n_zfaces(self) -> int:
        """Number of z-normal faces (they come first in FiPy's numbering)."""
        return self.nr * (self.nz + 1)

    def zface_aperture(self) -> np.ndarray:
        """Apertures of the z-normal faces as a ``(nz + 1, nr)`` array."""
        return self.face_aperture[:self.n_zfaces].reshape(self.nz + 1, self.nr)

    def rface_aperture(self) -> np.ndarray:
        """Apertures of the r-normal faces as a ``(nz, nr + 1)`` array."""
        return self.face_aperture[self.n_zfaces:].reshape(self.nz, self.nr + 1)


def _open_fraction_cells(boundary, r_nodes, z_nodes, n_sub):
    """Open fraction of each cell (r-weighted for an axisymmetric grid), by ``n_sub x n_sub``
    midpoint sub-sampling of ``boundary.in_solid`` (:class:`fipy_hopper.boundary.Boundary`)."""
    h_r, h_z = np.diff(r_nodes), np.diff(z_nodes)
    t = (np.arange(n_sub) + 0.5) / n_sub
    rs = r_nodes[:-1, None] + h_r[:, None] * t[None, :]          # (nr, n_sub)
    zs = z_nodes[:-1, None] + h_z[:, None] * t[None, :]          # (nz, n_sub)
    R = rs[None, :, None, :]                                      # (1, nr, 1, s)
    Z = zs[:, None, :, None]                                      # (nz, 1, s, 1)
    open_ = ~boundary.in_solid(R, Z)                              # (nz, nr, s, s)
    weight = np.broadcast_to(boundary.section.weight(R), open_.shape)
    return (open_ * weight).sum(axis=(2, 3)) / weight.sum(axis=(2, 3))


def _open_fraction_faces(boundary, r_nodes, z_nodes, n_sub):
    """Apertures of z-normal faces (nz+1, nr) and r-normal faces (nz, nr+1)."""
    t = (np.arange(n_sub) + 0.5) / n_sub
    h_r, h_z = np.diff(r_nodes), np.diff(z_nodes)
    rs = r_nodes[:-1, None] + h_r[:, None] * t[None, :]          # (nr, s)
    zs = z_nodes[:-1, None] + h_z[:, None] * t[None, :]          # (nz, s)
    # z-faces: area weight r (axisymmetric) or uniform (plane)
    open_z = ~boundary.in_solid(rs[None, :, :], z_nodes[:, None, None] + 1e-12)
    w = np.broadcast_to(boundary.section.weight(rs[None, :, :]), open_z.shape)
    a_z = (open_z * w).sum(axis=2) / w.sum(axis=2)
    # r-faces: uniform weight along z
    open_r = ~boundary.in_solid(r_nodes[None, :, None], zs[:, None, :])
    a_r = open_r.mean(axis=2)
    return a_z, a_r


def build_grid(cfg: HopperConfig, n_sub: int = 16) -> HopperGrid:
    """Build the FiPy grid covering the hopper, its wall's cut cells and the free-fall zone."""
    geom, num = cfg.hopper, cfg.numerics
    h = num.cell_size
    x0, _ = grid_columns(geom, h)
    nr, n_below, n_above = grid_rows(geom, num, h)
    nz = n_below + n_above
    z_bottom = -n_below * h
    if geom.axisymmetric:
        mesh = CylindricalGrid2D(dx=np.full(nr, h), dy=np.full(nz, h),
                                 origin=((0.0,), (z_bottom,)))
    else:                       # plane: a half-section or the full one, per metre of length
        mesh = UniformGrid2D(dx=h, dy=h, nx=nr, ny=nz, origin=((x0,), (z_bottom,)))
    r_nodes = x0 + h * np.arange(nr + 1)
    z_nodes = z_bottom + h * np.arange(nz + 1)
    z_nodes[n_below] = 0.0

    boundary = geom.boundary
    kappa = _open_fraction_cells(boundary, r_nodes, z_nodes, n_sub)
    a_z, a_r = _open_fraction_faces(boundary, r_nodes, z_nodes, n_sub)
    closed = kappa < num.min_open_fraction
    kappa = np.where(closed, 0.0, kappa)
    # a face is closed if either neighbour cell is closed (or it is an exterior wall face)
    a_z[1:-1] = np.where(closed[1:] | closed[:-1], 0.0, a_z[1:-1])
    a_r[:, 1:-1] = np.where(closed[:, 1:] | closed[:, :-1], 0.0, a_r[:, 1:-1])
    a_z[0] = np.where(closed[0], 0.0, a_z[0])
    a_z[-1] = np.where(closed[-1], 0.0, a_z[-1])
    a_r[:, 0] = 0.0            # axis: zero area anyway
    a_r[:, -1] = 0.0           # outer boundary is inside the wall
    face_aperture = np.concatenate([a_z.ravel(), a_r.ravel()])

    RN, ZN = np.meshgrid(r_nodes, z_nodes)
    node_distance = boundary.signed_distance(RN, ZN)
    node_normal = np.stack(boundary.wall_normal(RN, ZN))

    n_zfaces = nr * (nz + 1)
    outflow = np.zeros(len(face_aperture), dtype=bool)
    outflow[:nr] = True                                   # bottom row of z-faces
    outflow &= face_aperture > 0
    outlet = np.zeros(len(face_aperture), dtype=bool)
    outlet[n_below * nr: (n_below + 1) * nr] = True
    outlet &= face_aperture > 0
    cell_volume = np.asarray(mesh.cellVolumes).reshape(nz, nr)
    assert n_zfaces + (nr + 1) * nz == len(face_aperture)
    return HopperGrid(mesh=mesh, h=h, nr=nr, nz=nz, z_bottom=z_bottom, j_outlet=n_below,
                      r_nodes=r_nodes, z_nodes=z_nodes, kappa=kappa,
                      face_aperture=face_aperture, cell_volume=cell_volume,
                      node_distance=node_distance, node_normal=node_normal,
                      outflow_faces=outflow, outlet_faces=outlet)
