"""What a 3D run writes: the wall pressure around the circumference (``wall_pressure.csv`` with
``theta_deg``), the time series, the summary, and field snapshots as hexahedral VTU files with
a ParaView ``.pvd`` index.  Pure functions of a :class:`~fipy_hopper.space.run.SpaceRun` (its
model, state and record); every file is written atomically (a temporary file renamed over the
target, :func:`fipy_hopper.io.atomic_path`).

The whole silo is written: the computed part's patches and cells with their mirror images
(:mod:`fipy_hopper.space.wall`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import diagnostics
from ..io import _num, _write_csv, atomic_path, atomic_write_text, write_json
from .flow import flow_mode_by_sector
from .wall import circumference_extremes

#: Columns of the 3D ``wall_pressure.csv``: the sections' (``fipy_hopper.io``) with
#: ``theta_deg`` (the sector's centre) and ``segment`` (the profile's) beside ``s_m``, and the
#: hoop shear ``tau_theta_Pa``; no membrane forces (a shell of revolution's, not 3D's).
WALL_PRESSURE_COLUMNS = ("stage", "wall", "t_s", "s_m", "r_m", "z_m", "theta_deg", "segment",
                         "p_n_Pa", "tau_Pa", "tau_theta_Pa", "p_n_stress_Pa", "tau_stress_Pa",
                         "p_n_raw_Pa", "tau_raw_Pa", "window_s")
#: Columns of ``wall_extremes.csv``: per stage and height bin the largest and the smallest
#: pressure around the circumference, their sectors and their ratio.
EXTREMES_COLUMNS = ("stage", "s_m", "z_m", "p_max_Pa", "theta_max_deg", "p_min_Pa",
                    "theta_min_deg", "max_over_min")
TIMESERIES_COLUMNS = ("t_s", "mass_in_hopper_kg", "discharged_kg", "discharge_rate_kg_s")
#: Columns of ``loads.csv``: the sections' (``fipy_hopper.io.LOADS_COLUMNS``), the vertical
#: momentum balance over each interval as mean forces (N, whole silo, upward positive)
LOADS_COLUMNS = ("stage", "t_s", "weight_N", "wall_vertical_N", "outlet_N", "damping_N",
                 "light_nodes_N", "momentum_outflow_N", "momentum_rate_N", "residual_N",
                 "relative_residual")
_LOADS_KEYS = ("weight", "wall", "outlet", "damping", "stopped", "outflow", "momentum_rate",
               "residual", "relative_residual")
#: The stages of the wall loads, in the order written (the sections' ``WALL_STAGES``).
STAGES = ("filling", "early_discharge", "mid_discharge", "discharge_envelope")


def stage_maps(run) -> dict:
    """``{stage: dict}`` of the recorded wall-load windows: ``t_s`` (end of the window since
    the opening, 0 at rest), ``window_s``, the recovered ``p_n``, ``tau``, ``tau_theta``, the
    raw ``p_n_raw``, ``tau_raw`` and the stress-sampled ``p_n_stress``, ``tau_stress`` maps
    (n_bins, n_sectors, Pa); the envelope has only ``p_n`` (the others NaN)."""
    rec, loads = run.record, run.loads
    out = {}
    for stage in STAGES:
        if stage == "discharge_envelope":
            if rec.envelope is None:
                continue
            nan = np.full_like(rec.envelope, np.nan)
            out[stage] = {"t_s": rec.t[-1] if rec.t else math.nan,
                          "window_s": run.model.cfg.run.load_window_s, "p_n": rec.envelope,
                          "tau": nan, "tau_theta": nan, "p_n_raw": nan, "tau_raw": nan,
                          "p_n_stress": nan, "tau_stress": nan}
            continue
        if stage not in rec.windows:
            continue
        start, end = rec.windows[stage]
        p, tau, th = loads.maps(start, end)
        p_r, tau_r, _ = loads.raw_maps(start, end)
        nan = np.full_like(p, np.nan)
        p_s, tau_s, _ = rec.stress.get(stage, (nan, nan, nan))
        t_s = 0.0 if stage == "filling" else end["t"] - run.t_open
        out[stage] = {"t_s": t_s, "window_s": end["t"] - start["t"], "p_n": p, "tau": tau,
                      "tau_theta": th, "p_n_raw": p_r, "tau_raw": tau_r, "p_n_stress": p_s,
                      "tau_stress": tau_s}
    return out


def write_wall_pressure(path, run) -> None:
    """``wall_pressure.csv``: one row per stage, height bin and sector of the whole silo.
    ``s_m`` the bin's centre along the wall profile's meridian from the outlet's lip, ``(r_m,
    z_m)`` that point about its part's axis, ``theta_deg`` the sector's centre around it (0
    towards the outlet's offset); ``p_n_Pa``, ``tau_Pa`` (up the meridian), ``tau_theta_Pa``
    (towards increasing theta): the patch's mean of the traction recovered from the wall's
    reaction over the stage's window of ``window_s`` s; ``*_raw``: the plain binning;
    ``*_stress``: from the stresses of the cells next to the wall at the window's end
    (:mod:`fipy_hopper.space.wall`)."""
    P = run.loads.patches
    rows = []
    for stage, m in stage_maps(run).items():
        for b in range(P.n_bins):
            for k in range(P.n_sectors):
                rows.append([stage, "wall", _num(m["t_s"]), _num(P.s[b]), _num(P.r[b]),
                             _num(P.z[b]), _num(P.theta_deg[k]), int(P.segment[b]),
                             _num(m["p_n"][b, k]), _num(m["tau"][b, k]),
                             _num(m["tau_theta"][b, k]), _num(m["p_n_stress"][b, k]),
                             _num(m["tau_stress"][b, k]), _num(m["p_n_raw"][b, k]),
                             _num(m["tau_raw"][b, k]), _num(m["window_s"])])
    _write_csv(path, WALL_PRESSURE_COLUMNS, rows)


def extremes(run) -> dict:
    """``{stage: (largest, smallest, ratio, theta_max, theta_min)}`` (n_bins,) of the
    recovered pressure around the circumference (:func:`circumference_extremes`)."""
    P = run.loads.patches
    out = {}
    for stage, m in stage_maps(run).items():
        p = m["p_n"]
        big, small, ratio = circumference_extremes(p)
        finite = np.isfinite(p)
        safe_max = np.where(finite, p, -np.inf)
        safe_min = np.where(finite, p, np.inf)
        out[stage] = (big, small, ratio, P.theta_deg[np.argmax(safe_max, axis=1)],
                      P.theta_deg[np.argmin(safe_min, axis=1)])
    return out


def write_extremes(path, run) -> None:
    """``wall_extremes.csv`` (:data:`EXTREMES_COLUMNS`)."""
    P = run.loads.patches
    rows = []
    for stage, (big, small, ratio, t_max, t_min) in extremes(run).items():
        for b in range(P.n_bins):
            rows.append([stage, _num(P.s[b]), _num(P.z[b]), _num(big[b]), _num(t_max[b]),
                         _num(small[b]), _num(t_min[b]), _num(ratio[b])])
    _write_csv(path, EXTREMES_COLUMNS, rows)


def write_timeseries(path, run) -> None:
    """``timeseries.csv`` of the discharge's samples (:data:`TIMESERIES_COLUMNS`)."""
    rec = run.record
    rows = [[_num(t), _num(m), _num(d), _num(w)] for t, m, d, w in
            zip(rec.t, rec.mass_in_hopper, rec.discharged, rec.rate)]
    _write_csv(path, TIMESERIES_COLUMNS, rows)


def write_loads(path, run) -> None:
    """``loads.csv`` of the run's balance rows (:data:`LOADS_COLUMNS`)."""
    rows = [[row["stage"], _num(row["t_s"])] + [_num(row[k]) for k in _LOADS_KEYS]
            for row in run.record.loads]
    _write_csv(path, LOADS_COLUMNS, rows)


def summary(run, flow_rule=diagnostics.FlowModeRule()) -> dict:
    """The run's headline numbers: the sections' rate, mass balance, fill and rest-balance
    keys (``steady_discharge_rate_kg_s``, ``mass_balance_error``, ``fill_weight_N``,
    ``fill_wall_vertical_N``, ``fill_outlet_N``, ``fill_equilibrium_residual``,
    ``load_balance_residual_max`` over the rows of ``loads.csv``, ...), the
    wall's largest and smallest pressure around the circumference at each stage
    (``wall_pressure_max_Pa``, ``..._min_Pa``, ``..._max_over_min`` per height bin, and the
    largest ratio over the bins ``wall_pressure_max_over_min``), the flow-mode call per sector
    (``wall_slip_ratio_by_sector``, ``flow_mode_by_sector``, and ``flow_mode``: ``"mass"``
    when every sector is), and the model's 3D keys."""
    m, st, rec = run.model, run.state, run.record
    rate, spread, _ = diagnostics.steady_rate(rec.t, rec.mass_in_hopper, rec.rate)
    m0 = rec.initial_mass
    remaining = m.mass_in_hopper(st)
    out = {"steady_discharge_rate_kg_s": rate, "steady_rate_spread": spread,
           "initial_mass_kg": m0 if math.isfinite(m0) else remaining,
           "remaining_mass_kg": remaining, "discharged_kg": st.discharged,
           "mass_balance_error": (abs(remaining + st.discharged - m0) / m0
                                  if math.isfinite(m0) and m0 > 0 else math.nan),
           "discharge_time_s": float(rec.t[-1]) if rec.t else 0.0,
           "fill_time_s": rec.fill_time, "fill_at_rest": rec.fill_at_rest,
           "stop_reason": rec.stop_reason, "cells": m.n_cells, "steps": st.step, "dt_s": m.dt,
           "cell_size_m": m.cell_size, "wall_time_s": rec.wall_time,
           "gravity_ramp_time_s": m.ramp_time}
    residuals = [r["relative_residual"] for r in rec.loads
                 if math.isfinite(r["relative_residual"])]
    out["load_balance_residual_max"] = float(max(residuals)) if residuals else math.nan
    if rec.rest:
        bal = run.loads.balance(*rec.rest)
        out.update(fill_weight_N=bal["weight"], fill_wall_vertical_N=bal["wall"],
                   fill_outlet_N=bal["outlet"],
                   fill_equilibrium_residual=abs(bal["wall"] + bal["outlet"] - bal["weight"])
                   / bal["weight"])
    P = run.loads.patches
    out["wall_bins_s_m"] = P.s.tolist()
    out["wall_bins_z_m"] = P.z.tolist()
    for stage, (big, small, ratio, _, _) in extremes(run).items():
        out[f"{stage}_wall_pressure_max_Pa"] = big.tolist()
        out[f"{stage}_wall_pressure_min_Pa"] = small.tolist()
        out[f"{stage}_wall_pressure_max_over_min"] = ratio.tolist()
        out[f"{stage}_wall_pressure_max_over_min_largest"] = (
            float(np.nanmax(ratio)) if np.isfinite(ratio).any() else math.nan)
    ratio, calls = flow_mode_by_sector(rec.wall_slip, rec.t, rec.mass_in_hopper, m0, flow_rule)
    out["wall_slip_ratio_by_sector"] = [float(r) for r in ratio]
    out["flow_mode_by_sector"] = calls
    out["flow_mode"] = ("mass" if calls and all(c == "mass" for c in calls)
                        else "funnel" if calls else "none")
    out["sector_theta_deg"] = P.theta_deg.tolist()
    out.update(m.summary_extras(st))
    return out


def write_run(folder, run) -> Path:
    """Write ``wall_pressure.csv``, ``wall_extremes.csv``, ``timeseries.csv``, ``loads.csv``
    and ``summary.json`` of a run into ``folder``; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_wall_pressure(folder / "wall_pressure.csv", run)
    write_extremes(folder / "wall_extremes.csv", run)
    write_timeseries(folder / "timeseries.csv", run)
    write_loads(folder / "loads.csv", run)
    write_json(folder / "summary.json", summary(run))
    return folder


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


class SpaceFieldWriter:
    """Field snapshots of a 3D run as hexahedral VTU files (``fields_NNNN.vtu``) and a
    ParaView index (``fields.pvd``, physical time ``t_s``), rewritten after each snapshot.
    The open cells (``kappa > 0``) of the whole silo (the computed part and its mirror
    images); cell data ``alpha``, ``kappa``, ``sigma_xx`` ... ``sigma_xy`` (Pa, tension
    positive), ``pressure`` (``-tr sigma / 3``), ``q`` (von Mises), ``eps_p``, ``loose``,
    ``speed`` and ``velocity`` (the mean of the cell's nodes, m/s); point data
    ``node_velocity``.  Use it as a :class:`SpaceRun` callback: ``writer(model, state,
    record)``."""

    PVD = "fields.pvd"

    def __init__(self, folder, model):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
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
        self.entries = []

    def __call__(self, model, state, record=None) -> None:
        self.write(state)

    def mesh(self, state):
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

    def write(self, state) -> Path:
        import meshio

        name = f"fields_{len(self.entries):04d}.vtu"
        mesh = self.mesh(state)
        with atomic_path(self.folder / name) as tmp:
            meshio.write(tmp, mesh, file_format="vtu")
        self.entries.append((float(state.t), name))
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "  <Collection>"]
        lines += [f'    <DataSet timestep="{t!r}" group="" part="0" file="{f}"/>'
                  for t, f in self.entries]
        lines += ["  </Collection>", "</VTKFile>", ""]
        atomic_write_text(self.folder / self.PVD, "\n".join(lines))
        return self.folder / name
