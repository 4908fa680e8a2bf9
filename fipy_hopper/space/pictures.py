"""Pictures of a 3D run, drawn from the files it wrote (``fipy-hopper plot``,
:func:`fipy_hopper.plotting.plot_run`, draws them into a 3D run's directory):

* :func:`plane_picture`: the flow pattern and the speed in the vertical plane through the
  axis and the outlet (``y = 0``), from a field snapshot (``fields_NNNN.vtu``): the speed of
  the cells next to the plane, arrows of their velocity in the plane, empty cells blank;
* :func:`circumference_picture`: the wall pressure around the circumference at a few heights
  (polar), at rest and in discharge, from ``wall_pressure.csv``; for a circular silo with an
  off-centre outlet the codes' eccentric patterns beside it in discharge (:func:`code_curves`);
* :func:`unrolled_picture`: the wall pressure over the unrolled wall (``theta`` across, the
  bins up the meridian, labelled with their ``s`` and ``z``), one panel per stage, from
  ``wall_pressure.csv``.

The wall pictures show the walls that rise (a cone, a bin wall); a flat floor is left out
(its pressure is in the file).

Each returns the path written (PNG, written atomically).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import atomic_path, read_csv


def _figure():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return path


def plane_cells(vtu_path, y0: float = 0.0) -> dict:
    """The cells of a snapshot next to the plane ``y = 0`` (on its ``+y`` side; ``y0``: the
    node plane nearest ``y = y0``) on their ``(z, x)`` index grid: ``x``, ``z`` (cell centres,
    m), ``speed``, ``vx``, ``vz`` (m/s) and ``alpha`` ``(nz, nx)``, NaN where no open cell
    is."""
    from ..io import read_vtu
    mesh = read_vtu(vtu_path)
    hexes = mesh.cells_dict["hexahedron"]
    centres = mesh.points[hexes].mean(axis=1)
    h = float(np.ptp(mesh.points[hexes[0]][:, 0]))
    y0 = h * round(y0 / h)
    near = (centres[:, 1] > y0) & (centres[:, 1] < y0 + h)
    c = centres[near]
    xs = np.unique(np.round(c[:, 0] / h - 0.5)).astype(int)
    zs = np.unique(np.round(c[:, 2] / h - 0.5)).astype(int)
    ix = np.searchsorted(xs, np.round(c[:, 0] / h - 0.5).astype(int))
    iz = np.searchsorted(zs, np.round(c[:, 2] / h - 0.5).astype(int))
    out = {"x": (xs + 0.5) * h, "z": (zs + 0.5) * h}
    vel = mesh.cell_data_dict["velocity"]["hexahedron"][near]
    for name, values in (("speed", np.linalg.norm(vel, axis=1)), ("vx", vel[:, 0]),
                         ("vz", vel[:, 2]),
                         ("alpha", mesh.cell_data_dict["alpha"]["hexahedron"][near])):
        grid = np.full((len(zs), len(xs)), np.nan)
        grid[iz, ix] = values
        out[name] = grid
    return out


def plane_picture(vtu_path, png_path, title: str = "", y0: float = 0.0) -> Path:
    """The speed and the flow pattern in the plane through the axis and the outlet (a
    rectangular plan's: through the outlet's centre, ``y = y0``)."""
    plt = _figure()
    f = plane_cells(vtu_path, y0)
    empty = ~(f["alpha"] > 0.05)
    speed = np.ma.masked_where(empty, f["speed"])
    fig, ax = plt.subplots(figsize=(5.5, 6.5))
    h = f["x"][1] - f["x"][0] if len(f["x"]) > 1 else 1.0
    mesh = ax.pcolormesh(np.append(f["x"] - 0.5 * h, f["x"][-1] + 0.5 * h),
                         np.append(f["z"] - 0.5 * h, f["z"][-1] + 0.5 * h), speed,
                         cmap="viridis", shading="flat")
    fig.colorbar(mesh, ax=ax, label="speed (m/s)")
    X, Z = np.meshgrid(f["x"], f["z"])
    norm = np.where(f["speed"] > 0, f["speed"], 1.0)
    ok = ~empty & (f["speed"] > 1e-4)
    ax.quiver(X[ok], Z[ok], (f["vx"] / norm)[ok], (f["vz"] / norm)[ok], color="white",
              scale=35, width=0.004)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m): towards the outlet's offset")
    ax.set_ylabel("z (m)")
    ax.set_title(title or "flow in the plane through the axis and the outlet")
    fig.tight_layout()
    return _save(fig, png_path)


def _stage_table(csv_path, stage, floors: bool = False):
    """``(s, z, sectors, p (n_bins, n_sectors))`` of a stage's rows of ``wall_pressure.csv``,
    bins in the file's order (stretch by stretch up the wall); ``floors``: keep the bins of
    horizontal stretches (a flat floor), else only the walls that rise."""
    t = read_csv(csv_path)
    on = np.asarray(t["stage"]) == stage
    s = np.asarray(t["s_m"], float)[on]
    z = np.asarray(t["z_m"], float)[on]
    seg = np.asarray(t["segment"], float)[on]
    theta = np.asarray(t["theta_deg"], float)[on]
    p = np.asarray(t["p_n_Pa"], float)[on]
    sectors = np.unique(theta)
    n = len(sectors)
    bins_s, bins_z, bins_seg = s[::n], z[::n], seg[::n]
    grid = p.reshape(-1, n)
    keep = np.ones(len(bins_s), bool)
    if not floors:
        for k in np.unique(bins_seg):
            on_seg = bins_seg == k
            if np.ptp(bins_z[on_seg]) == 0.0 and on_seg.sum() > 1 or (
                    on_seg.sum() == 1 and np.any(bins_z[on_seg] == 0.0)):
                keep[on_seg] = False
    return bins_s[keep], bins_z[keep], sectors, grid[keep]


#: the angles (deg) at which the codes' patterns are drawn: fine enough for EN 1991-4's zones
CODE_THETA = np.linspace(-180.0, 180.0, 721)


def code_curves(theta_deg, z, p_hf, p_nf, codes) -> dict:
    """The codes' wall pressure around a circular silo with an off-centre outlet at the height
    ``z`` (m above the outlet plane) of its bin wall, at ``theta_deg`` (0 towards the outlet):
    ``{label: p (Pa)}``, empty without ``codes`` or for a centred outlet.

    * EN 1991-4's large-eccentricity pattern
      (:func:`fipy_hopper.theory.en1991_eccentric_wall_pressure`) for each ``G`` of
      ``codes["G"]`` (one number or several) at the depth ``codes["surface"] - z`` below the
      fill's level, as the code's own factors on its own filling pressure (``p_hce / p_hf``
      and ``p_hae / p_hf``, both of EN's formulas with the same ``K`` and ``mu``) times the
      given filling pressure ``p_hf`` (Pa);
    * AS 3774's eccentric outlet (:func:`fipy_hopper.theory.as3774_eccentric_increment`):
      ``p_nf`` (Pa, the symmetric flow pressure) plus its increment, ``h = z`` above the outlet.

    ``codes``: ``offset`` (m), ``radius`` (m), ``K``, ``mu`` (= tan phi_w), ``phi_deg``,
    ``gamma`` (N/m^3), ``surface`` (m above the outlet plane) and ``G``.  A ``G`` outside
    (0, 1), or a wall rougher than the solid (``mu > tan phi``), draws no EN curve; a height
    at or above the surface none either.
    """
    from .. import theory

    if not codes or not codes.get("offset", 0.0) > 0.0:
        return {}
    c = codes
    out = {}
    depth = c["surface"] - z
    Gs = np.atleast_1d(c.get("G", 0.4)).astype(float)
    for G in Gs:
        if depth > 0 and 0.0 < G < 1.0 and np.isfinite(p_hf):
            try:
                p = theory.en1991_eccentric_wall_pressure(
                    theta_deg, depth, c["gamma"], c["radius"], G, c["K"], c["mu"],
                    c["phi_deg"]).p_h
            except ValueError:        # mu above tan(phi): EN has no sliding channel
                continue
            own = theory.en1991_filling_vertical_walls(depth, c["gamma"], 2.0 * c["radius"],
                                                       c["K"], c["mu"]).p_h
            out[f"EN 1991-4, G = {G:.3g}"] = np.asarray(p, float) * (p_hf / float(own))
    if np.isfinite(p_nf):
        inc = theory.as3774_eccentric_increment(theta_deg, z, p_nf, c["offset"],
                                                2.0 * c["radius"], c["phi_deg"])
        out["AS 3774"] = p_nf + np.asarray(inc, float)
    return out


def circumference_figure(csv_path, stages=("filling", "early_discharge"), n_heights: int = 3,
                         codes=None):
    """The figure of :func:`circumference_picture` (pyplot's; the caller closes it)."""
    plt = _figure()
    recorded = np.asarray(read_csv(csv_path)["stage"])
    stages = [s for s in stages if np.any(recorded == s)]
    fig, axes = plt.subplots(1, max(len(stages), 1), subplot_kw={"projection": "polar"},
                             figsize=(4.5 * max(len(stages), 1), 5.6), squeeze=False)
    rest = _stage_table(csv_path, "filling") if codes and np.any(recorded == "filling") else None
    for ax, stage in zip(axes[0], stages):
        bins, z, sectors, grid = _stage_table(csv_path, stage)
        pick = np.unique(np.linspace(0, len(bins) - 1, n_heights).round().astype(int))
        closed = np.radians(np.append(sectors, sectors[0] + 360.0))
        named = {}
        for c, b in enumerate(pick):
            ax.plot(closed, np.append(grid[b], grid[b, 0]), marker="o", ms=3, color=f"C{c}",
                    label=f"s = {bins[b]:.3f} m (z = {z[b]:.3f} m)")
            if rest is None or stage == "filling" or not z[b] > codes.get("bin_foot", 0.0):
                continue
            curves = code_curves(CODE_THETA, z[b], float(np.nanmean(rest[3][b])),
                                 float(np.nanmean(grid[b])), codes)
            for (label, p), style in zip(curves.items(), ("--", "-.", ":", (0, (1, 3)))):
                style = ":" if label == "AS 3774" else style
                ax.plot(np.radians(CODE_THETA), p, ls=style, lw=1.0, color=f"C{c}")
                named.setdefault(label, style)
        for label, style in named.items():       # the codes in the legend, in black
            ax.plot([], [], ls=style, color="k", lw=1.0, label=(
                f"{label} eccentric discharge (p_hf: the height's mean at rest)"
                if label.startswith("EN") else
                f"{label} eccentric outlet (p_nf: the height's mean in the panel)"))
        ax.set_title(stage.replace("_", " "))
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08))
    fig.suptitle("wall pressure p_n (Pa) around the circumference; 0 deg: the outlet's side",
                 y=0.99)
    fig.tight_layout(rect=(0, 0.1, 1, 0.94))
    return fig


def circumference_picture(csv_path, png_path, stages=("filling", "early_discharge"),
                          n_heights: int = 3, codes=None) -> Path:
    """The wall pressure around the circumference at ``n_heights`` height bins (spread over
    the wall), one polar panel per stage (those recorded).  With ``codes`` (the keys of
    :func:`code_curves` and ``bin_foot``, the bin wall's foot, m) and an off-centre outlet,
    each discharge panel draws beside the simulated pressure of each height on the bin wall
    (``z > bin_foot``) EN 1991-4's eccentric pattern (its filling pressure ``p_hf`` the mean
    around the circumference at rest at that height) and AS 3774's (``p_nf`` the panel's
    mean around at that height), dashed and dotted in the height's colour; at rest, on the
    hopper, for a centred outlet (and a rectangular plan: not drawn here) none."""
    return _save(circumference_figure(csv_path, stages, n_heights, codes), png_path)


def unrolled_picture(csv_path, png_path, stages=("filling", "early_discharge")) -> Path:
    """The wall pressure over the unrolled wall (the walls that rise: a flat floor left out),
    one panel per recorded stage, on a common colour scale; the bins up the wall in their
    order, labelled with ``s`` (and ``z``) of their centres."""
    plt = _figure()
    stages = [s for s in stages if np.any(np.asarray(read_csv(csv_path)["stage"]) == s)]
    tables = [_stage_table(csv_path, s) for s in stages]
    top = max((np.nanmax(t[3]) for t in tables if np.isfinite(t[3]).any()), default=1.0)
    fig, axes = plt.subplots(1, max(len(stages), 1), figsize=(5.2 * max(len(stages), 1), 5.0),
                             squeeze=False)
    mesh = None
    for ax, stage, (bins, z, sectors, grid) in zip(axes[0], stages, tables):
        width = sectors[1] - sectors[0] if len(sectors) > 1 else 360.0
        t_edges = np.append(sectors - 0.5 * width, sectors[-1] + 0.5 * width)
        rows = np.arange(len(bins) + 1) - 0.5
        mesh = ax.pcolormesh(t_edges, rows, grid, vmin=0.0, vmax=top, cmap="magma",
                             shading="flat")
        ax.set_yticks(np.arange(len(bins)))
        ax.set_yticklabels([f"{a:.3f} ({b:.3f})" for a, b in zip(bins, z)]
                           if ax is axes[0, 0] else [], fontsize=7)
        ax.set_xlabel("theta (deg): 0 the outlet's side, 180 the far wall")
        ax.set_title(stage.replace("_", " "))
    axes[0, 0].set_ylabel("bin centre: s along the meridian (z) (m)")
    if mesh is not None:
        fig.colorbar(mesh, ax=list(axes[0]), label="p_n (Pa)")
    return _save(fig, png_path)


# ---------------------------------------------------------------- a rectangular plan
#: the bin's faces round the perimeter, counter-clockwise seen from above from +x, and
#: whether a face's width (its ``u``, along +y or +x) runs that way
PERIMETER = (("x_plus", True), ("y_plus", False), ("x_minus", False), ("y_minus", True))


def face_tables(csv_path, stage) -> dict:
    """``{face: (z (n_bins,), u (n_sectors,), p (n_bins, n_sectors))}`` of a stage's rows of a
    rectangular plan's ``wall_pressure.csv`` (the floor left out), bins up each face."""
    t = read_csv(csv_path)
    on = np.asarray(t["stage"]) == stage
    return faces_of(np.asarray(t["wall"])[on], np.asarray(t["z_m"], float)[on],
                    np.asarray(t["u"], float)[on], np.asarray(t["p_n_Pa"], float)[on])


def faces_of(wall, z, u, *values) -> dict:
    """``{face: (z (n_bins,), u (n_sectors,), *v (n_bins, n_sectors))}`` of one stage's rows
    of a rectangular plan's ``wall_pressure.csv`` (their ``wall``, ``z_m`` and ``u`` columns
    and any per-row ``values``, e.g. ``p_n_Pa``), the floor left out: each face's rows are
    its height bins, each with its sectors in order."""
    out = {}
    for face in dict.fromkeys(wall):
        if face == "floor":
            continue
        sel = wall == face
        sectors = np.unique(u[sel])
        n = len(sectors)
        out[face] = (z[sel][::n], sectors) + tuple(np.asarray(v)[sel].reshape(-1, n)
                                                   for v in values)
    return out


def _edges(centres) -> np.ndarray:
    """Cell edges round sorted centres (halfway between, the ends mirrored)."""
    c = np.asarray(centres, float)
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])


def faces_picture(csv_path, png_path, widths, stages=("filling", "early_discharge"),
                  hopper_height: float = 0.0) -> Path:
    """The wall pressure of a rectangular plan over its developed wall, one panel per
    recorded stage on a common colour scale: the bin's faces side by side round the
    perimeter (:data:`PERIMETER`, each as wide as it is, ``widths = (bin_width,
    bin_length)``), the height up; the hopper's faces below them, each sector at its fraction
    of the face's width (the floor is in the file)."""
    plt = _figure()
    stages = [s for s in stages if np.any(np.asarray(read_csv(csv_path)["stage"]) == s)]
    tables = [face_tables(csv_path, s) for s in stages]
    top = max((np.nanmax(p) for t in tables for _, _, p in t.values()
               if np.isfinite(p).any()), default=1.0)
    fig, axes = plt.subplots(1, max(len(stages), 1), figsize=(6.0 * max(len(stages), 1), 5.0),
                             squeeze=False)
    mesh = None
    for ax, stage, table in zip(axes[0], stages, tables):
        start = 0.0
        for face, forward in PERIMETER:
            width = widths[1] if face.startswith("x") else widths[0]
            for name in (face, "hopper_" + face):
                if name not in table:
                    continue
                z, u, p = table[name]
                u_edges = _edges(u)
                u_edges = np.clip(u_edges, 0.0, 1.0)
                x = start + width * (u_edges if forward else 1.0 - u_edges)
                order = np.argsort(x)
                grid = p if forward else p[:, ::-1]
                z_edges = _edges(z)
                if name == face and hopper_height > 0:
                    z_edges[0] = max(z_edges[0], hopper_height)
                elif name != face:
                    z_edges = np.clip(z_edges, 0.0, hopper_height)
                mesh = ax.pcolormesh(x[order], z_edges, grid, vmin=0.0, vmax=top,
                                     cmap="magma", shading="flat")
            ax.axvline(start, color="0.6", lw=0.6)
            ax.text(start + 0.5 * width, 1.0, face, transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=7)
            start += width
        if hopper_height > 0:
            ax.axhline(hopper_height, color="0.6", lw=0.6, ls=":")
        ax.set_xlabel("perimeter (m) from the +x face, counter-clockwise")
        ax.set_title(stage.replace("_", " "), pad=14)
    axes[0, 0].set_ylabel("z (m)")
    if mesh is not None:
        fig.colorbar(mesh, ax=list(axes[0]), label="p_n (Pa)")
    return _save(fig, png_path)


def perimeter_picture(csv_path, png_path, widths, stages=("filling", "early_discharge"),
                      n_heights: int = 3) -> Path:
    """The wall pressure of a rectangular plan's bin along its perimeter at ``n_heights``
    height bins, one panel per recorded stage (the faces' corners marked)."""
    plt = _figure()
    stages = [s for s in stages if np.any(np.asarray(read_csv(csv_path)["stage"]) == s)]
    fig, axes = plt.subplots(1, max(len(stages), 1), figsize=(5.6 * max(len(stages), 1), 4.4),
                             squeeze=False)
    for ax, stage in zip(axes[0], stages):
        table = face_tables(csv_path, stage)
        if "x_plus" not in table:
            continue
        z_bins = table["x_plus"][0]
        pick = np.unique(np.linspace(0, len(z_bins) - 1, n_heights).round().astype(int))
        for c, b in enumerate(pick):
            xs, ps = [], []
            start = 0.0
            for face, forward in PERIMETER:
                width = widths[1] if face.startswith("x") else widths[0]
                if face in table and b < len(table[face][0]):
                    _, u, p = table[face]
                    pos = start + width * (u if forward else 1.0 - u)
                    order = np.argsort(pos)
                    xs.append(pos[order])
                    ps.append(p[b][order])
                start += width
            ax.plot(np.concatenate(xs), np.concatenate(ps), marker="o", ms=2.5, color=f"C{c}",
                    label=f"z = {z_bins[b]:.3f} m")
        start = 0.0
        for face, _ in PERIMETER:
            width = widths[1] if face.startswith("x") else widths[0]
            ax.axvline(start, color="0.6", lw=0.6)
            ax.text(start + 0.5 * width, 1.0, face, transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=7)
            start += width
        ax.set_xlabel("perimeter (m) from the +x face, counter-clockwise")
        ax.set_ylabel("p_n (Pa)")
        ax.set_title(stage.replace("_", " "), pad=14)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, png_path)
