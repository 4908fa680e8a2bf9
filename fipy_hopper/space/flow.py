"""Flow measures of the 3D silo: wall slip per sector (the flow-mode call), the mass-flow index
and the stagnant fraction, the flow field and the flow channel in the vertical plane through
the axis and the outlet, an empty channel (rathole), the bin's lateral stress ratio.  All read a
model's state and never change it.

The sections' rules (:class:`fipy_hopper.diagnostics.FlowModeRule`,
:class:`~fipy_hopper.diagnostics.OutcomeRule`) in 3D:

* **wall slip per sector**: for every loaded contact entry on a hopper stretch (not vertical),
  its slip speed down the meridian ``u_e = -v . t`` over the downward speed ``U_e`` at the
  axis of its section at its node's height (the silo's axis, the eccentric cone's section
  centre ``(c(z), 0)``, or a flat floor's hole's centre ``(e, 0)``: the grid's node nearest
  to it in the plane ``y = 0``), weighted by its
  compressive normal impulse since the previous sample: the sections' wall slip ratio, per
  sector around the circumference (:func:`fipy_hopper.diagnostics.wall_slip` with the sector
  as the label) and per hopper stretch; a sector is ``"mass"`` when every hopper stretch slides
  there (ratio ``>= rule.slip_ratio``), else ``"funnel"``;
* **mass-flow index**: at the heights ``rule.heights`` of the hopper (fractions of the bin
  wall's foot ``z_b``), the mean downward speed of the cells 1 to 2.5 cells from the wall over
  that of the cells within 2 cells of the section's axis; **stagnant fraction**: the share of
  the hopper's material (``alpha > 1/2``) slower than ``rule.stagnant_speed`` times its mean
  downward speed;
* **the plane through the axis and the outlet** (``y = 0``, a node plane of every grid): the
  nodes' velocities and the mean ``alpha`` of their cells, the whole plane (mirrored across
  ``x = 0`` for a quarter); the **flow channel** at each node row is where the downward speed
  is at least ``rule.stagnant_speed`` times the mean downward speed of the material above the
  outlet plane: its extent ``x_left .. x_right`` and its centre (leaning towards the near wall
  with an off-centre outlet);
* **empty channel**: in that plane, from the outlet's centre ``x = e`` outwards both ways, the
  sections' rule (every row from the outlet plane to the top of the material empty at the
  centre; the radius where ``alpha`` first reaches ``rule.full``, the mean of both sides;
  the diameter twice the median).
"""

from __future__ import annotations

import math

import numpy as np

from .. import diagnostics


def _axis_column(model) -> np.ndarray:
    """Per node row, the node column (index into ``x_nodes``) nearest to the section's axis
    ``c(z)`` in the plane ``y = 0``: the axis of the part that holds the outlet (the eccentric
    cone's ``c(z)``; a flat floor's hole, ``c = e`` at every height, so that a floor's contacts
    are measured against the speed in its hole, never against a node of the floor), or where
    that node lies in the solid or within half a cell of it (an insert on the axis) the row's
    node nearest the axis at least half a cell from every wall and insert (the sections' rule,
    :func:`fipy_hopper.diagnostics.axis_columns`); a rectangular plan: nearest the centre of
    its section at that height.  Computed once per model (a function of its geometry)."""
    cached = getattr(model, "_axis_columns", None)
    if cached is not None:
        return cached
    g = model.grid
    if model.boundary.plan == "rectangular":
        c = model.boundary.section_centre(g.z_nodes)[0]
        columns = np.argmin(np.abs(g.x_nodes[None, :] - c[:, None]), axis=1)
    else:
        c = model.boundary.parts[0].centre(g.z_nodes)
        offset = np.abs(g.x_nodes[None, :] - c[:, None])
        centre = np.argmin(offset, axis=1)
        Z, X = np.meshgrid(g.z_nodes, g.x_nodes, indexing="ij")
        clear = model.boundary.distance_normal(X, np.zeros_like(X), Z)[0] >= 0.5 * g.h
        ranked = np.where(clear, offset, np.inf)
        nearest = np.argmin(ranked, axis=1)
        rows = np.arange(len(centre))
        keep = clear[rows, centre] | ~np.isfinite(ranked[rows, nearest])
        columns = np.where(keep, centre, nearest)
    model._axis_columns = columns
    return columns


def _axis_row(model) -> np.ndarray:
    """Per node row, the node row ``j`` of the section's axis: the plane ``y = 0`` (a
    rectangular plan: nearest the centre of its section at that height)."""
    g = model.grid
    if model.boundary.plan == "rectangular":
        c = model.boundary.section_centre(g.z_nodes)[1]
        return np.argmin(np.abs(g.y_nodes[None, :] - c[:, None]), axis=1)
    return np.full(len(g.z_nodes), _plane_row(model))


def _plane_row(model) -> int:
    """The node row ``j`` of the plane ``y = 0`` (a rectangular plan: through the outlet's
    centre, ``y = ey``)."""
    y0 = model.boundary.outlet_centre[1] if model.boundary.plan == "rectangular" else 0.0
    return int(np.argmin(np.abs(model.grid.y_nodes - y0)))


def contact_slip(model, state) -> tuple:
    """``(slip, axis_speed)`` (m/s) of every wall entry: its node's slip speed down the
    meridian of its wall point (NaN for the tube's entries) and the downward speed at its
    section's axis at the node's height."""
    W = model.wall_loads
    k, j, i = W.entry_node.T
    v = state.v[:, k, j, i]
    slip = -(v * W.entry_tangent).sum(axis=0)
    slip = np.where(W.entry_stretch >= 0, slip, np.nan)
    axis = -state.v[2, k, _axis_row(model)[k], _axis_column(model)[k]]
    return slip, axis


def hopper_stretches(patches) -> np.ndarray:
    """The indices of the stretches that are hopper wall (not vertical); on a rectangular
    plan with a hopper its faces, not the floor round a circular outlet in its foot (a dead
    corner that never slides, as a flat floor under a bin does)."""
    names = patches.names
    hopper = any(name.startswith("hopper_") for name in names)
    return np.array([k for k, st3 in enumerate(patches.stretches)
                     if abs(st3.stretch.tangent[0]) > 1e-9
                     and not (hopper and names[k] == "floor")], dtype=np.int64)


def wall_slip_by_sector(model, state, previous_impulse=None,
                        rule=diagnostics.FlowModeRule()) -> np.ndarray:
    """The wall slip ratio of every hopper stretch in every sector, the loads since
    ``previous_impulse`` (``state.wall_impulse`` then; None: since the start):
    ``(n_hopper_stretches, n_sectors)``, NaN where no loaded entry under a moving axis lies
    (module docstring)."""
    W = model.wall_loads
    P = W.patches
    hop = hopper_stretches(P)
    out = np.full((len(hop), P.n_sectors), np.nan)
    if not len(hop):
        return out
    impulse = state.wall_impulse if previous_impulse is None else \
        state.wall_impulse - previous_impulse
    load = -np.einsum("ec,ce->e", impulse, W.entry_normal)
    slip, axis = contact_slip(model, state)
    label_of = np.full(len(P.stretches), -1)
    label_of[hop] = np.arange(len(hop))
    on = W._on
    labels, loads, slips, axes, ss = [], [], [], [], []
    for bins, sectors, _, _, image_stretch in W._bin_sector:
        lab = label_of[image_stretch]
        labels.append(np.where(lab >= 0, lab * P.n_sectors + sectors, -1))
        loads.append(load[on])
        slips.append(slip[on])
        axes.append(axis[on])
        ss.append(W.entry_s[on])
    ratio, _ = diagnostics.wall_slip(np.concatenate(loads), np.concatenate(slips),
                                     np.concatenate(axes), np.concatenate(ss),
                                     np.concatenate(labels), rule)
    full = np.full(len(hop) * P.n_sectors, np.nan)
    full[:len(ratio)] = ratio
    return full.reshape(len(hop), P.n_sectors)


def wall_slip_measures(model, state, previous_impulse=None,
                       rule=diagnostics.FlowModeRule()) -> tuple:
    """The protocol's ``(ratio, fraction, stretch ratios, stretch fractions, profile,
    sectors)`` at one sample (:meth:`fipy_hopper.protocol.HopperModelProtocol.
    wall_slip_measures`): ``sectors`` the ratio per hopper stretch and sector
    (:func:`wall_slip_by_sector`); per hopper stretch of the silo's section
    (:func:`fipy_hopper.diagnostics.hopper_rows` of ``cfg.boundary``, NaN for one the
    material does not reach) its ratio, the smallest over the sectors (the stretch slides
    everywhere around when it reaches the rule's), and its fraction, the share of the measured
    sectors where it slides; ``ratio`` and ``fraction`` those of the stretch of the smallest
    ratio; ``profile`` the loaded hopper entries' ``(s, r, z, slip / axis speed)``."""
    sectors = wall_slip_by_sector(model, state, previous_impulse, rule)
    W = model.wall_loads
    P = W.patches
    hop = hopper_stretches(P)
    bnd = model.cfg.boundary
    rows = diagnostics.hopper_rows(bnd)
    ratios, fractions = np.full(len(rows), np.nan), np.full(len(rows), np.nan)
    by_segment = {}
    for n, k in enumerate(hop):          # a rectangular plan: several faces of a segment
        by_segment.setdefault(P.stretches[k].stretch.segment, []).append(n)
    for i, row in enumerate(rows):
        n = by_segment.get(int(bnd.table.segment[row]))
        values = sectors[n].ravel() if n is not None else np.zeros(0)
        values = values[np.isfinite(values)]
        if values.size:
            ratios[i] = float(values.min())
            fractions[i] = float(np.mean(values >= rule.slip_ratio))
    impulse = state.wall_impulse if previous_impulse is None else \
        state.wall_impulse - previous_impulse
    load = -np.einsum("ec,ce->e", impulse, W.entry_normal)
    slip, axis = contact_slip(model, state)
    on_hopper = np.isin(W.entry_stretch, hop)
    on = np.flatnonzero(on_hopper & (load > 0.0) & (axis > 0.0) & np.isfinite(slip))
    on = on[np.argsort(W.entry_s[on], kind="stable")]
    r_w, z_w = np.zeros(len(on)), np.zeros(len(on))
    for k in np.unique(W.entry_stretch[on]):
        at = W.entry_stretch[on] == k
        r_w[at], z_w[at] = P.stretches[k].stretch.point(W.entry_s[on][at])
    profile = np.column_stack([W.entry_s[on], r_w, z_w, slip[on] / axis[on]])
    if not np.isfinite(ratios).any():
        return math.nan, math.nan, ratios, fractions, profile, sectors
    worst = int(np.nanargmin(ratios))
    return (float(ratios[worst]), float(fractions[worst]), ratios, fractions, profile,
            sectors)


def flow_mode_by_sector(samples, window=None, n_sectors: int = 0,
                        rule=diagnostics.FlowModeRule()) -> tuple:
    """``(ratio (n_sectors,), calls)`` from the samples of :func:`wall_slip_by_sector`
    (matrices ``(n_hopper_stretches, n_sectors)``; empty ones are left out) chosen by
    ``window`` (a bool per sample, default all: the loop's flow-mode window,
    :func:`fipy_hopper.simulation.flow_mode_window`): the median of each stretch's ratio in
    each sector over them, the smallest over the hopper stretches per sector, and the call
    (``"mass"``, ``"funnel"``, ``"unknown"`` unmeasured) per sector."""
    window = [True] * len(samples) if window is None else list(window)
    chosen = [np.asarray(s, float) for s, w in zip(samples, window) if w and np.size(s)]
    ratio = np.full(n_sectors or (chosen[0].shape[1] if chosen else 0), np.nan)
    if chosen:
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            median = np.nanmedian(np.stack(chosen), axis=0)
            if median.shape[0]:
                ratio = np.nanmin(median, axis=0)
    return ratio, [diagnostics.classify_flow_mode(r, rule) for r in ratio]


def cell_down(state) -> np.ndarray:
    """The downward speed of every cell: minus the mean of its eight nodes' ``v_z`` (m/s)."""
    vz = state.v[2]
    return -0.125 * (vz[:-1, :-1, :-1] + vz[:-1, :-1, 1:] + vz[:-1, 1:, :-1] + vz[:-1, 1:, 1:]
                     + vz[1:, :-1, :-1] + vz[1:, :-1, 1:] + vz[1:, 1:, :-1] + vz[1:, 1:, 1:])


def flow_mode_measures(model, state, rule=diagnostics.FlowModeRule()) -> tuple:
    """``(mass-flow index, stagnant fraction)`` of the hopper (module docstring)."""
    g = model.grid
    z_b = model.boundary.bin_foot
    Z, Y, X = np.meshgrid(g.centres(2), g.centres(1), g.centres(0), indexing="ij")
    d, _ = model.boundary.distance_normal(X, Y, Z)
    down = cell_down(state)
    full = (state.alpha > 0.5) & (g.kappa > 0)
    rectangular = model.boundary.plan == "rectangular"
    part = None if rectangular else model.boundary.parts[0]
    ratios = []
    for frac in rule.heights:
        if z_b <= 0:
            break
        row = int(np.argmin(np.abs(g.centres(2) - frac * z_b)))
        if rectangular:
            c, cy = (float(v) for v in model.boundary.section_centre(g.centres(2)[row]))
        else:
            c, cy = float(part.centre(g.centres(2)[row])), 0.0
        near = (d[row] >= g.h) & (d[row] <= 2.5 * g.h) & full[row]
        axis = (np.hypot(X[row] - c, Y[row] - cy) < 2.0 * g.h) & full[row]
        if near.any() and axis.any():
            v_axis = float(np.mean(down[row][axis]))
            if v_axis > 1e-9:
                ratios.append(float(np.mean(down[row][near])) / v_axis)
    index = float(np.mean(ratios)) if ratios else math.nan
    cone = full & (Z > 0) & (Z < z_b)
    if cone.any():
        w = (state.alpha * model.open_volume)[cone]
        mean_down = float(np.sum(down[cone] * w) / np.sum(w))
        slow = down[cone] < rule.stagnant_speed * max(mean_down, 1e-12)
        stagnant = float(np.sum(w[slow]) / np.sum(w))
    else:
        stagnant = math.nan
    return index, stagnant


def plane_field(model, state) -> dict:
    """The vertical plane through the axis and the outlet (``y = 0``) on the grid's nodes,
    the whole plane (a quarter's mirrored across ``x = 0``): ``x`` (m), ``z`` (m), ``vx``,
    ``vz`` (nz + 1, nx') (m/s) and ``alpha`` (the mean of the cells round each node in the
    plane, those beyond the mirror counted as their images)."""
    g = model.grid
    j = _plane_row(model)
    vx, vz = state.v[0, :, j, :], state.v[2, :, j, :]
    a = state.alpha
    if j == 0:                           # the mirror plane y = 0: the cells on its side
        side = a[:, 0, :]
    else:
        side = 0.5 * (a[:, j - 1, :] + a[:, j, :])
    nzc, nxc = side.shape
    alpha = np.zeros((nzc + 1, nxc + 1))
    count = np.zeros_like(alpha)
    for dk in (0, 1):
        for di in (0, 1):
            alpha[dk:dk + nzc, di:di + nxc] += side
            count[dk:dk + nzc, di:di + nxc] += 1.0
    if g.mirror_x:                       # the column x = 0 has its images' cells too
        count[:, 0] *= 2.0
        alpha[:, 0] *= 2.0
    alpha /= count
    x = g.x_nodes
    if g.mirror_x:
        x = np.concatenate([-x[:0:-1], x])
        vx = np.concatenate([-vx[:, :0:-1], vx], axis=1)
        vz = np.concatenate([vz[:, :0:-1], vz], axis=1)
        alpha = np.concatenate([alpha[:, :0:-1], alpha], axis=1)
    return {"x": x, "z": g.z_nodes.copy(), "vx": vx, "vz": vz, "alpha": alpha}


def flow_channel(model, state, rule=diagnostics.FlowModeRule()) -> dict:
    """The flow channel in the plane through the axis and the outlet (module docstring): per
    node row above the outlet plane with material, ``z``, ``x_left``, ``x_right`` and
    ``centre`` (m; NaN in a row where nothing flows), and the ``threshold`` speed (m/s)."""
    f = plane_field(model, state)
    g = model.grid
    down = -cell_down(state)
    above = (g.centres(2) > 0)[:, None, None] & (state.alpha > 0.5) & (g.kappa > 0)
    w = (state.alpha * model.open_volume)[above]
    mean_down = -float(np.sum(down[above] * w) / np.sum(w)) if w.size else 0.0
    threshold = rule.stagnant_speed * max(mean_down, 1e-12)
    rows = np.flatnonzero((f["z"] > 0) & (f["alpha"] > 0.5).any(axis=1))
    out = {"z": f["z"][rows], "x_left": np.full(len(rows), np.nan),
           "x_right": np.full(len(rows), np.nan), "threshold": threshold}
    for n, k in enumerate(rows):
        flowing = (-f["vz"][k] >= threshold) & (f["alpha"][k] > 0.5)
        if flowing.any():
            xs = f["x"][flowing]
            out["x_left"][n], out["x_right"][n] = xs.min(), xs.max()
    out["centre"] = 0.5 * (out["x_left"] + out["x_right"])
    return out


def empty_channel(model, state, rule=diagnostics.OutcomeRule()) -> tuple:
    """``(diameter, height)`` (m) of an empty channel from the outlet up through the material
    in the plane through the axis and the outlet (module docstring); NaN when the material
    closes the outlet's centre line (or there is none)."""
    f = plane_field(model, state)
    e = model.boundary.outlet_centre[0]
    above = f["z"] >= 0.0
    full = f["alpha"] > rule.full
    rows = np.flatnonzero(above & full.any(axis=1))
    if not len(rows):
        return math.nan, math.nan
    k0, top = int(np.flatnonzero(above)[0]), int(rows[-1])
    c = int(np.argmin(np.abs(f["x"] - e)))
    band = full[k0:top + 1]
    if band[:, c].any():
        return math.nan, math.nan
    radii = []
    for row in range(band.shape[0]):
        sides = []
        for step in (1, -1):
            i = c
            while 0 <= i + step < band.shape[1] and not band[row, i + step]:
                i += step
            if 0 <= i + step < band.shape[1]:
                a0, a1 = f["alpha"][k0 + row, i], f["alpha"][k0 + row, i + step]
                x0, x1 = f["x"][i], f["x"][i + step]
                x = x0 + (rule.full - a0) / (a1 - a0) * (x1 - x0)
                sides.append(abs(x - e))
        if sides:
            radii.append(float(np.mean(sides)))
    if not radii:
        return math.nan, math.nan
    return 2.0 * float(np.median(radii)), float(f["z"][top])


def bin_lateral_stress_ratio(model, state) -> float:
    """The bin's lateral stress ratio ``K = sum(w sigma_rr) / sum(w sigma_zz)`` (``sigma_rr``
    the radial normal stress about the silo's axis, ``w = alpha kappa V``) over the full cells
    (``alpha >= 0.99``) of the bin from a quarter of its diameter above the bin wall's foot to a
    quarter below the material's surface: the sections' measure
    (:func:`fipy_hopper.diagnostics.bin_lateral_stress_ratio`); NaN when the band is empty or
    not in compression.  A rectangular plan: ``sigma_rr`` is the mean horizontal normal stress
    ``(sigma_xx + sigma_yy) / 2`` and the band from a quarter of the bin's shorter side
    above its foot to as far below the surface."""
    g = model.grid
    rectangular = model.boundary.plan == "rectangular"
    z_b = model.boundary.bin_foot
    quarter = (0.5 * min(model.boundary.half_extent) if rectangular
               else 0.5 * model.boundary.radius)
    Z, Y, X = np.meshgrid(g.centres(2), g.centres(1), g.centres(0), indexing="ij")
    in_bin = (Z > z_b) & (g.kappa > 0)
    filled = in_bin & (state.alpha >= 0.5)
    if not filled.any():
        return math.nan
    surface = float(Z[filled].max())
    band = in_bin & (state.alpha >= 0.99) & (Z >= z_b + quarter) & (Z <= surface - quarter)
    if not band.any():
        return math.nan
    s = state.sigma[band]
    if rectangular:             # the mean horizontal normal stress: (s_xx + s_yy) / 2
        s_rr = 0.5 * (s[:, 0] + s[:, 1])
    else:
        rho = np.hypot(X[band], Y[band])
        safe = np.where(rho > 0, rho, 1.0)
        nx, ny = np.where(rho > 0, X[band] / safe, 1.0), np.where(rho > 0, Y[band] / safe, 0.0)
        s_rr = nx * nx * s[:, 0] + ny * ny * s[:, 1] + 2.0 * nx * ny * s[:, 5]
    w = (state.alpha * model.open_volume)[band]
    vertical = float(np.sum(w * s[:, 2]))
    if not vertical < 0.0:
        return math.nan
    return float(np.sum(w * s_rr)) / vertical
