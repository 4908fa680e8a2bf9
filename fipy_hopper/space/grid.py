"""The fixed 3D Eulerian grid: a FiPy ``Grid3D`` of cubes of side ``h`` over the silo's computed
part, with its cut cells.

Mirror planes (``mirror_planes``): ``"auto"`` computes a centred silo as the quarter ``x >= 0,
y >= 0`` and an off-centre one (outlet on ``+x``) as the half ``y >= 0`` (a rectangular plan
with its outlet at ``(0, ey)``: the half ``x >= 0``; off both planes: the whole); ``"none"`` computes
all of it; ``"quarter"`` / ``"half"`` name the part.  A mirror plane is a plane of nodes
(``x = 0``, ``y = 0``) on which the normal velocity vanishes, and its faces are closed
(exterior) faces of the grid: nothing crosses it.  ``factor`` (4, 2 or 1) converts the
computed part's masses and forces to the whole silo's.

Extent: node planes ``x = h i`` and ``y = h j`` (exactly these products, so the cells of two
parts that overlap have the same sub-samples), two cells beyond the bin's radius (a
rectangular bin's half-width along x, half-length along y) on every side that is not a mirror
plane; rows as the sections' grid (:func:`fipy_hopper.config.grid_rows`):
at least ``free_fall_depth`` outlet diameters (and 3 cells) below the outlet plane, which is a
node plane, to a cell above the top.

Cells are ``(nz, ny, nx)`` arrays in FiPy's numbering ``i + nx j + nx ny k``; nodes
``(nz + 1, ny + 1, nx + 1)``; faces in FiPy's order: z-normal ``(nz + 1, ny, nx)``, then
y-normal ``(nz, ny + 1, nx)``, then x-normal ``(nz, ny, nx + 1)``.

Cut cells: the open fraction ``kappa`` of a cell (its volume fraction in the material) and the
aperture of a face (its open area fraction) by ``n_sub^3`` and ``n_sub^2`` midpoint sub-samples
of the exact ``SiloBoundary.in_solid`` (a point of a z-normal face is open if it is open
``1e-12`` m above and below its plane: a floor and the outlet's hole in it cut the faces of
their plane).  Only cells and faces within about a cell
of the wall are sampled; the others are wholly open or closed.  Cells with ``kappa <
min_open_fraction`` are closed with their faces; exterior faces are closed except the bottom
ones under open cells (outflow).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import fipy_adapter
from ..config import MIRROR_PLANES
from .boundary import SiloBoundary


def computed_part(mirror_planes: str, outlet_offset) -> tuple:
    """``(mirror_x, mirror_y)``: whether ``x = 0`` and ``y = 0`` are mirror planes, for an
    outlet ``outlet_offset`` off the axis along ``+x`` (a circular silo's distance) or at
    ``(ex, ey)`` (a rectangular plan's; ``"half"`` and ``"auto"`` take the mirror plane
    through the outlet's centre: ``y = 0`` when ``ey = 0``, else ``x = 0``; none when the
    outlet is on neither)."""
    if mirror_planes not in MIRROR_PLANES:
        raise ValueError(f"mirror_planes = {mirror_planes!r}: expected one of "
                         f"{', '.join(repr(m) for m in MIRROR_PLANES)}")
    if isinstance(outlet_offset, (tuple, list)):
        ex, ey = (float(e) for e in outlet_offset)
        if mirror_planes == "auto":
            mirror_planes = ("quarter" if ex == 0.0 and ey == 0.0 else
                             "half" if ex == 0.0 or ey == 0.0 else "none")
        if mirror_planes == "quarter" and (ex != 0.0 or ey != 0.0):
            raise ValueError("mirror_planes = 'quarter' needs a centred outlet "
                             "(outlet_offset = [0, 0])")
        if mirror_planes == "half":
            if ey == 0.0:
                return False, True
            if ex == 0.0:
                return True, False
            raise ValueError("mirror_planes = 'half' needs the outlet on x = 0 or y = 0")
        return {"quarter": (True, True), "none": (False, False)}[mirror_planes]
    if mirror_planes == "auto":
        mirror_planes = "quarter" if outlet_offset == 0.0 else "half"
    if mirror_planes == "quarter" and outlet_offset != 0.0:
        raise ValueError("mirror_planes = 'quarter' needs a centred outlet (outlet_offset = 0)")
    return {"quarter": (True, True), "half": (False, True), "none": (False, False)}[
        mirror_planes]


@dataclass
class SpaceGrid:
    """The grid and its immersed-wall data (lengths in m)."""

    mesh: object
    h: float
    nx: int
    ny: int
    nz: int
    x_nodes: np.ndarray           # (nx + 1,)
    y_nodes: np.ndarray           # (ny + 1,)
    z_nodes: np.ndarray           # (nz + 1,)
    k_outlet: int                 # node plane at z = 0
    mirror_x: bool                # x = 0 is a mirror plane (the grid's first node plane)
    mirror_y: bool                # y = 0 likewise
    kappa_sampled: np.ndarray     # (nz, ny, nx) open fraction before closing small cells
    kappa: np.ndarray             # (nz, ny, nx) open fraction used
    aperture_z: np.ndarray        # (nz + 1, ny, nx)
    aperture_y: np.ndarray        # (nz, ny + 1, nx)
    aperture_x: np.ndarray        # (nz, ny, nx + 1)
    node_distance: np.ndarray     # (nz + 1, ny + 1, nx + 1) signed distance, m
    node_normal: np.ndarray       # (3, nz + 1, ny + 1, nx + 1) unit normal into the wall
    outflow_z: np.ndarray         # (ny, nx) bool: bottom z-faces that material leaves by
    outlet_z: np.ndarray          # (ny, nx) bool: z-faces of the outlet plane in the outlet
    #                               (every open face of the plane: open above and below it)

    @property
    def factor(self) -> float:
        """The computed part to the whole silo: 4 (a quarter), 2 (a half) or 1."""
        return (2.0 if self.mirror_x else 1.0) * (2.0 if self.mirror_y else 1.0)

    @property
    def n_cells(self) -> int:
        return self.nx * self.ny * self.nz

    @property
    def cell_volume(self) -> float:
        return self.h ** 3

    def centres(self, axis: int) -> np.ndarray:
        nodes = (self.x_nodes, self.y_nodes, self.z_nodes)[axis]
        return 0.5 * (nodes[1:] + nodes[:-1])

    @property
    def face_aperture(self) -> np.ndarray:
        """Apertures of all faces in FiPy's order (z-, y-, then x-normal)."""
        return np.concatenate([self.aperture_z.ravel(), self.aperture_y.ravel(),
                               self.aperture_x.ravel()])

    @property
    def n_faces(self) -> tuple:
        """Numbers of the z-, y- and x-normal faces."""
        return (self.aperture_z.size, self.aperture_y.size, self.aperture_x.size)


def _axis_nodes(radius: float, h: float, mirror: bool) -> np.ndarray:
    """Node coordinates ``h i`` from 0 (a mirror plane) or two cells beyond ``-radius`` to two
    cells beyond ``radius``."""
    n = int(math.ceil(radius / h - 1e-9)) + 2
    return h * np.arange(0 if mirror else -n, n + 1)


def _solid(boundary, p, both_sides):
    """The solid test of points ``p`` (3, ...); with ``both_sides`` (z-normal faces) a point is
    open only if it is open ``1e-12`` m above and below: a floor, and a floor's hole, cut the
    faces of its plane."""
    if not both_sides:
        return boundary.in_solid(p[0], p[1], p[2])
    return boundary.in_solid(p[0], p[1], p[2] + 1e-12) | boundary.in_solid(p[0], p[1],
                                                                           p[2] - 1e-12)


def _sampled_fraction(boundary, lo, h, n_sub, dims, both_sides):
    """Open fraction of the boxes ``[lo, lo + h]`` along the axes ``dims`` (the other axes at
    ``lo``): ``lo`` (3, m) corner coordinates of m boxes; midpoint sub-samples."""
    t = (np.arange(n_sub) + 0.5) / n_sub * h
    grids = np.meshgrid(*([t] * len(dims)), indexing="ij")
    offsets = np.zeros((3, grids[0].size))
    for g, d in zip(grids, dims):
        offsets[d] = g.ravel()
    pts = lo[:, :, None] + offsets[:, None, :]
    return (~_solid(boundary, pts, both_sides)).mean(axis=1)


def _fractions(boundary, corner_lists, h, n_sub, dims, near, both_sides=False, chunk=1024):
    """Open fractions of boxes given by their corners ``(3, m)``: sampled where ``near``, else
    0 or 1 from the solid test of the box's centre."""
    lo = corner_lists
    centre = lo.copy()
    for d in dims:
        centre[d] += 0.5 * h
    out = (~_solid(boundary, centre, both_sides)).astype(float)
    idx = np.flatnonzero(near)
    for s in range(0, len(idx), chunk):
        sel = idx[s:s + chunk]
        out[sel] = _sampled_fraction(boundary, lo[:, sel], h, n_sub, dims, both_sides)
    return out


def build_grid(boundary, h: float, free_fall_depth: float = 1.0,
               min_open_fraction: float = 0.05, mirror_planes: str = "auto",
               n_sub: int = 8) -> SpaceGrid:
    """The grid of ``boundary`` (a :class:`SiloBoundary` or a
    :class:`~fipy_hopper.space.rectangular.RectangularSilo`) for cubes of side ``h`` (m)
    (module docstring)."""
    from ..fipy_adapter import UniformGrid3D

    mirror_x, mirror_y = computed_part(mirror_planes, boundary.outlet_offset)
    half_x, half_y = boundary.half_extent
    x_nodes = _axis_nodes(half_x, h, mirror_x)
    y_nodes = _axis_nodes(half_y, h, mirror_y)
    n_below = max(int(math.ceil(free_fall_depth * 2.0 * boundary.outlet_radius / h - 1e-9)), 3)
    n_above = int(math.ceil(boundary.top / h - 1e-9)) + 1
    z_nodes = h * np.arange(-n_below, n_above + 1)
    nx, ny, nz = len(x_nodes) - 1, len(y_nodes) - 1, len(z_nodes) - 1
    mesh = UniformGrid3D(dx=h, dy=h, dz=h, nx=nx, ny=ny, nz=nz,
                         origin=((x_nodes[0],), (y_nodes[0],), (z_nodes[0],)))

    Z, Y, X = np.meshgrid(z_nodes, y_nodes, x_nodes, indexing="ij")
    node_distance, node_normal = boundary.distance_normal(X, Y, Z)
    # a cell (face) is cut only if one of its corners lies within sqrt(3)/2 (sqrt(2)/2) of
    # a cell of the wall; 1.5 cells leave room for the sheared distance's first-order error
    near_node = np.abs(node_distance) < 1.5 * h

    def near(dims):
        """Boxes spanning the node ranges of ``dims`` with a near corner: (nz', ny', nx')."""
        out = near_node
        for d in dims:                        # axes of near_node: (z, y, x) = (2, 1, 0)
            ax = 2 - d
            sl_lo = [slice(None)] * 3
            sl_hi = [slice(None)] * 3
            sl_lo[ax], sl_hi[ax] = slice(None, -1), slice(1, None)
            out = out[tuple(sl_lo)] | out[tuple(sl_hi)]
        return out.ravel()

    def corners(shape):
        k, j, i = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
        return np.stack([x_nodes[i.ravel()], y_nodes[j.ravel()], z_nodes[k.ravel()]])

    kappa = _fractions(boundary, corners((nz, ny, nx)), h, n_sub, (0, 1, 2),
                       near((0, 1, 2))).reshape(nz, ny, nx)
    a_z = _fractions(boundary, corners((nz + 1, ny, nx)), h, n_sub, (0, 1), near((0, 1)),
                     both_sides=True).reshape(nz + 1, ny, nx)
    a_y = _fractions(boundary, corners((nz, ny + 1, nx)), h, n_sub, (0, 2),
                     near((0, 2))).reshape(nz, ny + 1, nx)
    a_x = _fractions(boundary, corners((nz, ny, nx + 1)), h, n_sub, (1, 2),
                     near((1, 2))).reshape(nz, ny, nx + 1)

    sampled = kappa.copy()
    closed = kappa < min_open_fraction
    kappa = np.where(closed, 0.0, kappa)
    a_z[1:-1] = np.where(closed[1:] | closed[:-1], 0.0, a_z[1:-1])
    a_y[:, 1:-1] = np.where(closed[:, 1:] | closed[:, :-1], 0.0, a_y[:, 1:-1])
    a_x[:, :, 1:-1] = np.where(closed[:, :, 1:] | closed[:, :, :-1], 0.0, a_x[:, :, 1:-1])
    a_z[0] = np.where(closed[0], 0.0, a_z[0])
    a_z[-1] = 0.0
    a_y[:, [0, -1]] = 0.0
    a_x[:, :, [0, -1]] = 0.0
    outflow = a_z[0] > 0.0
    # the outlet: the faces of the outlet plane open above and below it (all of them: a face
    # the outlet's edge cuts, whose centre lies outside it, lets material through too)
    outlet = a_z[n_below] > 0.0
    if not np.isclose(z_nodes[n_below], 0.0) or len(np.asarray(fipy_adapter.face_areas(mesh))) \
            != a_z.size + a_y.size + a_x.size:
        raise AssertionError("grid layout")
    return SpaceGrid(mesh=mesh, h=h, nx=nx, ny=ny, nz=nz, x_nodes=x_nodes, y_nodes=y_nodes,
                     z_nodes=z_nodes, k_outlet=n_below, mirror_x=mirror_x, mirror_y=mirror_y,
                     kappa_sampled=sampled, kappa=kappa, aperture_z=a_z, aperture_y=a_y,
                     aperture_x=a_x, node_distance=node_distance, node_normal=node_normal,
                     outflow_z=outflow, outlet_z=outlet)
