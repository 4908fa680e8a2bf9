"""Any silo a designer draws: expanded flow, an insert, an off-centre slot, a central hopper.

Five silos drawn as profiles (``hopper.shape = "profile"``), each an ordinary run
directory, with the outlet's radius (half-width) ``outlet_radius`` (30 mm), the bin's
``bin_radius`` (150 mm), the walls up to ``top`` (0.5 m) and the fill levelled at
``fill_level`` (0.4 m), phi = 30 deg:

* ``expanded``: an expanded-flow hopper (axisymmetric): a steep lower stretch
  (``expanded.lower_deg``, 15 deg) up to ``expanded.break_radius`` (60 mm) under a shallow
  one (``expanded.upper_deg``, 60 deg) up to the bin, phi_w = 15 deg (Jenike's theta_c
  36.9 deg: mass flow in the lower stretch, funnel flow in the upper);
* ``funnel`` and ``insert``: a 40 deg cone with phi_w = 20 deg (theta_c 28.4 deg: funnel
  flow), without and with an inverted-cone insert on the axis (a double cone: its widest
  radius ``insert.radius`` at ``insert.z_widest``, its apexes at ``insert.z_top`` and
  ``insert.z_bottom``);
* ``slot``: a flat-bottomed plane silo, full section (both walls, per metre of length),
  with a slot between the lips ``slot.lips`` (x = 60 to 120 mm of a silo from -150 to
  150 mm: its centre 90 mm off the silo's centre, a 30 mm floor to the near wall);
* ``ledge``: a flat-bottomed silo with a central hopper (axisymmetric): a
  ``ledge.hopper_deg`` (20 deg) hopper up to ``ledge.radius`` (80 mm), a flat ledge from
  there out to the bin wall, phi_w = 15 deg.

Each runs ``end_time`` seconds of discharge: by default the time Beverloo's rate (with
Rose-Tanaka's factor of the stretch at the outlet, or the slot form;
:func:`fipy_hopper.api.expected_quantities`) takes to discharge ``drained_fraction`` (0.7)
of the fill, rounded up to half a second, so that the 50 % stage and its load window fall in
the run of a silo that drains that far.  Measured from each run directory:

* per stretch of hopper wall (``summary.json`` ``hopper_stretches``): its slope, its slip
  ratio and call (mass flow where it slides) against Jenike's angle and call for it;
* the insert: its vertical force at rest and its largest in discharge against the fill's
  vertical stress at the insert's top height times its projected area, the stress from
  theory for the silo without the insert (Janssen in the bin with K = 1 - sin phi, or
  Walker's filling slice in the cone on Janssen's stress at the transition) and simulated
  (the material-weighted mean of -sigma_zz over the row of cells at that height in the
  ``funnel`` run's first snapshot of the discharge, taken as the outlet opens, when the
  opening's unloading has not yet reached that height);
* the slot: the normal pressure on the near wall (``wall``) and the far wall
  (``left_wall``) at the heights ``slot.heights`` at rest, at 90 % and 50 % left and the
  discharge envelope, their ratio there and its range over the vertical walls (where both
  carry more than ``loaded_fraction`` of the stage's peak); each wall's vertical reaction
  from the recovered traction (bin areas of :func:`fipy_hopper.diagnostics.wall_bins`),
  their sum against the summary's ``fill_wall_vertical_N_m``;
* where the wall slip was measured (``wall_slip.csv``): the rule's reference is the axis's
  speed at each height, so the rows whose axis lies inside the insert are left out;
* the stagnant share of the material (moving slower than ``FlowModeRule.stagnant_speed``
  of its mean speed) at the snapshot nearest the 50 % stage (the last one if the run did
  not get there), of the whole fill and, for ``slot`` and ``ledge``, of the material beside
  the outlet (``slot``: left of the left lip; ``ledge``: beyond the hopper's radius).

Written to ``--out`` (default ``studies/output/geometries``): ``results.csv`` (one row per
case), ``stretches.csv``, ``slot_pressure.csv``, ``geometries.png``, ``slot_walls.png``,
``flow_pattern_<case>.png`` and ``wall_pressure_<case>.png`` (the runs' own), ``study.json``
and ``cases/<name>/``.

Usage::

    python studies/geometries.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                 [--cell-size 0.005] [--end-time SECONDS]
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

_r = _sweep.rounded
NAME = "geometries"
TITLE = "Any silo: expanded flow, an insert, an off-centre slot and a central hopper"
CASES = ("expanded", "funnel", "insert", "slot", "ledge")


def num(value, spec: str) -> str:
    """``value`` formatted by ``spec``, or "n/a" where it is None (a ratio of loads where a wall
    carries nothing)."""
    return "n/a" if value is None else format(value, spec)
STAGES = ("filling", "early_discharge", "mid_discharge", "discharge_envelope")
DEFAULTS = {
    "cell_size": 0.005, "outlet_radius": 0.03, "bin_radius": 0.15, "top": 0.5,
    "fill_level": 0.4, "friction_angle_deg": 30.0,
    "expanded": {"lower_deg": 15.0, "upper_deg": 60.0, "break_radius": 0.06,
                 "wall_deg": 15.0},
    "funnel": {"half_angle_deg": 40.0, "wall_deg": 20.0},
    "insert": {"radius": 0.05, "z_widest": 0.09, "z_top": 0.18, "z_bottom": 0.04},
    "slot": {"lips": (0.06, 0.12), "wall_deg": 15.0, "heights": (0.05, 0.1, 0.2, 0.3)},
    "ledge": {"hopper_deg": 20.0, "radius": 0.08, "wall_deg": 15.0},
    "drained_fraction": 0.7, "end_time": None, "loaded_fraction": 0.05,
    "field_interval": 0.25, "case_plots": True,
}
QUICK = {"cell_size": 0.01, "fill_level": 0.3, "end_time": 1.5, "field_interval": 0.25}


# ---------------------------------------------------------------- the silos
def _up(x0, z0, x1, angle_deg):
    """The point at ``x1`` on the line from ``(x0, z0)`` rising at ``angle_deg`` from the
    vertical."""
    return [x1, z0 + abs(x1 - x0) / math.tan(math.radians(angle_deg))]


def silos(opts) -> dict:
    """``{case: (hopper section, wall friction in deg)}`` of the five silos."""
    r0, big, top, fill = (opts[k] for k in ("outlet_radius", "bin_radius", "top",
                                            "fill_level"))
    ex, fu, ins, sl, le = (opts[k] for k in CASES)
    brk = _up(r0, 0.0, ex["break_radius"], ex["lower_deg"])
    shoulder = _up(*brk, big, ex["upper_deg"])
    cone = _up(r0, 0.0, big, fu["half_angle_deg"])
    ledge = _up(r0, 0.0, le["radius"], le["hopper_deg"])
    profile = {"shape": "profile", "fill_level": fill}
    funnel = {**profile, "wall": [[r0, 0.0], cone, [big, top]]}
    diamond = [[0.0, ins["z_top"]], [ins["radius"], ins["z_widest"]], [0.0, ins["z_bottom"]]]
    near, far = max(sl["lips"]), min(sl["lips"])
    return {
        "expanded": ({**profile, "wall": [[r0, 0.0], brk, shoulder, [big, top]]},
                     ex["wall_deg"]),
        "funnel": (funnel, fu["wall_deg"]),
        "insert": ({**funnel, "inserts": [{"outline": diamond}]}, fu["wall_deg"]),
        "slot": ({**profile, "symmetry": "plane", "section": "full",
                  "wall": [[near, 0.0], [big, 0.0], [big, top]],
                  "left_wall": [[far, 0.0], [-big, 0.0], [-big, top]]}, sl["wall_deg"]),
        "ledge": ({**profile, "wall": [[r0, 0.0], ledge, [big, ledge[1]], [big, top]]},
                  le["wall_deg"]),
    }


def end_time(config: dict, opts) -> float:
    """The discharge to run (s): ``end_time``, or Beverloo's time for ``drained_fraction``
    of the fill rounded up to half a second."""
    if opts["end_time"] is not None:
        return float(opts["end_time"])
    from fipy_hopper.api import expected_quantities

    expected = expected_quantities(_sweep._config(config))
    return 0.5 * math.ceil(2.0 * opts["drained_fraction"] * expected[
        "expected_discharge_time_s"])


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    cases = []
    for name, (hopper, wall) in silos(opts).items():
        config = {"hopper": hopper,
                  "material": {"friction_angle_deg": opts["friction_angle_deg"]},
                  "wall": {"friction_angle_deg": float(wall)},
                  "numerics": {"cell_size": float(opts["cell_size"])},
                  "run": {"output_interval": 0.05, "field_interval": opts["field_interval"]}}
        config["run"]["end_time"] = end_time(config, opts)
        cases.append(_sweep.make_case(name, {"silo": name,
                                             "end_time_s": config["run"]["end_time"]},
                                      config, plots=opts["case_plots"]))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- measures
def _config_of(row):
    from fipy_hopper.config import HopperConfig

    return HopperConfig.from_toml(Path(row["run_dir"]) / "config.toml")


def _snapshot(run_dir, entry) -> dict:
    """A field snapshot (:func:`fipy_hopper.plotting.load_snapshot`) with its cell centres
    ``x``, ``z`` and ``stress_zz`` (Pa, tension positive), each ``(nz, nx)``."""
    from fipy_hopper import plotting
    from fipy_hopper.io import RunDirectory, read_vtu

    snap = plotting.load_snapshot(run_dir, entry)
    mesh = read_vtu(Path(run_dir) / RunDirectory.FIELDS / entry["file"])
    snap["stress_zz"] = np.asarray(mesh.cell_data["stress_zz"][0]).reshape(snap["alpha"].shape)
    xc = 0.5 * (snap["r_nodes"][1:] + snap["r_nodes"][:-1])
    zc = 0.5 * (snap["z_nodes"][1:] + snap["z_nodes"][:-1])
    snap["x"], snap["z"] = np.meshgrid(xc, zc)
    return snap


def _material(snap, axisymmetric: bool):
    """Each cell's material volume (per radian or per metre; any constant factor)."""
    weight = np.abs(snap["x"]) if axisymmetric else 1.0
    return np.where(snap["alpha"] > 0.5, snap["alpha"] * snap["open_fraction"] * weight, 0.0)


def row_vertical_stress(snap, z, axisymmetric: bool) -> float:
    """The material-weighted mean of ``-sigma_zz`` (Pa) over the row of cells at height
    ``z``."""
    j = int(np.argmin(np.abs(snap["z"][:, 0] - z)))
    w = _material(snap, axisymmetric)[j]
    return float(np.sum(-snap["stress_zz"][j] * w) / np.sum(w)) if w.sum() > 0 else math.nan


def stagnant_share(snap, axisymmetric: bool, where=None) -> float:
    """The share of the material (of the cells ``where``, default all) moving slower than
    ``FlowModeRule.stagnant_speed`` times the mean speed of all the material."""
    from fipy_hopper.diagnostics import FlowModeRule

    w = _material(snap, axisymmetric)
    if not w.sum() > 0:
        return math.nan
    mean = float(np.sum(snap["speed"] * w) / np.sum(w))
    w = w if where is None else np.where(where, w, 0.0)
    slow = snap["speed"] < FlowModeRule().stagnant_speed * mean
    return float(np.sum(w[slow]) / np.sum(w)) if w.sum() > 0 else math.nan


def snapshot_near(run_dir, t):
    """The discharge snapshot nearest ``t`` s after the opening (the last one if ``t`` is
    NaN), or ``None``."""
    from fipy_hopper import plotting

    entries = [e for e in plotting.snapshots(run_dir) if e["stage"] == "discharge"]
    if not entries:
        return None
    if not math.isfinite(t):
        return entries[-1]
    return min(entries, key=lambda e: abs(e["discharge_time_s"] - t))


def stage_times(wall) -> dict:
    """``{stage: t_s}`` of ``wall_pressure.csv``'s stages (s since the opening)."""
    return {str(s): float(wall["t_s"][wall["stage"] == s][0]) for s in np.unique(wall["stage"])}


def theory_vertical_stress(cfg, z) -> tuple:
    """``(sigma_v in Pa, name)``: the classic theories' mean vertical stress at rest at
    height ``z`` of a cone under a bin (:attr:`HopperGeometry.classic`): Janssen in the bin
    (K = 1 - sin phi, as :func:`fipy_hopper.plotting.theory_wall_pressure`), Walker's filling
    slice in the cone on Janssen's stress at the transition."""
    from fipy_hopper import theory

    geom, mat = cfg.hopper, cfg.material
    phi, phi_w = mat.friction_angle_deg, cfg.wall.friction_angle_deg
    mu, K = math.tan(math.radians(phi_w)), float(theory.k_jaky(phi))
    janssen = theory.janssen_vertical_stress
    if z >= geom.cone_height:
        return (float(janssen(geom.fill_level - z, mat.density, geom.bin_diameter, K, mu)),
                "Janssen")
    sigma_vt = float(janssen(geom.fill_height, mat.density, geom.bin_diameter, K, mu))
    theta = geom.half_angle_deg
    x = z + geom.outlet_radius / math.tan(geom.half_angle)
    h = geom.bin_radius / math.tan(geom.half_angle)
    p_n = theory.walker_hopper_wall_pressure(x, h, theta, mat.density, phi, phi_w, sigma_vt)
    return float(p_n / theory.en1991_steep_filling_F(theta, mu)), "Walker"


def bin_loads(row) -> tuple:
    """``(bins, {stage: load})``: the wall bins of a run
    (:func:`fipy_hopper.diagnostics.wall_bins`) and each bin's downward load (N, or N/m of a
    plane silo) at rest and at the 90 % and 50 % stages, from the recovered traction of
    ``wall_pressure.csv``: ``area (-p_n n_z + tau t_z)`` times the section's factor."""
    from fipy_hopper.diagnostics import wall_bins
    from fipy_hopper.io import read_csv

    cfg = _config_of(row)
    bins = wall_bins(cfg)
    wall = read_csv(Path(row["run_dir"]) / "wall_pressure.csv")
    factor = cfg.boundary.section.factor
    loads = {}
    for stage in STAGES[:3]:
        on = wall["stage"] == stage
        if not on.any():
            continue
        if not np.array_equal(wall["wall"][on], bins.wall):
            raise ValueError(f"{row['run_dir']}: wall_pressure.csv's bins are not the "
                             "configuration's")
        loads[stage] = factor * bins.area * (-bins.normal[:, 1] * wall["p_n_Pa"][on]
                                             + bins.tangent[:, 1] * wall["tau_Pa"][on])
    return bins, loads


def wall_vertical_forces(row) -> dict:
    """``{stage: {wall: {"bottom": F, "vertical": F}}}``: the downward load on each wall's
    floor or hopper (its bins facing down) and on its vertical stretch (:func:`bin_loads`)."""
    bins, loads = bin_loads(row)
    bottom = bins.normal[:, 1] < -0.5
    return {stage: {str(w): {"bottom": float(np.sum(load[(bins.wall == w) & bottom])),
                             "vertical": float(np.sum(load[(bins.wall == w) & ~bottom]))}
                    for w in np.unique(bins.wall) if not str(w).startswith("insert")}
            for stage, load in loads.items()}


def insert_surfaces(row, z_widest) -> dict:
    """The insert's load from its upper and lower surfaces (above and below ``z_widest``)
    and its upper surface's mean p_n and tau / p_n, at rest and at the 90 % and 50 %
    stages (:func:`bin_loads`)."""
    from fipy_hopper.io import read_csv

    bins, loads = bin_loads(row)
    wall = read_csv(Path(row["run_dir"]) / "wall_pressure.csv")
    on = bins.wall == "insert_1"
    upper = on & (bins.z > z_widest)
    out = {}
    for stage, load in loads.items():
        rows = wall["stage"] == stage
        p, tau = wall["p_n_Pa"][rows], wall["tau_Pa"][rows]
        w = bins.area[upper]
        out[stage] = {"upper_N": _r(float(np.sum(load[upper])), 3),
                      "lower_N": _r(float(np.sum(load[on & ~upper])), 3),
                      "upper_p_n_Pa": _r(float(np.sum(w * p[upper]) / np.sum(w)), 1),
                      "upper_tau_over_p_n": _r(float(np.sum(w * tau[upper])
                                                     / np.sum(w * p[upper])), 3)}
    return out


def vertical_profiles(row, stage):
    """``{wall: (z, p_n)}`` on the vertical stretches of the walls at ``stage``, by
    height."""
    from fipy_hopper.io import read_csv

    wall = read_csv(Path(row["run_dir"]) / "wall_pressure.csv")
    out = {}
    for name in ("wall", "left_wall"):
        on = (wall["stage"] == stage) & (wall["wall"] == name) & (wall["z_m"] > 0)
        x = wall["r_m"][on]
        vertical = np.abs(x - x[np.argmax(wall["z_m"][on])]) < 1e-9 if on.any() else on[on]
        order = np.argsort(wall["z_m"][on][vertical])
        out[name] = (wall["z_m"][on][vertical][order], wall["p_n_Pa"][on][vertical][order])
    return out


def slot_measures(row, opts) -> tuple:
    """The slot's numbers and rows of ``slot_pressure.csv`` (near/far p_n by height and
    stage), from its run directory."""
    rows, numbers = [], {}
    heights = opts["slot"]["heights"]
    for stage in STAGES:
        prof = vertical_profiles(row, stage)
        (z_n, p_n), (z_f, p_f) = prof["wall"], prof["left_wall"]
        if len(z_n) < 2 or len(z_f) < 2:
            continue
        for z in heights:
            near, far = float(np.interp(z, z_n, p_n)), float(np.interp(z, z_f, p_f))
            rows.append({"stage": stage, "z_m": z, "near_Pa": near, "far_Pa": far,
                         "near_over_far": near / far if far > 0 else math.nan})
        far_on_near = np.interp(z_n, z_f, p_f)
        peak = max(np.max(p_n), np.max(p_f))
        loaded = (p_n > opts["loaded_fraction"] * peak) & (
            far_on_near > opts["loaded_fraction"] * peak) & (z_n <= z_f.max())
        ratio = p_n[loaded] / far_on_near[loaded]
        numbers[stage] = {
            "heights_m": list(heights),
            "near_over_far": [_r(r["near_over_far"], 3) for r in rows if r["stage"] == stage],
            "ratio_max": _r(float(ratio.max()), 3) if ratio.size else None,
            "ratio_max_z_m": _r(float(z_n[loaded][np.argmax(ratio)]), 3) if ratio.size
            else None,
            "ratio_min": _r(float(ratio.min()), 3) if ratio.size else None,
            "ratio_min_z_m": _r(float(z_n[loaded][np.argmin(ratio)]), 3) if ratio.size
            else None,
            "near_peak_Pa": _r(float(np.max(p_n)), 1), "far_peak_Pa": _r(float(np.max(p_f)), 1)}
    return numbers, rows


def slip_coverage(row) -> dict:
    """Where the wall slip was measured (``wall_slip.csv``, the loaded contacts of the hopper
    wall at the flow-mode window's last sample): how many contacts and the highest (m).  The
    rule's reference speed is the axis's at each height, so rows whose axis lies inside an
    insert are not measured."""
    from fipy_hopper.io import read_csv

    slip = read_csv(Path(row["run_dir"]) / "wall_slip.csv")
    z = np.asarray(slip.get("z_m", []), float)
    return {"slip_contacts": int(z.size), "slip_measured_up_to_m": _r(
        float(z.max()), 3) if z.size else None}


def stretch_rows(row) -> list:
    """One row per stretch of hopper wall of a case (``hopper_stretches``; NaN for a number
    the run did not measure, ``null`` in ``summary.json``)."""
    out = []
    for k, st in enumerate(row.get("hopper_stretches") or []):
        st = {key: math.nan if v is None else v for key, v in st.items()}
        out.append({"case": row["case"], "stretch": k, "z_m": st["z_m"],
                    "half_angle_deg": st["half_angle_deg"],
                    "wall_friction_deg": st["wall_friction_deg"],
                    "slip_ratio": st["slip_ratio"], "call": st["call"],
                    "jenike_critical_half_angle_deg": st["jenike_critical_half_angle_deg"],
                    "jenike_call": st["jenike_call"]})
    return out


def _per(row, key):
    """A summary number of a run, per metre for a plane silo (``key_m``)."""
    return row.get(key, row.get(f"{key}_m", math.nan))


def analyse(rows, options):
    """Adds the measures to the rows; returns ``(numbers, stretches, slot rows)``."""
    from fipy_hopper.io import read_csv

    by = {r["case"]: r for r in rows if not r.get("error") and r.get("run_dir")}
    numbers, stretches, slot_rows = {}, [], []
    for name, row in by.items():
        cfg = _config_of(row)
        axi = cfg.hopper.axisymmetric
        row["discharged_fraction"] = 1.0 - row.get("remaining_mass_fraction", math.nan)
        times = stage_times(read_csv(Path(row["run_dir"]) / "wall_pressure.csv"))
        entry = snapshot_near(row["run_dir"], times.get("mid_discharge", math.nan))
        row["stagnant_snapshot_s"] = math.nan
        if entry is not None:
            snap = _snapshot(row["run_dir"], entry)
            row["stagnant_snapshot_s"] = float(entry["discharge_time_s"])
            row["stagnant_share"] = stagnant_share(snap, axi)
            lips = [c.points[0][0] for c in cfg.boundary.chains if c.kind == "wall"]
            beside = {"slot": snap["x"] < min(lips),
                      "ledge": snap["x"] > options["ledge"]["radius"]}.get(name)
            if beside is not None:
                row["stagnant_share_beside"] = stagnant_share(snap, axi, beside)
        mine = stretch_rows(row)
        stretches += mine
        numbers[name] = {
            "end_time_s": row["end_time_s"], "flow_mode": row.get("flow_mode"),
            "steady_rate": _r(_per(row, "steady_discharge_rate_kg_s"), 4),
            "discharged_fraction": _r(row["discharged_fraction"], 3),
            "stages_reached": [s for s in STAGES[1:3] if s in times],
            "wall_slip_ratio": _r(row.get("wall_slip_ratio"), 3),
            "wall_slip_fraction": _r(row.get("wall_slip_fraction"), 3),
            "stagnant_share": _r(row.get("stagnant_share"), 3),
            "stagnant_share_beside": _r(row.get("stagnant_share_beside"), 3),
            "stagnant_snapshot_s": _r(row["stagnant_snapshot_s"], 2),
            "stretches": [{k: (_r(v, 3) if isinstance(v, float) else v)
                           for k, v in s.items() if k not in ("case",)} for s in mine],
            "mass_balance_error": row.get("mass_balance_error"),
            "fill_equilibrium_residual": _r(row.get("fill_equilibrium_residual"), 5),
            "wall_time_s": _r(row.get("wall_time_s"), 1),
            **slip_coverage(row)}
    if "insert" in by:
        numbers["insert"].update(insert_measures(by["insert"], by.get("funnel"), options))
    if "slot" in by:
        slot_numbers, slot_rows = slot_measures(by["slot"], options)
        forces = wall_vertical_forces(by["slot"])
        numbers["slot"].update(pressure=slot_numbers, wall_vertical_N_m={
            stage: {side: {part: _r(v, 2) for part, v in f[wall].items()}
                    for side, wall in (("near", "wall"), ("far", "left_wall"))}
            for stage, f in forces.items()})
        rest = sum(sum(f.values()) for f in forces.get("filling", {}).values())
        row = by["slot"]
        numbers["slot"].update(
            fill_weight_N_m=_r(row.get("fill_weight_N_m"), 2),
            fill_wall_vertical_N_m=_r(row.get("fill_wall_vertical_N_m"), 2),
            fill_outlet_N_m=_r(row.get("fill_outlet_N_m"), 2),
            walls_sum_minus_summary_N_m=_r(rest - row.get("fill_wall_vertical_N_m", math.nan),
                                           6))
    return numbers, stretches, slot_rows


def insert_measures(row, plain, options) -> dict:
    """The insert's loads against the fill's vertical stress times its projected area, the
    stress at the insert's top and at its widest section, from theory and simulated (in
    the ``funnel`` run, the silo without the insert); the prism load (the weight of the fill
    straight above the insert); the loads of its upper and lower surfaces."""
    ins = options["insert"]
    area = math.pi * ins["radius"] ** 2
    cfg = _config_of(plain or row)
    snap = None
    if plain is not None:
        entry = snapshot_near(plain["run_dir"], 0.0)
        snap = _snapshot(plain["run_dir"], entry) if entry is not None else None
    rest, flow = row.get("insert_1_vertical_force_N"), row.get(
        "insert_1_vertical_force_discharge_max_N")
    mat = cfg.material
    prism = mat.density * 9.81 * area * (cfg.hopper.fill_level - ins["z_widest"]
                                         - (ins["z_top"] - ins["z_widest"]) / 3.0)
    out = {"projected_area_m2": _r(area, 6), "bottom_m": ins["z_bottom"],
           "force_rest_N": _r(rest, 3),
           "force_discharge_max_N": _r(flow, 3),
           "fill_weight_N": _r(row.get("fill_weight_N"), 3), "prism_load_N": _r(prism, 3),
           "surfaces": insert_surfaces(row, ins["z_widest"])}
    for where in ("top", "widest"):
        z = ins[f"z_{where}"]
        sigma_theory, which = theory_vertical_stress(cfg, z)
        sigma_sim = row_vertical_stress(snap, z, True) if snap is not None else math.nan
        ref = {"z_m": z, "theory": which, "sigma_v_theory_Pa": _r(sigma_theory, 1),
               "sigma_v_simulated_Pa": _r(sigma_sim, 1)}
        for label, sigma in (("theory", sigma_theory), ("simulated", sigma_sim)):
            ref[f"ratio_rest_{label}"] = _r(rest / (sigma * area), 3)
            ref[f"ratio_discharge_{label}"] = _r(flow / (sigma * area), 3)
        out[where] = ref
    if plain is not None:
        out["without_insert"] = {k: _r(plain.get(k), 3) for k in (
            "wall_slip_ratio", "wall_slip_fraction", "steady_discharge_rate_kg_s")}
        out["without_insert"]["flow_mode"] = plain.get("flow_mode")
    return out


# ---------------------------------------------------------------- pictures
def plot_summary(numbers, stretches):
    """Slip ratio per stretch against Jenike's call; the insert's loads against
    sigma_v A."""
    from fipy_hopper.diagnostics import FlowModeRule

    fig = _sweep.figure(12.0, 4.4)
    ax, bx = fig.subplots(1, 2, width_ratios=(1.5, 1.0))
    labels = [f"{s['case']}\n{s['half_angle_deg']:.0f} deg\n(theta_c "
              f"{s['jenike_critical_half_angle_deg']:.0f})" for s in stretches]
    colours = ["tab:green" if s["jenike_call"] == "mass" else "tab:red" for s in stretches]
    ax.bar(range(len(stretches)), [s["slip_ratio"] for s in stretches], color=colours)
    ax.axhline(FlowModeRule().slip_ratio, color="k", ls="--", lw=1,
               label=f"the rule's slip ratio {FlowModeRule().slip_ratio:g}")
    ax.set_xticks(range(len(stretches)), labels, fontsize=7)
    ax.set_ylabel("slip ratio S of the stretch (-)")
    ax.set_title("Slip ratio per stretch of hopper wall; Jenike's call green mass, red funnel",
                 fontsize=9)
    ax.legend(fontsize=7)
    ins = numbers.get("insert", {})
    if "force_rest_N" in ins:
        area = ins["projected_area_m2"]
        bars = [("at rest", ins["force_rest_N"], "tab:blue"),
                ("discharge\nmax", ins["force_discharge_max_N"], "tab:orange"),
                ("prism", ins["prism_load_N"], "0.8")]
        for where in ("top", "widest"):
            ref = ins[where]
            for label, key, shade in (("", "theory", "0.6"), ("sim.", "simulated", "0.4")):
                sigma = ref[f"sigma_v_{key}_Pa"]
                bars.append((f"sigma_v A\n{where}\n{label or ref['theory']}",
                             math.nan if sigma is None else sigma * area, shade))
        bx.bar(range(len(bars)), [math.nan if v is None else v for _, v, _ in bars],
               color=[c for _, _, c in bars])
        bx.set_xticks(range(len(bars)), [b[0] for b in bars], fontsize=7)
        bx.set_ylabel("vertical force (N)")
        bx.set_title("The insert's load against sigma_v x its projected area", fontsize=9)
    return fig


def plot_slot(row, options):
    """The slot's near and far wall pressure along the height, at rest and in discharge,
    and their ratio."""
    fig = _sweep.figure(10.0, 4.6)
    ax, bx = fig.subplots(1, 2, sharey=True)
    for k, stage in enumerate(STAGES):
        prof = vertical_profiles(row, stage)
        (z_n, p_n), (z_f, p_f) = prof["wall"], prof["left_wall"]
        if len(z_n) < 2:
            continue
        label = stage.replace("_", " ")
        ax.plot(p_n / 1e3, z_n, "-", color=f"C{k}", label=f"{label}, near wall")
        ax.plot(p_f / 1e3, z_f, "--", color=f"C{k}", label=f"{label}, far wall")
        far = np.interp(z_n, z_f, p_f)
        ok = far > options["loaded_fraction"] * max(np.max(p_n), np.max(p_f))
        bx.plot(p_n[ok] / far[ok], z_n[ok], "-", color=f"C{k}", label=label)
    ax.set_xlabel("normal pressure p_n (kPa)")
    ax.set_ylabel("z (m)")
    ax.legend(fontsize=7)
    ax.set_title("Vertical walls: near the slot (solid) and far (dashed)", fontsize=9)
    bx.axvline(1.0, color="k", lw=0.8)
    bx.set_xlabel("p_n near / p_n far (-)")
    bx.legend(fontsize=7)
    bx.set_title("The asymmetry of eccentric discharge", fontsize=9)
    return fig


# ---------------------------------------------------------------- outputs
def findings_of(numbers) -> list:
    out = []
    ex = numbers.get("expanded")
    if ex:
        parts = [f"the {s['half_angle_deg']:.0f} deg stretch slides with S = "
                 f"{s['slip_ratio']:.2f} ({s['call']} flow; Jenike's theta_c "
                 f"{s['jenike_critical_half_angle_deg']:.1f} deg: {s['jenike_call']})"
                 for s in ex["stretches"]]
        out.append("Expanded flow (a steep stretch under a shallow one, under a bin): "
                   + "; ".join(parts) + f"; the silo as a whole is called {ex['flow_mode']} "
                   "flow (the rule asks every stretch to slide), "
                   f"{ex['discharged_fraction']:.0%} out in {ex['end_time_s']:g} s.")
    ins, fu = numbers.get("insert"), numbers.get("funnel")
    if ins and fu and "force_rest_N" in ins:
        st = fu["stretches"][0]
        out.append(
            f"A {st['half_angle_deg']:.0f} deg cone with phi_w = "
            f"{st['wall_friction_deg']:.0f} deg (Jenike: {st['jenike_call']}, theta_c "
            f"{st['jenike_critical_half_angle_deg']:.1f} deg): without the insert its wall "
            f"slides with S = {fu['wall_slip_ratio']:.2f} over {fu['wall_slip_fraction']:.0%} "
            f"of it ({fu['flow_mode']} flow, W = {fu['steady_rate']:.3g} kg/s, stagnant "
            f"{fu['stagnant_share']:.0%} of the material at {fu['stagnant_snapshot_s']:g} s); "
            f"with the inverted cone S = {ins['wall_slip_ratio']:.2f} over "
            f"{ins['wall_slip_fraction']:.0%} ({ins['flow_mode']} flow, W = "
            f"{ins['steady_rate']:.3g} kg/s, stagnant {ins['stagnant_share']:.0%} at "
            f"{ins['stagnant_snapshot_s']:g} s). The slip is measured against the axis's speed "
            f"at each height: without the insert on {fu['slip_contacts']} contacts up to z = "
            f"{fu['slip_measured_up_to_m']:g} m, with it on {ins['slip_contacts']} up to "
            f"{ins['slip_measured_up_to_m']:g} m only (above, the axis is inside the insert), "
            f"so the insert's S is that of the wall up to about its lower apex (z = "
            f"{ins['bottom_m']:g} m).")
        refs = "; ".join(
            f"at its {w} (z = {ins[w]['z_m']:g} m) sigma_v = "
            f"{ins[w]['sigma_v_theory_Pa']:.0f} Pa by {ins[w]['theory']} and "
            f"{ins[w]['sigma_v_simulated_Pa']:.0f} Pa simulated: ratios "
            f"{ins[w]['ratio_rest_theory']:.2f} / {ins[w]['ratio_rest_simulated']:.2f} at rest,"
            f" {ins[w]['ratio_discharge_theory']:.2f} / "
            f"{ins[w]['ratio_discharge_simulated']:.2f} in discharge" for w in ("top", "widest"))
        surf = ins["surfaces"].get("filling", {})
        out.append(
            f"The insert carries {ins['force_rest_N']:.1f} N at rest and at most "
            f"{ins['force_discharge_max_N']:.1f} N in discharge ({ins['fill_weight_N']:.0f} N "
            f"of fill; the prism above it weighs {ins['prism_load_N']:.1f} N); against sigma_v "
            f"times its projected area ({1e4 * ins['projected_area_m2']:.1f} cm^2; the silo "
            f"without the insert; theory / simulated): {refs}. At rest its upper cone carries "
            f"{surf.get('upper_N', math.nan):.1f} N (mean p_n {surf.get('upper_p_n_Pa', 0):.0f}"
            f" Pa, tau/p_n {surf.get('upper_tau_over_p_n', math.nan):.2f}), its lower cone "
            f"{surf.get('lower_N', math.nan):.1f} N.")
    sl = numbers.get("slot")
    if sl and sl.get("pressure"):
        parts = []
        for stage, p in sl["pressure"].items():
            ratios = ", ".join(num(v, ".2f") for v in p["near_over_far"])
            parts.append(f"{stage.replace('_', ' ')} {ratios} (range {num(p['ratio_min'], '.2f')}"
                         f" at z = {num(p['ratio_min_z_m'], 'g')} m to "
                         f"{num(p['ratio_max'], '.2f')} at {num(p['ratio_max_z_m'], 'g')} m)")
        heights = ", ".join(f"{z:g}" for z in next(iter(sl["pressure"].values()))["heights_m"])
        out.append(f"Off-centre slot (flat-bottomed plane silo, full section): p_n near / far "
                   f"wall at z = {heights} m: " + "; ".join(parts) + ".")
        def walls(f):
            return ", ".join(f"{side} wall {f[side]['bottom']:.1f} (floor) + "
                             f"{f[side]['vertical']:.1f} (vertical)" for side in ("near", "far"))

        forces = sl["wall_vertical_N_m"]
        flow = "; ".join(f"{s.replace('_', ' ')}: {walls(f)}" for s, f in forces.items()
                         if s != "filling")
        out.append(
            f"Off-centre slot, vertical balance at rest (N/m): weight {sl['fill_weight_N_m']:.1f}"
            f" = {walls(forces['filling'])} + plate {sl['fill_outlet_N_m']:.1f} (the walls' "
            f"sum less the summary's {sl['fill_wall_vertical_N_m']:.1f}: "
            f"{sl['walls_sum_minus_summary_N_m']:.1e}); in discharge {flow}. Stagnant: "
            f"{sl['stagnant_share']:.0%} of the material, {sl['stagnant_share_beside']:.0%} of "
            f"that left of the slot, at {sl['stagnant_snapshot_s']:g} s.")
    le = numbers.get("ledge")
    if le:
        parts = [f"{s['half_angle_deg']:.0f} deg stretch S = {s['slip_ratio']:.2f} "
                 f"({s['call']}; Jenike {s['jenike_call']})" for s in le["stretches"]]
        out.append("Central hopper under a flat ledge: " + "; ".join(parts)
                   + f"; stagnant {le['stagnant_share']:.0%} of the material, "
                   f"{le['stagnant_share_beside']:.0%} of that beyond the hopper's radius, at "
                   f"{le['stagnant_snapshot_s']:g} s.")
    return out


def headline_of(numbers, stretches) -> str:
    """One line: the stretches' calls against Jenike's, the insert's load ratio at its top,
    the slot's near/far pressure ratio at 90 % left."""
    agree = sum(s["call"] == s["jenike_call"] for s in stretches)
    parts = [f"{agree} of {len(stretches)} stretches of hopper wall slide as Jenike's angle "
             "says"]
    top = numbers.get("insert", {}).get("top")
    if top:
        parts.append(f"the insert carries {top['ratio_rest_theory']:.2f} x sigma_v A at rest "
                     f"({top['theory']} at its top), {top['ratio_discharge_theory']:.2f} at most "
                     "in discharge")
    early = numbers.get("slot", {}).get("pressure", {}).get("early_discharge")
    if early:
        parts.append(f"off-centre slot: near / far wall pressure {num(early['ratio_min'], '.2f')}-"
                     f"{num(early['ratio_max'], '.2f')} at 90 % left (1.00 at rest)")
    return "; ".join(parts) + "."


CAPTIONS = {
    "expanded": "expanded-flow hopper (a 15 deg stretch under a 60 deg one)",
    "funnel": "40 deg cone, phi_w = 20 deg, no insert",
    "insert": "the same cone with an inverted-cone (double-cone) insert on the axis",
    "slot": "flat-bottomed plane silo with an off-centre slot (full section)",
    "ledge": "flat-bottomed silo with a central hopper (a ledge out to the bin wall)",
}


def write_outputs(out, rows, numbers, stretches, slot_rows, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "silo", "end_time_s", "flow_mode", "wall_slip_ratio", "wall_slip_fraction",
        "discharged_fraction", "stagnant_share", "stagnant_share_beside", "error"))
    _sweep.write_rows_csv(out / "stretches.csv", stretches)
    _sweep.write_rows_csv(out / "slot_pressure.csv", slot_rows)
    figures = []
    if stretches:
        _sweep.save(plot_summary(numbers, stretches), out / "geometries.png")
        figures.append({"file": "geometries.png", "caption": (
            "Left: each stretch of hopper wall's slip ratio (the package's call: mass flow "
            "where S reaches the dashed line), coloured by Jenike's call for its slope and "
            "wall friction (the insert's: the wall below its lower apex only). Right: the "
            "insert's vertical load at rest and its largest in discharge, the weight of the "
            "prism of fill above it, and the fill's vertical stress at its top and at its "
            "widest section (theory, and simulated without the insert) times its projected "
            "area.")})
    slot = next((r for r in rows if r["case"] == "slot" and not r.get("error")), None)
    if slot is not None:
        _sweep.save(plot_slot(slot, options), out / "slot_walls.png")
        figures.append({"file": "slot_walls.png", "caption": (
            "Off-centre slot: the normal pressure on the near and the far vertical wall at "
            "rest, at 90 % and 50 % left and the discharge envelope, and their ratio.")})
    for row in rows:
        for picture in ("flow_pattern", "wall_pressure"):
            source = Path(row.get("run_dir", "")) / f"{picture}.png"
            if source.is_file():
                name = f"{picture}_{row['case']}.png"
                shutil.copyfile(source, out / name)
                figures.append({"file": name, "caption": (
                    f"{row['case']}: {CAPTIONS[row['case']]}: "
                    + ("the flow pattern (the run's picture)." if picture == "flow_pattern"
                       else "the wall pressure (the run's picture)."))})
    columns = ["case", "end time (s)", "flow mode", "S (worst stretch)", "slip fraction",
               "out (%)", "stagnant (%)", "wall time (s)"]
    table_rows = [[name, n["end_time_s"], n["flow_mode"], n["wall_slip_ratio"],
                   n["wall_slip_fraction"], _r(100 * n["discharged_fraction"], 1),
                   _r(100 * n["stagnant_share"], 1) if n["stagnant_share"] is not None
                   else None, n["wall_time_s"]] for name, n in numbers.items()]
    stretch_table = [[s["case"], s["stretch"], _r(s["half_angle_deg"], 1),
                      s["wall_friction_deg"], _r(s["slip_ratio"], 3), s["call"],
                      _r(s["jenike_critical_half_angle_deg"], 1), s["jenike_call"]]
                     for s in stretches]
    tables = [{"title": "Runs", "columns": columns, "rows": table_rows},
              {"title": "Stretches of hopper wall", "columns": [
                  "case", "stretch", "slope (deg)", "phi_w (deg)", "slip ratio", "call",
                  "Jenike theta_c (deg)", "Jenike's call"], "rows": stretch_table}]
    if slot_rows:
        tables.append({"title": "Off-centre slot: near and far wall pressure", "columns": [
            "stage", "z (m)", "near p_n (Pa)", "far p_n (Pa)", "near / far"],
            "rows": [[r["stage"], r["z_m"], _r(r["near_Pa"], 0), _r(r["far_Pa"], 0),
                      _r(r["near_over_far"], 3)] for r in slot_rows]})
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    findings = findings_of(numbers)
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables, rows, argv, headline=headline_of(numbers, stretches))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m")
    parser.add_argument("--end-time", type=float,
                        help="s of discharge for every case (default: Beverloo's time for "
                             "drained_fraction of each fill)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_size", "end_time"))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    numbers, stretches, slot_rows = analyse(rows, study["options"])
    write_outputs(args.out, rows, numbers, stretches, slot_rows, study["options"],
                  study["setting"], argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
