"""Writers of a run directory: configuration, manifest, summary, tables and field snapshots.

A run directory describes itself::

    config.toml          the resolved configuration (every key, defaults included)
    manifest.json        package and dependency versions, code commit, start/end time, wall time,
                         stop reason
    summary.json         the run's headline numbers (see :meth:`Simulation.summary`)
    summary.txt          the same summary as the terminal shows it (:mod:`.summary_text`)
    timeseries.csv       t_s, mass_in_hopper_kg, discharged_kg, discharge_rate_kg_s, ...
    wall_pressure.csv    stage, t_s, s_m, r_m, z_m, p_n_Pa, tau_Pa, ..., hoop and meridional forces
                         (3D: theta_deg, segment, tau_theta_Pa, no forces; one row per patch)
    wall_extremes.csv    3D: the largest and smallest pressure around the circumference
    channel_windows.csv  3D, a circular plan: the flow channel per window of the discharge
    fields/fields.pvd    the field snapshots over time for ParaView (a VTU series)
    fields/fields_NNNN.vtu, fields/snapshots.csv
    fields/markers_NNNN.vtu   the passive layer markers of snapshot NNNN (when the run has them)
    checkpoint.npz       while a run is unfinished (removed when it finishes)
    *.png, discharge.gif the pictures (:mod:`fipy_hopper.plotting`)
    .lock                while a run is using the directory (see :class:`RunDirectory`)

Every file is written atomically: to a temporary file in the same folder, then renamed over
the target with :func:`os.replace`, so a run killed at any moment leaves each file either in
its old or in its new complete form.  Writers read the state and never change it.
"""

from __future__ import annotations

import contextlib
import csv
import datetime
import errno
import functools
import io as _io
import json
import math
import os
import platform
import re
import stat
import subprocess
import sys
import tempfile
import warnings
import zipfile
from pathlib import Path
from typing import Iterable, Optional, Union

import numpy as np

from .config import short_text as _short

try:                      # POSIX; elsewhere runs are not locked
    import fcntl
except ImportError:       # pragma: no cover
    fcntl = None

__all__ = [
    "RunDirectory", "RunDirectoryError", "CheckpointError", "RunFileError", "read_checkpoint",
    "validate_checkpoint", "checkpoint_template", "checkpoint_size_limit", "check_run_files",
    "check_checkpoint_times",
    "Manifest", "FieldWriter", "atomic_path",
    "atomic_write_text", "write_json", "write_timeseries", "write_wall_pressure", "read_csv",
    "environment_versions", "code_commit", "grid_points_and_quads", "cell_fields", "marker_file",
    "write_markers", "read_markers", "read_vtu",
    "TIMESERIES_COLUMNS", "WALL_PRESSURE_COLUMNS", "WALL_SLIP_COLUMNS", "write_wall_slip",
]

PathLike = Union[str, os.PathLike]

#: Columns of ``timeseries.csv`` (the first four are the public contract).
TIMESERIES_COLUMNS = ("t_s", "mass_in_hopper_kg", "discharged_kg", "discharge_rate_kg_s",
                      "mass_flow_index", "stagnant_fraction", "bin_lateral_stress_ratio",
                      "wall_slip_ratio", "wall_slip_fraction")
#: Columns of ``wall_pressure.csv`` (public contract).
WALL_PRESSURE_COLUMNS = ("stage", "wall", "t_s", "s_m", "r_m", "z_m", "p_n_Pa", "tau_Pa",
                         "p_n_stress_Pa", "tau_stress_Pa", "p_n_raw_Pa", "tau_raw_Pa",
                         "window_s", "hoop_force_N_m",
                         "meridional_force_N_m")
#: Columns of ``wall_pressure.csv`` in 3D (``hopper.dimensions = 3``): the sections' with
#: ``theta_deg`` (the sector's centre around the axis, 0 towards the outlet's offset) and
#: ``segment`` (the wall profile's) beside ``s_m``, and the hoop shear ``tau_theta_Pa``; no
#: membrane forces (a shell of revolution's); one row per stage, height bin and sector.
WALL_PRESSURE_COLUMNS_3D = ("stage", "wall", "t_s", "s_m", "r_m", "z_m", "theta_deg",
                            "segment", "p_n_Pa", "tau_Pa", "tau_theta_Pa", "p_n_stress_Pa",
                            "tau_stress_Pa", "p_n_raw_Pa", "tau_raw_Pa", "window_s")
#: Columns of ``wall_pressure.csv`` of a rectangular plan (``plan = "rectangular"``): ``wall``
#: the face (``x_plus``, ``x_minus``, ``y_plus``, ``y_minus``, ``hopper_x_plus``, ...,
#: ``floor``), ``u`` the sector's centre across the face's width as a fraction of it (0 at
#: its -y end on the x faces and the floor, its -x end on the y faces), ``tau_h_Pa`` the shear
#: along the width (towards +u); one row per stage, height bin and sector of each face.
WALL_PRESSURE_COLUMNS_FACES = ("stage", "wall", "t_s", "s_m", "r_m", "z_m", "u", "segment",
                               "p_n_Pa", "tau_Pa", "tau_h_Pa", "p_n_stress_Pa",
                               "tau_stress_Pa", "p_n_raw_Pa", "tau_raw_Pa", "window_s")
#: Columns of ``wall_extremes.csv`` (3D): per stage and height bin the largest and the
#: smallest pressure around the circumference, their sectors and their ratio.
WALL_EXTREMES_COLUMNS = ("stage", "s_m", "z_m", "p_max_Pa", "theta_max_deg", "p_min_Pa",
                         "theta_min_deg", "max_over_min")
#: ``wall_extremes.csv`` of a rectangular plan: per stage, face and height bin the largest and
#: the smallest pressure across the face's width, where (``u``, a fraction of the width) and
#: their ratio
WALL_EXTREMES_COLUMNS_FACES = ("stage", "wall", "s_m", "z_m", "p_max_Pa", "u_max", "p_min_Pa",
                               "u_min", "max_over_min")
#: Columns of ``channel_windows.csv`` (3D, a circular plan): per window of the discharge
#: (``window``, its number among the load windows; its start and end, s since the outlet
#: opened; the checks its mean fields average) and node plane of the bin the flow channel of
#: the window's mean velocity (:func:`fipy_hopper.space.channel.field_channel`): its area,
#: equivalent radius and centroid, its contact half-angle with the wall and the contact's
#: middle, EN 1991-4's ``r_c`` and ``e_c`` of it, the fitted circle's RMS, the speed that
#: bounds it and its outline's extent (how far it reaches across the section each way)
CHANNEL_WINDOWS_COLUMNS = ("window", "t_start_s", "t_end_s", "checks", "z_m", "area_m2",
                           "r_eq_m", "centroid_x_m", "centroid_y_m", "theta_c_deg",
                           "contact_angle_deg", "r_c_m", "e_c_m", "fit_rms_m",
                           "threshold_m_s", "x_min_m", "x_max_m", "y_min_m", "y_max_m")
#: Columns of ``wall_slip.csv``: the loaded contacts of the hopper wall at the last sample of
#: the flow-mode window (:class:`fipy_hopper.diagnostics.FlowModeRule`).
WALL_SLIP_COLUMNS = ("s_m", "r_m", "z_m", "slip_ratio", "sliding")
#: Columns of ``loads.csv`` (public contract): the vertical momentum balance of the grid over
#: each interval, as mean forces (N, 3D, upward positive; ``weight`` positive).
LOADS_COLUMNS = ("stage", "t_s", "weight_N", "wall_vertical_N", "outlet_N", "damping_N",
                 "light_nodes_N", "momentum_outflow_N", "momentum_rate_N", "residual_N",
                 "relative_residual")
#: Columns of ``fields/snapshots.csv``.
SNAPSHOT_COLUMNS = ("index", "file", "step", "t_s", "discharge_time_s", "stage")

#: unit suffixes of extensive quantities and their per-metre forms (wedge hoppers)
PER_METRE = (("_kg_s", "_kg_s_m"), ("_kg", "_kg_m"), ("_N", "_N_m"), ("_J", "_J_m"))


def per_metre(values: dict) -> dict:
    """The same values with the names of masses, rates, forces and energies per metre of
    length (``steady_discharge_rate_kg_s`` -> ``steady_discharge_rate_kg_s_m``, ``_kg`` ->
    ``_kg_m``, ``_N`` -> ``_N_m``): what a wedge's results are."""
    out = {}
    for key, value in values.items():
        for suffix, metre in PER_METRE:
            if key.endswith(suffix):
                key = key[: -len(suffix)] + metre
                break
        out[key] = value
    return out


def result_key(key: str, axisymmetric: bool = True) -> str:
    """The name of a result (a ``summary.json`` key or a CSV column): as given for a cone, per
    metre of length for a wedge (:func:`per_metre`)."""
    return key if axisymmetric else next(iter(per_metre({key: None})))


def result_columns(columns, axisymmetric: bool = True) -> tuple:
    """The CSV header of ``columns`` for a cone, or per metre of length for a wedge."""
    return tuple(result_key(c, axisymmetric) for c in columns)

#: The dependencies whose versions the manifest records.
DEPENDENCIES = ("fipy", "numpy", "scipy", "numba", "matplotlib", "meshio", "pillow", "tomli")


def _file_mode() -> int:
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


_FILE_MODE = _file_mode()


class RunDirectoryError(Exception):
    """The output directory cannot be used (exists and is not empty, nothing to resume, ...)."""


class CheckpointError(RunDirectoryError):
    """A checkpoint file cannot be restored (corrupt, too large, wrong arrays)."""


class RunFileError(RunDirectoryError, ValueError):
    """A file of a run directory cannot be read (corrupt, truncated, not what its name says)."""


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
    """Read a CSV written here: ``{column: array}``; numeric columns as float arrays.

    Raises ``ValueError`` naming the file for text that is not such a table (not UTF-8, no
    header, rows of another length than the header).
    """
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            rows = list(reader)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{_short(path)} is not a CSV table: {exc}") from None
    if not header:
        raise ValueError(f"{_short(path)} is empty (no header line)")
    for n, row in enumerate(rows, start=2):
        if len(row) != len(header):
            raise ValueError(f"{_short(path)}, line {n}: {len(row)} values for "
                             f"{len(header)} columns")
    out = {}
    for k, name in enumerate(header):
        values = [row[k] for row in rows]
        try:
            out[name] = np.array([float(v) for v in values], dtype=float)
        except ValueError:
            out[name] = np.array(values, dtype=str)
    return out


# ---------------------------------------------------------------- tables
def write_timeseries(path: PathLike, record, axisymmetric: bool = True) -> None:
    """``timeseries.csv`` from a :class:`~fipy_hopper.simulation.RunRecord`.

    ``t_s`` is the time since the outlet opened (s); masses are for the full 3D hopper (kg);
    ``discharge_rate_kg_s`` is the mass through the outlet over the preceding sample interval;
    ``bin_lateral_stress_ratio`` the bin's ``sigma_rr / sigma_zz``
    (:func:`fipy_hopper.diagnostics.bin_lateral_stress_ratio`); ``wall_slip_ratio`` and
    ``wall_slip_fraction`` the slip along the hopper wall of
    :class:`fipy_hopper.diagnostics.FlowModeRule`.
    A wedge's masses and rates are per metre of length and named so (``mass_in_hopper_kg_m``,
    ``discharge_rate_kg_s_m``, :func:`result_columns`).
    """
    n = len(record.t)
    rows = ([_num(record.t[i]), _num(record.mass_in_hopper[i]), _num(record.discharged[i]),
             _num(record.rate[i]), _num(record.mass_flow_index[i]),
             _num(record.stagnant_fraction[i]), _num(record.bin_lateral_stress_ratio[i]),
             _num(record.wall_slip_ratio[i]), _num(record.wall_slip_fraction[i])]
            for i in range(n))
    _write_csv(path, result_columns(TIMESERIES_COLUMNS, axisymmetric), rows)


def write_wall_pressure(path: PathLike, record) -> None:
    """``wall_pressure.csv`` from the record's wall loads, one row per bin of wall.

    ``stage`` is ``filling`` (at rest), ``early_discharge`` / ``mid_discharge`` (90 % / 50 %
    of the mass left) or ``discharge_envelope`` (the largest windowed pressure per bin over
    the discharge); ``wall`` the wall the bin is on (``wall``, ``left_wall`` of a full
    section, ``insert_1``, ...); ``s_m`` the arc length along that wall from its lowest point
    (a wall's outlet lip) to the bin's centre, ``(r_m, z_m)`` the wall point there; the bins divide each straight stretch of
    wall into equal parts of about ``run.wall_bin_width``.  ``p_n_Pa`` is the normal
    pressure (compression positive) and ``tau_Pa`` the shear the wall exerts on the material
    (up the wall positive): the bin's mean of the traction recovered from the wall's reaction
    averaged over the stage's window of ``window_s`` seconds
    (:class:`fipy_hopper.diagnostics.WallLoads`; over each stretch it carries the stretch's
    reaction exactly).  ``p_n_raw_Pa``, ``tau_raw_Pa``: the plain binning of the reaction
    (each wall node's force in the bin of its wall point, over the bin's area), for checking:
    noisy where the wall cuts the cells.  ``p_n_stress_Pa``, ``tau_stress_Pa``: the estimate
    from the stresses of the cells next to the wall (empty where a bin held no material).
    ``t_s``: the time since the outlet opened at the end of the window (0 at rest).
    ``hoop_force_N_m`` and ``meridional_force_N_m``: the forces in the wall per unit length
    of its circumference (per metre of a wedge's length), tension positive, the hopper hung
    from the transition and the bin's wall standing on it
    (:meth:`fipy_hopper.diagnostics.WallLoads.membrane_forces`; the envelope has no
    meridional force, a wedge and a flat floor no hoop force: empty).
    """
    if getattr(record, "wall_theta", None):
        return _write_wall_pressure_3d(path, record)
    rows = []
    stress = getattr(record, "wall_stress", {})
    raw = getattr(record, "wall_raw", {})
    window = getattr(record, "wall_window", {})
    forces = getattr(record, "wall_forces", {})
    names = list(getattr(record, "wall_names", [])) or ["wall"] * max(
        (len(v[1]) for v in record.wall.values()), default=0)
    for stage, (t, s, r, z, p, tau) in record.wall.items():
        empty = np.full(len(s), np.nan)
        p_s, tau_s = stress.get(stage, (empty, empty))
        p_r, tau_r = raw.get(stage, (empty, empty))
        hoop, meridional = forces.get(stage, (empty, empty))[:2]
        for k in range(len(s)):
            rows.append([stage, names[k], _num(t), _num(s[k]), _num(r[k]), _num(z[k]),
                         _num(p[k]), _num(tau[k]), _num(p_s[k]), _num(tau_s[k]), _num(p_r[k]),
                         _num(tau_r[k]), _num(window.get(stage, math.nan)), _num(hoop[k]),
                         _num(meridional[k])])
    _write_csv(path, WALL_PRESSURE_COLUMNS, rows)


def _write_wall_pressure_3d(path: PathLike, record) -> None:
    """``wall_pressure.csv`` of a 3D run (:data:`WALL_PRESSURE_COLUMNS_3D`): one row per
    stage and patch (a height bin times a sector, the sectors of a bin together, the bins up
    the wall), the whole silo.  ``s_m`` the bin's centre along the wall profile's meridian
    from the outlet's lip, ``(r_m, z_m)`` that point about its part's axis (the silo's; an
    eccentric cone's section centre; the outlet's centre on a flat floor with an off-centre
    outlet), ``theta_deg`` the sector's centre around it (0 towards the outlet's offset,
    positive towards +y), ``segment`` the wall profile's segment; ``p_n_Pa``, ``tau_Pa`` (up
    the meridian), ``tau_theta_Pa`` (towards increasing theta): the patch's mean of the
    traction recovered from the wall's reaction over the stage's window;
    ``*_raw``: the plain binning; ``*_stress``: from the cells next to the wall
    (:mod:`fipy_hopper.space.wall`)."""
    theta, segment = record.wall_theta, record.wall_segment
    stress = getattr(record, "wall_stress", {})
    raw = getattr(record, "wall_raw", {})
    window = getattr(record, "wall_window", {})
    names = _face_names(record)
    rows = []
    for stage, values in record.wall.items():
        t, s, r, z, p, tau = values[:6]
        empty = np.full(len(s), np.nan)
        hoop = values[6] if len(values) > 6 else empty
        p_s, tau_s = stress.get(stage, (empty, empty))
        p_r, tau_r = raw.get(stage, (empty, empty))
        for k in range(len(s)):
            rows.append([stage, "wall" if names is None else names[k], _num(t), _num(s[k]),
                         _num(r[k]), _num(z[k]), _num(theta[k]), int(segment[k]), _num(p[k]),
                         _num(tau[k]), _num(hoop[k]), _num(p_s[k]), _num(tau_s[k]),
                         _num(p_r[k]), _num(tau_r[k]), _num(window.get(stage, math.nan))])
    _write_csv(path, WALL_PRESSURE_COLUMNS_3D if names is None else WALL_PRESSURE_COLUMNS_FACES,
               rows)


def _face_names(record):
    """The faces of a rectangular plan's patches (``record.wall_names``), or None (a circular
    silo's wall is ``"wall"``)."""
    names = list(getattr(record, "wall_names", []) or [])
    return names if names and any(n != "wall" for n in names) else None


def wall_extremes(record) -> dict:
    """``{stage: (s, z, largest, theta_max, smallest, theta_min, ratio)}`` per height bin of a
    3D run's recorded stages: the recovered pressure's largest and smallest around the
    circumference (Pa), their sectors' angles (deg) and their ratio
    (:func:`fipy_hopper.space.wall.circumference_extremes`); empty for a section."""
    from .space.wall import circumference_extremes

    theta = np.asarray(getattr(record, "wall_theta", []), float)
    if not len(theta):
        return {}
    n = len(np.unique(theta))
    sectors = theta[:n]
    names = _face_names(record)
    out = {}
    for stage, values in record.wall.items():
        p = np.asarray(values[4], float).reshape(-1, n)
        big, small, ratio = circumference_extremes(p)
        finite = np.isfinite(p)
        k_max = np.argmax(np.where(finite, p, -np.inf), axis=1)
        k_min = np.argmin(np.where(finite, p, np.inf), axis=1)
        out[stage] = (np.asarray(values[1])[::n], np.asarray(values[3])[::n], big,
                      sectors[k_max], small, sectors[k_min], ratio)
        if names is not None:
            out[stage] += (names[::n],)
    return out


def write_wall_extremes(path: PathLike, record) -> None:
    """``wall_extremes.csv`` of a 3D run (:data:`WALL_EXTREMES_COLUMNS`,
    :func:`wall_extremes`)."""
    rows = []
    faces = False
    for stage, values in wall_extremes(record).items():
        s, z, big, t_max, small, t_min, ratio = values[:7]
        faces = len(values) > 7
        for b in range(len(s)):
            rows.append(([stage, values[7][b]] if faces else [stage])
                        + [_num(s[b]), _num(z[b]), _num(big[b]), _num(t_max[b]),
                           _num(small[b]), _num(t_min[b]), _num(ratio[b])])
    _write_csv(path, WALL_EXTREMES_COLUMNS_FACES if faces else WALL_EXTREMES_COLUMNS, rows)


def write_wall_slip(path: PathLike, record, slip_ratio: float) -> None:
    """``wall_slip.csv``: one row per loaded contact of the hopper wall at the last sample of
    the flow-mode window (``RunRecord.wall_slip_profile``): its wall point (arc length
    ``s_m`` from the outlet lip, ``r_m``, ``z_m``), its slip speed down the wall over the axis
    speed at its height (``slip_ratio``) and whether that reaches the rule's ``slip_ratio``
    (``sliding``, 1 or 0).  No rows when nothing was measured."""
    rows = ([_num(s), _num(r), _num(z), _num(x), int(x >= slip_ratio)]
            for s, r, z, x in getattr(record, "wall_slip_profile", []))
    _write_csv(path, WALL_SLIP_COLUMNS, rows)


def write_channel_windows(path: PathLike, record) -> None:
    """``channel_windows.csv`` (:data:`CHANNEL_WINDOWS_COLUMNS`) from
    ``record.channel_windows``."""
    rows = ([_num(row.get(name, math.nan)) for name in CHANNEL_WINDOWS_COLUMNS]
            for row in record.channel_windows)
    _write_csv(path, CHANNEL_WINDOWS_COLUMNS, rows)


def write_loads(path: PathLike, record, axisymmetric: bool = True) -> None:
    """``loads.csv``: the vertical momentum balance of the grid over each output interval
    (:meth:`fipy_hopper.diagnostics.WallLoads.balance`), filling and discharge; ``t_s`` the
    time since filling began at the end of the interval (s).  With inserts, each insert's
    vertical force on the material (``insert_1_vertical_N``, ...: its part of
    ``wall_vertical_N``).  A plane section's forces are per metre of length (``weight_N_m``,
    ...)."""
    keys = ("weight", "wall", "outlet", "damping", "stopped", "outflow", "momentum_rate",
            "residual", "relative_residual")
    loads = getattr(record, "loads", [])
    inserts = sorted(k for k in (loads[0] if loads else {}) if k.startswith("insert_"))
    rows = [[row["stage"], _num(row["t_s"])] + [_num(row[k]) for k in keys]
            + [_num(row.get(k, math.nan)) for k in inserts] for row in loads]
    columns = LOADS_COLUMNS + tuple(f"{k}_vertical_N" for k in inserts)
    _write_csv(path, result_columns(columns, axisymmetric), rows)


# ---------------------------------------------------------------- run directory
class RunDirectory:
    """The folder of one run, with the names of everything written into it.

    A new run refuses an existing directory that is not empty unless ``force=True``; with
    ``force`` the directory must be an earlier run's (it holds a ``manifest.json`` of
    fipy-hopper), and only the files a run writes (:meth:`is_output`: the outputs, the
    pictures, the snapshots in ``fields/`` and the temporary files of their writers) are
    removed, after the directory and ``fields/`` are known to be writable (other files are
    left alone).  Nothing is followed out of the directory: a ``fields`` or ``.lock`` that is
    a symbolic link (or not a folder / a regular file), or an output name that is a folder,
    is refused before anything changes.  ``resume=True`` requires the directory of an
    unfinished run (its configuration and checkpoint).  An empty path (the current directory
    by accident) is refused.

    The directory is locked for the run: an exclusive ``fcntl.flock`` on ``DIR/.lock`` (opened
    with ``O_NOFOLLOW``: never through a link) is taken
    before anything in it is removed or written, and held until :meth:`close` (or the end of a
    ``with`` block, or the object's garbage collection).  A second run, ``--force`` or
    ``--resume`` into a directory that a live process holds is refused; the kernel drops the
    lock of a process that dies, so a ``.lock`` left by a killed run does not block.
    """

    CONFIG = "config.toml"
    MANIFEST = "manifest.json"
    SUMMARY = "summary.json"
    SUMMARY_TEXT = "summary.txt"
    PROFILE = "profile.json"
    TIMESERIES = "timeseries.csv"
    WALL_PRESSURE = "wall_pressure.csv"
    LOADS = "loads.csv"
    WALL_SLIP = "wall_slip.csv"
    WALL_EXTREMES = "wall_extremes.csv"
    CHANNEL_WINDOWS = "channel_windows.csv"
    CHECKPOINT = "checkpoint.npz"
    FIELDS = "fields"
    ERROR_LOG = "error.log"
    LOCK = ".lock"

    def __init__(self, path: PathLike, force: bool = False, resume: bool = False,
                 _check_only: bool = False):
        self._lock_fd = None
        if not os.fspath(path).strip():
            raise RunDirectoryError(f"the run directory {os.fspath(path)!r} is an empty path; "
                                    "give a directory name")
        self.path = Path(path)
        try:
            self._refusals(force, resume)
            if not _check_only:
                self._open(force, resume)
        except OSError as exc:       # a name too long, no permission, ...
            self.close()
            raise RunDirectoryError(f"cannot use {_short(self.path)} as a run directory: "
                                    f"{exc.strerror or exc}") from None
        except BaseException:
            self.close()
            raise

    @classmethod
    def check(cls, path: PathLike, force: bool = False, resume: bool = False) -> None:
        """Raise the :class:`RunDirectoryError` that opening ``path`` would raise before
        anything is written (not a directory, not empty, in use, nothing to resume), creating,
        locking and removing nothing."""
        cls(path, force=force, resume=resume, _check_only=True)

    def _refusals(self, force: bool, resume: bool) -> None:
        """The refusals that need no lock (taken again under it by :meth:`_open`)."""
        if self.path.exists() and not self.path.is_dir():
            raise RunDirectoryError(f"{_short(self.path)} exists and is not a directory")
        self._refuse_foreign_entries()
        if resume:
            missing = [name for name in (self.CONFIG, self.CHECKPOINT)
                       if not (self.path / name).is_file()]
            if missing:
                raise RunDirectoryError(
                    f"cannot resume: {_short(self.path)} holds no {' and no '.join(missing)} "
                    "(only an interrupted run can be resumed)")
            self._refuse_if_in_use()
        elif self._contents():
            self._refuse_if_in_use()
            if not force:
                self._refuse_not_empty()
            self._refuse_not_a_run()

    def _open(self, force: bool, resume: bool) -> None:
        if resume:
            self._lock()
            self._refuse_foreign_entries()
            self._refuse_unwritable()
            self._remove_temporaries()
        else:
            self.path.mkdir(parents=True, exist_ok=True)
            self._lock()
            self._refuse_foreign_entries()
            if self._contents():      # again under the lock: another run may have written
                if not force:
                    self._refuse_not_empty()
                self._refuse_not_a_run()
                self._refuse_unwritable()      # before anything of the earlier run goes
                self._remove_outputs()
        self.fields.mkdir(exist_ok=True)

    def _refuse_foreign_entries(self) -> None:
        """Refuse what a run would write through or cannot replace: a ``fields`` or ``.lock``
        that is a symbolic link (or not a folder, not a regular file), an output's name that
        is a folder."""
        if not self.path.is_dir():
            return
        for name, want in ((self.FIELDS, "a folder"), (self.LOCK, "a regular file")):
            try:
                st = os.lstat(self.path / name)
            except FileNotFoundError:
                continue
            if stat.S_ISLNK(st.st_mode):
                raise RunDirectoryError(
                    f"{_short(self.path / name)} is a symbolic link; a run writes its "
                    f"{'snapshots' if name == self.FIELDS else 'lock'} there itself and never "
                    f"through a link: remove the link (or choose another directory)")
            if not (stat.S_ISDIR(st.st_mode) if name == self.FIELDS
                    else stat.S_ISREG(st.st_mode)):
                raise RunDirectoryError(f"{_short(self.path / name)} is not {want}, as a run "
                                        "writes it: remove it (or choose another directory)")
        for name in self.output_names():
            if (self.path / name).is_dir() and not (self.path / name).is_symlink():
                raise RunDirectoryError(f"{_short(self.path / name)} is a folder, not the file "
                                        "a run writes there: move it (or choose another "
                                        "directory)")

    def _is_run(self) -> bool:
        """True when the directory holds a ``manifest.json`` of fipy-hopper (a run wrote it)."""
        manifest = self.path / self.MANIFEST
        try:
            data = Manifest.load(manifest).data if manifest.is_file() else None
        except (RunFileError, OSError):
            data = None
        return isinstance(data, dict) and data.get("package") == "fipy_hopper"

    def _refuse_not_a_run(self) -> None:
        """``--force`` replaces an earlier run only: refuse a directory without a manifest of
        fipy-hopper (a folder of other files, which no run wrote)."""
        if not self._is_run():
            raise RunDirectoryError(
                f"{_short(self.path)} is not empty and is not a run directory of fipy-hopper "
                f"(no {self.MANIFEST} of a run); --force replaces only an earlier run's "
                "outputs: choose a new or empty directory")

    def _refuse_unwritable(self) -> None:
        """Refuse a directory (or its ``fields/``) the run cannot write into, before anything
        in it is removed: a file is made and removed in each."""
        for folder in (self.path, self.fields):
            if not folder.is_dir():
                continue
            try:
                fd, probe = tempfile.mkstemp(prefix=".probe.", suffix=".tmp", dir=folder)
                os.close(fd)
                os.unlink(probe)
            except OSError as exc:
                raise RunDirectoryError(
                    f"cannot write in {_short(folder)}: {exc.strerror or exc}; nothing in "
                    f"{_short(self.path)} was removed") from None

    def _contents(self) -> list:
        """The directory's entries other than the lock file and an empty ``fields/`` (which
        opening a run directory makes) ([] if it does not exist)."""
        if not self.path.is_dir():
            return []
        return [item for item in self.path.iterdir() if item.name != self.LOCK and not (
            item.name == self.FIELDS and item.is_dir() and not item.is_symlink()
            and not any(item.iterdir()))]

    def _refuse_not_empty(self):
        if not self._is_run():
            raise RunDirectoryError(f"{_short(self.path)} exists, is not empty and is not a run "
                                    "directory of fipy-hopper: choose a new or empty directory")
        raise RunDirectoryError(
            f"{_short(self.path)} exists and is not empty; choose another directory, add "
            "--force to overwrite it, or --resume to continue an interrupted run")

    # ------------------------------------------------------------ the lock
    def _lock(self) -> None:
        """Take the exclusive lock on ``DIR/.lock`` or raise :class:`RunDirectoryError`."""
        if fcntl is None:          # pragma: no cover - not POSIX
            return
        lock = self.path / self.LOCK
        while True:
            fd = _open_lock(lock, os.O_RDWR | os.O_CREAT)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = _read_pid(fd)
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise self._in_use(holder) from None
                warnings.warn(f"{_short(lock)} cannot be locked ({exc.strerror}); the run "
                              "directory is not protected against a second run",
                              RuntimeWarning, stacklevel=3)
                return
            # a holder that finished unlinks the file while holding it: make sure the lock
            # taken is on the file that is there now, not on the unlinked one
            try:
                same = os.stat(lock).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd = fd

    def _in_use(self, holder) -> RunDirectoryError:
        who = f"process {holder}" if holder else "another process"
        return RunDirectoryError(
            f"{_short(self.path)} is in use by another run ({who} holds {self.LOCK}); wait "
            "for it to finish or choose another directory")

    def _refuse_if_in_use(self) -> None:
        """Raise if a live process holds the directory's lock (never creates the lock file)."""
        lock = self.path / self.LOCK
        if fcntl is None or not lock.is_file():
            return
        try:
            fd = _open_lock(lock, os.O_RDONLY)
        except (OSError, RunDirectoryError):
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise self._in_use(_read_pid(fd)) from None
        finally:
            os.close(fd)

    @property
    def locked(self) -> bool:
        """True while this object holds the directory's lock."""
        return self._lock_fd is not None

    def close(self) -> None:
        """Release the lock (the lock file is removed while still held).  Idempotent."""
        fd, self._lock_fd = getattr(self, "_lock_fd", None), None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            if os.stat(self.path / self.LOCK).st_ino == os.fstat(fd).st_ino:
                os.unlink(self.path / self.LOCK)
        with contextlib.suppress(OSError):
            os.close(fd)

    def __enter__(self) -> "RunDirectory":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:      # pragma: no cover - at interpreter shutdown
            pass

    def __truediv__(self, name: str) -> Path:
        return self.path / name

    @property
    def fields(self) -> Path:
        return self.path / self.FIELDS

    @property
    def checkpoint(self) -> Path:
        return self.path / self.CHECKPOINT

    #: every file a run writes at the top of its directory, besides the pictures
    OUTPUTS = (CONFIG, MANIFEST, SUMMARY, SUMMARY_TEXT, PROFILE, TIMESERIES, WALL_PRESSURE,
               LOADS, WALL_SLIP, WALL_EXTREMES, CHANNEL_WINDOWS, CHECKPOINT, ERROR_LOG)

    @classmethod
    def output_names(cls) -> tuple:
        """The files of a run at the top of its directory: :data:`OUTPUTS` and every picture
        of :data:`fipy_hopper.plotting.PICTURES`."""
        from .plotting import PICTURES
        return cls.OUTPUTS + tuple(picture.name for picture in PICTURES)

    #: the temporary files of the writers: :func:`atomic_path`'s ``.<stem>.XXXXXXXX.tmp<suffix>``
    #: (``tempfile``'s eight characters), the checkpoint's and the writability probe's
    _TEMPORARY = r"\.(?P<stem>.+)\.[a-z0-9_]{8}\.tmp(?P<suffix>\.\w+)?"
    _OTHER_TEMPORARIES = re.compile(r"\.checkpoint-[a-z0-9_]{8}\.npz|\.probe\.[a-z0-9_]{8}\.tmp")
    #: the files of ``fields/``: the snapshots, their markers, the index and the ParaView file
    _FIELD_FILES = re.compile(r"(fields|markers)_\d{4,}\.vtu|fields\.pvd|snapshots\.csv")

    @classmethod
    def is_output(cls, name: str, in_fields: bool = False) -> bool:
        """True when ``name`` is a file a run writes at the top of its directory (or in
        ``fields/``): an output, a picture, a snapshot, or a temporary file of their writers.
        Nothing else is ever removed from a run directory."""
        if in_fields:
            own = lambda n: bool(cls._FIELD_FILES.fullmatch(n))      # noqa: E731
        else:
            names = set(cls.output_names())
            own = names.__contains__
        if own(name):
            return True
        temp = re.fullmatch(cls._TEMPORARY, name)
        if temp and own(temp["stem"] + (temp["suffix"] or "")):
            return True
        return bool(cls._OTHER_TEMPORARIES.fullmatch(name))

    def _remove_outputs(self) -> None:
        """Remove the earlier run's files (:meth:`is_output`) and nothing else; links are
        removed, never followed."""
        for folder, in_fields in ((self.path, False), (self.fields, True)):
            if not folder.is_dir() or folder.is_symlink():
                continue
            with os.scandir(folder) as entries:
                doomed = [e.path for e in entries if self.is_output(e.name, in_fields)
                          and not e.is_dir(follow_symlinks=False)]
            for path in doomed:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(path)

    def remove_profile(self) -> None:
        """Remove the profile of an earlier session (a resumed run, once its checkpoint has
        been restored)."""
        with contextlib.suppress(FileNotFoundError):
            (self.path / self.PROFILE).unlink()

    def _remove_temporaries(self) -> None:
        """Temporary files left by a run killed in the middle of a write (its writers' only,
        :meth:`is_output`; never through a link)."""
        for folder, in_fields in ((self.path, False), (self.fields, True)):
            if not folder.is_dir() or folder.is_symlink():
                continue
            for item in folder.glob(".*"):
                if item.name not in (self.LOCK,) and self.is_output(item.name, in_fields) \
                        and not item.is_dir():
                    with contextlib.suppress(OSError):
                        item.unlink()


def _open_lock(path: Path, flags: int) -> int:
    """Open a lock file without following a link (``O_NOFOLLOW``) or blocking on a FIFO
    (``O_NONBLOCK``); :class:`RunDirectoryError` for a link or what is not a regular file."""
    extra = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | \
        getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags | extra, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise RunDirectoryError(f"{_short(path)} is a symbolic link; a run writes its lock "
                                    "there itself and never through a link: remove the "
                                    "link") from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
        os.close(fd)
        what = "not a regular file" if not stat.S_ISREG(st.st_mode) else \
            f"a hard link (the file has {st.st_nlink} names)"
        raise RunDirectoryError(f"{_short(path)} is {what}, which a run's lock never is; a run "
                                "writes its lock there itself: remove it")
    return fd


def _read_pid(fd: int) -> str:
    """The process id a lock file holds ('' if none can be read)."""
    with contextlib.suppress(OSError, ValueError):
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        if text.isdigit():
            return text
    return ""


# ---------------------------------------------------------------- manifest
@functools.lru_cache(maxsize=8)
def code_commit(also: tuple = ()) -> str:
    """The git commit (short hash) of the checkout this package was imported from, followed by
    " (with uncommitted changes)" when the package's files, or the paths ``also`` (relative to
    the package's folder), differ from it; "" when the package is not a tracked file of a git
    checkout (an installed copy) or git is not available.  Asked once per process."""
    here = Path(__file__).resolve().parent

    def git(*args):
        return subprocess.run(["git", *args], cwd=here, capture_output=True, text=True,
                              timeout=10)

    try:
        tracked = git("ls-files", "--error-unmatch", Path(__file__).name)
        head = git("rev-parse", "--short", "HEAD")
        dirty = git("status", "--porcelain", "--", ".", *also)
    except (OSError, subprocess.SubprocessError):
        return ""
    if tracked.returncode != 0 or head.returncode != 0:
        return ""
    return head.stdout.strip() + (" (with uncommitted changes)" if dirty.stdout.strip() else "")


def environment_versions() -> dict:
    """Versions of Python, the platform, fipy_hopper (and the git commit of its code,
    :func:`code_commit`) and its dependencies."""
    from importlib import metadata

    from . import __version__
    deps = {}
    for name in DEPENDENCIES:
        try:
            deps[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return {"package": "fipy_hopper", "version": __version__, "code_commit": code_commit(),
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
        """Read ``manifest.json``; :class:`RunFileError` naming it if it is not a manifest."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except (ValueError, UnicodeDecodeError) as exc:
            raise RunFileError(f"{_short(path)} is not JSON: {_short(exc, 120)}") from None
        if not isinstance(data, dict) or not isinstance(data.get("sessions"), list):
            raise RunFileError(f"{_short(path)} is not a manifest of fipy-hopper")
        return cls(path, data)

    def begin_session(self, command: str, resumed_from_step: Optional[int] = None,
                      resumed_from_t: Optional[float] = None) -> None:
        versions = environment_versions()
        session = {"start_time": _now(), "end_time": None, "wall_time_s": None,
                   "command": command, "version": versions["version"],
                   "code_commit": versions["code_commit"],
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


def cell_fields(state, grid, cohesion: float = 0.0, friction_angle_deg: float = 30.0) -> dict:
    """The cell data of a snapshot (SI units), each ``(n_cells,)`` or ``(n_cells, 3)``.

    ``alpha`` material fraction of the open cell volume, ``open_fraction`` the cut-cell open
    fraction ``kappa`` (0 inside the wall), ``layer`` the layer tracer, ``velocity`` the mean of
    the cell's four nodal velocities as ``(v_r, v_z, 0)`` (m/s), ``speed`` its magnitude,
    ``stress_rr/zz/tt/rz`` the material stress (Pa, tension positive), ``pressure``
    ``p = -(s_rr + s_zz + s_tt) / 3`` (Pa, compression positive), ``plastic_strain`` the
    accumulated equivalent plastic strain, ``loose_strain`` the loose volumetric strain of
    the dense/loose rule (0 = dense, see :func:`fipy_hopper.dense_loose.close_loose_volume`);
    the stress pattern (:func:`fipy_hopper.diagnostics.stress_pattern`, compression
    positive): ``sigma1``, ``sigma3`` the major and minor principal stresses (Pa),
    ``sigma1_angle_deg`` the angle of the major principal direction from the vertical
    (degrees) and ``sin_phi_mob`` the mobilised friction (for the material's ``cohesion`` in Pa
    and ``friction_angle_deg``).
    """
    v = np.asarray(state.v, float)
    v_cell = 0.25 * (v[:, :-1, :-1] + v[:, :-1, 1:] + v[:, 1:, :-1] + v[:, 1:, 1:])
    loose = (np.zeros(np.size(state.alpha)) if getattr(state, "loose", None) is None
             else np.asarray(state.loose, float).ravel())
    return {
        "alpha": np.asarray(state.alpha, float).ravel(),
        "open_fraction": np.asarray(grid.kappa, float).ravel(),
        "layer": np.asarray(state.layer, float).ravel(),
        **material_fields(np.column_stack([v_cell[0].ravel(), v_cell[1].ravel()]),
                          np.asarray(state.sigma, float).reshape(-1, 4),
                          np.asarray(state.eps_p, float).ravel(), loose, cohesion,
                          friction_angle_deg),
    }


def material_fields(velocity, sigma, eps_p, loose, cohesion: float = 0.0,
                    friction_angle_deg: float = 30.0) -> dict:
    """The cell data of a snapshot that any cell or element has (SI units): ``velocity``
    ``(v_r, v_z, 0)`` from the ``(n, 2)`` cell velocities (m/s), ``speed``,
    ``stress_rr/zz/tt/rz`` from the ``(n, 4)`` stresses (Pa, tension positive), ``pressure``
    ``p = -(s_rr + s_zz + s_tt) / 3`` (Pa), ``plastic_strain``, ``loose_strain`` and the stress
    pattern (:func:`fipy_hopper.diagnostics.stress_pattern`)."""
    from .diagnostics import stress_pattern

    velocity = np.column_stack([velocity, np.zeros(len(velocity))])
    return {
        "velocity": velocity,
        "speed": np.hypot(velocity[:, 0], velocity[:, 1]),
        "stress_rr": sigma[:, 0].copy(),
        "stress_zz": sigma[:, 1].copy(),
        "stress_tt": sigma[:, 2].copy(),
        "stress_rz": sigma[:, 3].copy(),
        "pressure": -(sigma[:, 0] + sigma[:, 1] + sigma[:, 2]) / 3.0,
        "plastic_strain": eps_p,
        "loose_strain": loose,
        **stress_pattern(sigma, cohesion, friction_angle_deg),
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


def read_vtu(path: PathLike):
    """The ``meshio.Mesh`` of a VTU file; :class:`RunFileError` naming the file if it cannot
    be read (meshio's reader is called directly: ``meshio.read`` prints and calls
    ``sys.exit(1)`` on a corrupt file, which is caught here all the same)."""
    import meshio

    try:
        return meshio.vtu.read(os.fspath(path))
    except (SystemExit, Exception) as exc:
        raise RunFileError(f"{_short(path)} is not a readable VTU file: "
                           f"{type(exc).__name__}: {_short(exc, 120)}") from None


def read_markers(path: PathLike) -> Optional[np.ndarray]:
    """The markers ``(n, 3)`` = ``(r, z, layer)`` of a file of :func:`write_markers`, or
    ``None`` if there is no such file."""
    path = Path(path)
    if not path.is_file():
        return None
    mesh = read_vtu(path)
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

    def __init__(self, folder: PathLike, grid, cohesion: float = 0.0,
                 friction_angle_deg: float = 30.0):
        self._open(folder, cohesion, friction_angle_deg)
        self.grid = grid
        self.points, self.quads = grid_points_and_quads(grid)

    def _open(self, folder: PathLike, cohesion: float, friction_angle_deg: float) -> None:
        """The snapshot folder, the strength for the mobilised friction, no entries yet."""
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.strength = (cohesion, friction_angle_deg)
        self.entries: list = []

    def __call__(self, sim, state) -> None:
        self.write(state, t_open=sim.t_open)

    @property
    def last_step(self) -> Optional[int]:
        return self.entries[-1]["step"] if self.entries else None

    def _mesh(self, state):
        """The snapshot of ``state`` as a ``meshio.Mesh``."""
        import meshio

        return meshio.Mesh(self.points, [("quad", self.quads)],
                           point_data={"node_velocity": np.column_stack([
                               np.asarray(state.v[0], float).ravel(),
                               np.asarray(state.v[1], float).ravel(),
                               np.zeros(state.v[0].size)])},
                           cell_data={k: [v] for k, v in cell_fields(state, self.grid,
                                                                  *self.strength).items()})

    def write(self, state, t_open: float = math.nan) -> Path:
        import meshio

        index = len(self.entries)
        name = f"fields_{index:04d}.vtu"
        mesh = self._mesh(state)
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


class MeshFieldWriter(FieldWriter):
    """:class:`FieldWriter` for a mesh that moves with the material (the Lagrangian model):
    each snapshot holds the mesh where it is (x = r, y = z; quads of
    :class:`~fipy_hopper.lagrangian.LagrangianMesh`), point data ``node_velocity`` and the cell
    data of :func:`cell_fields` that apply to an element: ``alpha`` 1 for an element still in
    the run and 0 for one eroded below the outlet, ``layer``, ``velocity`` (the mean of the
    element's nodes), ``speed``, the stresses, ``pressure``, ``plastic_strain``,
    ``loose_strain`` and the stress pattern."""

    def __init__(self, folder: PathLike, model, cohesion: float = 0.0,
                 friction_angle_deg: float = 30.0):
        self._open(folder, cohesion, friction_angle_deg)
        self.conn, self.layer = model.mesh.conn, model.layer

    def _mesh(self, state):
        import meshio

        v = np.asarray(state.v, float)
        zeros = np.zeros((len(v), 1))
        cells = {"alpha": np.asarray(state.active, float), "layer": self.layer,
                 **material_fields(v[self.conn].mean(axis=1), np.asarray(state.sigma, float),
                                   np.asarray(state.eps_p, float),
                                   np.asarray(state.loose, float), *self.strength)}
        return meshio.Mesh(np.column_stack([state.x, zeros]), [("quad", self.conn)],
                           point_data={"node_velocity": np.column_stack([v, zeros])},
                           cell_data={k: [np.asarray(c)] for k, c in cells.items()})


def read_snapshot_index(folder: PathLike) -> list:
    """The rows of ``fields/snapshots.csv`` as dictionaries (numbers converted)."""
    with open(Path(folder) / FieldWriter.INDEX, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return [{"index": int(r["index"]), "file": r["file"], "step": int(r["step"]),
             "t_s": float(r["t_s"]), "discharge_time_s": float(r["discharge_time_s"]),
             "stage": r["stage"]} for r in rows]


# ---------------------------------------------------------------- reading a run back
def check_run_files(path: PathLike) -> None:
    """Check that ``path`` holds the readable files of a run before anything is drawn from it.

    ``config.toml`` must be a valid configuration and ``timeseries.csv`` a table with the
    columns of :data:`TIMESERIES_COLUMNS` (numbers, per metre for a wedge); ``wall_pressure.csv``, ``summary.json``
    and ``fields/snapshots.csv``, when present, must read back as written.  Raises
    :class:`RunDirectoryError` with one line naming the file.
    """
    from .config import ConfigError, HopperConfig

    folder = Path(path)
    where = _short(folder)
    try:
        if not folder.is_dir():
            raise RunDirectoryError(f"{where} is not a directory")
        missing = [n for n in (RunDirectory.CONFIG, RunDirectory.TIMESERIES)
                   if not (folder / n).is_file()]
        if missing:
            raise RunDirectoryError(f"{where} is not a run directory (no "
                                    f"{' and no '.join(missing)})")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                config = HopperConfig.from_toml(folder / RunDirectory.CONFIG)
        except ConfigError as exc:
            raise RunDirectoryError(f"{where} is not a run directory of fipy-hopper: {exc}") \
                from None
        axisymmetric = config.hopper.axisymmetric
        _check_table(folder / RunDirectory.TIMESERIES,
                     result_columns(TIMESERIES_COLUMNS[:4], axisymmetric), ())
        if (folder / RunDirectory.WALL_PRESSURE).is_file():
            _check_table(folder / RunDirectory.WALL_PRESSURE,     # the public columns (older
                         ("stage", "t_s", "s_m", "r_m", "z_m", "p_n_Pa", "tau_Pa"),  # runs have
                         ("stage",))                                 # no more, no wall)
        if (folder / RunDirectory.SUMMARY).is_file():
            try:
                with open(folder / RunDirectory.SUMMARY, encoding="utf-8") as fh:
                    summary = json.load(fh)
            except (ValueError, UnicodeDecodeError) as exc:
                raise RunDirectoryError(f"{_short(folder / RunDirectory.SUMMARY)} is not "
                                        f"JSON: {exc}") from None
            if not isinstance(summary, dict):
                raise RunDirectoryError(f"{_short(folder / RunDirectory.SUMMARY)} is not a "
                                        "JSON object")
        fields = folder / RunDirectory.FIELDS
        if (fields / FieldWriter.INDEX).is_file():
            try:
                entries = read_snapshot_index(fields)
            except (ValueError, KeyError, TypeError, UnicodeDecodeError, csv.Error) as exc:
                raise RunDirectoryError(f"{_short(fields / FieldWriter.INDEX)} is not an index "
                                        f"of snapshots: {type(exc).__name__}: {exc}") from None
            for e in entries:
                if not re.fullmatch(r"fields_\d+\.vtu", e["file"]) or \
                        not (fields / e["file"]).is_file():
                    raise RunDirectoryError(f"{_short(fields / FieldWriter.INDEX)} lists "
                                            f"{e['file']!r}, which is not a snapshot in {where}")
    except OSError as exc:
        raise RunDirectoryError(f"cannot read {where}: {exc.strerror or exc}") from None


def _check_table(path: Path, columns, text_columns) -> None:
    try:
        table = read_csv(path)
    except ValueError as exc:
        raise RunDirectoryError(str(exc)) from None
    missing = [c for c in columns if c not in table]
    if missing:
        raise RunDirectoryError(f"{_short(path)} has no column {missing[0]!r} (expected "
                                f"{', '.join(columns)}): not written by fipy-hopper")
    for c in columns:
        if c not in text_columns and table[c].dtype.kind != "f":
            raise RunDirectoryError(f"{_short(path)}: column {c!r} holds text, not numbers")


# ---------------------------------------------------------------- checkpoints
_WALL_ARRAY = re.compile(r"wall__(?P<stage>[A-Za-z_]\w*?)__(?P<k>[0-5])")
#: The measurement arrays :meth:`Simulation.checkpoint` writes beside the state's (regular
#: expressions of their names; keep in step with it): any float64 array of up to 3 axes,
#: NaN allowed.  The wall samples ``wall__<stage>__<k>`` must also match the stages of the
#: metadata.
CHECKPOINT_AUXILIARY = (r"wall__\w+?__[0-5]", r"wallstress__\w+?__[01]",
                        r"wallraw__\w+?__[01]", r"wallforces__\w+?__[0-2]",
                        r"reading__\w+?__(wall|plate|budget)", r"stresssum__\w+?__[0-2]",
                        r"envelope", r"envelope_raw", r"window_low", r"window_high",
                        r"channelsum__\d")
_META_KEYS = ("state", "record", "wall_times", "t_open", "next_sample", "schedules")


def checkpoint_template(state) -> tuple:
    """``(expected_shapes, optional)`` for :func:`validate_checkpoint` from a state of the same
    run (``model.State``, e.g. the fresh ``Simulation.state``): the shape of each of its arrays
    (the number of markers free), and the arrays an older checkpoint may lack (the fields of
    ``State`` that default to ``None``)."""
    import dataclasses

    shapes = {k: v.shape for k, v in vars(state).items() if isinstance(v, np.ndarray)}
    if "markers" in shapes:
        shapes["markers"] = (None,) + tuple(shapes["markers"][1:])
    optional = tuple(f.name for f in dataclasses.fields(state) if f.default is None)
    return shapes, optional


def checkpoint_size_limit(state, cfg) -> int:
    """Bytes a checkpoint of ``cfg`` may declare (uncompressed), generously: twice what the
    arrays of ``state`` (a state of the same run) take with 6 x 6 markers a cell (the most
    allowed), plus 4 kB for each time-series sample the run can take (the metadata holds the
    record as JSON stored as UTF-32, 4 bytes a character) and 64 MB (wall samples, the rest
    of the metadata)."""
    arrays = sum(v.nbytes for k, v in vars(state).items()
                 if isinstance(v, np.ndarray) and k != "markers")
    arrays += 8 * 3 * 36 * np.size(state.alpha)
    samples = cfg.run.discharge_time / cfg.run.output_interval + 10
    return int(2 * arrays + 4096 * samples + 64 * 2 ** 20)


def checkpoint_time_limit(cfg, dt: float) -> tuple:
    """``(t_max, step_max)``: the latest time (s) and the most steps a checkpoint of ``cfg``
    with the time step ``dt`` can hold: the longest fill and discharge, ``max_fill_time`` +
    :attr:`RunConfig.discharge_time`, and 1 s and ten steps more (the checks that end them)."""
    t_max = cfg.numerics.max_fill_time + cfg.run.discharge_time + 1.0 + 10.0 * dt
    return t_max, int(math.ceil(t_max / dt)) + 10


def read_checkpoint(path: PathLike, state, cfg, dt: Optional[float] = None) -> tuple:
    """:func:`validate_checkpoint` for a run whose fresh state is ``state`` (``model.State``)
    and whose configuration is ``cfg`` (time step ``dt``, by default ``cfg.time_step``):
    ``(arrays, meta)``.

    The expected arrays and the optional ones come from ``state``
    (:func:`checkpoint_template`), the size bound from :func:`checkpoint_size_limit`, the
    bounds of the time and the step from :func:`checkpoint_time_limit`, and the scalars of
    ``meta["state"]`` must be fields of ``state`` of the types of its values.
    """
    shapes, optional = checkpoint_template(state)
    dt = cfg.time_step if dt is None else dt
    t_max, step_max = checkpoint_time_limit(cfg, dt)
    scalars = {k: v for k, v in vars(state).items() if not isinstance(v, np.ndarray)}
    arrays, meta = validate_checkpoint(path, shapes, checkpoint_size_limit(state, cfg),
                                       optional=optional, state_keys=list(vars(state)),
                                       state_types=scalars, t_max=t_max, step_max=step_max)
    check_checkpoint_times(meta, cfg, dt, f"checkpoint {_short(path)}")
    return arrays, meta


def check_checkpoint_times(meta: dict, cfg, dt: float, where: str = "checkpoint") -> None:
    """The times and the masses of a checkpoint's metadata within this run's, so that the
    resumed run stops as the uninterrupted one would (a NaN opening time never would).

    ``t`` is the state's time and ``tol`` two steps (``dt``).  Filling: the next row of
    ``loads.csv`` in ``[0, t + output_interval + tol]`` (the rest is set at the opening).
    Discharge: the opening ``t_open`` in ``[0, t]``; the next sample and the next row in
    ``[t_open, t + output_interval + tol]``; the end of the envelope window in
    ``[t_open, t + load_window + tol]``; the initial mass finite and positive.  Either stage:
    the mass books, when given, finite and positive.  :class:`CheckpointError` in one line
    naming the file, the value and its allowed range."""
    t, stage = meta["state"]["t"], meta["state"]["stage"]
    run, tol = cfg.run, 2.0 * dt + 1e-9

    def within(key, value, low, high, what="a time of this run"):
        if not (is_number(value) and math.isfinite(value) and low <= value <= high):
            raise CheckpointError(f"{where}: its {key} = {_short(value, 40)} is not {what} "
                                  f"(allowed range [{low:.6g}, {high:.6g}], the "
                                  f"checkpoint's {stage} at t = {t:.6g} s)")

    def positive(key, value):
        if not (is_number(value) and math.isfinite(value) and value > 0.0):
            raise CheckpointError(f"{where}: its {key} = {_short(value, 40)} is not a mass of "
                                  "this run (allowed range (0, inf) kg)")

    if stage == "filling":
        within("next_load_sample", meta.get("next_load_sample"), 0.0,
               t + run.output_interval + tol)
    else:
        t_open = meta.get("t_open")
        within("t_open", t_open, 0.0, t, "the opening time of this run's discharge")
        for key, step in (("next_sample", run.output_interval),
                          ("next_load_sample", run.output_interval),
                          ("next_envelope", run.load_window_s)):
            within(key, meta.get(key), t_open, t + step + tol)
        positive("record's initial_mass", meta["record"].get("initial_mass"))
    if meta.get("mass_books") is not None:
        positive("mass_books", meta["mass_books"])


def is_number(value) -> bool:
    """A JSON number of the metadata (an int or a float, NaN allowed; not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def same_kind(value, like) -> bool:
    """``value`` of the JSON type of ``like``: a bool, a whole number, a number (for a float
    or None: finite or not), a string; None is also a number."""
    if isinstance(like, bool):
        return isinstance(value, bool)
    if isinstance(like, int):
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(like, float) or like is None:
        return value is None or is_number(value)
    return isinstance(value, type(like))


def validate_checkpoint(path: PathLike, expected_shapes: dict, max_bytes: int,
                        optional: Iterable[str] = (), dtypes: Optional[dict] = None,
                        state_keys: Optional[Iterable[str]] = None,
                        auxiliary: Iterable[str] = CHECKPOINT_AUXILIARY,
                        state_types: Optional[dict] = None, t_max: float = math.inf,
                        step_max: int = 2 ** 62) -> tuple:
    """Open a checkpoint ``.npz`` of :meth:`Simulation.checkpoint` safely: ``(arrays, meta)``.

    Nothing is read before the archive's members are known to be what a checkpoint holds:
    the sum of their declared uncompressed sizes (``zipfile`` ``file_size``) is at most
    ``max_bytes``; each is a ``.npy`` array whose header declares a plain numeric dtype
    (``float64`` unless ``dtypes`` says otherwise; never objects, so never pickle) and, for
    a name in ``expected_shapes``, its shape (``None`` matches any length); the header and the
    declared size agree.  Then the arrays are read; those of ``expected_shapes`` (the state,
    which the compiled kernels index) must be finite.  ``__meta__`` is the JSON metadata (a
    dict with the keys the checkpoint writes).  Other arrays are measurements whose names
    match a pattern of ``auxiliary`` (up to 3 axes, NaN allowed); the wall samples
    ``wall__<stage>__<k>`` (``k`` 0-4, one length per stage) must be complete for each stage
    in ``meta["wall_times"]``.  Every name of ``expected_shapes`` must be present unless listed
    in ``optional``; any other name is refused.  ``meta["state"]`` holds a time ``t`` in
    ``[0, t_max]``, a whole ``step`` in ``[0, step_max]``, a ``stage`` (``filling`` or
    ``discharge``) and other plain JSON scalars (only names in ``state_keys``, when given, none
    of them an array's name; of the type of their value in ``state_types``, when given,
    :func:`same_kind`; floats finite).

    Raises :class:`CheckpointError` (one line naming the file) for anything else: a corrupt or
    truncated file, a zip bomb, an unexpected, missing or misshapen array.
    """
    where = f"checkpoint {_short(path)}"
    dtypes = dtypes or {}
    auxiliary = [re.compile(pattern) for pattern in auxiliary]

    def fail(message):
        raise CheckpointError(f"{where}: {message}")

    try:
        archive = zipfile.ZipFile(path)
    except FileNotFoundError:
        fail("no such file")
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError, EOFError) as exc:
        fail(f"not a checkpoint (an .npz archive): {exc}")
    with archive:
        infos = archive.infolist()
        names = [info.filename for info in infos]
        if len(set(names)) != len(names):
            fail("it holds a member twice")
        declared = sum(info.file_size for info in infos)
        if declared > max_bytes:
            fail(f"it declares {declared:,} bytes uncompressed, more than the {max_bytes:,} "
                 "a checkpoint of this run can hold")
        arrays, meta = {}, None
        for info in infos:
            key = info.filename[:-4] if info.filename.endswith(".npy") else None
            if key == "__meta__":
                want_shape, want_kind = (), "U"
            elif key in expected_shapes:
                want_shape, want_kind = tuple(expected_shapes[key]), None
            elif key and any(pattern.fullmatch(key) for pattern in auxiliary):
                want_shape, want_kind = None, None
            else:
                fail(f"unexpected member {info.filename[:60]!r}")
            want_dtype = np.dtype(dtypes.get(key, np.float64))
            try:
                with archive.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    if version == (1, 0):
                        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
                    elif version == (2, 0):
                        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
                    else:
                        fail(f"array {key!r}: unsupported .npy version {version}")
                    if dtype.hasobject:
                        fail(f"array {key!r} holds Python objects (pickled data is never "
                             "loaded)")
                    if want_kind == "U" and dtype.kind != "U" or \
                            want_kind is None and dtype != want_dtype:
                        fail(f"array {key!r} has dtype {dtype}, expected "
                             f"{'text' if want_kind == 'U' else want_dtype}")
                    if want_shape is None:
                        if len(shape) > 3:
                            fail(f"array {key!r} has {len(shape)} axes, at most 3 expected")
                    elif len(shape) != len(want_shape) or any(
                            w is not None and n != w for n, w in zip(shape, want_shape)):
                        shown = tuple("any" if w is None else w for w in want_shape)
                        fail(f"array {key!r} has shape {shape}, expected {shown}")
                    nbytes = math.prod(shape) * dtype.itemsize
                    if fh.tell() + nbytes != info.file_size:
                        fail(f"array {key!r}: its header declares {nbytes:,} bytes of data, "
                             f"the archive {info.file_size - fh.tell():,}")
                    data = fh.read(nbytes)
                    fh.read()          # to the end, where zipfile checks the CRC
            except CheckpointError:
                raise
            except Exception as exc:   # zlib, zipfile, numpy header errors: a corrupt file
                fail(f"corrupt (array {key!r}): {type(exc).__name__}: {_short(exc, 120)}")
            if len(data) != nbytes:
                fail(f"array {key!r} is truncated")
            array = np.frombuffer(data, dtype=dtype).reshape(
                shape, order="F" if fortran else "C").copy()
            if key == "__meta__":
                try:
                    meta = json.loads(str(array[()]))
                except ValueError as exc:
                    fail(f"its metadata is not JSON: {exc}")
                continue
            if key in expected_shapes and not np.all(np.isfinite(array)):
                fail(f"array {key!r} holds {int(np.size(array) - np.isfinite(array).sum())} "
                     "non-finite values")
            arrays[key] = array
    if meta is None:
        fail("it holds no metadata (__meta__)")
    if not isinstance(meta, dict) or any(k not in meta for k in _META_KEYS):
        fail(f"its metadata lacks {', '.join(k for k in _META_KEYS if k not in meta)}"
             if isinstance(meta, dict) else "its metadata is not a JSON object")
    if not all(isinstance(meta[k], dict) for k in ("state", "record", "wall_times")) or \
            not isinstance(meta["schedules"], list):
        fail("its metadata is malformed (state, record, wall_times, schedules)")
    state = meta["state"]
    t, step = state.get("t"), state.get("step")
    if not (is_number(t) and 0.0 <= t <= t_max):
        fail(f"its state time t = {_short(t, 40)} is not a time of this run (a number of "
             f"seconds in [0, {t_max:.6g}])")
    if isinstance(step, bool) or not isinstance(step, int) or not 0 <= step <= step_max:
        fail(f"its state step = {_short(step, 40)} is not a step of this run (a whole number "
             f"in [0, {step_max}])")
    if state.get("stage") not in ("filling", "discharge"):
        fail(f"its state stage = {_short(state.get('stage'), 40)!s} is not filling or "
             "discharge")
    allowed = None if state_keys is None else set(state_keys) - set(expected_shapes)
    for key, value in state.items():
        if allowed is not None and key not in allowed or \
                not isinstance(value, (int, float, str, bool, type(None))):
            fail(f"its metadata holds an unexpected state value {str(key)[:40]!r}")
        like = (state_types or {}).get(key, value)
        if not same_kind(value, like) or is_number(value) and not math.isfinite(value):
            fail(f"its state value {str(key)[:40]} = {_short(value, 40)} is not "
                 f"{'a finite number' if is_number(like) else type(like).__name__}")
    missing = [k for k in expected_shapes if k not in arrays and k not in optional]
    if missing:
        fail(f"array {missing[0]!r} is missing")
    stages = meta["wall_times"]
    for stage in stages:
        parts = [arrays.get(f"wall__{stage}__{k}") for k in range(5)]
        if f"wall__{stage}__5" in arrays:       # 3D: the hoop shear
            parts.append(arrays[f"wall__{stage}__5"])
        if any(p is None or p.ndim != 1 for p in parts) or len({len(p) for p in parts}) != 1:
            fail(f"the wall samples of stage {stage!r} are incomplete")
    stray = [k for k in arrays if _WALL_ARRAY.fullmatch(k)
             and _WALL_ARRAY.fullmatch(k)["stage"] not in stages]
    if stray:
        fail(f"array {stray[0]!r} belongs to no stage of the metadata")
    return arrays, meta
