"""Pictures of a run, drawn from its run directory only (never from a live simulation).

- :func:`flow_pattern`: snapshots of the discharge, each the r-z section mirrored about the
  axis: the coloured layers on the left (the passive marker points of
  :mod:`fipy_hopper.markers` when the run wrote them, else the cell layer tracer with cells of
  material fraction below 1/2 blank), the speed on the right, the hopper wall in grey;
- :func:`discharge_curves`: the mass in the hopper ``M(t)`` and the discharge rate ``W(t)``,
  with the steady rate and Beverloo's rate times the Rose-Tanaka factor;
- :func:`wall_pressure`: the normal wall pressure along the wall against Janssen in the bin
  (``K = 1 - sin(phi)``, Jaky, used at the wall) and Walker's slice method in the cone
  (filling and discharge ratios), all from :mod:`fipy_hopper.theory`;
- :func:`animate`: an animated GIF of the snapshots.

Each returns a :class:`matplotlib.figure.Figure` built on the Agg canvas (no pyplot, no global
backend switch); :func:`plot_run` draws them all into the run directory, atomically.

Usage: ``python -m fipy_hopper.plotting RUN_DIR`` (or ``fipy-hopper plot RUN_DIR``).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np

from . import geometry, theory
from .config import HopperConfig
from .io import (FieldWriter, RunDirectory, atomic_path, marker_file, read_csv, read_markers,
                 read_snapshot_index)

__all__ = ["plot_run", "flow_pattern", "discharge_curves", "wall_pressure", "animate",
           "load_snapshot", "draw_layers", "theory_wall_pressure"]

#: Diameter of a drawn marker over the markers' median nearest-neighbour spacing: above
#: ``sqrt(2)``, the discs of a square lattice cover it (the material looks filled).
MARKER_DIAMETER = 1.5

_STAGE_STYLE = {"filling": ("o", "C0", "filled, at rest"),
                "early_discharge": ("s", "C1", "discharge, 90 % left"),
                "mid_discharge": ("^", "C3", "discharge, 50 % left")}


def _figure(width, height):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _config(run) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_toml(Path(run) / RunDirectory.CONFIG)


def _summary(run) -> dict:
    path = Path(run) / RunDirectory.SUMMARY
    if not path.is_file():
        return {}
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


def _save(fig, path: Path, dpi=110) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


# ---------------------------------------------------------------- snapshots
def snapshots(run) -> list:
    """The index of the field snapshots (``fields/snapshots.csv``)."""
    folder = Path(run) / RunDirectory.FIELDS
    if not (folder / FieldWriter.INDEX).is_file():
        return []
    return read_snapshot_index(folder)


def load_snapshot(run, entry) -> dict:
    """One snapshot as ``(nz, nr)`` arrays with its node coordinates ``r_nodes``, ``z_nodes``;
    ``markers`` is its ``(n, 3)`` array of marker points ``(r, z, layer)``, or ``None``."""
    import meshio

    folder = Path(run) / RunDirectory.FIELDS
    mesh = meshio.read(folder / entry["file"])
    r_nodes = np.unique(mesh.points[:, 0])
    z_nodes = np.unique(mesh.points[:, 1])
    shape = (len(z_nodes) - 1, len(r_nodes) - 1)
    out = {"r_nodes": r_nodes, "z_nodes": z_nodes, **entry}
    for name in ("alpha", "layer", "speed", "open_fraction", "pressure", "plastic_strain"):
        out[name] = np.asarray(mesh.cell_data[name][0]).reshape(shape)
    out["markers"] = read_markers(folder / marker_file(entry["file"]))
    return out


def _pick(entries, n):
    """Up to ``n`` snapshots of the discharge, evenly spread from its start to its end."""
    chosen = [e for e in entries if e["stage"] == "discharge"] or list(entries)
    if len(chosen) <= n:
        return chosen
    idx = np.unique(np.round(np.linspace(0, len(chosen) - 1, n)).astype(int))
    return [chosen[i] for i in idx]


def _layer_colours(n_layers):
    from matplotlib import colormaps
    from matplotlib.colors import BoundaryNorm, ListedColormap

    base = colormaps["tab10"].colors
    colours = [base[k % len(base)] for k in range(n_layers)]
    return ListedColormap(colours), BoundaryNorm(np.arange(n_layers + 1) - 0.5, n_layers)


def _has_markers(snap) -> bool:
    markers = snap.get("markers")
    return markers is not None and len(markers) > 0


def _marker_spacing(markers) -> float:
    """The median distance (m) from a marker to its nearest neighbour (its lattice spacing
    ``h / per_side`` where the material has not deformed)."""
    from scipy.spatial import cKDTree

    points = np.asarray(markers)[:, :2]
    if len(points) < 2:
        return 0.0
    distance, _ = cKDTree(points).query(points, k=2)
    return float(np.median(distance[:, 1]))


def draw_layers(ax, snap, n_layers=None, side: float = -1.0):
    """The layers of a snapshot on one half of a mirrored section (``side`` -1: left, x = -r).

    With markers (``snap["markers"]``), each is a disc of diameter ``MARKER_DIAMETER`` times
    their median spacing, in data units, coloured by its layer id; without, the cell layer
    tracer, cells with ``alpha < 1/2`` blank.  Colours: :func:`_layer_colours`; ``n_layers``
    defaults to the layers of this snapshot.
    """
    from matplotlib.collections import EllipseCollection

    cmap, norm = _layer_colours(n_layers if n_layers is not None else _n_layers([snap]))
    if not _has_markers(snap):
        layer = np.ma.masked_where(snap["alpha"] < 0.5, snap["layer"])
        return ax.pcolormesh(side * snap["r_nodes"], snap["z_nodes"], layer, cmap=cmap,
                             norm=norm, shading="flat")
    markers = np.asarray(snap["markers"])
    size = MARKER_DIAMETER * _marker_spacing(markers)
    discs = EllipseCollection(size, size, 0.0, units="xy", cmap=cmap, norm=norm,
                              offsets=np.column_stack([side * markers[:, 0], markers[:, 1]]),
                              offset_transform=ax.transData, linewidths=0)
    discs.set_array(markers[:, 2])
    ax.add_collection(discs, autolim=False)
    return discs


def _draw_section(ax, snap, cfg, n_layers, speed_max):
    """Layers on the left (r < 0), speed on the right, the wall in grey; returns the mesh.

    The layers are drawn by :func:`draw_layers` (markers when the snapshot has them).  The grey
    cells are the grid cells closed by the wall (open fraction 0); the black line is the exact
    wall of :func:`fipy_hopper.geometry.wall_polyline`.
    """
    from matplotlib.colors import ListedColormap

    r, z = snap["r_nodes"], snap["z_nodes"]
    alpha = snap["alpha"]
    speed = np.ma.masked_where(alpha < 0.05, snap["speed"])
    solid = np.ma.masked_where(snap["open_fraction"] > 0, np.ones_like(alpha))
    grey = ListedColormap(["0.78"])
    draw_layers(ax, snap, n_layers, side=-1.0)
    mesh = ax.pcolormesh(r, z, speed, cmap="viridis", vmin=0.0, vmax=speed_max, shading="flat")
    wall = geometry.wall_polyline(cfg.hopper, r[-1], z[-1])
    for sign in (-1.0, 1.0):
        ax.pcolormesh(sign * r, z, solid, cmap=grey, vmin=0, vmax=1, shading="flat")
        ax.plot(sign * wall[:, 0], wall[:, 1], color="k", lw=1.0)
    ax.axvline(0.0, color="w", lw=0.5)
    ax.set_xlim(-r[-1], r[-1])
    ax.set_ylim(z[0], z[-1])
    ax.set_aspect("equal")
    ax.set_xlabel("r (m)")
    return mesh


def _speed_scale(snaps):
    """Colour scale of the speed: the largest finite speed of the material in the hopper."""
    top = 0.0
    for s in snaps:
        z_c = 0.5 * (s["z_nodes"][1:] + s["z_nodes"][:-1])
        inside = (s["alpha"] > 0.5) & (z_c >= 0)[:, None] & np.isfinite(s["speed"])
        if inside.any():
            top = max(top, float(np.max(s["speed"][inside])))
    return top if top > 0 else 1.0


def _n_layers(snaps):
    """Number of layers: one more than the largest layer id of the cells with ``alpha > 1/2``
    and of the markers."""
    values = [s["layer"][(s["alpha"] > 0.5) & np.isfinite(s["layer"])] for s in snaps]
    values += [np.asarray(s["markers"])[:, 2] for s in snaps if _has_markers(s)]
    values = [v[np.isfinite(v)] for v in values]
    values = [v for v in values if v.size]
    return int(round(max(float(v.max()) for v in values))) + 1 if values else 1


def _label(entry):
    if entry["stage"] == "discharge" and math.isfinite(entry["discharge_time_s"]):
        return f"t = {entry['discharge_time_s']:.2f} s"
    return f"{entry['stage']}, t = {entry['t_s']:.2f} s"


def flow_pattern(run, n: int = 4):
    """Flow-pattern snapshots: layers (left half) and speed (right half) at ``n`` times."""
    run = Path(run)
    cfg = _config(run)
    entries = _pick(snapshots(run), n)
    if not entries:
        raise FileNotFoundError(f"{run} holds no field snapshots")
    snaps = [load_snapshot(run, e) for e in entries]
    n_layers = _n_layers(snaps)
    vmax = _speed_scale(snaps)
    fig = _figure(2.6 * len(snaps) + 1.0, 4.6)
    axes = fig.subplots(1, len(snaps), sharey=True, squeeze=False)[0]
    mesh = None
    for ax, snap in zip(axes, snaps):
        mesh = _draw_section(ax, snap, cfg, n_layers, vmax)
        ax.set_title(_label(snap), fontsize=9)
    axes[0].set_ylabel("z (m)")
    fig.colorbar(mesh, ax=list(axes), label="speed (m/s)", shrink=0.8)
    fig.suptitle("Flow pattern: layers (left half) and speed (right half)", fontsize=10)
    return fig


def animate(run, path=None, max_frames: int = 80, fps: int = 6) -> Path:
    """An animated GIF of all snapshots (at most ``max_frames``); returns its path."""
    from matplotlib.animation import PillowWriter

    run = Path(run)
    path = Path(path) if path is not None else run / "discharge.gif"
    cfg = _config(run)
    entries = snapshots(run)
    if not entries:
        raise FileNotFoundError(f"{run} holds no field snapshots")
    if len(entries) > max_frames:
        idx = np.unique(np.round(np.linspace(0, len(entries) - 1, max_frames)).astype(int))
        entries = [entries[i] for i in idx]
    snaps = [load_snapshot(run, e) for e in entries]
    n_layers = _n_layers(snaps)
    vmax = _speed_scale(snaps)
    fig = _figure(3.6, 4.6)
    writer = PillowWriter(fps=fps)
    with atomic_path(path) as tmp:
        with writer.saving(fig, str(tmp), dpi=80):
            for snap in snaps:
                fig.clear()
                ax = fig.add_subplot()
                mesh = _draw_section(ax, snap, cfg, n_layers, vmax)
                ax.set_ylabel("z (m)")
                ax.set_title(_label(snap), fontsize=9)
                fig.colorbar(mesh, ax=ax, label="speed (m/s)", shrink=0.8)
                writer.grab_frame()
    return path


# ---------------------------------------------------------------- time series
def discharge_curves(run):
    """``M(t)`` and the discharged mass (top), ``W(t)`` with the steady and Beverloo rates."""
    run = Path(run)
    cfg = _config(run)
    ts = read_csv(run / RunDirectory.TIMESERIES)
    summary = _summary(run)
    t = ts["t_s"]
    fig = _figure(6.4, 5.6)
    ax_m, ax_w = fig.subplots(2, 1, sharex=True)
    ax_m.plot(t, ts["mass_in_hopper_kg"], "-", color="C0", label="M(t), in the hopper")
    ax_m.plot(t, ts["discharged_kg"], "--", color="C1", label="discharged")
    ax_m.set_ylabel("mass (kg)")
    ax_m.legend(loc="best", fontsize=8)
    ax_w.step(t, ts["discharge_rate_kg_s"], where="pre", color="C0", label="W(t), simulated")
    steady = summary.get("steady_discharge_rate_kg_s")
    if steady is not None:
        ax_w.axhline(steady, color="C0", ls=":", label=f"steady rate {steady:.3g} kg/s")
    bev = float(theory.beverloo_rate(cfg.material.density, cfg.hopper.outlet_diameter)
                * theory.rose_tanaka_factor(cfg.hopper.half_angle_deg))
    ax_w.axhline(bev, color="k", ls="--",
                 label=f"Beverloo x Rose-Tanaka {bev:.3g} kg/s (C = 0.58, k d = 0)")
    ax_w.set_xlabel("time since the outlet opened (s)")
    ax_w.set_ylabel("discharge rate (kg/s)")
    ax_w.set_ylim(bottom=0.0)
    ax_w.legend(loc="best", fontsize=8)
    mode = summary.get("flow_mode")
    fig.suptitle("Discharge" + (f" ({mode} flow)" if mode else ""), fontsize=10)
    return fig


# ---------------------------------------------------------------- wall pressure
def theory_wall_pressure(cfg: HopperConfig, n: int = 120) -> dict:
    """Closed-form normal wall pressures against the arc length ``s`` from the outlet lip.

    Bin (``s`` above the transition): Janssen with ``K = 1 - sin(phi)`` (Jaky, taken as the
    wall value) and ``mu = tan(phi_w)``, depth from the levelled fill surface.  Cone: Walker's
    slice method (D = 1) with the EN 1991-4 filling ratio and Walker's discharge ratio, the
    Janssen vertical stress at the transition as its top load.  Returns ``{name: (s, p_n)}``;
    a curve the theory cannot give (e.g. a frictionless wall) is left out.
    """
    geom, mat, wall = cfg.hopper, cfg.material, cfg.wall
    phi, phi_w = mat.friction_angle_deg, wall.friction_angle_deg
    rho, D = mat.density, geom.bin_diameter
    K = float(theory.k_jaky(phi))
    mu = math.tan(math.radians(phi_w))
    s_t = float(geometry.transition_arc_length(geom))
    s_fill = float(geometry.arc_length(geom.fill_level, geom))
    curves = {}
    try:
        s_bin = np.linspace(s_t, s_fill, n)
        curves["Janssen, bin (K = 1 - sin phi)"] = (
            s_bin, np.asarray(theory.janssen_wall_pressure(s_fill - s_bin, rho, D, K, mu)))
        sigma_vt = float(theory.janssen_vertical_stress(geom.fill_height, rho, D, K, mu))
    except ValueError:
        sigma_vt = rho * theory.G * geom.fill_height
    s_cone = np.linspace(0.0, s_t, n)
    theta = geom.half_angle
    x = s_cone * math.cos(theta) + geom.outlet_radius / math.tan(theta)
    h = geom.bin_radius / math.tan(theta)
    for mode in ("filling", "discharge"):
        try:
            p = theory.walker_hopper_wall_pressure(np.clip(x, 0.0, h), h, geom.half_angle_deg,
                                                   rho, phi, phi_w, sigma_vt, mode=mode)
            curves[f"Walker, cone, {mode}"] = (s_cone, np.asarray(p))
        except ValueError:
            continue
    return curves


def wall_pressure(run):
    """Simulated normal wall pressure along the wall against Janssen (bin) and Walker (cone)."""
    run = Path(run)
    cfg = _config(run)
    table = read_csv(run / RunDirectory.WALL_PRESSURE)
    fig = _figure(6.4, 4.4)
    ax = fig.add_subplot()
    stages = np.asarray(table.get("stage", np.array([])), dtype=str)
    for stage in dict.fromkeys(stages.tolist()):
        marker, colour, label = _STAGE_STYLE.get(stage, ("x", "C4", stage))
        sel = stages == stage
        ax.plot(table["s_m"][sel], table["p_n_Pa"][sel] / 1e3, marker, color=colour, ms=4,
                label=f"simulated, {label}")
    styles = {"Janssen": ("k", "-"), "Walker, cone, filling": ("C0", "-"),
              "Walker, cone, discharge": ("C3", "--")}
    for name, (s, p) in theory_wall_pressure(cfg).items():
        colour, ls = next((v for k, v in styles.items() if name.startswith(k)), ("0.4", "-"))
        ax.plot(s, p / 1e3, ls, color=colour, lw=1.2, label=name)
    s_t = float(geometry.transition_arc_length(cfg.hopper))
    ax.axvline(s_t, color="0.5", lw=0.8, ls=":")
    ax.text(s_t, ax.get_ylim()[1], " transition", va="top", fontsize=8, color="0.4")
    ax.set_xlabel("arc length along the wall from the outlet lip, s (m)")
    ax.set_ylabel("normal wall pressure p_n (kPa)")
    ax.set_xlim(left=0.0)
    ax.set_ylim(bottom=0.0)
    ax.legend(loc="best", fontsize=7)
    ax.set_title(f"Wall pressure (phi = {cfg.material.friction_angle_deg:g} deg, "
                 f"phi_w = {cfg.wall.friction_angle_deg:g} deg)", fontsize=10)
    return fig


# ---------------------------------------------------------------- all of them
def plot_run(run) -> list:
    """Draw every picture of a run directory into it; returns the paths written.

    A picture whose data are missing (no snapshots yet, no wall samples) is skipped.
    """
    run = Path(run)
    written = []
    if (run / RunDirectory.TIMESERIES).is_file():
        written.append(_save(discharge_curves(run), run / "discharge.png"))
    if (run / RunDirectory.WALL_PRESSURE).is_file():
        written.append(_save(wall_pressure(run), run / "wall_pressure.png"))
    if snapshots(run):
        written.append(_save(flow_pattern(run), run / "flow_pattern.png"))
        written.append(animate(run))
    return written


if __name__ == "__main__":  # pragma: no cover
    import sys

    for p in plot_run(sys.argv[1]):
        print(p)
