"""Writers of a run directory: configuration, manifest, summary, tables and field snapshots.

A run directory describes itself::

    config.toml          the resolved configuration (every key, defaults included)
    manifest.json        package and dependency versions, start/end time, wall time, stop reason
    summary.json         the run's headline numbers (see :meth:`Simulation.summary`)
    timeseries.csv       t_s, mass_in_hopper_kg, discharged_kg, discharge_rate_kg_s, ...
    wall_pressure.csv    stage, t_s, s_m, r_m, z_m, p_n_Pa, tau_Pa
    fields/fields.pvd    the field snapshots over time for ParaView (a VTU series)
    fields/fields_NNNN.vtu, fields/snapshots.csv
    fields/markers_NNNN.vtu   the passive layer markers of snapshot NNNN (when the run has them)
    checkpoint.npz       while a run is unfinished (removed when it finishes)
    *.png, discharge.gif the pictures (:mod:`fipy_hopper.plotting`)

Every file is written atomically: to a temporary file in the same folder, then renamed over
the target with :func:`os.replace`, so a run killed at any moment leaves each file either in
its old or in its new complete form.  Writers read the state and never change it.
"""

from __future__ import annotations

import contextlib
import csv
import datetime
import io as _io
import json
import math
import os
import platform
import sys
import tempfile
from pathlib import Path
from typing import Iterable, Optional, Union

import numpy as np

__all__ = [
    "RunDirectory", "RunDirectoryError", "Manifest", "FieldWriter", "atomic_path",
    "atomic_write_text", "write_json", "write_timeseries", "write_wall_pressure", "read_csv",
    "environment_versions", "grid_points_and_quads", "cell_fields", "marker_file",
    "write_markers", "read_markers",
    "TIMESERIES_COLUMNS", "WALL_PRESSURE_COLUMNS",
]

PathLike = Union[str, os.PathLike]

#: Columns of ``timeseries.csv`` (the first four are the public contract).
TIMESERIES_COLUMNS = ("t_s", "mass_in_hopper_kg", "discharged_kg", "discharge_rate_kg_s",
                      "mass_flow_index", "stagnant_fraction")
#: Columns of ``wall_pressure.csv`` (public contract).
WALL_PRESSURE_COLUMNS = ("stage", "t_s", "s_m", "r_m", "z_m", "p_n_Pa", "tau_Pa")
#: Columns of ``fields/snapshots.csv``.
SNAPSHOT_COLUMNS = ("index", "file", "step", "t_s", "discharge_time_s", "stage")

#: The dependencies whose versions the manifest records.
DEPENDENCIES = ("fipy", "numpy", "scipy", "numba", "matplotlib", "meshio", "pillow", "tomli")


def _file_mode() -> int:
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


_FILE_MODE = _file_mode()


class RunDirectoryError(Exception):
    """The output directory cannot be used (exists and is not empty, nothing to resume, ...)."""


# ---------------------------------------------------------------- atomic files
@contextlib.contextmanager
def atomic_path(path: PathLike):
    """Yield a temporary path next to ``path``; on success rename it over ``path``.

    The temporary name keeps the target's suffix (writers that pick a format from the file
    name, such as Pillow's, still work) and starts with a dot.  On an exception the temporary
    file is removed and ``path`` is untouched.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}",
                               dir=path.parent)
    os.close(fd)
    os.chmod(tmp, _FILE_MODE)      # mkstemp makes 0600; outputs get the usual permissions
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, flushed to disk before the rename."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())


def _jsonable(value):
    """Plain JSON values: numpy scalars to Python, non-finite floats to ``None``."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


def write_json(path: PathLike, data: dict) -> None:
    """Write ``data`` as strict JSON (NaN and infinities become ``null``), atomically."""
    atomic_write_text(path, json.dumps(_jsonable(data), indent=2, allow_nan=False) + "\n")


def _num(value) -> str:
    """A number as text that reads back to the same float (``repr``), or ``nan``."""
    return repr(float(value))


def _write_csv(path: PathLike, columns: Iterable[str], rows: Iterable[Iterable]) -> None:
    buf = _io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(rows)
    atomic_write_text(path, buf.getvalue())


def read_csv(path: PathLike) -> dict:
    """Read a CSV written here: ``{column: array}``; numeric columns as float arrays."""
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        rows = list(reader)
    out = {}
    for k, name in enumerate(header):
        values = [row[k] for row in rows]
        try:
            out[name] = np.array([float(v) for v in values], dtype=float)
        except ValueError:
            out[name] = np.array(values, dtype=str)
    return out


# ---------------------------------------------------------------- tables
def write_timeseries(path: PathLike, record) -> None:
    """``timeseries.csv`` from a :class:`~fipy_hopper.simulation.RunRecord`.

    ``t_s`` is the time since the outlet opened (s); masses are for the full 3D hopper (kg);
    ``discharge_rate_kg_s`` is the mass through the outlet over the preceding sample interval.
    """
    n = len(record.t)
    rows = ([_num(record.t[i]), _num(record.mass_in_hopper[i]), _num(record.discharged[i]),
             _num(record.rate[i]), _num(record.mass_flow_index[i]),
             _num(record.stagnant_fraction[i])] for i in range(n))
    _write_csv(path, TIMESERIES_COLUMNS, rows)


def write_wall_pressure(path: PathLike, record) -> None:
    """``wall_pressure.csv`` from the record's wall samples, one row per arc-length bin.

    ``s_m`` is the arc length along the wall from the outlet lip, ``(r_m, z_m)`` the wall point,
    ``p_n_Pa`` the normal pressure (compression positive), ``tau_Pa`` the shear stress (up the
    wall positive); ``t_s`` is the time since the outlet opened (0 for the filled state).
    """
    rows = []
    for stage, (t, s, r, z, p, tau) in record.wall.items():
        for k in range(len(s)):
            rows.append([stage, _num(t), _num(s[k]), _num(r[k]), _num(z[k]), _num(p[k]),
                         _num(tau[k])])
    _write_csv(path, WALL_PRESSURE_COLUMNS, rows)


# ---------------------------------------------------------------- run directory
class RunDirectory:
    """The folder of one run, with the names of everything written into it.

    A new run refuses an existing directory that is not empty unless ``force=True``; with
    ``force`` the files a previous run wrote there are removed first (other files are left
    alone).  ``resume=True`` requires the directory of an unfinished run (its configuration
    and checkpoint).
    """

    CONFIG = "config.toml"
    MANIFEST = "manifest.json"
    SUMMARY = "summary.json"
    TIMESERIES = "timeseries.csv"
    WALL_PRESSURE = "wall_pressure.csv"
    CHECKPOINT = "checkpoint.npz"
    FIELDS = "fields"
    ERROR_LOG = "error.log"
    FIGURES = ("flow_pattern.png", "discharge.png", "wall_pressure.png", "discharge.gif")

    def __init__(self, path: PathLike, force: bool = False, resume: bool = False):
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise RunDirectoryError(f"{self.path} exists and is not a directory")
        if resume:
            missing = [name for name in (self.CONFIG, self.CHECKPOINT)
                       if not (self.path / name).is_file()]
            if missing:
                raise RunDirectoryError(
                    f"cannot resume: {self.path} holds no {' and no '.join(missing)} "
                    "(only an interrupted run can be resumed)")
            self._remove_temporaries()
        else:
            if self.path.is_dir() and any(self.path.iterdir()):
                if not force:
                    raise RunDirectoryError(
                        f"{self.path} exists and is not empty; choose another directory, "
                        "add --force to overwrite it, or --resume to continue an interrupted run")
                self._remove_outputs()
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            self.fields.mkdir(exist_ok=True)
        except OSError as exc:
            raise RunDirectoryError(f"cannot create {self.path}: {exc.strerror}") from None

    def __truediv__(self, name: str) -> Path:
        return self.path / name

    @property
    def fields(self) -> Path:
        return self.path / self.FIELDS

    @property
    def checkpoint(self) -> Path:
        return self.path / self.CHECKPOINT

    def _remove_outputs(self) -> None:
        names = (self.CONFIG, self.MANIFEST, self.SUMMARY, self.TIMESERIES, self.WALL_PRESSURE,
                 self.CHECKPOINT, self.ERROR_LOG) + self.FIGURES
        for name in names:
            with contextlib.suppress(FileNotFoundError):
                (self.path / name).unlink()
        if self.fields.is_dir():
            for item in self.fields.iterdir():
                if item.is_file() and (item.suffix in (".vtu", ".pvd") or item.name ==
                                       "snapshots.csv" or ".tmp" in item.name):
                    item.unlink()
        self._remove_temporaries()

    def _remove_temporaries(self) -> None:
        """Temporary files left by a run killed in the middle of a write."""
        for folder in (self.path, self.fields):
            if folder.is_dir():
                for item in folder.glob(".*.tmp*"):
                    with contextlib.suppress(OSError):
                        item.unlink()


# ---------------------------------------------------------------- manifest
def environment_versions() -> dict:
    """Versions of Python, the platform, fipy_hopper and its dependencies."""
    from importlib import metadata

    from . import __version__
    deps = {}
    for name in DEPENDENCIES:
        try:
            deps[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return {"package": "fipy_hopper", "version": __version__,
            "python": sys.version.split()[0], "platform": platform.platform(),
            "dependencies": deps}


def _now() -> str:
    return datetime.datetime.now().astimezone().isoformat(timespec="seconds")


class Manifest:
    """``manifest.json``: what ran, with which versions, when, for how long, and why it stopped.

    A run may span several sessions (an interrupted run and its resumptions); ``start_time`` is
    that of the first, ``end_time`` that of the last, ``wall_time_s`` the sum of their wall times.
    ``status`` is ``"running"`` while a session runs, then ``"finished"``, ``"failed"``,
    ``"interrupted"`` (Ctrl-C or SIGTERM) or ``"stopped"`` (at ``run.wall_time_limit``; the
    last two can be resumed from the checkpoint).
    """

    def __init__(self, path: PathLike, data: dict):
        self.path = Path(path)
        self.data = data

    @classmethod
    def new(cls, path: PathLike, config_source: str, command: str) -> "Manifest":
        data = dict(environment_versions())
        data.update({"config_source": config_source, "command": command,
                     "start_time": _now(), "end_time": None, "wall_time_s": 0.0,
                     "status": "running", "stop_reason": "", "checkpoints_written": 0,
                     "sessions": []})
        return cls(path, data)

    @classmethod
    def load(cls, path: PathLike) -> "Manifest":
        with open(path, encoding="utf-8") as fh:
            return cls(path, json.load(fh))

    def begin_session(self, command: str, resumed_from_step: Optional[int] = None,
                      resumed_from_t: Optional[float] = None) -> None:
        versions = environment_versions()
        session = {"start_time": _now(), "end_time": None, "wall_time_s": None,
                   "command": command, "version": versions["version"],
                   "dependencies": versions["dependencies"]}
        if resumed_from_step is not None:
            session.update(resumed_from_step=resumed_from_step, resumed_from_t_s=resumed_from_t)
        self.data["sessions"].append(session)
        self.data.update(status="running", end_time=None, stop_reason="")
        self.write()

    def end_session(self, status: str, stop_reason: str, wall_time: float) -> None:
        now = _now()
        session = self.data["sessions"][-1]
        session.update(end_time=now, wall_time_s=wall_time, status=status,
                       stop_reason=stop_reason)
        self.data.update(status=status, stop_reason=stop_reason, end_time=now,
                         wall_time_s=self.total_wall_time())
        self.write()

    def total_wall_time(self) -> float:
        return float(sum(s.get("wall_time_s") or 0.0 for s in self.data["sessions"]))

    def checkpoint_written(self, t: float, step: int) -> None:
        self.data["checkpoints_written"] = self.data.get("checkpoints_written", 0) + 1
        self.data["last_checkpoint"] = {"time": _now(), "t_s": t, "step": step}
        self.write()

    def write(self) -> None:
        write_json(self.path, self.data)


# ---------------------------------------------------------------- fields
def grid_points_and_quads(grid):
    """Points ``(N, 3)`` = ``(r, z, 0)`` of the grid's nodes and the quads of its cells.

    Node ``(j, i)`` (row ``j`` in z, column ``i`` in r) is point ``j (nr + 1) + i``; cell
    ``(j, i)`` is quad ``j nr + i`` (the order of ``state.alpha.ravel()``), counter-clockwise
    in the r-z plane.
    """
    nr, nz = grid.nr, grid.nz
    R, Z = np.meshgrid(np.asarray(grid.r_nodes, float), np.asarray(grid.z_nodes, float))
    points = np.column_stack([R.ravel(), Z.ravel(), np.zeros(R.size)])
    j, i = np.meshgrid(np.arange(nz), np.arange(nr), indexing="ij")
    n0 = (j * (nr + 1) + i).ravel()
    quads = np.column_stack([n0, n0 + 1, n0 + nr + 2, n0 + nr + 1]).astype(np.int64)
    return points, quads


def cell_fields(state, grid) -> dict:
    """The cell data of a snapshot (SI units), each ``(n_cells,)`` or ``(n_cells, 3)``.

    ``alpha`` material fraction of the open cell volume, ``open_fraction`` the cut-cell open
    fraction ``kappa`` (0 inside the wall), ``layer`` the layer tracer, ``velocity`` the mean of
    the cell's four nodal velocities as ``(v_r, v_z, 0)`` (m/s), ``speed`` its magnitude,
    ``stress_rr/zz/tt/rz`` the material stress (Pa, tension positive), ``pressure``
    ``p = -(s_rr + s_zz + s_tt) / 3`` (Pa, compression positive), ``plastic_strain`` the
    accumulated equivalent plastic strain, ``loose_strain`` the loose volumetric strain of
    the dense/loose rule (0 = dense, see :func:`fipy_hopper.material.close_loose_volume`).
    """
    v = np.asarray(state.v, float)
    v_cell = 0.25 * (v[:, :-1, :-1] + v[:, :-1, 1:] + v[:, 1:, :-1] + v[:, 1:, 1:])
    velocity = np.column_stack([v_cell[0].ravel(), v_cell[1].ravel(),
                                np.zeros(v_cell[0].size)])
    sigma = np.asarray(state.sigma, float).reshape(-1, 4)
    return {
        "alpha": np.asarray(state.alpha, float).ravel(),
        "open_fraction": np.asarray(grid.kappa, float).ravel(),
        "layer": np.asarray(state.layer, float).ravel(),
        "velocity": velocity,
        "speed": np.hypot(velocity[:, 0], velocity[:, 1]),
        "stress_rr": sigma[:, 0].copy(),
        "stress_zz": sigma[:, 1].copy(),
        "stress_tt": sigma[:, 2].copy(),
        "stress_rz": sigma[:, 3].copy(),
        "pressure": -(sigma[:, 0] + sigma[:, 1] + sigma[:, 2]) / 3.0,
        "plastic_strain": np.asarray(state.eps_p, float).ravel(),
        "loose_strain": (np.zeros(np.size(state.alpha)) if getattr(state, "loose", None) is None
                         else np.asarray(state.loose, float).ravel()),
    }


def marker_file(field_file: str) -> str:
    """The name of the marker file of a snapshot: ``fields_NNNN.vtu`` -> ``markers_NNNN.vtu``."""
    return "markers_" + field_file.removeprefix("fields_")


def write_markers(path: PathLike, markers) -> None:
    """Marker points ``(n, 3)`` = ``(r, z, layer)`` as a VTU of vertices, atomically.

    The points are ``(r, z, 0)`` (m, x = r, y = z as the field snapshots) with the layer id as
    point data ``layer``.
    """
    import meshio

    markers = np.asarray(markers, dtype=float).reshape(-1, 3)
    n = len(markers)
    points = np.column_stack([markers[:, 0], markers[:, 1], np.zeros(n)])
    mesh = meshio.Mesh(points, [("vertex", np.arange(n, dtype=np.int64)[:, None])],
                       point_data={"layer": markers[:, 2].copy()})
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu")


def read_markers(path: PathLike) -> Optional[np.ndarray]:
    """The markers ``(n, 3)`` = ``(r, z, layer)`` of a file of :func:`write_markers`, or
    ``None`` if there is no such file."""
    import meshio

    path = Path(path)
    if not path.is_file():
        return None
    mesh = meshio.read(path)
    return np.column_stack([mesh.points[:, 0], mesh.points[:, 1],
                            np.asarray(mesh.point_data["layer"], dtype=float).ravel()])


class FieldWriter:
    """Field snapshots as a VTU series with a ParaView ``.pvd`` index (physical time ``t_s``).

    Each snapshot ``fields_NNNN.vtu`` holds the r-z plane of the axisymmetric hopper as quads
    (x = r, y = z) with the cell data of :func:`cell_fields` and the nodal velocity as point
    data ``node_velocity``.  A state with passive layer markers (``state.markers``, a
    non-empty ``(n, 3)`` array, see :mod:`fipy_hopper.markers`) also gets
    ``markers_NNNN.vtu`` (:func:`write_markers`, same ``NNNN``).  ``fields.pvd`` and
    ``snapshots.csv`` (index, file, step, ``t_s`` since the start of filling,
    ``discharge_time_s`` since the outlet opened, stage) are rewritten after every snapshot.
    Use it as a simulation callback: ``writer(sim, state)``.
    """

    PVD = "fields.pvd"
    INDEX = "snapshots.csv"

    def __init__(self, folder: PathLike, grid):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.grid = grid
        self.points, self.quads = grid_points_and_quads(grid)
        self.entries: list = []

    def __call__(self, sim, state) -> None:
        self.write(state, t_open=sim.t_open)

    @property
    def last_step(self) -> Optional[int]:
        return self.entries[-1]["step"] if self.entries else None

    def write(self, state, t_open: float = math.nan) -> Path:
        import meshio

        index = len(self.entries)
        name = f"fields_{index:04d}.vtu"
        mesh = meshio.Mesh(self.points, [("quad", self.quads)],
                           point_data={"node_velocity": np.column_stack([
                               np.asarray(state.v[0], float).ravel(),
                               np.asarray(state.v[1], float).ravel(),
                               np.zeros(state.v[0].size)])},
                           cell_data={k: [v] for k, v in cell_fields(state, self.grid).items()})
        with atomic_path(self.folder / name) as tmp:
            meshio.write(tmp, mesh, file_format="vtu")
        markers = getattr(state, "markers", None)
        marker_path = self.folder / marker_file(name)
        if markers is not None and len(markers):
            write_markers(marker_path, markers)
        else:
            marker_path.unlink(missing_ok=True)      # never pair a snapshot with stale markers
        t_dis = state.t - t_open if math.isfinite(t_open) else math.nan
        self.entries.append({"index": index, "file": name, "step": int(state.step),
                             "t_s": float(state.t), "discharge_time_s": t_dis,
                             "stage": state.stage})
        self._write_index()
        return self.folder / name

    def _write_index(self) -> None:
        rows = ([e["index"], e["file"], e["step"], _num(e["t_s"]), _num(e["discharge_time_s"]),
                 e["stage"]] for e in self.entries)
        _write_csv(self.folder / self.INDEX, SNAPSHOT_COLUMNS, rows)
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "  <Collection>"]
        lines += [f'    <DataSet timestep="{e["t_s"]!r}" group="" part="0" file="{e["file"]}"/>'
                  for e in self.entries]
        lines += ["  </Collection>", "</VTKFile>", ""]
        atomic_write_text(self.folder / self.PVD, "\n".join(lines))

    def resume(self, step: int) -> None:
        """Continue the series of an interrupted run from a checkpoint taken at ``step``.

        Snapshots taken after the checkpoint are dropped with their marker files (the resumed
        run takes them again, at the same steps), so the series continues as if the run had
        never stopped.
        """
        self.entries = []
        index_path = self.folder / self.INDEX
        if index_path.is_file():
            table = read_snapshot_index(self.folder)
            self.entries = [e for e in table if e["step"] <= step]
        keep = {e["file"] for e in self.entries}
        keep |= {marker_file(name) for name in keep}
        for item in (*self.folder.glob("fields_*.vtu"), *self.folder.glob("markers_*.vtu")):
            if item.name not in keep:
                item.unlink()
        self._write_index()


def read_snapshot_index(folder: PathLike) -> list:
    """The rows of ``fields/snapshots.csv`` as dictionaries (numbers converted)."""
    with open(Path(folder) / FieldWriter.INDEX, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return [{"index": int(r["index"]), "file": r["file"], "step": int(r["step"]),
             "t_s": float(r["t_s"]), "discharge_time_s": float(r["discharge_time_s"]),
             "stage": r["stage"]} for r in rows]
