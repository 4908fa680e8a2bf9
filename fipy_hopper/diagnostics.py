"""What is measured from a run (docs/physics_and_numerics.md, section 8).  Diagnostics read the
state, never change it.

- discharge rate ``W`` from the mass booked through the outlet faces (the same face values the
  transport uses, so ``M(t) + discharged(t) = M(0)`` to round-off), and its steady value;
- the ``mass``/``funnel`` call from the slip of the material along the hopper wall (the wall
  slip ratio and fraction), beside the mass-flow index and stagnant fraction of the cone;
  once the flow has stopped, ``no_flow`` (an arch) or ``rathole`` (:class:`OutcomeRule`);
- the normal wall pressure ``p_n = -n.sigma.n`` and shear ``tau = t.sigma.n`` along the wall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np



# ---------------------------------------------------------------- discharge rate
def steady_rate(t, mass_in_hopper, discharge_rate, t_open=0.0, upper=0.9, lower=0.2,
                settle_time=0.1):
    """Steady discharge rate (kg/s) and the spread of ``W`` over the plateau.

    Plateau rule: the samples taken at least ``settle_time`` s after the outlet opened while the
    hopper still held between ``lower`` and ``upper`` of its initial mass (the start transient
    and the final emptying of the cone are excluded).  The steady rate is the median of ``W``
    over the plateau, the spread its interquartile range relative to the median.  When no sample
    qualifies (a short run), the samples of the last 75% of the run are used.  Samples without
    a rate (NaN: the last one when it covers less than half an interval) are left out.
    Returns ``(rate, spread, n_samples)``; ``rate`` is NaN when there is nothing to measure.
    """
    t = np.asarray(t, float)
    m = np.asarray(mass_in_hopper, float)
    w = np.asarray(discharge_rate, float)
    if len(t) == 0:
        return math.nan, math.nan, 0
    m0 = m[0] if len(m) else 0.0
    sel = (t >= t_open + settle_time) & (m <= upper * m0) & (m >= lower * m0) & np.isfinite(w)
    if sel.sum() < 3:
        sel = (t >= t_open + 0.25 * (t[-1] - t_open)) & np.isfinite(w)
    if sel.sum() == 0:
        return math.nan, math.nan, 0
    ws = w[sel]
    med = float(np.median(ws))
    q75, q25 = np.percentile(ws, [75, 25])
    spread = float((q75 - q25) / med) if med > 0 else math.nan
    return med, spread, int(sel.sum())


def fit_power_law(x, y):
    """Least-squares fit of ``y = a x^n`` in log space; returns ``(a, n)``."""
    n, log_a = np.polyfit(np.log(np.asarray(x, float)), np.log(np.asarray(y, float)), 1)
    return float(math.exp(log_a)), float(n)


# ---------------------------------------------------------------- flow mode
@dataclass(frozen=True)
class FlowModeRule:
    """Mass/funnel classification (stated rule): mass flow is flow that slides along the
    whole hopper wall (Jenike), so the call is read from the wall contact.

    For every loaded contact of a stretch of hopper wall (a contact entry whose normal impulse
    since the previous sample is compressive, ``N_e > 0``), the slip ratio is
    ``u_e / U_e``: its slip speed down the wall (the tangential speed of the node after the
    step's Coulomb contact, m/s) over the downward speed at the axis at the same height (m/s).
    The stretch's **wall slip ratio** is the load-weighted mean

        S = sum_e N_e (u_e / U_e) / sum_e N_e,

    i.e. the wall's friction power ``sum mu N_e u_e`` over what it would be if the material
    slid along the wall at the axis speed.  Its **wall slip fraction** is the share of its
    loaded contact length (each contact standing for the wall between the midpoints to its
    neighbours) with ``u_e >= slip_ratio U_e``.  A stretch's S over a run is the median of its
    samples' (:func:`stretch_calls`), its call mass where ``S >= slip_ratio``, funnel below,
    unknown without a sample; the run's call is funnel when any counted stretch says funnel,
    mass when at least one says mass, else unknown (:func:`overall_call`); ``slip_ratio`` is
    the rule's one threshold (docs/physics_and_numerics.md, section 8).

    Reported beside it (not used for the call): the mass-flow index, the mean ratio of the
    downward speed of the cells 1 to 2.5 cells from the wall to the speed at the axis at the
    heights ``z/h_c`` in ``heights``; and the stagnant fraction, the share of the cone's
    material (``alpha > 1/2``) moving slower than ``stagnant_speed`` times its mean downward
    speed (the stagnant zone's extent from the velocity field).
    """

    slip_ratio: float = 0.2
    heights: tuple = (0.3, 0.5, 0.7)
    stagnant_speed: float = 0.05


def hopper_rows(boundary) -> np.ndarray:
    """The rows of ``boundary.table`` that are hopper wall: the segments of the walls
    (``wall``, ``left_wall``) that are not vertical (a hopper's slopes, a floor or ledge),
    below the top of the wall."""
    tab = boundary.table
    kind = np.array([boundary.chains[c].kind for c in tab.chain])
    vertical = np.abs(tab.normal[:, 1]) < 1e-9
    return np.flatnonzero((kind == "wall") & ~vertical)


def hopper_stretches(segment, rows) -> np.ndarray:
    """Labels ``0, 1, ...`` of the stretches of hopper wall that the contact entries belong
    to (their ``segment``, a table row, is the ``k``-th of the hopper ``rows``: label ``k``),
    ``-1`` for the other entries (other walls, convex corners)."""
    segment = np.asarray(segment)
    lookup = np.full(max(int(np.max(rows, initial=-1)), int(np.max(segment, initial=-1))) + 2,
                     -1)
    lookup[np.asarray(rows, dtype=int)] = np.arange(len(rows))
    return np.where(segment >= 0, lookup[segment], -1)


def wall_slip(load, slip, axis_speed, s, stretch, rule: FlowModeRule = FlowModeRule()):
    """``(ratio, fraction)`` arrays, one entry per stretch label ``0..max(stretch)``: the wall
    slip ratio ``S`` and the wall slip fraction of :class:`FlowModeRule` from every contact
    entry's normal load ``load`` (its normal impulse since the previous sample, > 0 when
    pressed, any unit), slip speed ``slip`` down the wall and the axis's downward speed
    ``axis_speed`` at its height (m/s), arc length ``s`` (m) and stretch label (-1: not hopper
    wall).  A stretch with no loaded contact under a moving axis gives NaN."""
    load, slip, axis_speed, s = (np.asarray(a, float) for a in (load, slip, axis_speed, s))
    stretch = np.asarray(stretch)
    n = int(stretch.max()) + 1 if stretch.size else 0
    ratio, fraction = np.full(n, math.nan), np.full(n, math.nan)
    for k in range(n):
        on = np.flatnonzero((stretch == k) & (load > 0.0) & (axis_speed > 0.0)
                            & np.isfinite(slip))
        if on.size == 0:
            continue
        on = on[np.argsort(s[on], kind="stable")]
        r = slip[on] / axis_speed[on]
        w = load[on]
        ratio[k] = float(np.sum(w * r) / np.sum(w))
        x = s[on]
        edges = np.concatenate([x[:1], 0.5 * (x[1:] + x[:-1]), x[-1:]])
        length = np.diff(edges)
        total = float(np.sum(length))
        sliding = r >= rule.slip_ratio
        fraction[k] = (float(np.sum(length[sliding]) / total) if total > 0
                       else float(np.mean(sliding)))
    return ratio, fraction


def entry_slip(v, normals, side=1.0):
    """Slip speed down the wall (m/s) of contact entries with velocities ``v`` (n, 2) and
    normals into the wall ``normals`` (n, 2): ``-v . t`` with ``t = side (-n_z, n_r)`` the
    tangent pointing up the wall (``side`` +1 on a wall with the solid to its right, -1 on a
    left wall: one value or one per entry)."""
    v, normals = np.asarray(v, float), np.asarray(normals, float)
    return -side * (-v[:, 0] * normals[:, 1] + v[:, 1] * normals[:, 0])


def normal_load(impulse, normals):
    """The compressive normal impulse of each contact entry, ``-I . n`` (positive when the
    wall pushes the material out of it), from impulses ``impulse`` (n, 2)."""
    return -np.einsum("ec,ec->e", np.asarray(impulse, float), np.asarray(normals, float))


def wall_slip_measures(model, state, previous_impulse=None,
                       rule: FlowModeRule = FlowModeRule()):
    """``(ratio, fraction, stretch ratios, stretch fractions, profile)`` of
    :class:`FlowModeRule` from a model's wall contact at one sample: the smallest wall slip
    ratio over the hopper stretches, the slip fraction of that stretch, every stretch's ratio
    and slip fraction (one per :func:`hopper_rows`, NaN where a stretch has no loaded
    contact), and the loaded hopper contacts as rows ``(s, r, z, u/U)`` (their wall point, m,
    and slip ratio; (0, 4) when none).  The loads are ``state.wall_impulse`` less
    ``previous_impulse`` (its value at the previous sample; ``None``: since the start), the
    slip and axis speeds the model's :meth:`contact_slip` (read from the state, which is left
    as it is)."""
    s, normals, segment = model.wall_entries()
    impulse = state.wall_impulse if previous_impulse is None else (
        state.wall_impulse - previous_impulse)
    slip, axis_speed = model.contact_slip(state)
    bnd = model.cfg.boundary
    rows = hopper_rows(bnd)
    stretch = hopper_stretches(segment, rows)
    load = normal_load(impulse, normals)
    measured = wall_slip(load, slip, axis_speed, s, stretch, rule)
    ratios, fractions = (np.concatenate([m, np.full(len(rows) - len(m), math.nan)])
                         for m in measured)
    on = np.flatnonzero((stretch >= 0) & (load > 0.0) & (axis_speed > 0.0) & np.isfinite(slip))
    on = on[np.argsort(s[on], kind="stable")]
    chain = bnd.table.chain[np.maximum(segment[on], 0)]
    r_w, z_w = np.zeros(len(on)), np.zeros(len(on))
    for c in np.unique(chain):
        r_w[chain == c], z_w[chain == c] = bnd.wall_point(int(c), s[on][chain == c])[:2]
    profile = np.column_stack([s[on], r_w, z_w, slip[on] / axis_speed[on]])
    if not np.isfinite(ratios).any():
        return math.nan, math.nan, ratios, fractions, profile
    worst = int(np.nanargmin(ratios))
    return float(ratios[worst]), float(fractions[worst]), ratios, fractions, profile


def axis_columns(grid, boundary, centre_column: int) -> np.ndarray:
    """Per node row of the grid, the node column whose downward speed is the flow-mode rule's
    axis speed at that height: the centreline's (``centre_column``), or where that node lies
    in the solid or within half a cell of it (an insert on the axis), the nearest node column
    of the row to the centreline at least half a cell from every wall and insert: the
    material's nearest column beside the insert.  A row with no such node keeps the
    centreline's (its speed, zero, gives no ratio)."""
    h = grid.h
    offset = np.abs(grid.r_nodes - boundary.section.centreline)
    X, Z = np.meshgrid(grid.r_nodes, grid.z_nodes)
    clear = boundary.signed_distance(X, Z) >= 0.5 * h
    ranked = np.where(clear, offset[None, :], np.inf)
    nearest = np.argmin(ranked, axis=1)
    keep = clear[:, centre_column] | ~np.isfinite(ranked[np.arange(len(nearest)), nearest])
    return np.where(keep, centre_column, nearest).astype(np.int64)


def flow_mode_measures(model, state, rule: FlowModeRule = FlowModeRule()):
    """Mass-flow index and stagnant fraction of the hopper (the wall below its transition,
    :meth:`~fipy_hopper.boundary.Boundary.transition_height`) from the current velocity
    field.  The index's axis speed is that of the full cells within two cells of the row's
    open cell nearest to the centreline (the axis, or beside an insert on it the material's
    nearest column)."""
    g = model.grid
    bnd = model.cfg.boundary
    z_t = bnd.transition_height("wall")
    vz_cell = 0.25 * (state.v[1, :-1, :-1] + state.v[1, :-1, 1:] + state.v[1, 1:, :-1]
                      + state.v[1, 1:, 1:])
    down = -vz_cell
    R, Z = np.meshgrid(g.r_cells, g.z_cells)
    d = bnd.signed_distance(R, Z)
    offset = np.abs(g.r_cells - bnd.section.centreline)
    full = state.alpha > 0.5
    ratios = []
    for frac in rule.heights:
        row = int(np.argmin(np.abs(g.z_cells - frac * z_t)))
        open_ = g.kappa[row] > 0
        if not open_.any():
            continue
        centre = offset - offset[open_].min() < 1.5 * g.h     # two columns from the axis
        near_wall = (d[row] >= 1.0 * g.h) & (d[row] <= 2.5 * g.h) & full[row]
        axis = centre & open_ & full[row]
        if near_wall.any() and axis.any():
            v_axis = float(np.mean(down[row, axis]))
            if v_axis > 1e-9:
                ratios.append(float(np.mean(down[row, near_wall])) / v_axis)
    index = float(np.mean(ratios)) if ratios else math.nan
    cone = full & (Z > 0) & (Z < z_t) & (g.kappa > 0)
    if cone.any():
        weights = (state.alpha * model.open_volume)[cone]
        mean_down = float(np.sum(down[cone] * weights) / np.sum(weights))
        slow = down[cone] < rule.stagnant_speed * max(mean_down, 1e-12)
        stagnant = float(np.sum(weights[slow]) / np.sum(weights))
    else:
        stagnant = math.nan
    return index, stagnant


def bin_lateral_stress_ratio(model, state) -> float:
    """The bin's lateral stress ratio ``K = sum(w sigma_rr) / sum(w sigma_zz)`` (-), ``w`` the
    material volume ``alpha kappa V``, over the full cells (``alpha >= 0.99``) of the bin (above
    the wall's transition, :meth:`~fipy_hopper.boundary.Boundary.transition`) from a quarter
    of its width above the transition to a quarter below the material's surface (the highest
    cell of the bin with ``alpha >= 1/2``): about ``nu / (1 - nu)`` in a bin filled at rest,
    larger where discharge switches the stress state.  NaN without a bin, when the band holds
    no cell (a bin emptied below it) or no compression."""
    g, bnd = model.grid, model.cfg.boundary
    if bnd.transition("wall") is None:
        return math.nan
    z_t = bnd.transition_height("wall")
    quarter = 0.25 * bnd.span_at(z_t)
    Z = np.broadcast_to(g.z_cells[:, None], state.alpha.shape)
    in_bin = (Z > z_t) & (g.kappa > 0)
    filled = in_bin & (state.alpha >= 0.5)
    if not filled.any():
        return math.nan
    surface = float(Z[filled].max())
    band = in_bin & (state.alpha >= 0.99) & (Z >= z_t + quarter) & (Z <= surface - quarter)
    weights = (state.alpha * model.open_volume)[band]
    vertical = float(np.sum(weights * state.sigma[..., 1][band]))
    if not vertical < 0.0:
        return math.nan
    return float(np.sum(weights * state.sigma[..., 0][band])) / vertical


def counted_stretches(cfg) -> np.ndarray:
    """Which stretches of hopper wall (:func:`hopper_rows`) enter the overall calls
    (:func:`overall_call`): those at least one cell long (the grid resolves them: a sliver
    shorter than a cell neither carries a contact of its own nor describes the hopper) whose
    bottom lies below the fill level (the material fills them)."""
    tab, bnd = cfg.boundary.table, cfg.boundary
    rows = hopper_rows(bnd)
    length = np.hypot(*(tab.b[rows] - tab.a[rows]).T)
    bottom = np.minimum(tab.a[rows, 1], tab.b[rows, 1])
    return (length >= cfg.numerics.cell_size) & (bottom < bnd.fill_level)


def overall_call(calls) -> str:
    """The overall call from the calls of the stretches that count (:func:`counted_stretches`):
    ``"funnel"`` when any says funnel (the material rests against part of the hopper wall),
    else ``"mass"`` when at least one says mass (it slides along every measured stretch), else
    ``"unknown"`` (no stretch measured: a run too short, or no hopper wall in the material)."""
    calls = list(calls)
    if "funnel" in calls:
        return "funnel"
    return "mass" if "mass" in calls else "unknown"


def stretch_calls(cfg, samples, fractions=(), rule: FlowModeRule = FlowModeRule()) -> list:
    """The call per stretch of hopper wall (:func:`hopper_rows`): a dict of its ``wall``,
    ``segment``, ``z_m`` (its bottom and top), ``length_m``, ``half_angle_deg`` (its slope
    from the vertical), ``wall_friction_deg``, ``counted`` (whether it enters the overall
    calls, :func:`counted_stretches`), ``samples`` (the samples in which it was measured),
    ``slip_ratio`` and ``slip_fraction`` (the medians of those samples' ratios and slip
    fractions of that stretch: ``samples``, ``fractions``, one row per sample), the ``call``
    (:func:`classify_flow_mode`: ``"mass"`` where it slides, ``slip_ratio >=
    rule.slip_ratio``, ``"funnel"`` where it does not: a stagnant zone on it, ``"unknown"``
    without a sample), and Jenike's critical half-angle for its wall friction with the call it
    gives for that slope (``jenike_critical_half_angle_deg``, ``jenike_call``; conical or
    plane by the section; ``"unknown"`` outside the range of Jenike's fit)."""
    from . import theory

    bnd, mat = cfg.boundary, cfg.material
    tab = bnd.table
    counted = counted_stretches(cfg)

    def table(values):
        values = np.asarray(values, float) if len(values) else np.zeros((0, 0))
        return values if values.ndim == 2 else np.zeros((0, 0))

    ratios, shares = table(samples), table(fractions)
    out = []
    for k, row in enumerate(hopper_rows(bnd)):
        a, b = tab.a[row], tab.b[row]
        angle = float(np.degrees(np.arctan2(abs(b[0] - a[0]), b[1] - a[1])))
        values = ratios[:, k] if ratios.shape[1] > k else np.zeros(0)
        measured = np.isfinite(values)
        slip = float(np.median(values[measured])) if measured.any() else math.nan
        share = shares[:, k][measured] if shares.shape[1] > k else np.zeros(0)
        share = share[np.isfinite(share)]
        phi_w = float(tab.friction_deg[row])
        geometry = "conical" if bnd.section.axisymmetric else "plane"
        critical = (theory.jenike_critical_half_angle if geometry == "conical"
                    else theory.jenike_critical_half_angle_plane)
        try:
            theta_c = float(critical(mat.friction_angle_deg, phi_w))
            jenike = str(theory.jenike_flow_mode(angle, mat.friction_angle_deg, phi_w,
                                                 geometry=geometry))
        except ValueError:
            theta_c, jenike = math.nan, "unknown"
        out.append({"wall": bnd.chains[tab.chain[row]].name, "segment": int(tab.segment[row]),
                    "z_m": [float(a[1]), float(b[1])],
                    "length_m": float(np.hypot(*(b - a))), "half_angle_deg": angle,
                    "wall_friction_deg": phi_w, "counted": bool(counted[k]),
                    "samples": int(measured.sum()), "slip_ratio": slip,
                    "slip_fraction": float(np.median(share)) if share.size else math.nan,
                    "call": classify_flow_mode(slip, rule),
                    "jenike_critical_half_angle_deg": theta_c, "jenike_call": jenike})
    return out


def flow_call(stretches) -> dict:
    """The overall flow-mode numbers of the per-stretch calls (:func:`stretch_calls`), by the
    documented rule (:func:`overall_call` over the stretches that count): ``flow_mode``,
    ``wall_slip_ratio`` and ``wall_slip_fraction`` (the measured counted stretch with the
    smallest slip ratio: the call is mass exactly when it reaches the threshold) and
    ``jenike_flow_mode`` (the same rule over the stretches' Jenike calls)."""
    counted = [st for st in stretches if st["counted"]]
    measured = [st for st in counted if math.isfinite(st["slip_ratio"])]
    worst = min(measured, key=lambda st: st["slip_ratio"]) if measured else None
    return {"flow_mode": overall_call(st["call"] for st in counted),
            "wall_slip_ratio": worst["slip_ratio"] if worst else math.nan,
            "wall_slip_fraction": worst["slip_fraction"] if worst else math.nan,
            "jenike_flow_mode": overall_call(st["jenike_call"] for st in counted)}


def classify_flow_mode(slip_ratio, rule: FlowModeRule = FlowModeRule()) -> str:
    """``"mass"`` or ``"funnel"`` by :class:`FlowModeRule` from a stretch's wall slip ratio;
    ``"unknown"`` when it was not measured (NaN)."""
    if not np.isfinite(slip_ratio):
        return "unknown"
    return "mass" if slip_ratio >= rule.slip_ratio else "funnel"


@dataclass(frozen=True)
class OutcomeRule:
    """How a discharge whose flow has stopped is named (stated rule).

    Once the flow has stopped (the ``at_rest`` rule of :mod:`fipy_hopper.simulation`), the
    stopped state is searched for an empty channel: the cells of the first column (at the axis)
    hold less than ``full`` material in every row from the outlet plane up to the top of the
    material (the highest row with a cell above ``full``).  Its radius in each of those rows
    is where ``alpha`` first reaches ``full`` going out from the axis (linear between cell
    centres); the channel's diameter is twice their median.

    - ``"rathole"``: such a channel whose height (outlet plane to the top of the material) is
      at least its diameter, with at least ``rathole_left`` of the initial mass standing
      around it: walls steeper than the 45 deg of a channel as high as it is wide (a crater at
      the angle of repose is wider).  How much stands depends on how wide the bin is around
      the channel, so this bound is low: it only keeps a film left on the walls from counting;
    - ``"no_flow"``: otherwise, with at least ``most_left`` of the initial mass left (an arch
      over the outlet, or over the hollow that the material which fell out left below it).

    Otherwise the mass/funnel call of the flowing discharge (a heel on a shallow cone, or a
    cohesive heel around a crater).
    """

    full: float = 0.5
    most_left: float = 0.5
    rathole_left: float = 0.1


def centreline(model) -> float:
    """The ``x`` (m) of a model's centreline: the axis, or the middle of a full section's
    outlet (0 for a model that names no configuration)."""
    cfg = getattr(model, "cfg", None)
    return cfg.boundary.section.centreline if cfg is not None else 0.0


def empty_channel(model, state, rule: OutcomeRule = OutcomeRule()):
    """``(diameter, height)`` (m) of the empty channel of :class:`OutcomeRule` from the outlet
    through the material to its top, measured from the section's centreline outwards (in a
    full section on its right side); ``(nan, nan)`` where the material closes the centreline
    (or there is none).  In each row the channel's first cell is the first open cell from
    the centreline: beside an insert on the axis, the material's column next to the insert
    (the insert itself is solid, not an empty channel)."""
    g = model.grid
    centre = centreline(model)
    c0 = int(np.searchsorted(g.r_cells, centre))   # the first cell column past the centreline
    full = state.alpha[:, c0:] > rule.full
    above = g.z_cells > 0.0
    rows = np.flatnonzero(above & full.any(axis=1))
    if len(rows) == 0:
        return math.nan, math.nan
    j0, top = int(np.flatnonzero(above)[0]), int(rows[-1])
    band = full[j0:top + 1]
    open_ = np.asarray(g.kappa)[j0:top + 1, c0:] > 0.0
    first = np.argmax(open_, axis=1)                   # first open cell from the centreline
    if band[np.arange(len(band)), first].any():
        return math.nan, math.nan
    held = band.any(axis=1)
    k = np.argmax(band, axis=1)[held]                  # first full cell from the centreline
    a = state.alpha[j0:top + 1, c0:][held]
    rows_ = np.arange(len(k))
    a0, a1 = a[rows_, k - 1], a[rows_, k]
    r0, r1 = g.r_cells[c0 + k - 1] - centre, g.r_cells[c0 + k] - centre
    radius = r0 + (rule.full - a0) / (a1 - a0) * (r1 - r0)
    return 2.0 * float(np.median(radius)), float(g.z_nodes[top + 1])


def material_speed(model, state, full: float = 0.5) -> float:
    """The rms speed (m/s) of the material in the hopper (above the outlet plane): on the
    Eulerian grid over the cells holding more than ``full`` material (the mean of their four
    nodes' velocities), weighted by their material volume ``alpha kappa V``; on the
    Lagrangian mesh over the active elements (their nodes' mean), by volume.  A node of
    almost no mass (a trace at a free surface, which gravity alone moves) does not count, as
    it would in the kinetic energy.  0 where there is no material."""
    g = getattr(model, "grid", None)
    if g is None:                                       # the Lagrangian mesh
        conn = model.mesh.conn
        v = state.v[conn].mean(axis=1)
        sel = state.active & (state.x[conn, 1].mean(axis=1) > 0.0)
        w = model.volume0[sel]
        speed2 = np.sum(v[sel] ** 2, axis=1)
    else:
        v = state.v
        vc = 0.25 * (v[:, :-1, :-1] + v[:, :-1, 1:] + v[:, 1:, :-1] + v[:, 1:, 1:])
        sel = (state.alpha > full) & (g.z_cells > 0.0)[:, None]
        w = (state.alpha * model.open_volume)[sel]
        speed2 = (vc[0] ** 2 + vc[1] ** 2)[sel]
    return float(math.sqrt(np.sum(w * speed2) / np.sum(w))) if np.sum(w) > 0 else 0.0


def heap_angle(model, state, full: float = 0.5) -> float:
    """The angle (deg from the horizontal) of the free surface of the material left in the
    hopper once the flow has stopped: in each open cell column above the outlet plane the
    surface is where ``alpha`` falls below ``full`` going up from the highest cell holding
    more (linear between cell centres; a column whose next cell up is closed, under an
    insert, has no free surface there), and the angle is that of the least-squares line
    through the surface heights against the distance from the centreline, over the columns
    holding material, the column at the wall left out (its cell is cut).  Set it against the
    angle of repose (for this Mohr-Coulomb material about its friction angle).  NaN with
    fewer than three such columns, or on a model without a grid (the Lagrangian mode)."""
    g = getattr(model, "grid", None)
    if g is None:
        return math.nan
    alpha = np.asarray(state.alpha, float)
    kappa = np.asarray(g.kappa, float)
    rows = np.flatnonzero(g.z_cells > 0.0)
    held = (alpha > full) & (g.z_cells > 0.0)[:, None]
    x, z = [], []
    for i in range(alpha.shape[1]):
        top = np.flatnonzero(held[:, i])
        if not len(top):
            continue
        j = int(top[-1])
        if j + 1 >= alpha.shape[0] or kappa[j + 1, i] <= 0.0 or j < rows[0]:
            continue
        if kappa[j, i] < 1.0 and (i + 1 == alpha.shape[1] or kappa[j, i + 1] <= 0.0):
            continue                                  # the cut cell at the wall
        frac = (alpha[j, i] - full) / max(alpha[j, i] - alpha[j + 1, i], 1e-12)
        x.append(abs(g.r_cells[i] - model.cfg.boundary.section.centreline))
        z.append(g.z_cells[j] + min(frac, 1.0) * g.h)
    if len(x) < 3:
        return math.nan
    slope = np.polyfit(np.asarray(x), np.asarray(z), 1)[0]
    return float(np.degrees(np.arctan(abs(slope))))


def classify_outcome(mode: str, stopped: bool, left_fraction: float, channel_diameter: float,
                     channel_height: float, rule: OutcomeRule = OutcomeRule()) -> str:
    """``"rathole"``, ``"no_flow"`` or ``mode`` (the mass/funnel call) by
    :class:`OutcomeRule`, for a discharge whose flow has ``stopped`` (else ``mode``)."""
    if not stopped:
        return mode
    if (np.isfinite(channel_diameter) and channel_height >= channel_diameter
            and left_fraction >= rule.rathole_left):
        return "rathole"
    return "no_flow" if left_fraction >= rule.most_left else mode


# ---------------------------------------------------------------- wall bins
#: the wall traction's spline has knots at least this many cells apart (and at least a bin
#: width): its support, four knot spans, then averages the pattern in which the cut cells
#: share the wall's reaction among the nodes (docs/physics_and_numerics.md, section 8)
KNOT_CELLS = 4.0

def wall_stretches(cfg) -> list:
    """The straight stretches of wall the material can load
    (:class:`~fipy_hopper.boundary.Segment` s, one per segment of the boundary's walls
    and inserts; the free-fall tubes left out): a wall's segments up to the fill level (the
    one through it cut there), every segment of every insert.  Their arc length ``s_start`` is
    the boundary's position along all the chains (:meth:`Boundary.position`), their
    ``index`` the chain's segment index and ``chain`` the chain's name."""
    bnd = cfg.boundary
    out = []
    for ci, chain in enumerate(bnd.chains):
        if chain.kind == "tube":
            continue
        offset = bnd.chain_offset(ci)
        for k, seg in enumerate(chain.segments):
            a, b = np.asarray(seg.a, float), np.asarray(seg.b, float)
            if chain.kind == "wall":
                if a[1] >= bnd.fill_level and k > 0:
                    break
                if b[1] > bnd.fill_level > a[1]:
                    b = a + (b - a) * (bnd.fill_level - a[1]) / (b[1] - a[1])
            out.append(replace(seg, a=tuple(a), b=tuple(b), s_start=offset + seg.s_start,
                               axisymmetric=bnd.section.axisymmetric))
    return out


@dataclass(frozen=True)
class WallBins:
    """The bins along the walls that every wall-load profile is reported on: each straight
    stretch of wall (:func:`wall_stretches`) divided into equal bins of about the
    configuration's ``wall_bin_width_m``, chain after chain and along each from its lowest
    point, so no bin straddles a corner.  Per bin: ``wall`` the name of its chain, ``s`` the
    arc length of its centre along the chain (m), ``position`` that along all the chains
    (:meth:`Boundary.position`), ``(r, z)`` its centre, ``normal`` (nb, 2) the wall's normal
    into the wall, ``tangent`` (nb, 2) the tangent along ``s`` (up a wall), ``area`` its wall
    area per radian (per metre of a plane wall), ``stretch`` the index of its stretch,
    ``lo``/``hi`` its bounds in ``position``."""

    wall: np.ndarray
    s: np.ndarray
    position: np.ndarray
    r: np.ndarray
    z: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    area: np.ndarray
    stretch: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    stretches: tuple

    @classmethod
    def of(cls, stretches, width: float, offsets: dict) -> "WallBins":
        """Bins of about ``width`` m on ``stretches``; ``offsets``: each chain's position
        (m) along all the chains, by name."""
        from .wall_traction import bin_edges
        parts = []
        for k, st in enumerate(stretches):
            edges = bin_edges(st, width)
            centres = 0.5 * (edges[1:] + edges[:-1])
            r, z = st.point(centres)
            n = len(centres)
            parts.append((np.full(n, st.chain, dtype=object), centres - offsets[st.chain],
                          centres, r, z, np.tile(st.normal, (n, 1)),
                          np.tile(st.tangent, (n, 1)), st.area(edges[:-1], edges[1:]),
                          np.full(n, k), edges[:-1], edges[1:]))
        cols = [np.concatenate(c) for c in zip(*parts)]
        return cls(*cols, stretches=tuple(stretches))

    def index(self, position) -> np.ndarray:
        """The bin of each ``position`` along the chains (m): the bin that holds it, or the
        nearest bin of its chain (a point above a wall's fill level: its top bin)."""
        position = np.asarray(position, float)
        return np.clip(np.searchsorted(self.lo, position, side="right") - 1, 0,
                       len(self.lo) - 1)

    @property
    def width(self) -> np.ndarray:
        return self.hi - self.lo


def wall_bins(cfg, cell_size: float | None = None) -> WallBins:
    """The :class:`WallBins` of a configuration (on a grid of ``cell_size``, default its
    own)."""
    bnd = cfg.boundary
    width = cfg.wall_bin_width_at(cfg.numerics.cell_size if cell_size is None else cell_size)
    offsets = {c.name: bnd.chain_offset(i) for i, c in enumerate(bnd.chains)}
    return WallBins.of(wall_stretches(cfg), width, offsets)


# ---------------------------------------------------------------- wall pressure
class WallSampler:
    """Normal pressure and shear on the wall from the stresses next to it, on the
    :class:`WallBins`.

    The material next to the wall (:meth:`HopperModelProtocol.wall_stress_points
    <fipy_hopper.protocol.HopperModelProtocol.wall_stress_points>`: on the Eulerian grid the
    cells whose centres lie between ``0.5`` and ``2.5`` cells from the wall, inside the
    material, off the cut cells) is assigned to the bin of the wall point nearest to it; each
    bin averages its stress weighted by volume (``alpha kappa V``), and ``p_n = -n.sigma.n``,
    ``tau = t.sigma.n`` with the wall normal ``n`` (into the wall) and the tangent ``t``
    pointing up the wall.  Pressures are positive in compression (Pa).
    """

    #: a section's bins have no angle around a circumference (3D: the patches' sectors)
    theta = None

    def __init__(self, model, bins: "WallBins | None" = None):
        self.model = model
        self.bins = bins if bins is not None else wall_bins(model.cfg)
        self.centres, self.r, self.z = self.bins.s, self.bins.r, self.bins.z
        self.nr, self.nz = self.bins.normal[:, 0], self.bins.normal[:, 1]

    def profile(self, state):
        """``(s, r, z, p_n, tau)`` arrays for the bins that hold material (Pa)."""
        s, r, z, p_n, tau = self.profile_all(state)
        ok = np.isfinite(p_n)
        return s[ok], r[ok], z[ok], p_n[ok], tau[ok]

    def mean_stress(self, state):
        """The weighted mean stress ``(rr, zz, tt, rz)`` (Pa) of each bin's cells, (nb, 4);
        NaN where a bin holds no material."""
        s, w, sig = self.model.wall_stress_points(state)
        nb = len(self.centres)
        bins = self.bins.index(s)
        wsum = np.bincount(bins, w, nb)
        mean = np.stack([np.bincount(bins, w * sig[:, k], nb) for k in range(4)],
                        axis=1).astype(float)       # (integers when no cell has material)
        ok = wsum > 0
        mean[ok] /= wsum[ok, None]
        mean[~ok] = np.nan
        return mean

    def profile_all(self, state):
        """``(s, r, z, p_n, tau)`` for every bin; NaN where a bin holds no material."""
        mean = self.mean_stress(state)
        ok = np.isfinite(mean[:, 0])
        n_r, n_z = self.nr, self.nz
        t_r, t_z = self.bins.tangent[:, 0], self.bins.tangent[:, 1]   # up the wall, any side
        trac_r = mean[:, 0] * n_r + mean[:, 3] * n_z
        trac_z = mean[:, 3] * n_r + mean[:, 1] * n_z
        p_n = np.where(ok, -(trac_r * n_r + trac_z * n_z), np.nan)
        tau = np.where(ok, trac_r * t_r + trac_z * t_z, np.nan)
        return self.centres, self.r, self.z, p_n, tau


# ---------------------------------------------------------------- wall loads from the reaction
class WallLoads:
    """Wall loads from the wall's reaction: the contact impulses the model measures, recovered
    as a smooth traction stretch by stretch (:mod:`fipy_hopper.wall_traction`).

    Every step, the contact of a node with a wall segment changes its velocity by ``dv``; the
    impulse ``m dv`` is the wall's force on the material times ``dt`` (per radian), and the
    model adds it up per contact entry (``State.wall_impulse``, ``State.plate_impulse``).
    Over a window of duration ``T`` the difference ``I`` of those sums gives the mean force
    ``F = I / T`` of each entry.  Each entry belongs to the stretch of its wall segment (the
    outlet lip's entries to the first stretch, at ``s = 0``; the frictionless free-fall tube
    below the outlet is left out) and is split into its stretch's normal and tangential
    components, ``f_n = -F . n`` (compression positive) and ``f_t = F . t`` (``n`` the
    stretch's normal into the wall, ``t`` its tangent up the wall).  The recovered traction's
    bin means are

        p_n = mean over the bin of  sum_k (sum_e B_k(s_e) f_n,e / A_k) B_k(s),   likewise tau,

    (:class:`~fipy_hopper.wall_traction.StretchRecovery`): over every stretch the traction
    times its wall area is the stretch's summed reaction, to round-off.  ``p_n`` is
    compressive (Pa), ``tau`` the shear the wall exerts on the material, positive up the wall
    (resisting downward flow).  :meth:`raw_profile` gives the plain binning of the entries'
    forces (each in the bin of its wall point, over the bin's area), for checking.
    """

    def __init__(self, model, sampler: "WallSampler | None" = None):
        from .wall_traction import StretchRecovery

        self.model = model
        self.sampler = sampler if sampler is not None else WallSampler(model)
        self.bins = self.sampler.bins
        bnd = model.cfg.boundary
        s, _, _ = model.wall_entries()
        rows = model.wall_load_rows()
        tab = bnd.table
        chain, segment = tab.chain[rows], tab.segment[rows]
        position = bnd.position(chain, s)
        stretches = self.bins.stretches
        width = model.cfg.wall_bin_width_m
        self.recoveries = []
        for k, st in enumerate(stretches):
            ci = bnd.chain_index(st.chain)
            last = k + 1 == len(stretches) or stretches[k + 1].chain != st.chain
            # a wall's segments above the fill level load its top stretch
            on = (segment >= st.index) if last else (segment == st.index)
            members = np.flatnonzero((chain == ci) & on & ~tab.tube[rows])
            self.recoveries.append(StretchRecovery.build(st, members, position[members],
                                                         width, KNOT_CELLS * model.cell_size))
        self.entries = np.concatenate([rec.entries for rec in self.recoveries])
        kind = np.array([c.kind for c in bnd.chains])
        #: the contact entries of the inserts (the rest are the walls' and the tubes')
        self._on_insert = kind[chain] == "insert"
        self.wall, self.centres = self.bins.wall, self.bins.s
        self.r_w, self.z_w = self.bins.r, self.bins.z
        self.bin_area = self.bins.area

    @staticmethod
    def estimated_bytes(n_bins: int, n_entries: int) -> int:
        """Peak bytes of the wall loads of ``n_bins`` bins and ``n_entries`` contact entries
        while they are built and used: the sparse maps of
        :class:`~fipy_hopper.wall_traction.StretchRecovery` (four basis values and one bin an
        entry, a few quadrature points a bin) with their temporaries, and a window's forces:
        at most 256 bytes an entry and 2 kB a bin (measured with tracemalloc:
        ``tests/test_reliability.py``)."""
        return 256 * int(n_entries) + 2048 * int(n_bins)

    @staticmethod
    def reading(model, state) -> dict:
        """The cumulative measurements of ``state`` at this moment (copies): the impulses,
        the momentum budget, the vertical momentum ``sum m v_z`` (per radian) and the time."""
        return {"t": state.t, "wall": state.wall_impulse.copy(),
                "plate": state.plate_impulse.copy(),
                "budget": state.momentum_budget.copy(),
                "momentum": model.vertical_momentum(state)}

    def stretch_forces(self, start: dict, end: dict) -> list:
        """Per stretch, the mean force of its entries over the window in the stretch's frame,
        ``(f_n, f_t)`` (n_entries, 2) (N per radian; per metre of a plane wall)."""
        duration = end["t"] - start["t"]
        if not duration > 0:
            raise ValueError("a wall-load window needs a positive duration")
        out = []
        for rec in self.recoveries:
            force = (end["wall"] - start["wall"])[rec.entries] / duration
            st = rec.stretch
            out.append(np.stack([-(force @ st.normal), force @ st.tangent], axis=1))
        return out

    def _profile(self, start: dict, end: dict, recovered: bool):
        values = [rec.traction(f) if recovered else rec.raw_traction(f)
                  for rec, f in zip(self.recoveries, self.stretch_forces(start, end))]
        p = np.concatenate(values)
        return self.centres, self.r_w, self.z_w, p[:, 0], p[:, 1]

    def profile(self, start: dict, end: dict):
        """``(s, r, z, p_n, tau)`` of the window between two :meth:`reading` s (Pa): the
        recovered traction's bin means."""
        return self._profile(start, end, True)

    def raw_profile(self, start: dict, end: dict):
        """``(s, r, z, p_n, tau)`` of the window by plain binning of the entries' forces (Pa),
        for checking the recovery (noisy where the wall cuts the cells)."""
        return self._profile(start, end, False)

    def hoop_force(self, p_n):
        """Hoop force ``N_theta = p_n r / n_r`` (N/m, tension positive) of the bins' normal
        pressures ``p_n`` (Pa) on the walls; NaN on a flat floor, on an insert and for a plane
        section (:meth:`membrane_forces`)."""
        p_n = np.asarray(p_n, dtype=float)
        n_r = self.bins.normal[:, 0]
        if not self.model.cfg.hopper.axisymmetric:
            return np.full_like(p_n, np.nan)
        curved = (n_r > 0.0) & (self.bins.wall == "wall")
        return np.where(curved, p_n * self.r_w / np.where(curved, n_r, 1.0), np.nan)

    def membrane_forces(self, start: dict, end: dict, p_n, tau=None):
        """The forces in the wall per unit length of its circumference (N/m; per metre of a
        wedge's length), tension positive, from the recovered traction over a window, as a
        shell of revolution carries them: the hoop force per bin (:meth:`hoop_force`) and the
        meridional force per bin and at the transition of :func:`membrane_statics` (the
        window's recovered bin means ``p_n``, ``tau``: :meth:`profile`, computed here when not
        given).  Returns ``(hoop, meridional, (hopper_tension_t, bin_compression_t))``, the
        last the (right) wall's transition's (NaN without one), so that ``section factor * c_t
        * (cos(theta) N_hopper + N_bin)`` is the wall's vertical force."""
        if tau is None:
            p_n, tau = self.profile(start, end)[3:]
        meridional, corners = membrane_statics(self.model.cfg.boundary, self.bins, p_n, tau)
        at = next((c for c in corners if c["wall"] == "wall" and c["transition"]), None)
        at_transition = ((at["meridional_below_N_m"], -at["meridional_above_N_m"])
                         if at is not None else (math.nan, math.nan))
        return self.hoop_force(p_n), meridional, at_transition

    def chain_forces(self, start: dict, end: dict) -> dict:
        """The mean force of each wall and insert on the material over a window,
        ``{name: (F_x, F_z)}`` (N, for the whole silo: times the section factor; per metre of
        a plane section), from its contact entries' impulses (the tubes' left out)."""
        duration = end["t"] - start["t"]
        if not duration > 0:
            raise ValueError("a load window needs a positive duration")
        bnd = self.model.cfg.boundary
        rows = self.model.wall_load_rows()
        chain = bnd.table.chain[rows]
        force = (end["wall"] - start["wall"]) * (self.model.section_factor / duration)
        return {c.name: tuple(float(v) for v in force[chain == k].sum(axis=0))
                for k, c in enumerate(bnd.chains) if c.kind != "tube"}

    def corner_forces(self, p_n, tau) -> list:
        """The forces at every corner of the walls for the bins' recovered ``p_n`` and
        ``tau`` of a window (:func:`membrane_statics`), one dict per corner without its
        ``transition`` flag (a record holds numbers and names only)."""
        _, corners = membrane_statics(self.model.cfg.boundary, self.bins, p_n, tau)
        return [{k: v for k, v in c.items() if k != "transition"} for c in corners]

    def wall_k(self, p_n, state) -> float:
        """:func:`wall_k` of a pressure profile at rest."""
        return wall_k(self, p_n, state, self.model.cfg.hopper)

    def summary(self, sim) -> dict:
        """:func:`load_summary` of a run."""
        return load_summary(sim)

    def balance(self, start: dict, end: dict) -> dict:
        """The vertical momentum balance of the whole grid over a window, as mean forces in N
        (3D, upward positive): ``weight`` (positive), ``wall`` and ``outlet`` (the plate's
        reaction), ``damping``, ``stopped`` (light nodes), ``outflow`` (momentum leaving
        through the bottom, as a force), ``momentum_rate`` (``dP/dt``) and the ``residual``
        of ``dP/dt = wall + outlet + damping + stopped + outflow - weight``, also relative to
        the weight (``relative_residual``); with inserts, each insert's share of ``wall``
        under its name (``insert_1``, ...)."""
        duration = end["t"] - start["t"]
        if not duration > 0:
            raise ValueError("a load window needs a positive duration")
        to_n = self.model.section_factor / duration
        budget = (end["budget"] - start["budget"]) * to_n
        rise = end["wall"][:, 1] - start["wall"][:, 1]
        # the walls' entries, then the inserts': the walls' sum as it is without inserts
        wall = (float(np.sum(rise[~self._on_insert])) + float(np.sum(rise[self._on_insert])))
        out = {"weight": -budget[0],
               "wall": wall * to_n,
               "outlet": float(np.sum(end["plate"][:, 1] - start["plate"][:, 1])) * to_n,
               "damping": budget[1], "stopped": budget[2], "outflow": budget[3],
               "momentum_rate": (end["momentum"] - start["momentum"]) * to_n}
        out["residual"] = (out["wall"] + out["outlet"] + out["damping"] + out["stopped"]
                           + out["outflow"] - out["weight"] - out["momentum_rate"])
        inserts = self.model.cfg.boundary.inserts
        if inserts:                      # each insert's share of ``wall`` (upward on the fill)
            forces = self.chain_forces(start, end)
            out.update({c.name: forces[c.name][1] for c in inserts})
        out["relative_residual"] = (abs(out["residual"]) / out["weight"]
                                    if out["weight"] > 0 else math.nan)
        return out


def vertical_loads(bins: WallBins, p_n, tau) -> np.ndarray:
    """The vertical load of each bin's recovered traction on the material, ``A_b (-p_n n_z +
    tau t_z)`` (N per radian; per metre of a plane wall; upward on the material, so the
    material's load on the wall downward), taken at the bin centre."""
    return bins.area * (-np.asarray(p_n, float) * bins.normal[:, 1]
                        + np.asarray(tau, float) * bins.tangent[:, 1])


def membrane_statics(boundary, bins: WallBins, p_n, tau) -> tuple:
    """The membrane statics of the walls (``wall``, ``left_wall``) under the bins' traction
    ``p_n``, ``tau`` (Pa): the meridional force per bin and the forces at every corner, one
    computation for both.

    The supports: each wall hangs from its :meth:`~fipy_hopper.boundary.Boundary.transition`
    (the bottom of its top vertical stretch) and its bin wall stands on it.  With ``V`` the
    material's downward load (per radian; per metre of a plane wall) on the wall below a
    point, ``U`` that on the wall above it (:func:`vertical_loads`, summed bin by bin), ``c``
    the point's radius (1 in plane flow) and ``beta`` the slope from the vertical of the
    segment there (``cos(beta) = |n_x|``), the meridional force (N/m, tension positive) is

        N_m = V / (c cos(beta))   below the transition (hung),
        N_m = -U / c              above it (standing: a compression),

    NaN on a horizontal floor or ledge (``cos(beta) = 0``: it carries its load in bending,
    not hung).  Per bin the load is taken at the bin centre (half its own bin's).  At a
    corner (a point of the chain's :attr:`~fipy_hopper.boundary.Chain.corners`, at arc length
    ``s``) the same forces on the segments below and above it, ``N_b`` and ``N_a``, leave a
    horizontal pull ``N_b sin(beta_b) - N_a sin(beta_a)`` (inward positive) that a ring there
    takes: in a section of revolution the ring's compression is ``c`` times the pull (N).

    Returns ``(meridional, corners)``: ``meridional`` (nb,) N/m (NaN off the walls), and one
    dict per corner of ``wall``, ``s_m``, ``r_m``, ``z_m``, ``transition`` (True at the
    wall's transition), ``meridional_below_N_m``, ``meridional_above_N_m``,
    ``horizontal_pull_N_m`` and ``ring_compression_N`` (NaN in plane flow)."""
    axisymmetric = boundary.section.axisymmetric
    down = vertical_loads(bins, p_n, tau)
    c = np.abs(bins.r) if axisymmetric else np.ones_like(bins.r)
    n_r = np.abs(bins.normal[:, 0])
    curved = n_r > 1e-12
    meridional = np.full(len(down), np.nan)
    corners = []
    for chain in boundary.walls:
        on = bins.wall == chain.name
        z_t = boundary.transition_height(chain.name)
        hung = on & (bins.z < z_t)
        stands = on & ~hung & curved
        load_h, load_s = np.where(hung, down, 0.0), np.where(stands, down, 0.0)
        below = np.cumsum(load_h) - 0.5 * load_h
        above = np.cumsum(load_s[::-1])[::-1] - 0.5 * load_s
        hanging = hung & curved
        meridional[hanging] = below[hanging] / (c[hanging] * n_r[hanging])
        meridional[stands] = -above[stands] / c[stands]
        transition = boundary.transition(chain.name)
        for corner in chain.corners:
            x, z = corner.point
            radius = abs(x) if axisymmetric else 1.0
            n_b, n_a = chain.normals[corner.segment - 1], chain.normals[corner.segment]
            load_below = float(np.sum(load_h[bins.s < corner.s]))
            load_above = float(np.sum(load_s[bins.s > corner.s]))
            m_b = load_below / (radius * abs(n_b[0])) if abs(n_b[0]) > 1e-12 else math.nan
            if z < z_t:
                m_a = load_below / (radius * abs(n_a[0])) if abs(n_a[0]) > 1e-12 else math.nan
            else:
                m_a = -load_above / radius if abs(n_a[0]) > 1e-12 else math.nan
            pull = m_b * abs(n_b[1]) - (m_a * abs(n_a[1]) if math.isfinite(m_a)
                                        and abs(n_a[1]) > 0 else 0.0)
            corners.append({"wall": chain.name, "s_m": float(corner.s), "r_m": float(x),
                            "z_m": float(z), "transition": corner == transition,
                            "meridional_below_N_m": m_b, "meridional_above_N_m": m_a,
                            "horizontal_pull_N_m": pull,
                            "ring_compression_N": pull * abs(x) if axisymmetric else math.nan})
    return meridional, corners


def wall_k(wall_loads: WallLoads, p_n, state, geom, margin_bins: int = 2) -> float:
    """The lateral pressure ratio measured at the bin wall: the median over the bin wall's
    bins (the wall's top vertical stretch, above its transition) of ``p_n / (-sigma_zz)``,
    ``p_n`` from the reaction and ``sigma_zz`` the mean vertical stress of the cells next to
    the wall (:meth:`WallSampler.mean_stress`), leaving out ``margin_bins`` bins next to the
    transition and next to the free surface."""
    bins = wall_loads.bins
    s = bins.s
    bnd = wall_loads.model.cfg.boundary
    if bnd.transition("wall") is None:
        return math.nan
    s_t = bnd.transition_s("wall")
    s_top = bnd.arc_at_height("wall", bnd.fill_level)
    margin = margin_bins * bins.width
    szz = wall_loads.sampler.mean_stress(state)[:, 1]
    keep = ((bins.wall == "wall") & (np.abs(bins.normal[:, 1]) < 1e-9)
            & (s > s_t + margin) & (s < s_top - margin) & np.isfinite(szz) & (szz < 0.0))
    if not keep.any():
        return math.nan
    return float(np.median(p_n[keep] / -szz[keep]))


def relative_l2(a, b) -> float:
    """``|a - b|_2 / |b|_2`` over the entries where both are finite."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.linalg.norm(a[ok] - b[ok]) / np.linalg.norm(b[ok]))


def smooth_fit_rms(s, p, lo: float, hi: float) -> float:
    """RMS of the relative deviation of a profile ``p`` (bins at arc lengths ``s``) from a
    cubic fitted over its finite bins with ``lo < s < hi`` (NaN with fewer than five)."""
    s, p = np.asarray(s, float), np.asarray(p, float)
    sel = (s > lo) & (s < hi) & np.isfinite(p)
    if sel.sum() < 5:
        return math.nan
    fit = np.polyval(np.polyfit(s[sel], p[sel], 3), s[sel])
    return float(np.sqrt(np.mean(((p[sel] - fit) / fit) ** 2)))


def bin_scatter(p) -> float:
    """Mean over a profile's inner bins of ``|p_i - (p_(i-1) + p_(i+1)) / 2| / p_i``, over
    the bins whose three values are finite (a real peak barely raises it; NaN if none)."""
    p = np.asarray(p, float)
    if len(p) < 3:
        return math.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        terms = np.abs(p[1:-1] - 0.5 * (p[:-2] + p[2:])) / p[1:-1]
    terms = terms[np.isfinite(terms)]
    return float(np.mean(terms)) if terms.size else math.nan


def load_summary(sim) -> dict:
    """The wall-load numbers of ``summary.json`` from a :class:`~fipy_hopper.simulation.
    Simulation`'s record.

    * ``fill_weight_N``, ``fill_wall_vertical_N``, ``fill_outlet_N``: the weight and the
      vertical reactions of the wall and the outlet plate at rest (N, 3D);
      ``fill_equilibrium_residual``: ``|wall + outlet - weight| / weight`` there;
    * ``load_balance_residual_max``: the largest relative residual of the vertical momentum
      balance over the rows of ``loads.csv`` (round-off when every force is accounted for);
    * ``wall_k_bin``: the lateral pressure ratio at the bin wall at rest (:func:`wall_k`);
    * ``overpressure_factor_bin_max``, ``overpressure_factor_cone_max``: the largest ratio of
      the discharge envelope to the filled pressure in the bin (above the transition zone)
      and in the cone, with EN 1991-4's discharge factor ``en1991_discharge_factor_bin``;
    * ``corners``: every corner of the walls with its forces and switch peak
      (:func:`_insert_and_corner_loads`); the wall's transition's values are also given at
      the top level (:func:`_transition_forces`), the same numbers:
      ``switch_peak_Pa``, ``switch_peak_s_m`` (the envelope's peak within a bin diameter of
      the transition), and the forces in the wall at the transition per unit length of
      circumference (N/m, :func:`membrane_statics`), at rest and the larger of the 90 % and
      50 % stages: ``hopper_meridional_tension_N_m`` / ``..._discharge_N_m`` (the hopper
      hangs from the transition), ``bin_wall_axial_compression_N_m`` / ``..._discharge_N_m``
      (the bin's wall friction carried down to it), ``transition_ring_compression_N`` /
      ``..._discharge_N`` (the ring that takes the inward pull of the hopper's tension,
      ``N_m sin(beta) r`` with ``beta`` the slope of the segment under the transition);
      NaN where they do not apply (no transition; no hopper: a flat floor; the ring: a plane
      section);
    * ``walker_switch_pressure_Pa``, Walker's passive pressure just below the transition for
      the Janssen vertical stress there (with the measured ``K``), and
      ``janssen_wall_axial_compression_N_m``, Janssen's at the transition for the fill's
      height with the measured ``K``: for the silos the classic theories cover.
    """
    from . import theory

    rec, m = sim.record, sim.model
    geom, mat = m.cfg.hopper, m.cfg.material
    nan = math.nan
    out = {"fill_weight_N": nan, "fill_wall_vertical_N": nan, "fill_outlet_N": nan,
           "fill_equilibrium_residual": nan, "load_balance_residual_max": nan,
           "wall_k_bin": getattr(rec, "wall_k", nan), "overpressure_factor_bin_max": nan,
           "overpressure_factor_cone_max": nan,
           "en1991_discharge_factor_bin": theory.en1991_discharge_factors()[0],
           "walker_switch_pressure_Pa": nan, "janssen_wall_axial_compression_N_m": nan}
    corners = _insert_and_corner_loads(rec, m.cfg)
    out.update(_transition_forces(corners.get("corners", [])))
    rest = rec.rest_balance
    if rest and rest.get("weight", 0) > 0:
        out.update(fill_weight_N=rest["weight"], fill_wall_vertical_N=rest["wall"],
                   fill_outlet_N=rest["outlet"],
                   fill_equilibrium_residual=abs(rest["wall"] + rest["outlet"] - rest["weight"])
                   / rest["weight"])
    residuals = [r["relative_residual"] for r in rec.loads
                 if math.isfinite(r.get("relative_residual", nan))]
    if residuals:
        out["load_balance_residual_max"] = float(max(residuals))
    # Janssen's K: the one measured at the bin wall at rest, else Jaky's
    K = out["wall_k_bin"] if math.isfinite(out["wall_k_bin"]) else float(
        theory.k_jaky(mat.friction_angle_deg))
    mu = m.mu_wall
    rectangular = getattr(geom, "rectangular", False)
    if "filling" in rec.wall and "discharge_envelope" in rec.wall and rectangular:
        out.update(_face_overpressure(rec, m))
    elif "filling" in rec.wall and "discharge_envelope" in rec.wall:
        on_wall = np.asarray(rec.wall_names) == "wall" if rec.wall_names else slice(None)
        s, p_fill = rec.wall["filling"][1][on_wall], rec.wall["filling"][4][on_wall]
        envelope = rec.wall["discharge_envelope"][4][on_wall]
        bnd = m.cfg.boundary
        z_t = bnd.transition_height("wall")
        s_t = bnd.transition_s("wall")
        s_top = bnd.arc_at_height("wall", bnd.fill_level)
        loaded = p_fill > 0.05 * np.nanmax(p_fill)
        ratio = np.where(loaded, envelope / np.where(loaded, p_fill, 1.0), np.nan)
        near = bnd.span_at(z_t)
        in_bin = (s > s_t + 0.5 * near) & (s < s_top - 0.25 * near)
        in_cone = (s < s_t - 0.1 * near) & (s > 0.25 * near)
        if np.isfinite(ratio[in_bin]).any():
            out["overpressure_factor_bin_max"] = float(np.nanmax(ratio[in_bin]))
        if np.isfinite(ratio[in_cone]).any():
            out["overpressure_factor_cone_max"] = float(np.nanmax(ratio[in_cone]))
    classic = m.cfg.boundary.hopper_shape if geom.classic else None
    if classic is not None and mu > 0 and m.cfg.boundary.fill_level > classic.transition_height:
        depth = m.cfg.boundary.fill_level - classic.transition_height
        if "filling" in rec.wall and "discharge_envelope" in rec.wall \
                and classic.half_angle_deg < 90.0:
            janssen = (theory.janssen_vertical_stress if geom.axisymmetric
                       else theory.janssen_plane_vertical_stress)
            sigma_vt = float(janssen(depth, mat.density, 2.0 * classic.bin_x, K, mu))
            out["walker_switch_pressure_Pa"] = float(theory.walker_switch_pressure(
                sigma_vt, K, mat.friction_angle_deg, m.cfg.wall.friction_angle_deg,
                classic.half_angle_deg).hopper)
        axial = (theory.janssen_wall_axial_force if geom.axisymmetric
                 else theory.janssen_plane_wall_axial_force)
        out["janssen_wall_axial_compression_N_m"] = float(axial(
            depth, mat.density, 2.0 * classic.bin_x, K, mu))
    elif classic is not None and mu > 0:     # filled below the bin: nothing in it to carry
        out["janssen_wall_axial_compression_N_m"] = 0.0
    out.update(corners)
    if classic is None:           # no closed form for this silo: left out, not NaN
        del out["walker_switch_pressure_Pa"], out["janssen_wall_axial_compression_N_m"]
    return out


def _face_overpressure(rec, model) -> dict:
    """``overpressure_factor_bin_max`` and ``..._cone_max`` of a rectangular plan (3D): the
    largest ratio of the discharge envelope to the filled pressure over the patches of the
    bin's faces above the transition zone (half the bin's shorter side above the transition,
    a quarter below the fill level) and of the hopper's faces (a tenth below the transition,
    a quarter above the outlet), by height (the faces' own arc lengths differ)."""
    bnd = model.boundary
    names = np.asarray(rec.wall_names)
    z, p_fill = np.asarray(rec.wall["filling"][3]), np.asarray(rec.wall["filling"][4])
    envelope = np.asarray(rec.wall["discharge_envelope"][4])
    loaded = p_fill > 0.05 * np.nanmax(p_fill)
    ratio = np.where(loaded, envelope / np.where(loaded, p_fill, 1.0), np.nan)
    near = 2.0 * min(bnd.half_extent)
    z_t = bnd.bin_foot
    on_bin = np.isin(names, ("x_plus", "x_minus", "y_plus", "y_minus"))
    on_hopper = np.char.startswith(names.astype(str), "hopper_")
    in_bin = on_bin & (z > z_t + 0.5 * near) & (z < bnd.fill_level - 0.25 * near)
    in_cone = on_hopper & (z < z_t - 0.1 * near) & (z > 0.25 * near)
    out = {}
    if np.isfinite(ratio[in_bin]).any():
        out["overpressure_factor_bin_max"] = float(np.nanmax(ratio[in_bin]))
    if np.isfinite(ratio[in_cone]).any():
        out["overpressure_factor_cone_max"] = float(np.nanmax(ratio[in_cone]))
    return out


def _insert_and_corner_loads(rec, cfg) -> dict:
    """The inserts' and the corners' numbers of :func:`load_summary`: per insert the
    material's downward load on it at rest, ``<insert>_vertical_force_N``, and the largest
    over the discharge's load windows, ``<insert>_vertical_force_discharge_max_N`` (N, 3D);
    and ``corners``, the forces at every corner of the walls (:func:`membrane_statics`) at
    rest and, as ``..._discharge``, the larger in size of the 90 % and 50 % stages, with its
    ``transition`` flag and its switch peak (:func:`corner_switch_peaks`)."""
    out = {}
    rest = getattr(rec, "chain_forces", {}).get("filling", {})
    for insert in cfg.boundary.inserts:
        out[f"{insert.name}_vertical_force_N"] = (rest[insert.name][1] if insert.name in rest
                                                  else math.nan)
        out[f"{insert.name}_vertical_force_discharge_max_N"] = float(
            getattr(rec, "insert_force_max", {}).get(insert.name, math.nan))
    corners = getattr(rec, "corner_forces", {})
    if "filling" in corners:
        rows = [dict(c) for c in corners["filling"]]
        stages = [corners[s] for s in ("early_discharge", "mid_discharge") if s in corners]
        peaks = corner_switch_peaks(rec, cfg.boundary, rows)
        for k, row in enumerate(rows):
            transition = cfg.boundary.transition(row["wall"])
            row["transition"] = transition is not None and transition.s == row["s_m"]
            for key in ("meridional_below_N_m", "meridional_above_N_m", "horizontal_pull_N_m",
                        "ring_compression_N"):
                values = [st[k][key] for st in stages if len(st) > k
                          and math.isfinite(st[k][key])]
                row[key.replace("_N", "_discharge_N", 1)] = (
                    max(values, key=abs) if values else math.nan)
            row["switch_peak_Pa"], row["switch_peak_s_m"] = peaks[k]
        out["corners"] = rows
    return out


def corner_switch_peaks(rec, boundary, rows) -> list:
    """Per corner row (its ``wall`` and ``s_m``), ``(p, s)``: the discharge envelope's
    largest recovered ``p_n`` (Pa) on the corner's wall within the silo's width at the
    corner's height (:meth:`~fipy_hopper.boundary.Boundary.span_at`: the bin's diameter at a
    hopper's transition) of it along the wall, and its arc length ``s`` (m); NaN without an
    envelope, and none (NaN) at a corner at or above the fill level: the material never
    switches there."""
    nan = (math.nan, math.nan)
    if "discharge_envelope" not in rec.wall:
        return [nan] * len(rows)
    s, envelope = rec.wall["discharge_envelope"][1], rec.wall["discharge_envelope"][4]
    names = np.asarray(rec.wall_names) if rec.wall_names else np.full(len(s), "wall")
    out = []
    for row in rows:
        if row["z_m"] >= boundary.fill_level:
            out.append(nan)
            continue
        near = boundary.span_at(row["z_m"])
        zone = np.flatnonzero((names == row["wall"]) & (np.abs(s - row["s_m"]) <= near)
                              & np.isfinite(envelope))
        if not len(zone):
            out.append(nan)
            continue
        k = zone[np.argmax(envelope[zone])]
        out.append((float(envelope[k]), float(s[k])))
    return out


def _transition_forces(rows) -> dict:
    """The transition's numbers of :func:`load_summary`: those of the corner rows'
    (:func:`_insert_and_corner_loads`) transition of the (right) wall, NaN without one."""
    at = next((r for r in rows if r["wall"] == "wall" and r["transition"]), None)
    nan = math.nan
    get = (lambda key, sign=1.0: sign * at[key]) if at is not None else (lambda *_: nan)
    return {"hopper_meridional_tension_N_m": get("meridional_below_N_m"),
            "bin_wall_axial_compression_N_m": get("meridional_above_N_m", -1.0),
            "transition_ring_compression_N": get("ring_compression_N"),
            "hopper_meridional_tension_discharge_N_m": get("meridional_below_discharge_N_m"),
            "bin_wall_axial_compression_discharge_N_m":
                get("meridional_above_discharge_N_m", -1.0),
            "transition_ring_compression_discharge_N": get("ring_compression_discharge_N"),
            "switch_peak_Pa": get("switch_peak_Pa"), "switch_peak_s_m": get("switch_peak_s_m")}


# ---------------------------------------------------------------- stress pattern
def stress_pattern(sigma, cohesion: float = 0.0, friction_angle_deg: float = 30.0):
    """Principal stresses and mobilised friction of cell stresses ``sigma`` (..., 4) =
    ``(rr, zz, tt, rz)`` (Pa, tension positive).

    Returns a dict of arrays, compression positive (Pa): ``sigma1`` and ``sigma3``, the major
    and minor principal stresses of the three (the hoop stress included); ``sigma1_angle_deg``,
    the angle from the vertical of the major principal direction in the r-z plane (the
    eigenvector of the larger in-plane compression; 0: vertical, the active state of a fill,
    +-90: horizontal, across the flow, the passive state of an arch), in (-90, 90], positive
    when the direction leans outward going up; and ``sin_phi_mob``,
    ``(sigma1 - sigma3) / (sigma1 + sigma3 + 2 c cot(phi))``, the mobilised friction (1 on the
    Mohr-Coulomb yield surface, NaN where the denominator is not positive).
    """
    s = np.asarray(sigma, dtype=float)
    rr, zz, tt, rz = -s[..., 0], -s[..., 1], -s[..., 2], -s[..., 3]   # compression positive
    mid, half = 0.5 * (rr + zz), 0.5 * (rr - zz)
    radius = np.hypot(half, rz)
    major, minor = mid + radius, mid - radius
    sigma1 = np.maximum(major, tt)
    sigma3 = np.minimum(minor, tt)
    # eigenvector of the major in-plane compression: angle 2w from the r axis with
    # tan 2w = 2 rz / (rr - zz); from the vertical: 90 deg - w
    w = 0.5 * np.degrees(np.arctan2(2.0 * rz, rr - zz))
    angle = 90.0 - w
    angle = np.where(angle > 90.0, angle - 180.0, angle)
    apex = 2.0 * cohesion / math.tan(math.radians(friction_angle_deg))
    denominator = sigma1 + sigma3 + apex
    with np.errstate(invalid="ignore", divide="ignore"):
        mobilised = np.where(denominator > 0, (sigma1 - sigma3) / denominator, np.nan)
    return {"sigma1": sigma1, "sigma3": sigma3, "sigma1_angle_deg": angle,
            "sin_phi_mob": mobilised}
