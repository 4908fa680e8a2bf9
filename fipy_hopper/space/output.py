"""Field snapshots of a 3D run as hexahedral VTU files with a ParaView ``.pvd`` index
(:class:`SpaceFieldWriter`, the 3D :class:`fipy_hopper.io.FieldWriter`): the whole silo, the
computed part's cells with their mirror images.  The tables of a 3D run
(``wall_pressure.csv`` with ``theta_deg``, ``wall_extremes.csv``, ``timeseries.csv``,
``loads.csv``, ``summary.json``) are the shared loop's (:mod:`fipy_hopper.io`,
:class:`fipy_hopper.simulation.Simulation`); every file is written atomically.
"""

from __future__ import annotations

import numpy as np

from ..io import FieldWriter


# ---------------------------------------------------------------- fields
#: VTK hexahedron corner order as (di, dj, dk)
_HEX = ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))
#: the order that keeps a reflected hexahedron's orientation (each face's ring reversed)
_REVERSED = (3, 2, 1, 0, 7, 6, 5, 4)
#: the stress components (xx, yy, zz, yz, xz, xy) and the axes whose reflection flips each
_STRESS = ("xx", "yy", "zz", "yz", "xz", "xy")
_FLIPS = ((), (), (), (1, 2), (0, 2), (0, 1))


def _reflections(grid) -> list:
    """The whole silo's copies of the computed part: ``(signs (3,), flips orientation)``."""
    out = [(np.array([1.0, 1.0, 1.0]), False)]
    if grid.mirror_y:
        out.append((np.array([1.0, -1.0, 1.0]), True))
    if grid.mirror_x:
        out.append((np.array([-1.0, 1.0, 1.0]), True))
    if grid.mirror_x and grid.mirror_y:
        out.append((np.array([-1.0, -1.0, 1.0]), False))
    return out


class SpaceFieldWriter(FieldWriter):
    """Field snapshots of a 3D run as hexahedral VTU files (``fields_NNNN.vtu``), the
    ParaView index (``fields.pvd``, physical time ``t_s``) and ``snapshots.csv``, rewritten
    after each snapshot (:class:`fipy_hopper.io.FieldWriter`: the same series, index and
    resumption).  The open cells (``kappa > 0``) of the whole silo (the computed part and its
    mirror images); cell data ``alpha``, ``kappa``, ``sigma_xx`` ... ``sigma_xy`` (Pa,
    tension positive), ``pressure`` (``-tr sigma / 3``), ``q`` (von Mises), ``eps_p``,
    ``loose``, ``speed`` and ``velocity`` (the mean of the cell's nodes, m/s); point data
    ``node_velocity``.  A simulation callback: ``writer(sim, state)``."""

    def __init__(self, folder, model):
        self._open(folder, 0.0, 30.0)
        self.model = model
        g = model.grid
        self.cells = np.argwhere(g.kappa > 0)                       # (n, 3) k, j, i
        Z, Y, X = np.meshgrid(g.z_nodes, g.y_nodes, g.x_nodes, indexing="ij")
        base = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        n_nodes = len(base)
        shape = (g.nz + 1, g.ny + 1, g.nx + 1)
        k, j, i = self.cells.T
        corners = np.stack([np.ravel_multi_index((k + dk, j + dj, i + di), shape)
                            for di, dj, dk in _HEX], axis=1)
        self.copies = _reflections(g)
        self.points = np.concatenate([base * sgn for sgn, _ in self.copies])
        self.hexes = np.concatenate([
            (corners[:, _REVERSED] if flip else corners) + c * n_nodes
            for c, (_, flip) in enumerate(self.copies)])

    def _mesh(self, state):
        """The snapshot of ``state`` as a ``meshio.Mesh``."""
        import meshio

        from ..material.principal3d import to_matrix
        k, j, i = self.cells.T
        sig = state.sigma[k, j, i]                                  # (n, 6)
        v = state.v
        vc = np.zeros((len(k), 3))
        for di, dj, dk in _HEX:
            vc += 0.125 * v[:, k + dk, j + dj, i + di].T
        pressure = -(sig[:, 0] + sig[:, 1] + sig[:, 2]) / 3.0
        dev = to_matrix(sig) + pressure[:, None, None] * np.eye(3)
        q = np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))
        scalars = {"alpha": state.alpha[k, j, i], "kappa": self.model.grid.kappa[k, j, i],
                   "pressure": pressure, "q": q, "eps_p": state.eps_p[k, j, i],
                   "loose": state.loose[k, j, i], "speed": np.linalg.norm(vc, axis=1)}
        cell_data = {name: [] for name in list(scalars) + [f"sigma_{c}" for c in _STRESS]
                     + ["velocity"]}
        for sgn, _ in self.copies:
            for name, values in scalars.items():
                cell_data[name].append(values)
            for c, (name, flips) in enumerate(zip(_STRESS, _FLIPS)):
                cell_data[f"sigma_{name}"].append(sig[:, c] * np.prod([sgn[a] for a in flips]))
            cell_data["velocity"].append(vc * sgn)
        cell_data = {name: [np.concatenate(values)] for name, values in cell_data.items()}
        nodes = v.reshape(3, -1).T
        point_data = {"node_velocity": np.concatenate([nodes * sgn for sgn, _ in self.copies])}
        return meshio.Mesh(self.points, [("hexahedron", self.hexes)], point_data=point_data,
                           cell_data=cell_data)
