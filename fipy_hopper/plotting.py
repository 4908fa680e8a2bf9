"""Pictures of a run, drawn from its run directory only (never from a live simulation).

- :func:`flow_pattern`: snapshots of the discharge, each the r-z section mirrored about the
  axis: the coloured layers on the left (the passive marker points of
  :mod:`fipy_hopper.markers` when the run wrote them, else the cell layer tracer with cells of
  material fraction below 1/2 blank), the speed on the right, the hopper wall in grey;
- :func:`discharge_curves`: the mass in the hopper ``M(t)`` and the discharge rate ``W(t)``,
  with the steady rate and Beverloo's rate times the Rose-Tanaka factor;
- :func:`wall_pressure`: the normal wall pressure along the wall (from the wall's reaction, with
  the stress-sampled estimate beside it) at rest, in discharge and its envelope, against
  Janssen in the bin (``K = 1 - sin(phi)``, Jaky, used at the wall), Walker's slice method in
  the cone (filling and discharge ratios), EN 1991-4's discharge factor for the bin and its
  hopper loads (filling and discharge), all from :mod:`fipy_hopper.theory`; the overpressure
  factor per bin and the switch peak;
- :func:`stress_pattern`: the major principal stress trajectories over the mobilised
  friction, at rest and in discharge;
- :func:`animate`: an animated GIF of the snapshots.

Each returns a :class:`matplotlib.figure.Figure` built on the Agg canvas (no pyplot, no global
backend switch); :func:`plot_run` draws them all into the run directory, atomically.

Usage: ``python -m fipy_hopper.plotting RUN_DIR`` (or ``fipy-hopper plot RUN_DIR``).
"""

from __future__ import annotations

import json
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from . import theory
from .config import HopperConfig
from .io import (FieldWriter, RunDirectory, atomic_path, marker_file, read_csv, read_markers,
                 read_snapshot_index, read_vtu, result_key)

__all__ = ["plot_run", "PICTURES", "Picture", "flow_pattern", "discharge_curves",
           "wall_pressure", "stress_pattern", "animate", "load_snapshot", "draw_layers",
           "theory_wall_pressure"]

#: Diameter of a drawn marker over the markers' median nearest-neighbour spacing: above
#: ``sqrt(2)``, the discs of a square lattice cover it (the material looks filled).
MARKER_DIAMETER = 1.5

_STAGE_STYLE = {"filling": ("o", "C0", "filled, at rest"),
                "early_discharge": ("s", "C1", "discharge, 90 % left"),
                "mid_discharge": ("^", "C2", "discharge, 50 % left")}


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
    folder = Path(run) / RunDirectory.FIELDS
    mesh = read_vtu(folder / entry["file"])
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


def wall_lines(cfg: HopperConfig, bottom: float, top: float) -> list:
    """The boundary's walls and inserts as polylines ``(k, 2)`` (m) to draw: each wall from
    ``bottom`` (its free-fall tube) up to ``top``, each insert's outline."""
    bnd = cfg.boundary
    lines = []
    for c in bnd.chains:
        points = np.asarray(c.points, float)
        if c.kind == "wall":
            lip = points[0]
            last = points[-1]
            lines.append(np.vstack([[lip[0], bottom], points,
                                    [[last[0], max(top, last[1])]]]))
        elif c.kind == "insert":
            outline = np.asarray(c.polygon if c.polygon else c.points, float)
            lines.append(np.vstack([outline, outline[:1]]))
    return lines


def _draw_section(ax, snap, cfg, n_layers, speed_max):
    """Layers on the left (r < 0), speed on the right, the wall in grey; returns the mesh.

    The layers are drawn by :func:`draw_layers` (markers when the snapshot has them).  The grey
    cells are the grid cells closed by the wall (open fraction 0); the black line is the exact
    walls and inserts of the boundary (:func:`wall_lines`).
    """
    return _draw_section_parts(ax, snap, cfg, n_layers, speed_max)[0]


def _masked_speed(snap):
    return np.ma.masked_where(snap["alpha"] < 0.05, snap["speed"])


def _draw_section_parts(ax, snap, cfg, n_layers, speed_max):
    """:func:`_draw_section`; returns ``(speed mesh, layers artist)``."""
    from matplotlib.colors import ListedColormap

    r, z = snap["r_nodes"], snap["z_nodes"]
    alpha = snap["alpha"]
    solid = np.ma.masked_where(snap["open_fraction"] > 0, np.ones_like(alpha))
    grey = ListedColormap(["0.78"])
    mirror = cfg.boundary.section.mirror
    layers = draw_layers(ax, snap, n_layers, side=-1.0) if mirror else None
    mesh = ax.pcolormesh(r, z, _masked_speed(snap), cmap="viridis", vmin=0.0, vmax=speed_max,
                         shading="flat")
    for sign in (-1.0, 1.0) if mirror else (1.0,):
        ax.pcolormesh(sign * r, z, solid, cmap=grey, vmin=0, vmax=1, shading="flat")
        for line in wall_lines(cfg, z[0], z[-1]):
            ax.plot(sign * line[:, 0], line[:, 1], color="k", lw=1.0)
    if mirror:
        ax.axvline(0.0, color="w", lw=0.5)
        ax.set_xlim(-r[-1], r[-1])
    else:
        ax.set_xlim(r[0], r[-1])
    ax.set_ylim(z[0], z[-1])
    ax.set_aspect("equal")
    ax.set_xlabel("r (m)" if cfg.hopper.axisymmetric else "x (m)")
    return mesh, layers


def _section_limits(cfg: HopperConfig) -> tuple:
    """The ``x`` range (m) of one side of a half-section or of a full section, with 5 %."""
    x_min, x_max = cfg.hopper.x_extent
    pad = 0.05 * (x_max - x_min)
    return (x_min - pad if cfg.hopper.full_section else 0.0), x_max + pad


def _update_section(ax, mesh, layers, snap, n_layers):
    """Another snapshot of the same run on a section drawn by :func:`_draw_section_parts`: the
    speed and the layers change, the grid, the wall and the axes stay.  Returns the new
    layers artist (drawn first, beneath the rest, as in a fresh section)."""
    mesh.set_array(_masked_speed(snap))
    if layers is None:                   # a full section: the speed only
        return None
    layers.remove()
    layers = draw_layers(ax, snap, n_layers, side=-1.0)
    layers.set_zorder(0.5)
    return layers


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


def wall_slip_segments(run, cfg: HopperConfig):
    """The hopper wall's loaded contacts of ``wall_slip.csv`` as wall segments: a list of
    ``((r, z) points, sliding)``, each contact standing for the wall between the midpoints
    to its neighbours (arc length ``s``); empty when the run wrote none."""
    path = Path(run) / RunDirectory.WALL_SLIP
    if not path.is_file():
        return []
    table = read_csv(path)
    s = np.asarray(table.get("s_m", []), float)
    if s.size == 0:
        return []
    sliding = np.asarray(table["sliding"], float) > 0.5
    bnd = cfg.boundary
    chain = bnd.table.chain[bnd.load_row(np.asarray(table["r_m"], float),
                                         np.asarray(table["z_m"], float))]
    out = []
    for c in np.unique(chain):
        on = np.flatnonzero(chain == c)
        arc = s[on]
        edges = np.concatenate([arc[:1], 0.5 * (arc[1:] + arc[:-1]), arc[-1:]])
        for k, q in enumerate(on):
            r, z, _, _ = bnd.wall_point(int(c), np.linspace(edges[k], edges[k + 1], 3))
            out.append((np.column_stack([r, z]), bool(sliding[q])))
    return out


def _draw_wall_slip(ax, segments):
    """The wall slip on the right half of a section: green where the material slides along
    the hopper wall, red where it does not (:func:`wall_slip_segments`)."""
    for points, sliding in segments:
        ax.plot(points[:, 0], points[:, 1], "-", color="limegreen" if sliding else "red",
                lw=3.0, solid_capstyle="butt", zorder=4)


def flow_pattern(run, n: int = 4):
    """Flow-pattern snapshots: layers (left half) and speed (right half) at ``n`` times; on
    the right half's hopper wall, where the material slides along it (green) and where it
    does not (red) in the flow-mode window (``wall_slip.csv``, the rule's slip ratio)."""
    run = Path(run)
    cfg = _config(run)
    entries = _pick(snapshots(run), n)
    if not entries:
        raise FileNotFoundError(f"{run} holds no field snapshots")
    snaps = [load_snapshot(run, e) for e in entries]
    n_layers = _n_layers(snaps)
    vmax = _speed_scale(snaps)
    segments = wall_slip_segments(run, cfg)
    mirror = cfg.boundary.section.mirror
    rows = 1 if mirror else 2               # a full section: the layers in a row of their own
    fig = _figure(2.6 * len(snaps) + 1.0, 4.6 * rows)
    grid = fig.subplots(rows, len(snaps), sharey=True, squeeze=False)
    axes = grid[0]
    mesh = None
    for k, (ax, snap) in enumerate(zip(axes, snaps)):
        mesh = _draw_section(ax, snap, cfg, n_layers, vmax)
        _draw_wall_slip(ax, segments)
        ax.set_title(_label(snap), fontsize=9)
        if not mirror:
            below = grid[1][k]
            draw_layers(below, snap, n_layers, side=1.0)
            for line in wall_lines(cfg, snap["z_nodes"][0], snap["z_nodes"][-1]):
                below.plot(line[:, 0], line[:, 1], color="k", lw=1.0)
            below.set_xlim(*ax.get_xlim())
            below.set_aspect("equal")
            below.set_xlabel("x (m)")
    for row in grid:
        row[0].set_ylabel("z (m)")
    fig.colorbar(mesh, ax=list(axes), label="speed (m/s)", shrink=0.8)
    title = ("Flow pattern: layers (left half) and speed (right half)" if mirror else
             "Flow pattern: speed (above) and layers (below)")
    if segments:
        share = _summary(run).get("wall_slip_fraction")
        title += ("\nhopper wall: slides (green) / does not (red)"
                  + (f", sliding over {100 * share:.0f} % of it" if share is not None
                     and math.isfinite(share) else ""))
    fig.suptitle(title, fontsize=10)
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
    ax = fig.add_subplot()
    with atomic_path(path) as tmp:
        with writer.saving(fig, str(tmp), dpi=80):
            for k, snap in enumerate(snaps):
                if not k:                  # the grid, the wall, the axes and the colour bar
                    mesh, layers = _draw_section_parts(ax, snap, cfg, n_layers, vmax)
                    ax.set_ylabel("z (m)")
                    fig.colorbar(mesh, ax=ax, label="speed (m/s)", shrink=0.8)
                else:                      # serve every frame (one speed scale)
                    layers = _update_section(ax, mesh, layers, snap, n_layers)
                ax.set_title(_label(snap), fontsize=9)
                writer.grab_frame()
                if not k:                  # the layout of the first frame serves them all
                    fig.set_layout_engine("none")
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
    axisymmetric = cfg.hopper.axisymmetric
    per = "" if axisymmetric else " per m"            # a wedge: per metre of length
    column = {c: result_key(c, axisymmetric) for c in ("mass_in_hopper_kg", "discharged_kg",
                                                       "discharge_rate_kg_s")}
    ax_m.plot(t, ts[column["mass_in_hopper_kg"]], "-", color="C0", label="M(t), in the hopper")
    ax_m.plot(t, ts[column["discharged_kg"]], "--", color="C1", label="discharged")
    ax_m.set_ylabel(f"mass (kg{per})")
    ax_m.legend(loc="best", fontsize=8)
    ax_w.step(t, ts[column["discharge_rate_kg_s"]], where="pre", color="C0",
              label="W(t), simulated")
    steady = summary.get(result_key("steady_discharge_rate_kg_s", axisymmetric))
    if steady is not None:
        ax_w.axhline(steady, color="C0", ls=":", label=f"steady rate {steady:.3g} kg/s{per}")
    bev = summary.get(result_key("beverloo_rate_kg_s", axisymmetric))
    if bev is not None and math.isfinite(bev):      # only for the silos it describes
        label = (f"Beverloo x Rose-Tanaka {bev:.3g} kg/s (C = 0.58, k d = 0)" if axisymmetric
                 else f"Beverloo, slot {bev:.3g} kg/s per m (C' = 1.03, k d = 0)")
        ax_w.axhline(bev, color="k", ls="--", label=label)
    ax_w.set_xlabel("time since the outlet opened (s)")
    ax_w.set_ylabel(f"discharge rate (kg/s{per})")
    ax_w.set_ylim(bottom=0.0)
    ax_w.legend(loc="best", fontsize=8)
    mode = summary.get("flow_mode")
    label = {"mass": "mass flow", "funnel": "funnel flow", "no_flow": "no flow: an arch",
             "rathole": "a rathole"}.get(mode, mode)
    fig.suptitle("Discharge" + (f" ({label})" if mode else ""), fontsize=10)
    return fig


# ---------------------------------------------------------------- wall pressure
def theory_wall_pressure(cfg: HopperConfig, n: int = 120) -> dict:
    """Closed-form normal wall pressures p_n (Pa) against the arc length s (m) from the outlet
    lip.

    Bin (``s`` above the transition): Janssen with ``K = 1 - sin(phi)`` (Jaky, taken as the
    wall value) and ``mu = tan(phi_w)``, depth from the levelled fill surface.  Cone: Walker's
    slice method (D = 1) with the EN 1991-4 filling ratio and Walker's discharge ratio, on the
    Janssen vertical stress at the transition; and EN 1991-4's hopper loads in filling and
    discharge (section 6: the class, steep or shallow, picks F and n) with ``mu_h = tan(phi_w)``,
    ``phi_i = phi`` and the code's ``K_m = 1.1 (1 - sin phi)`` for the lower characteristic K
    (no a_K is known), on ``p_vft`` = EN's vertical-wall filling stress at the transition
    (the slender-silo form, Janssen with K_m; ``C_b = 1``).  A wedge gets the plane forms:
    Janssen for a long bin of width B and the slices with ``S = 1``.  A silo the classic
    theories do not cover (:attr:`HopperGeometry.classic`: several slopes, inserts, a full
    section) gets Janssen on its wall's top vertical stretch only (with the bin's width at
    the transition), and none without one.  Returns ``{name: (s, p_n)}``; a curve the theory
    refuses (a frictionless wall; for EN, a bottom flatter than 85 deg) is left out.
    """
    geom, mat, wall = cfg.hopper, cfg.material, cfg.wall
    bnd = cfg.boundary
    if bnd.transition("wall") is None or bnd.fill_level <= bnd.transition_height("wall"):
        return {}
    phi, phi_w = mat.friction_angle_deg, wall.friction_angle_deg
    z_t = bnd.transition_height("wall")
    rho, D, fill = mat.density, bnd.span_at(z_t), bnd.fill_level - z_t
    K = float(theory.k_jaky(phi))
    K_m = float(theory.k_en1991(phi))
    mu = math.tan(math.radians(phi_w))
    s_t = bnd.transition_s("wall")
    s_fill = bnd.arc_at_height("wall", bnd.fill_level)
    curves = {}
    # a wedge: the plane forms (Janssen for a long bin of width B, Walker's plane slice, S = 1)
    plane = not geom.axisymmetric
    bin_name, hopper_name, slices = (("plane bin", "wedge", 1) if plane else ("bin", "cone", 2))
    wall_pressure = theory.janssen_plane_wall_pressure if plane else theory.janssen_wall_pressure
    vertical = theory.janssen_plane_vertical_stress if plane else theory.janssen_vertical_stress
    try:
        s_bin = np.linspace(s_t, s_fill, n)
        curves[f"Janssen, {bin_name} (K = 1 - sin phi)"] = (
            s_bin, np.asarray(wall_pressure(s_fill - s_bin, rho, D, K, mu)))
        sigma_vt = float(vertical(fill, rho, D, K, mu))
    except ValueError:
        sigma_vt = rho * theory.G * fill
    shape = bnd.hopper_shape
    if not geom.classic or shape.half_angle_deg >= 90.0:   # EN 1991-4's hoppers: a cone
        curves.update(_stacked_walker(cfg, sigma_vt, slices, hopper_name, n))
        return curves
    s_cone = np.linspace(0.0, s_t, n)
    theta = math.radians(shape.half_angle_deg)
    x = s_cone * math.cos(theta) + shape.outlet_x / math.tan(theta)
    h = shape.bin_x / math.tan(theta)
    x = np.clip(x, 0.0, h)
    for mode in ("filling", "discharge"):
        try:
            p = theory.walker_hopper_wall_pressure(x, h, shape.half_angle_deg, rho, phi, phi_w,
                                                   sigma_vt, mode=mode, S=slices)
            curves[f"Walker, {hopper_name}, {mode}"] = (s_cone, np.asarray(p))
        except ValueError:
            pass
        try:
            p_vft = float(vertical(fill, rho, D, K_m, mu))
            en = theory.en1991_hopper_pressures(x, h, shape.half_angle_deg, rho * theory.G,
                                                K_m, mu, p_vft, mode=mode, phi_i=phi, S=slices)
            curves[f"EN 1991-4, {hopper_name}, {mode}"] = (s_cone, np.asarray(en.p_n))
        except ValueError:
            pass
    return curves


def _stacked_walker(cfg: HopperConfig, sigma_vt: float, slices: int, hopper_name: str,
                    n: int = 60) -> dict:
    """Walker's slices (D = 1) down a wall of several sloping stretches under its top
    vertical one, stretch by stretch: each from its own virtual apex (``x = r / tan(beta)``),
    with the mean vertical stress at its top the one its upper neighbour leaves at its bottom
    (``sigma_v = p_n / F``), starting from ``sigma_vt`` at the transition.  Drawn only for a
    half-section without inserts in the material, down to the first flat stretch.  Returns
    ``{"Walker, <hopper> stretch k, <mode>": (s, p_n)}``."""
    geom, mat = cfg.hopper, cfg.material
    if geom.full_section or any(min(z for _, z in i.outline) < geom.fill_level
                                for i in geom.inserts):
        return {}
    wall = cfg.boundary.chain("wall")
    a, b = wall.ends()
    sv = wall.s_vertices
    below = [k for k in range(wall.n_segments)
             if b[k, 1] <= cfg.boundary.transition_height("wall") + 1e-12]
    curves = {}
    for mode in ("filling", "discharge"):
        top = sigma_vt
        for k in reversed(below):
            dx, dz = b[k, 0] - a[k, 0], b[k, 1] - a[k, 1]
            if dz <= 0.0 or dx <= 0.0:
                break                          # a floor or a ledge ends the slices
            beta = math.degrees(math.atan2(dx, dz))
            tan_b = dx / dz
            h = b[k, 0] / tan_b                 # the virtual apex to the stretch's top
            s = np.linspace(sv[k], sv[k + 1], n)
            x = np.clip((a[k, 0] + (s - sv[k]) / (sv[k + 1] - sv[k]) * dx) / tan_b, 0.0, h)
            try:
                p = np.asarray(theory.walker_hopper_wall_pressure(
                    x, h, beta, mat.density, mat.friction_angle_deg,
                    cfg.wall.friction_angle_deg, top, mode=mode, S=slices))
            except ValueError:
                break
            curves[f"Walker, {hopper_name} stretch {k}, {mode}"] = (s, p)
            mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
            F = float(theory.en1991_steep_filling_F(beta, mu) if mode == "filling" else
                      theory.walker_discharge_ratio(mat.friction_angle_deg,
                                                    cfg.wall.friction_angle_deg, beta))
            top = float(p[0]) / F
    return curves


def _few_curves(curves: dict, most: int = 8) -> dict:
    """Walker's stretch-by-stretch curves (:func:`_stacked_walker`) as one curve per mode
    (stretches apart by a NaN) when there are more than ``most`` stretches: a wall drawn as
    thousands of points would otherwise make thousands of lines and legend entries, which
    take minutes to draw."""
    stretch = re.compile(r"(Walker, .+) stretch \d+, (\w+)")
    groups = {}
    for name in curves:
        match = stretch.fullmatch(name)
        if match:
            groups.setdefault(f"{match[1]} stretches, {match[2]}", []).append(name)
    out = dict(curves)
    for merged, names in groups.items():
        if len(names) > most:
            parts = sorted((curves[n] for n in names), key=lambda c: float(np.min(c[0])))
            out[merged] = tuple(np.concatenate([np.append(np.asarray(c[k], float), np.nan)
                                                for c in parts]) for k in (0, 1))
            for name in names:
                del out[name]
    return out


def wall_pressure(run):
    """The wall loads of a run against Janssen (bin), Walker (cone) and EN 1991-4.

    Left: the normal pressure along the wall (kPa), the traction recovered from the wall's
    reaction (markers joined by lines) at rest and at the discharge stages, the discharge
    envelope (the largest windowed pressure per bin), the stress-sampled estimate at rest
    (open markers), the reaction binned node by node at rest (grey dots), and the
    closed forms of :func:`theory_wall_pressure`: Janssen (solid black), Walker's slices
    (solid filling, dashed discharge), EN 1991-4's hopper loads (dash-dot) and its bin
    discharge load ``C_h`` x Janssen (dotted black).  Right: the overpressure factor
    (envelope / at rest) per bin with EN 1991-4's discharge factor for the bin wall, and the
    switch peak against Walker's switch pressure.  A run without a discharge (a fill-only
    run, ``end_time = 0``) gets the left panel alone, with the theories at rest only.  A full
    section's left wall is drawn dashed on the same axis (its ``s`` from its own lip); the
    inserts' pressure, along each insert from its lowest point, in a panel of their own.
    """
    run = Path(run)
    cfg = _config(run)
    summary = _summary(run)
    table = read_csv(run / RunDirectory.WALL_PRESSURE)
    stages = np.asarray(table.get("stage", np.array([])), dtype=str)
    s_all = np.asarray(table.get("s_m", []), dtype=float)
    p_all = np.asarray(table.get("p_n_Pa", []), dtype=float)
    walls = np.asarray(table.get("wall", np.full(len(stages), "wall")), dtype=str)
    inserts = {c.name for c in cfg.boundary.inserts}
    others = [w for w in dict.fromkeys(walls.tolist()) if w != "wall" and w not in inserts]
    on_inserts = [w for w in dict.fromkeys(walls.tolist()) if w in inserts]
    main = walls == "wall"           # the (right) wall; the others drawn dashed
    table = {k: (np.asarray(v)[main] if np.ndim(v) else v) for k, v in table.items()}
    other = (stages, s_all, p_all, walls)
    stages, s_all, p_all = stages[main], s_all[main], p_all[main]
    filled, envelope = stages == "filling", stages == "discharge_envelope"
    discharged = any(st != "filling" for st in stages)
    overpressure = filled.any() and envelope.any() and filled.sum() == envelope.sum()
    rows = 2 if on_inserts else 1
    if overpressure:
        fig = _figure(11.0, 4.4 * rows)
        grid = fig.subplots(rows, 2, width_ratios=(3, 2), squeeze=False)
        ax, ax_f = grid[0]
    else:
        fig = _figure(6.6, 4.4 * rows)
        grid = fig.subplots(rows, 1, squeeze=False)
        ax, ax_f = grid[0][0], None
    ax_i = grid[1][0] if on_inserts else None
    if on_inserts and overpressure:
        grid[1][1].set_axis_off()
    for stage in dict.fromkeys(stages.tolist()):
        sel = stages == stage
        if stage == "discharge_envelope":
            ax.plot(s_all[sel], p_all[sel] / 1e3, "-", color="C3", lw=2.0, alpha=0.6,
                    label="simulated, discharge envelope")
            continue
        marker, colour, label = _STAGE_STYLE.get(stage, ("x", "C4", stage))
        ax.plot(s_all[sel], p_all[sel] / 1e3, marker + "-", color=colour, ms=4, lw=0.8,
                label=f"simulated, {label}")
        if stage == "filling" and "p_n_stress_Pa" in table:
            ax.plot(s_all[sel], np.asarray(table["p_n_stress_Pa"], float)[sel] / 1e3, marker,
                    mfc="none", color=colour, ms=5, lw=0,
                    label="stress-sampled estimate, at rest")
        if stage == "filling" and "p_n_raw_Pa" in table:
            ax.plot(s_all[sel], np.asarray(table["p_n_raw_Pa"], float)[sel] / 1e3, ".",
                    color="0.55", ms=3, lw=0, label="reaction binned node by node, at rest")
    styles = {"Janssen": ("k", "-"), "Walker, cone, filling": ("C0", "-"),
              "Walker, cone, discharge": ("C3", "--"), "Walker, wedge, filling": ("C0", "-"),
              "Walker, wedge, discharge": ("C3", "--"), "EN 1991-4, cone, filling": ("C9", "-."),
              "EN 1991-4, cone, discharge": ("C6", "-."), "EN 1991-4, wedge, filling": ("C9", "-."),
              "EN 1991-4, wedge, discharge": ("C6", "-.")}
    o_stages, o_s, o_p, o_walls = other
    for k, name in enumerate(others):
        for stage, style in (("filling", "--"), ("discharge_envelope", ":")):
            sel = (o_walls == name) & (o_stages == stage)
            if sel.any():
                ax.plot(o_s[sel], o_p[sel] / 1e3, style, color=f"C{5 + k % 4}", lw=1.2,
                        label=f"{name}, {'at rest' if stage == 'filling' else 'envelope'} "
                              f"(s from its lip)")
    for k, name in enumerate(on_inserts):
        for stage, style in (("filling", "o-"), ("discharge_envelope", "-")):
            sel = (o_walls == name) & (o_stages == stage)
            if sel.any():
                ax_i.plot(o_s[sel], o_p[sel] / 1e3, style, color=f"C{5 + k % 4}", ms=3,
                          lw=1.2 if stage == "filling" else 2.0,
                          label=f"{name}, {'at rest' if stage == 'filling' else 'envelope'}")
    if ax_i is not None:
        ax_i.set_xlabel("arc length along each insert from its lowest point, s (m)")
        ax_i.set_ylabel("normal pressure p_n (kPa)")
        ax_i.set_xlim(left=0.0)
        ax_i.set_ylim(bottom=0.0)
        ax_i.legend(loc="best", fontsize=6.5)
        ax_i.set_title("Inserts (no closed form)", fontsize=10)
    curves = _few_curves(theory_wall_pressure(cfg))
    if not discharged:               # a fill-only run: the theories at rest only
        curves = {k: v for k, v in curves.items() if not k.endswith("discharge")}
    for name, (s, p) in curves.items():
        colour, ls = next((v for k, v in styles.items() if name.startswith(k)),
                          (("C0", "-") if name.endswith("filling") else ("C3", "--"))
                          if name.startswith("Walker") else ("0.4", "-"))
        ax.plot(s, p / 1e3, ls, color=colour, lw=1.2, label=name)
    c_h = theory.en1991_discharge_factors()[0]
    for name, (s, p) in curves.items():
        if name.startswith("Janssen") and discharged:
            ax.plot(s, c_h * p / 1e3, ":", color="k", lw=1.2,
                    label=f"EN 1991-4 discharge, bin (C_h = {c_h:g} x Janssen)")
    s_t = cfg.boundary.transition_s("wall")
    if cfg.boundary.transition("wall") is not None:
        for a in (ax, ax_f) if overpressure else (ax,):
            a.axvline(s_t, color="0.5", lw=0.8, ls=":")
        ax.text(s_t, 0.0, " transition", va="bottom", fontsize=8, color="0.4")
    ax.set_xlabel("arc length along the wall from the outlet lip, s (m)")
    ax.set_ylabel("normal wall pressure p_n (kPa)")
    ax.set_xlim(left=0.0)
    ax.set_ylim(bottom=0.0)
    ax.legend(loc="best", fontsize=6.5)
    ax.set_title(f"Wall pressure (phi = {cfg.material.friction_angle_deg:g} deg, "
                 f"phi_w = {cfg.wall.friction_angle_deg:g} deg)", fontsize=10)
    if overpressure:
        p_fill, p_env = p_all[filled], p_all[envelope]
        loaded = p_fill > 0.05 * p_fill.max()
        ratio = np.where(loaded, p_env / np.where(loaded, p_fill, 1.0), np.nan)
        ax_f.plot(s_all[filled], ratio, "o-", color="C3", ms=4, lw=0.8,
                  label="simulated: envelope / at rest")
        ax_f.axhline(c_h, color="k", ls=":", lw=1.2, label=f"EN 1991-4 C_h = {c_h:g} (bin)")
        ax_f.axhline(1.0, color="0.6", lw=0.8)
        walker = summary.get("walker_switch_pressure_Pa")
        peak, s_peak = summary.get("switch_peak_Pa"), summary.get("switch_peak_s_m")
        if walker is not None and peak is not None and np.isfinite(walker or np.nan):
            ax.plot([s_t], [walker / 1e3], "*", color="C3", ms=11,
                    label="Walker switch pressure")
            ax.plot([s_peak], [peak / 1e3], "P", color="k", ms=8, mfc="none",
                    label="simulated switch peak")
            ax.legend(loc="best", fontsize=6.5)
        ax_f.set_xlabel("s (m)")
        ax_f.set_ylabel("overpressure factor")
        ax_f.set_ylim(bottom=0.0)
        ax_f.legend(loc="best", fontsize=7)
        ax_f.set_title("Discharge overpressure", fontsize=10)
    return fig


def wall_forces(run):
    """The forces in the wall per metre of circumference (N/m, or kN/m from 1 kN/m up; tension
    positive) along the wall, from ``wall_pressure.csv``'s ``hoop_force_N_m`` and
    ``meridional_force_N_m``.

    Left: the hoop force at rest, at the discharge stages and from the discharge envelope,
    with Janssen's ``p_n R`` in the bin.  Right: the meridional force: the hopper's tension
    (hung from the transition) and the bin wall's compression (standing on it), with
    Janssen's ``-n_z`` in the bin and the transition's totals of ``summary.json``.  Both of
    Janssen's curves take one ``K``, named in their labels: the one measured at the bin wall
    at rest (``wall_k_bin``, the ``K`` of the summary's Janssen numbers), else Jaky's
    ``1 - sin(phi)``; for a silo the classic theories cover only.  A wedge's plates have no
    hoop force.  Returns None when the table has no forces (a run directory written before
    they were).
    """
    run = Path(run)
    table = read_csv(run / RunDirectory.WALL_PRESSURE)
    if "meridional_force_N_m" not in table:
        return None
    cfg, summary = _config(run), _summary(run)
    geom, mat = cfg.hopper, cfg.material
    main = np.asarray(table.get("wall", np.full(len(table["stage"]), "wall")), str) == "wall"
    stages = np.asarray(table["stage"], dtype=str)[main]
    s_all = np.asarray(table["s_m"], dtype=float)[main]
    hoop = np.asarray(table["hoop_force_N_m"], dtype=float)[main]
    meridional = np.asarray(table["meridional_force_N_m"], dtype=float)[main]
    largest = np.nanmax(np.abs(np.concatenate([hoop, meridional, [0.0]])))
    scale, unit = (1e3, "kN/m") if largest >= 1e3 else (1.0, "N/m")
    hoop, meridional = hoop / scale, meridional / scale
    fig = _figure(11.0, 4.2)
    ax_h, ax_m = fig.subplots(1, 2)
    for stage in dict.fromkeys(stages.tolist()):
        sel = stages == stage
        if stage == "discharge_envelope":
            ax_h.plot(s_all[sel], hoop[sel], "-", color="C3", lw=2.0, alpha=0.6,
                      label="from the discharge envelope")
            continue
        marker, colour, label = _STAGE_STYLE.get(stage, ("x", "C4", stage))
        ax_h.plot(s_all[sel], hoop[sel], marker + "-", color=colour, ms=4, lw=0.8, label=label)
        ax_m.plot(s_all[sel], meridional[sel], marker + "-", color=colour, ms=4, lw=0.8,
                  label=label)
    bnd = cfg.boundary
    s_t = bnd.transition_s("wall")
    s_fill = bnd.arc_at_height("wall", bnd.fill_level)
    mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
    plane = not geom.axisymmetric
    if mu > 0 and s_fill > s_t and geom.classic:
        s_bin = np.linspace(s_t, s_fill, 120)
        depth = s_fill - s_bin
        D = 2.0 * bnd.hopper_shape.bin_x
        K_w = summary.get("wall_k_bin")
        measured = K_w is not None and np.isfinite(K_w)
        K_w = K_w if measured else float(theory.k_jaky(mat.friction_angle_deg))
        which = (f"K = {K_w:.2f} measured at the bin wall at rest" if measured
                 else f"K = 1 - sin phi = {K_w:.2f}")
        if not plane:
            p = theory.janssen_wall_pressure(depth, mat.density, D, K_w, mu)
            ax_h.plot(s_bin, np.asarray(p) * 0.5 * D / scale, "k-", lw=1.2,
                      label=f"Janssen p_n R ({which})")
        axial = theory.janssen_plane_wall_axial_force if plane else theory.janssen_wall_axial_force
        n_z = axial(depth, mat.density, D, K_w, mu)
        ax_m.plot(s_bin, -np.asarray(n_z) / scale, "k-", lw=1.2,
                  label=f"Janssen -n_z ({which})")
    for key, sign, marker, label in (
            ("hopper_meridional_tension_N_m", 1.0, "^", "hopper tension at the transition"),
            ("bin_wall_axial_compression_N_m", -1.0, "v", "bin wall compression there")):
        value = summary.get(key)
        if value is not None and np.isfinite(value):
            ax_m.plot([s_t], [sign * value / scale], marker, color="k", ms=8, mfc="none",
                      label=f"{label}, at rest")
    for a in (ax_h, ax_m):
        if bnd.transition("wall") is not None:
            a.axvline(s_t, color="0.5", lw=0.8, ls=":")
        a.set_xlabel("arc length along the wall from the outlet lip, s (m)")
        a.set_xlim(left=0.0)
    ax_m.axhline(0.0, color="0.6", lw=0.8)
    per = "per metre of length" if plane else "per metre of circumference"
    if np.isfinite(hoop).any():
        ax_h.set_ylim(bottom=0.0)
        ax_h.set_ylabel(f"hoop force N_theta ({unit}, {per})")
        ax_h.legend(loc="best", fontsize=7)
        ax_h.set_title("Hoop force (tension)", fontsize=10)
    else:
        ax_h.set_axis_off()
        ax_h.text(0.5, 0.5, "plane walls: no hoop force", ha="center", va="center",
                  transform=ax_h.transAxes)
    ax_m.set_ylabel(f"meridional force N_m ({unit}, {per})")
    ax_m.legend(loc="best", fontsize=7)
    ax_m.set_title("Meridional force: hopper hung from the transition (+), bin wall on it (-)",
                   fontsize=9)
    return fig


# ---------------------------------------------------------------- stress pattern
def _stage_snapshots(entries):
    """The snapshot at rest (the last of the fill) and the one of the discharge nearest to
    half of its duration; either may be missing."""
    filled = [e for e in entries if e["stage"] == "filling"]
    discharge = [e for e in entries if e["stage"] == "discharge"]
    chosen = []
    if filled:
        chosen.append(("at rest", filled[-1]))
    if len(discharge) > 1:
        times = np.array([float(e["discharge_time_s"]) for e in discharge])
        k = int(np.argmin(np.abs(times - 0.5 * times.max())))
        chosen.append((f"discharge, t = {times[k]:.2f} s", discharge[k]))
    return chosen


def stress_pattern(run):
    """Trajectories of the major principal stress over the mobilised friction, at rest and in
    discharge: the active state of the fill (sigma1 near vertical) and the passive, arched
    state of the flow (sigma1 across it), from the stresses of the field snapshots.  The
    material present (``alpha > 1/2``) but stress-free (at the apex: loose, or a free surface
    in flow) is drawn grey, apart from the empty cells (white), so the free surface shows
    where it is."""
    import textwrap

    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from . import diagnostics

    run = Path(run)
    cfg = _config(run)
    chosen = _stage_snapshots(snapshots(run))
    fig = _figure(max(3.2 * max(len(chosen), 1) + 1.2, 5.6), 6.0)
    axes = np.atleast_1d(fig.subplots(1, max(len(chosen), 1)))
    folder = run / RunDirectory.FIELDS
    mesh_artist = None
    for ax, (title, entry) in zip(axes, chosen):
        mesh = read_vtu(folder / entry["file"])
        r_nodes, z_nodes = np.unique(mesh.points[:, 0]), np.unique(mesh.points[:, 1])
        shape = (len(z_nodes) - 1, len(r_nodes) - 1)
        cell = {k: np.asarray(mesh.cell_data[k][0]).reshape(shape)
                for k in ("alpha", "stress_rr", "stress_zz", "stress_tt", "stress_rz")}
        sigma = np.stack([cell["stress_rr"], cell["stress_zz"], cell["stress_tt"],
                          cell["stress_rz"]], axis=-1)
        pattern = diagnostics.stress_pattern(sigma, cfg.material.cohesion,
                                             cfg.material.friction_angle_deg)
        present = cell["alpha"] > 0.5
        ax.pcolormesh(r_nodes, z_nodes, np.ma.masked_where(~present, np.ones(shape)),
                      cmap=ListedColormap(["0.82"]), vmin=0, vmax=1, shading="flat")
        mob = np.ma.masked_where(~present | ~np.isfinite(pattern["sin_phi_mob"]),
                                 pattern["sin_phi_mob"])
        mesh_artist = ax.pcolormesh(r_nodes, z_nodes, mob, cmap="magma_r", vmin=0.0,
                                    vmax=math.sin(math.radians(cfg.material.friction_angle_deg)),
                                    shading="flat")
        rc, zc = 0.5 * (r_nodes[1:] + r_nodes[:-1]), 0.5 * (z_nodes[1:] + z_nodes[:-1])
        step = max(1, int(round(len(rc) / 14)))
        R, Z = np.meshgrid(rc[::step], zc[::step])
        angle = np.radians(pattern["sigma1_angle_deg"][::step, ::step])
        keep = present[::step, ::step] & (pattern["sigma1"][::step, ::step] > 0)
        u, w = np.sin(angle), np.cos(angle)
        ax.quiver(R[keep], Z[keep], u[keep], w[keep], angles="xy", pivot="middle",
                  headwidth=0, headlength=0, headaxislength=0,
                  color="deepskyblue", width=0.012, edgecolor="k", linewidth=0.3,
                  scale=1.0 / (0.9 * step * (rc[1] - rc[0])), scale_units="xy")
        for line in wall_lines(cfg, z_nodes[0], z_nodes[-1]):
            ax.plot(line[:, 0], line[:, 1], color="k", lw=1.0)
        ax.set_xlim(*_section_limits(cfg))
        ax.set_ylim(z_nodes[0], min(z_nodes[-1], cfg.hopper.fill_level * 1.08))
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("r (m)" if cfg.hopper.axisymmetric else "x (m)")
    axes[0].set_ylabel("z (m)")
    axes[0].legend(handles=[Patch(color="0.82", label="material, stress-free"),
                            Patch(facecolor="w", edgecolor="0.5", label="empty")],
                   loc="upper right", fontsize=7)
    if mesh_artist is not None:
        fig.colorbar(mesh_artist, ax=list(axes), shrink=0.8,
                     label="mobilised friction sin phi_mob = (s1 - s3)/(s1 + s3 + 2c cot phi)")
    width = fig.get_figwidth()
    fig.suptitle("\n".join(textwrap.wrap("Major principal stress trajectories (lines) over "
                                         "the mobilised friction", int(11 * width))),
                 fontsize=10)
    return fig


# ---------------------------------------------------------------- all of them
def lagrangian_mesh(run):
    """The Lagrangian mesh of a ``formulation = "lagrangian"`` run, coloured by layer, at the
    opening of the outlet (the last snapshot of the fill) and at the end of the run (where a
    distortion stopped it), with the hopper wall."""
    from matplotlib.collections import PolyCollection

    run = Path(run)
    cfg, summary = _config(run), _summary(run)
    entries = snapshots(run)
    filled = [e for e in entries if e["stage"] == "filling"]
    chosen = ([filled[-1]] if filled else []) + ([entries[-1]] if entries else [])
    fig = _figure(4.2 * max(len(chosen), 1), 5.2)
    axes = np.atleast_1d(fig.subplots(1, max(len(chosen), 1)))
    walls = wall_lines(cfg, -cfg.hopper.outlet_diameter, cfg.hopper.top)
    meshes = [read_vtu(run / RunDirectory.FIELDS / entry["file"]) for entry in chosen]
    cells = [{"alpha": np.asarray(mesh.cell_data["alpha"][0]),
              "layer": np.asarray(mesh.cell_data["layer"][0])} for mesh in meshes]
    cmap, norm = _layer_colours(_n_layers(cells))
    for ax, entry, mesh, cell in zip(axes, chosen, meshes, cells):
        active, layer = cell["alpha"] > 0.5, cell["layer"]
        polys = mesh.points[mesh.cells_dict["quad"]][active][:, :, :2]
        ax.add_collection(PolyCollection(polys, array=layer[active], cmap=cmap, norm=norm,
                                         edgecolors="k", linewidths=0.3))
        for line in walls:
            ax.plot(line[:, 0], line[:, 1], "k-", lw=1.5)
        ax.set_aspect("equal")
        ax.set_xlim(0.0, 1.05 * cfg.boundary.x_extent[1])
        ax.set_ylim(-cfg.hopper.outlet_diameter, cfg.hopper.fill_level * 1.05)
        ax.set_xlabel("r (m)")
        ax.set_ylabel("z (m)")
        t_dis = entry.get("discharge_time_s", math.nan)
        ax.set_title("at the opening" if entry["stage"] == "filling"
                     else f"{t_dis:.3g} s after the opening", fontsize=9)
    kind = summary.get("distortion_kind")
    stop = (f"stopped by distortion: {kind}, element {summary.get('distortion_element')}"
            if kind else f"stop: {summary.get('stop_reason', '')}")
    fig.suptitle(f"Lagrangian mesh ({stop})", fontsize=9)
    return fig


@dataclass(frozen=True)
class Picture:
    """A picture :func:`plot_run` draws into a run directory: its file ``name``, what it
    ``shows``, ``draw(run, path)`` (writes it) and ``applies(facts)``, whether the run has what
    it shows (``facts``: :func:`_run_facts`)."""

    name: str
    shows: str
    draw: Callable
    applies: Callable


def _figure_file(make):
    """``draw(run, path)`` for a function that returns a figure (or None: nothing to draw)."""
    def draw(run, path):
        fig = make(run)
        return None if fig is None else _save(fig, path)
    return draw


def _run_facts(run) -> dict:
    """What a run directory holds, for :attr:`Picture.applies`: ``samples`` (the time
    series has rows: a discharge), ``wall`` (wall loads), ``snapshots``, ``discharge`` (a
    snapshot of the discharge), ``lagrangian`` (the formulation) and ``three_d`` (a 3D run,
    ``hopper.dimensions = 3``: its own pictures of :mod:`fipy_hopper.space.pictures`)."""
    entries = snapshots(run)
    series = run / RunDirectory.TIMESERIES
    cfg = _config(run)
    three_d = cfg.hopper.dimensions == 3
    wall = (run / RunDirectory.WALL_PRESSURE).is_file() and (
        not three_d or len(read_csv(run / RunDirectory.WALL_PRESSURE)["stage"]) > 0)
    return {"samples": series.is_file() and len(read_csv(series)["t_s"]) > 0,
            "wall": wall, "snapshots": bool(entries),
            "discharge": any(e["stage"] == "discharge" for e in entries),
            "lagrangian": bool(entries) and cfg.numerics.formulation == "lagrangian",
            "three_d": three_d, "rectangular": cfg.hopper.rectangular}


# ---------------------------------------------------------------- 3D
def flow_plane(run, path):
    """The 3D run's flow pattern and speed in the vertical plane through the axis and the
    outlet (:func:`fipy_hopper.space.pictures.plane_picture`), from the snapshot of the
    discharge in the middle of its snapshots (at least one after the opening)."""
    from .space.pictures import plane_picture

    entries = [e for e in snapshots(run) if e["stage"] == "discharge"]
    if not entries:
        return None
    later = [e for e in entries if e["discharge_time_s"] > 0] or entries
    entry = later[(len(later) - 1) // 2]
    geom = _config(run).hopper
    y0 = geom.offset_xy[1] if geom.rectangular else 0.0
    where = (f"the plane y = {y0:g} m through the outlet" if y0 else
             "the plane through the axis and the outlet")
    title = (f"{where},\n{entry['discharge_time_s']:.3g} s after the opening")
    return plane_picture(Path(run) / RunDirectory.FIELDS / entry["file"], path, title, y0)


def _wall_stages(run) -> tuple:
    """The recorded stages drawn in the 3D wall pictures: at rest and the first of the
    discharge's (90 %, 50 % left, the envelope) the run has."""
    stages = list(dict.fromkeys(read_csv(Path(run) / RunDirectory.WALL_PRESSURE)["stage"]))
    shown = [s for s in ("filling",) if s in stages]
    shown += [s for s in ("early_discharge", "mid_discharge", "discharge_envelope")
              if s in stages][:1]
    return tuple(shown)


def eccentric_codes(run):
    """What :func:`fipy_hopper.space.pictures.code_curves` needs to draw the codes' eccentric
    patterns for a 3D run: a circular silo's outlet offset, radius and fill level, the bin
    wall's foot, ``mu = tan(phi_w)``, ``phi``, ``gamma = rho g``, EN 1991-4's middle
    ``G = 0.4`` and ``K`` (measured at the bin wall at rest, ``wall_k_bin``, else EN's
    ``1.1 (1 - sin phi)``); ``None`` for a centred outlet, a rectangular plan or a section."""
    cfg = _config(run)
    geom = cfg.hopper
    if geom.dimensions != 3 or geom.rectangular or not geom.outlet_offset > 0.0:
        return None
    phi = cfg.material.friction_angle_deg
    K = _summary(run).get("wall_k_bin")
    if not (isinstance(K, (int, float)) and math.isfinite(K) and K > 0):
        K = float(theory.k_en1991(phi))
    return {"offset": float(geom.outlet_offset), "radius": 0.5 * geom.bin_diameter,
            "surface": float(geom.fill_level),
            "bin_foot": max(cfg.boundary.transition_height("wall"), 0.0),
            "mu": math.tan(math.radians(cfg.wall.friction_angle_deg)), "phi_deg": phi,
            "gamma": cfg.material.density * theory.G, "K": float(K), "G": 0.4}


def wall_circumference(run, path):
    """The 3D run's wall pressure around the circumference at a few heights, at rest and in
    discharge (:func:`fipy_hopper.space.pictures.circumference_picture`), with the codes'
    eccentric patterns in discharge for an off-centre outlet (:func:`eccentric_codes`)."""
    from .space.pictures import circumference_picture
    return circumference_picture(Path(run) / RunDirectory.WALL_PRESSURE, path,
                                 stages=_wall_stages(run), codes=eccentric_codes(run))


def wall_unrolled(run, path):
    """The 3D run's wall pressure over the unrolled wall, (theta, s), at rest and in
    discharge (:func:`fipy_hopper.space.pictures.unrolled_picture`)."""
    from .space.pictures import unrolled_picture
    return unrolled_picture(Path(run) / RunDirectory.WALL_PRESSURE, path,
                            stages=_wall_stages(run))


def wall_faces(run, path):
    """A rectangular plan's wall pressure over its developed wall, at rest and in discharge
    (:func:`fipy_hopper.space.pictures.faces_picture`)."""
    from .space.pictures import faces_picture
    geom = _config(run).hopper
    return faces_picture(Path(run) / RunDirectory.WALL_PRESSURE, path,
                         (geom.bin_width, geom.bin_length), stages=_wall_stages(run),
                         hopper_height=geom.cone_height)


def wall_perimeter(run, path):
    """A rectangular plan's wall pressure along the bin's perimeter at a few heights
    (:func:`fipy_hopper.space.pictures.perimeter_picture`)."""
    from .space.pictures import perimeter_picture
    geom = _config(run).hopper
    return perimeter_picture(Path(run) / RunDirectory.WALL_PRESSURE, path,
                             (geom.bin_width, geom.bin_length), stages=_wall_stages(run))


#: Every picture :func:`plot_run` can draw, in the order drawn: the one list (the help of
#: ``fipy-hopper plot`` and the files ``--force`` removes are read from it).  A fill-only run
#: (``end_time = 0``) has no time series, so no ``discharge.png``; a Lagrangian run gets
#: ``lagrangian_mesh.png`` in place of the pictures of the grid's fields.
PICTURES = (
    Picture("discharge.png", "the mass in the hopper and the discharge rate",
            _figure_file(discharge_curves), lambda f: f["samples"]),
    Picture("wall_pressure.png", "the wall pressure against Janssen, Walker and EN 1991-4",
            _figure_file(wall_pressure), lambda f: f["wall"] and not f["three_d"]),
    Picture("wall_forces.png", "the hoop and meridional forces in the wall",
            _figure_file(wall_forces), lambda f: f["wall"] and not f["three_d"]),
    Picture("lagrangian_mesh.png", "the mesh of a Lagrangian run",
            _figure_file(lagrangian_mesh), lambda f: f["lagrangian"]),
    Picture("stress_pattern.png", "the major principal stress trajectories",
            _figure_file(stress_pattern),
            lambda f: f["snapshots"] and not f["lagrangian"] and not f["three_d"]),
    Picture("flow_pattern.png", "the layers and the speed in discharge",
            _figure_file(flow_pattern),
            lambda f: f["discharge"] and not f["lagrangian"] and not f["three_d"]),
    Picture("discharge.gif", "an animation of the snapshots",
            lambda run, path: animate(run, path),
            lambda f: f["discharge"] and not f["lagrangian"] and not f["three_d"]),
    Picture("flow_plane.png", "3D: the flow pattern and speed in the plane through the axis "
            "and the outlet", flow_plane, lambda f: f["discharge"] and f["three_d"]),
    Picture("wall_circumference.png", "3D: the wall pressure around the circumference at a "
            "few heights", wall_circumference,
            lambda f: f["wall"] and f["three_d"] and not f["rectangular"]),
    Picture("wall_unrolled.png", "3D: the wall pressure over the unrolled wall (theta, s)",
            wall_unrolled, lambda f: f["wall"] and f["three_d"] and not f["rectangular"]),
    Picture("wall_faces.png", "3D, a rectangular plan: the wall pressure over the developed "
            "faces", wall_faces, lambda f: f["wall"] and f["three_d"] and f["rectangular"]),
    Picture("wall_perimeter.png", "3D, a rectangular plan: the wall pressure along the bin's "
            "perimeter at a few heights", wall_perimeter,
            lambda f: f["wall"] and f["three_d"] and f["rectangular"]),
)


def plot_run(run) -> list:
    """Draw every picture of :data:`PICTURES` that the run directory has the data of into
    it; returns the paths written.  A picture whose data are missing (no snapshots yet, no
    wall samples, no discharge) is skipped."""
    run = Path(run)
    facts = _run_facts(run)
    written = [picture.draw(run, run / picture.name) for picture in PICTURES
               if picture.applies(facts)]
    return [path for path in written if path is not None]


if __name__ == "__main__":  # pragma: no cover
    import sys

    for p in plot_run(sys.argv[1]):
        print(p)
