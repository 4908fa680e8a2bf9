"""Wall loads along the wall: at rest and in discharge, against the theories; their
convergence with the cell size and their independence of the stiffness.

Each case fills a hopper, brings it to rest quasi-statically (gravity ramped over ten periods
of the column's lowest elastic mode) and discharges it past the half-way mark.  The package
measures the wall loads from the wall's reaction (the contact impulses, ``wall_pressure.csv``,
see :class:`fipy_hopper.diagnostics.WallLoads`): at rest (``filling``), over 0.1 s windows from
the moment 90 % and 50 % of the mass is left (``early_discharge``, ``mid_discharge``), and the
envelope of consecutive 0.1 s windows over the discharge (``discharge_envelope``); beside them
the plain binning of the same reaction node by node (``p_n_raw_Pa``) and the estimate from
the stresses of the cells next to the wall (``p_n_stress_Pa``).  The default cases are the
reference hopper (D = 0.3 m, 20 deg, D0 = 0.06 m, 0.3 m fill, phi = 30 deg, phi_w = 15 deg)
at 7.5, 5, 3.75 and 2.5 mm cells (E = 5 MPa), at 5 mm with E = 2 and 20 MPa, the same hopper
with a 30 deg cone at 5 mm, and filled to rest only (``end_time = 0``) at 5 mm with cones of
10, 35 and 60 deg and a 20 deg wedge (the 20 deg cone at rest is the reference's ``filling``).
Every case reports its wall loads on bins of ``wall_bin_width`` = 15 mm of wall
(``run.wall_bin_width``: what ``"auto"`` gives at 5 mm and finer, set so that the 7.5 mm case,
whose ``"auto"`` is 22.5 mm, has the same bins too).

Theory, from :mod:`fipy_hopper.theory` (all with the material's phi and the wall's phi_w):

* bin (vertical wall): Janssen with ``K = 1 - sin(phi)`` (Jaky) and ``mu = tan(phi_w)``;
  EN 1991-4 filling loads with ``K_m = 1.1 (1 - sin(phi))`` (mean values, no a_K factors),
  for slender silos (``h_c/d_c >= 2``) eq. 5.1-5.6 and otherwise the §5.3 squat/intermediate
  form with a levelled surface (angle of repose 0, ``h0 = 0``); EN discharge ``C_h = 1.15``
  times the filling load (the slender-silo factor; for squat silos EN allows 1.0 [M]);
* cone: Walker's slice method (D = 1) with the EN filling ratio ``F_f`` and Walker's
  discharge ratio ``F_e`` on top of the Janssen vertical stress at the transition; EN 1991-4
  hopper loads (class from K_m and mu; steep: F_f / F_e, shallow: F_s) on top of the EN
  vertical stress at the transition (``C_b = 1``);
* the switch: Walker's simple estimate, ``F_e sigma_vt`` just below the transition
  (:func:`fipy_hopper.theory.walker_switch_pressure`), against the largest simulated
  discharge pressure within a quarter of the cone's slant length below the transition.

During discharge the theories are evaluated with the *equivalent levelled surface* of the
mass left in the hopper at the sample time (EN's equivalent surface).  The comparison numbers
are means over two regions that avoid the outlet, the transition and the free surface: the
bin from 5 % to 85 % of the (equivalent) fill depth below the surface, and the cone from 20 %
to 80 % of its slant length; ``diff`` is ``100 (mean simulated - mean theory) / mean theory``.

Convergence and stiffness, bin by bin: the cases share their bins, so two profiles of a stage
(each stage and the envelope) are compared bin by bin with no merging or interpolation: the
largest relative difference ``|p_a - p_b| / p_b`` of a bin, leaving out the two bins at the
outlet lip (a re-entrant corner, where the stress is singular) and the bins whose top reaches
above the material's surface (the equivalent levelled surface in discharge), with its place
and the largest with the transition's corner bin (the bin wall's first) aside; and the
relative L2 difference ``|p_a - p_b| / |p_b|`` over every bin of the wall, the lip's included.

Smoothness, per case and stage, of the three estimates of p_n along the hopper wall (the
bins below the transition): the RMS relative deviation from a cubic fitted over its bins,
2 cm left out at each end (:func:`fipy_hopper.diagnostics.smooth_fit_rms`), and the
bin-to-bin scatter ``mean_i |p_i - (p_(i-1) + p_(i+1))/2| / p_i`` over its bins
(:func:`fipy_hopper.diagnostics.bin_scatter`).

Written to ``--out`` (default ``studies/output/wall_pressure``): ``profiles.csv`` (the three
estimates and the theories' p_n at every bin), ``comparison.csv`` (the region means),
``switch.csv``, ``convergence.csv``, ``smoothness.csv``, ``study.json``,
``wall_pressure_<case>.png``, ``rest_profiles.png``, ``convergence.png``,
``stress_pattern_<case>.png`` and ``cases/<name>/``.

Usage::

    python studies/wall_pressure.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                    [--cell-sizes 0.0075 0.005 0.00375 0.0025]
                                    [--half-angles 20 30] [--youngs-moduli 2e6 5e6 20e6]
                                    [--wall-bin-width 0.015] [--rest-angles 10 20 35 60]
                                    [--rest-wedges 20]
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

from fipy_hopper import geometry, theory  # noqa: E402
from fipy_hopper.config import HopperConfig  # noqa: E402
from fipy_hopper.diagnostics import (bin_scatter, relative_l2, wall_bins,  # noqa: E402
                                     smooth_fit_rms)

NAME = "wall_pressure"
TITLE = "Wall pressure at rest and in discharge against Janssen, Walker and EN 1991-4"
DEFAULTS = {
    "half_angles": (20.0, 30.0),     # deg; the first is the reference of the series below
    "wall_friction": 15.0,           # deg
    "friction_angle": 30.0,          # deg
    "bin_diameter": 0.3,             # m
    "outlet_diameter": 0.06,         # m
    "fill_height": 0.3,              # m above the transition
    "bin_height": 0.35,              # m
    "cell_size": 0.005,              # m (the other half-angles and the stiffness series)
    "cell_sizes": (0.0075, 0.005, 0.00375, 0.0025),    # m, the grid series (reference angle)
    "youngs_modulus": 5.0e6,         # Pa
    "youngs_moduli": (2.0e6, 5.0e6, 20.0e6),           # Pa, the stiffness series
    "end_time": None,                # s; None: emptying_fraction of the Beverloo emptying time
    "emptying_fraction": 0.65,
    "wall_bin_width": 0.015,         # m, every case's bins (auto at <= 5 mm; 22.5 mm at 7.5)
    "rest_angles": (10.0, 20.0, 35.0, 60.0),           # deg, cones at rest at cell_size
    "rest_wedges": (20.0,),          # deg, wedges at rest at cell_size
    "case_plots": True,
}
QUICK = {"half_angles": (30.0,), "bin_diameter": 0.2, "fill_height": 0.1, "bin_height": 0.12,
         "cell_size": 0.01, "cell_sizes": (0.01, 0.0075), "youngs_moduli": (2.0e6, 20.0e6),
         "end_time": 0.5, "wall_bin_width": 0.02, "rest_angles": (15.0, 30.0),
         "rest_wedges": (15.0,), "case_plots": False}
STAGES = ("filling", "early_discharge", "mid_discharge")
#: the stages compared between cell sizes and moduli: the windowed stages and the envelope
SERIES_STAGES = STAGES + ("discharge_envelope",)
#: bins at the outlet lip left out of the comparisons bin by bin (a re-entrant corner)
LIP_BINS = 2
#: m of the hopper wall left out at each end of the smoothness measure's cubic fit
FIT_MARGIN = 0.02
#: the estimates of p_n measured for smoothness: their columns of ``wall_pressure.csv``
ESTIMATES = (("recovered", "p_n_Pa"), ("raw", "p_n_raw_Pa"), ("stress", "p_n_stress_Pa"))


def base_config(opts, theta, cell_size=None, youngs_modulus=None, shape="conical") -> dict:
    if shape == "wedge":
        hopper = {"shape": "wedge", "bin_width": opts["bin_diameter"],
                  "outlet_width": opts["outlet_diameter"]}
    else:
        hopper = {"bin_diameter": opts["bin_diameter"], "outlet_diameter": opts["outlet_diameter"]}
    hopper.update(half_angle_deg=float(theta), fill_height=opts["fill_height"],
                  bin_height=opts["bin_height"])
    return {"hopper": hopper,
            "material": {"friction_angle_deg": opts["friction_angle"],
                         "youngs_modulus": float(youngs_modulus or opts["youngs_modulus"])},
            "wall": {"friction_angle_deg": opts["wall_friction"]},
            "numerics": {"cell_size": float(cell_size or opts["cell_size"])},
            "run": {"output_interval": 0.05, "wall_bin_width": float(opts["wall_bin_width"])}}


def case_variants(opts) -> list:
    """``(theta, shape, cell_size, E, series)`` of every case, without repeats: the grid
    series and the stiffness series at the first half-angle, the other half-angles, and the
    cones and wedges at rest (``rest``) at ``cell_size`` that are not among them (a cone
    discharged at that cell size is at rest in its ``filling`` stage)."""
    ref = float(opts["half_angles"][0])
    h, E0 = float(opts["cell_size"]), float(opts["youngs_modulus"])
    variants = {}
    for cell in opts["cell_sizes"]:
        variants[(ref, "conical", float(cell), E0)] = "grid"
    for E in opts["youngs_moduli"]:
        variants.setdefault((ref, "conical", h, float(E)), "stiffness")
    for theta in opts["half_angles"][1:]:
        variants.setdefault((float(theta), "conical", h, E0), "angle")
    for shape, angles in (("conical", opts["rest_angles"]), ("wedge", opts["rest_wedges"])):
        for theta in angles:
            variants.setdefault((float(theta), shape, h, E0), "rest")
    return [(t, shape, cell, E, series) for (t, shape, cell, E), series in variants.items()]


def rest_cases(rows: list, options: dict) -> list:
    """The rows of the hoppers at rest of ``rest_angles`` and ``rest_wedges`` (at
    ``cell_size`` and ``youngs_modulus``; a discharged cone's row stands for its angle)."""
    wanted = ([(float(t), "conical") for t in options["rest_angles"]]
              + [(float(t), "wedge") for t in options["rest_wedges"]])
    found = {(r["half_angle_deg"], r.get("shape", "conical")): r for r in rows
             if r["cell_size_m"] == options["cell_size"]
             and r["youngs_modulus_Pa"] == options["youngs_modulus"]}
    return [found[key] for key in wanted if key in found]


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    cases = []
    for theta, shape, cell, E, series in case_variants(opts):
        config = base_config(opts, theta, cell, E, shape)
        if series == "rest":
            config["run"]["end_time"] = 0.0
            cases.append(_sweep.make_case(
                _sweep.case_name(("wedge" if shape == "wedge" else "theta", float(theta)),
                                 ("wall", float(opts["wall_friction"])), ("h", 1000 * cell),
                                 ("E", E / 1e6), ("rest", "")),
                {"half_angle_deg": float(theta), "shape": shape,
                 "wall_friction_deg": float(opts["wall_friction"]), "cell_size_m": cell,
                 "youngs_modulus_Pa": E, "series": series, "end_time_s": 0.0},
                config, plots=opts["case_plots"]))
            continue
        end = opts["end_time"]
        if end is None:
            cfg = _sweep._config(config)
            rate = float(theory.beverloo_rate(cfg.material.density, cfg.hopper.outlet_diameter)
                         * theory.rose_tanaka_factor(theta))
            mass = cfg.material.density * cfg.hopper.fill_volume()
            end = round(opts["emptying_fraction"] * mass / rate, 2)
        config["run"]["end_time"] = float(end)
        cases.append(_sweep.make_case(
            _sweep.case_name(("theta", float(theta)), ("wall", float(opts["wall_friction"])),
                             ("h", 1000 * cell), ("E", E / 1e6)),
            {"half_angle_deg": float(theta), "shape": shape,
             "wall_friction_deg": float(opts["wall_friction"]), "cell_size_m": cell,
             "youngs_modulus_Pa": E, "series": series, "end_time_s": float(end)},
            config, plots=True))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- theory along the wall
def equivalent_fill(cfg: HopperConfig, mass: float) -> float:
    """Height above the transition of the levelled surface holding ``mass`` (m; may be < 0
    when the surface is in the cone, then the bin curves are not drawn)."""
    geom = cfg.hopper
    r0, r1, h = geom.outlet_radius, geom.bin_radius, geom.cone_height
    cone = math.pi * h / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)
    return (mass / cfg.material.density - cone) / (math.pi * r1 * r1)


def theory_curves(cfg: HopperConfig, s, fill: float, stage: str) -> dict:
    """``{name: p_n(s)}`` (Pa) for the wall points ``s`` with a levelled surface ``fill`` m
    above the transition; NaN outside a theory's section or where it does not apply."""
    geom, mat = cfg.hopper, cfg.material
    phi, phi_w = mat.friction_angle_deg, cfg.wall.friction_angle_deg
    rho, g = mat.density, theory.G
    gamma = rho * g
    D = geom.bin_diameter
    mu = math.tan(math.radians(phi_w))
    K_j = float(theory.k_jaky(phi))
    K_m = float(theory.k_en1991(phi))
    s = np.asarray(s, float)
    r, z, _, _ = geometry.wall_point(s, geom)
    s_t = float(geometry.transition_arc_length(geom))
    in_bin = s > s_t
    depth = geom.cone_height + fill - z
    out = {}
    discharge = stage != "filling"
    if fill <= 0 or mu <= 0:
        return out
    # bin
    dz = np.clip(depth, 0.0, None)
    ok_bin = in_bin & (depth >= 0)
    jan = np.where(ok_bin, theory.janssen_wall_pressure(dz, rho, D, K_j, mu), np.nan)
    out["Janssen (K = 1 - sin phi)"] = jan
    slender = fill / D >= 2.0
    if slender:
        en = theory.en1991_filling_vertical_walls(dz, gamma, D, K_m, mu)
        p_vft_en = float(theory.en1991_filling_vertical_walls(fill, gamma, D, K_m, mu).p_v)
    else:
        en = theory.en1991_filling_intermediate(dz, gamma, D, K_m, mu, 0.0)
        p_vft_en = float(theory.en1991_filling_intermediate(fill, gamma, D, K_m, mu, 0.0).p_v)
    p_h = np.asarray(en.p_h, float)
    if discharge:
        p_h = np.asarray(theory.en1991_discharge_vertical_walls(p_h, mu * p_h)[0], float)
    out["EN 1991-4 bin" + (" discharge (C_h = 1.15)" if discharge else " filling")] = \
        np.where(ok_bin, p_h, np.nan)
    # cone (theta < 90)
    if geom.cone_height > 0:
        theta = geom.half_angle_deg
        h = geom.bin_radius / math.tan(geom.half_angle)
        x = np.clip(z + geom.outlet_radius / math.tan(geom.half_angle), 0.0, h)
        sigma_vt = float(theory.janssen_vertical_stress(fill, rho, D, K_j, mu))
        mode = "discharge" if discharge else "filling"
        try:
            walker = theory.walker_hopper_wall_pressure(x, h, theta, rho, phi, phi_w, sigma_vt,
                                                        mode=mode)
            out[f"Walker slice, {mode}"] = np.where(~in_bin, walker, np.nan)
        except ValueError:
            pass
        try:
            en_h = theory.en1991_hopper_pressures(x, h, theta, gamma, K_m, mu, p_vft_en,
                                                  mode=mode, phi_i=phi)
            label = f"EN 1991-4 hopper ({en_h.hopper_class}), {mode}"
            out[label] = np.where(~in_bin, np.asarray(en_h.p_n, float), np.nan)
        except ValueError:
            pass
    return {k: np.asarray(v, float) for k, v in out.items()}


def switch_estimate(cfg: HopperConfig, fill: float):
    """Walker's switch estimate ``(K sigma_vt, F_e sigma_vt, F_e / K)`` (Pa, Pa, -)."""
    mat = cfg.material
    K = float(theory.k_jaky(mat.friction_angle_deg))
    mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
    sigma_vt = float(theory.janssen_vertical_stress(max(fill, 0.0), mat.density,
                                                    cfg.hopper.bin_diameter, K, mu))
    sw = theory.walker_switch_pressure(sigma_vt, K, mat.friction_angle_deg,
                                       cfg.wall.friction_angle_deg, cfg.hopper.half_angle_deg)
    return float(sw.cylinder), float(sw.hopper), float(sw.ratio)


# ---------------------------------------------------------------- analysis
def load_case(row):
    from fipy_hopper.api import read_results

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_results(row["run_dir"])


def stage_fill(res, stage: str) -> float:
    """The equivalent levelled fill (m above the transition) at a wall sample."""
    cfg = res.config
    if stage == "filling":
        return cfg.hopper.fill_height
    sel = res.wall_stage(stage)
    if not len(sel["t_s"]):
        return math.nan
    t = float(sel["t_s"][0])
    ts = res.timeseries
    mass = float(np.interp(t, ts["t_s"], ts["mass_in_hopper_kg"]))
    return equivalent_fill(cfg, mass)


def analyse(rows: list, options: dict) -> tuple:
    """Returns ``(profiles, comparison, switch, numbers)`` (lists of dicts and a dict)."""
    profiles, comparison, switch = [], [], []
    for row in rows:
        try:
            res = load_case(row)
        except FileNotFoundError:
            continue
        cfg = res.config
        geom = cfg.hopper
        s_t = float(geometry.transition_arc_length(geom))
        h = cfg.numerics.cell_size
        for stage in STAGES:
            sel = res.wall_stage(stage)
            if not len(sel["s_m"]):
                continue
            fill = stage_fill(res, stage)
            s, p = sel["s_m"], sel["p_n_Pa"]
            at_rest_only = row.get("series") == "rest"      # no theory: wedges, other slopes
            curves = {} if at_rest_only else theory_curves(cfg, s, fill, stage)
            for k in range(len(s)):
                profiles.append({"case": row["case"], "stage": stage, "t_s": float(sel["t_s"][k]),
                                 "s_m": float(s[k]), "z_m": float(sel["z_m"][k]),
                                 "p_n_sim_Pa": float(p[k]),
                                 "p_n_raw_Pa": float(sel["p_n_raw_Pa"][k]),
                                 "p_n_stress_Pa": float(sel["p_n_stress_Pa"][k]),
                                 **{name: float(v[k]) for name, v in curves.items()}})
            z = sel["z_m"]
            depth = geom.cone_height + fill - z
            regions = {"bin": (s > s_t) & (depth >= 0.05 * fill) & (depth <= 0.85 * fill),
                       "cone": (s >= 0.2 * s_t) & (s <= 0.8 * s_t)}
            for region, mask in regions.items():
                for name, v in curves.items():
                    m = mask & np.isfinite(v) & np.isfinite(p)
                    if m.sum() < 2:
                        continue
                    mean_sim, mean_th = float(np.mean(p[m])), float(np.mean(v[m]))
                    comparison.append({
                        "case": row["case"], "half_angle_deg": row["half_angle_deg"],
                        "stage": stage, "region": region, "theory": name, "points": int(m.sum()),
                        "fill_m": fill, "mean_sim_Pa": mean_sim, "mean_theory_Pa": mean_th,
                        "diff_pct": _sweep.pct(mean_sim, mean_th),
                        "rms_rel_diff_pct": float(100 * np.sqrt(np.mean((p[m] - v[m]) ** 2))
                                                  / mean_th)})
            if stage != "filling" and geom.cone_height > 0:
                window = (s >= s_t - 0.25 * s_t) & (s <= s_t + 2 * h)
                fsel = res.wall_stage("filling")
                fwin = (fsel["s_m"] >= s_t - 0.25 * s_t) & (fsel["s_m"] <= s_t + 2 * h)
                if window.any():
                    k = int(np.argmax(np.where(window, p, -np.inf)))
                    cyl, hop, ratio = switch_estimate(cfg, fill)
                    fill_peak = float(np.max(fsel["p_n_Pa"][fwin])) if fwin.any() else math.nan
                    switch.append({
                        "case": row["case"], "half_angle_deg": row["half_angle_deg"],
                        "stage": stage, "fill_m": fill, "peak_sim_Pa": float(p[k]),
                        "peak_s_m": float(s[k]), "transition_s_m": s_t,
                        "peak_filling_sim_Pa": fill_peak,
                        "sim_ratio_discharge_to_filling": float(p[k]) / fill_peak,
                        "walker_hopper_Pa": hop, "walker_cylinder_Pa": cyl,
                        "walker_ratio_Fe_over_K": ratio,
                        "diff_peak_vs_walker_pct": _sweep.pct(float(p[k]), hop)})
    numbers = {}
    for c in comparison:
        key = f"diff_pct[{c['case']}|{c['stage']}|{c['region']}|{c['theory']}]"
        numbers[key] = c["diff_pct"]
    for sw in switch:
        numbers[f"switch_peak_Pa[{sw['case']}|{sw['stage']}]"] = sw["peak_sim_Pa"]
        numbers[f"switch_diff_vs_walker_pct[{sw['case']}|{sw['stage']}]"] = \
            sw["diff_peak_vs_walker_pct"]
    numbers["failed"] = [r["case"] for r in rows if r.get("error")]
    numbers["missing_stages"] = sorted(
        {f"{r['case']}:{st}" for r in rows for st in
         (STAGES[:1] if r.get("series") == "rest" else STAGES)}
        - {f"{p['case']}:{p['stage']}" for p in profiles})
    return profiles, comparison, switch, numbers


# ---------------------------------------------------------------- convergence, stiffness
def stage_profile(res, stage: str):
    """``(s, p_n)`` of a stage on the run's own bins (the recovered traction), ``None`` when
    the stage is missing."""
    sel = res.wall_stage(stage)
    if not len(sel["s_m"]):
        return None
    return sel["s_m"], sel["p_n_Pa"]


def surface_arc_length(res, stage: str) -> float:
    """Arc length (m) of the wall at the material's surface in a stage: the fill's at rest and
    for the envelope (its first window holds the full hopper), else the equivalent levelled
    surface at the window."""
    geom = res.config.hopper
    fill = (stage_fill(res, stage) if stage in ("early_discharge", "mid_discharge")
            else geom.fill_height)
    return float(geometry.arc_length(geom.cone_height + fill, geom))


def compared_bins(res, stage: str) -> np.ndarray:
    """The bins that a comparison bin by bin counts: all but the outlet lip's
    :data:`LIP_BINS` (a re-entrant corner: the stress is singular) and those whose top
    reaches above the material's surface (:func:`surface_arc_length`)."""
    cfg = res.config
    bins = wall_bins(cfg)
    top = bins.hi                              # the wall's own chain: positions are its s
    return (np.arange(len(top)) >= LIP_BINS) & (top <= surface_arc_length(res, stage) + 1e-9)


def bin_by_bin(res_a, res_b, stage: str):
    """Two runs' profiles of a stage on the same bins, compared bin by bin: the largest
    relative difference ``|p_a - p_b| / p_b`` over the bins both count
    (:func:`compared_bins`) and its place (``s``, and which bin: on the cone or the bin wall,
    the bin wall's first above the transition's corner, the top one at the surface); the
    largest on the cone and on the bin wall with its first and the top bins aside; and the
    relative L2 difference over every bin of the wall, the lip's included (all in %).
    ``None`` when a run misses the stage; ``ValueError`` when the bins differ."""
    a, b = stage_profile(res_a, stage), stage_profile(res_b, stage)
    if a is None or b is None:
        return None
    (s, pa), (s_b, pb) = a, b
    if len(s) != len(s_b) or not np.allclose(s, s_b, rtol=0.0, atol=1e-9):
        raise ValueError(f"{res_a.path.name} and {res_b.path.name} are not on the same wall "
                         "bins: give them the same run.wall_bin_width")
    s_t = float(geometry.transition_arc_length(res_b.config.hopper))
    keep = compared_bins(res_a, stage) & compared_bins(res_b, stage) & (pb > 0)
    diff = 100 * np.abs(pa - pb) / np.where(keep, pb, 1.0)
    special = {int(np.argmax(s > s_t)): "first bin above the transition",
               int(np.flatnonzero(keep)[-1]): "top bin at the surface"}
    k = int(np.flatnonzero(keep)[np.argmax(diff[keep])])
    where = ("cone" if s[k] < s_t else "bin wall") + (f", {special[k]}" if k in special else "")
    inner = keep.copy()
    inner[list(special)] = False

    def largest(mask):
        return float(diff[mask].max()) if mask.any() else math.nan

    return {"max_diff_pct": float(diff[k]), "at_s_m": float(s[k]), "where": where,
            "cone_max_diff_pct": largest(inner & (s < s_t)),
            "bin_wall_max_diff_pct": largest(inner & (s > s_t)),
            "l2_change_pct": 100 * relative_l2(pa, pb)}


def corner_deficit(res) -> float:
    """How much less the bin wall's first bin above the transition carries at rest than the
    next one up, ``100 (1 - p_1 / p_2)`` (%): where the corner's node takes the cone's load
    along the cone's normal and the bin wall's first cell is under-loaded."""
    s, p = stage_profile(res, "filling")
    k = int(np.argmax(s > float(geometry.transition_arc_length(res.config.hopper))))
    return 100 * (1 - float(p[k] / p[k + 1]))


def smoothness_analysis(rows: list) -> list:
    """Per case and stage, how smooth p_n is along the hopper wall (the cone, the wedge's
    plate: the bins below the transition) for each of :data:`ESTIMATES`: ``rms_<estimate>_pct``,
    the RMS relative deviation from a cubic fitted over its bins with :data:`FIT_MARGIN` left
    out at each end (:func:`~fipy_hopper.diagnostics.smooth_fit_rms`), and
    ``scatter_<estimate>_pct``, the bin-to-bin scatter over its bins
    (:func:`~fipy_hopper.diagnostics.bin_scatter`)."""
    out = []
    for row in rows:
        try:
            res = load_case(row)
        except FileNotFoundError:
            continue
        s_t = float(geometry.transition_arc_length(res.config.hopper))
        for stage in SERIES_STAGES:
            sel = res.wall_stage(stage)
            if not len(sel["s_m"]):
                continue
            s = sel["s_m"]
            cone = s < s_t
            entry = {"case": row["case"], "series": row.get("series", ""),
                     "shape": row.get("shape", "conical"),
                     "half_angle_deg": row["half_angle_deg"], "cell_size_m": row["cell_size_m"],
                     "youngs_modulus_Pa": row["youngs_modulus_Pa"], "stage": stage}
            for name, column in ESTIMATES:
                p = sel[column]
                entry[f"rms_{name}_pct"] = 100 * smooth_fit_rms(s, p, FIT_MARGIN,
                                                                s_t - FIT_MARGIN)
                entry[f"scatter_{name}_pct"] = 100 * bin_scatter(p[cone])
            out.append(entry)
    return out


def estimates_analysis(rows: list) -> list:
    """Where the two estimates of the filled wall pressure differ: the reaction's and the
    stress-sampled mean ``p_n`` per region (the outlet lip's bin, the cone's middle, the two
    bins at the transition, the bin's middle) and ``100 (stress - reaction) / reaction``."""
    out = []
    for row in rows:
        try:
            res = load_case(row)
        except FileNotFoundError:
            continue
        sel = res.wall_stage("filling")
        if not len(sel["s_m"]) or "p_n_stress_Pa" not in sel:
            continue
        geom = res.config.hopper
        s, p, q = sel["s_m"], sel["p_n_Pa"], sel["p_n_stress_Pa"]
        s_t = float(geometry.transition_arc_length(geom))
        s_top = float(geometry.arc_length(geom.fill_level, geom))
        width = res.config.wall_bin_width_m
        regions = {"outlet lip": s < width,
                   "cone middle": (s > 0.2 * s_t) & (s < 0.8 * s_t),
                   "transition": np.abs(s - s_t) < width,
                   "bin middle": ((s > s_t + 0.2 * (s_top - s_t))
                                  & (s < s_top - 0.2 * (s_top - s_t)))}
        for region, mask in regions.items():
            mask = mask & np.isfinite(q)
            if not mask.any():
                continue
            a, b = float(np.mean(p[mask])), float(np.mean(q[mask]))
            out.append({"case": row["case"], "region": region, "reaction_Pa": a,
                        "stress_sampled_Pa": b, "diff_pct": _sweep.pct(b, a)})
    return out


def series_analysis(rows: list) -> tuple:
    """Convergence with the cell size and the spread with E, bin by bin on the runs' shared
    bins (:func:`bin_by_bin`): ``(table rows, numbers, profiles {case: {stage: (s, p)}})``."""
    loaded = {}
    for row in rows:
        try:
            loaded[row["case"]] = (row, load_case(row))
        except FileNotFoundError:
            continue
    profiles = {case: {stage: stage_profile(res, stage) for stage in SERIES_STAGES}
                for case, (row, res) in loaded.items()}
    table, numbers = [], {}
    grid = sorted((r for r, _ in loaded.values() if _in_series(r, rows, "grid")),
                  key=lambda r: -r["cell_size_m"])
    for stage in SERIES_STAGES:
        runs = [(r, loaded[r["case"]][1]) for r in grid if profiles[r["case"]][stage] is not None]
        if len(runs) < 2:
            continue
        finest = runs[-1][1]
        for (ra, a), (rb, b) in zip(runs[:-1], runs[1:]):
            key = f"{1000 * ra['cell_size_m']:g}->{1000 * rb['cell_size_m']:g} mm"
            pair = bin_by_bin(a, b, stage)
            to_finest = bin_by_bin(a, finest, stage)
            for name in ("l2_change_pct", "max_diff_pct", "cone_max_diff_pct",
                         "bin_wall_max_diff_pct"):
                numbers[f"{name}[{stage}|{key}]"] = pair[name]
            table.append({"series": "grid", "stage": stage, "pair": key, **pair,
                          "l2_from_finest_pct": to_finest["l2_change_pct"]})
        if stage == "filling":
            for r, res in runs:
                numbers[f"corner_deficit_pct[{1000 * r['cell_size_m']:g} mm]"] = \
                    corner_deficit(res)
        changes = [t["l2_change_pct"] for t in table
                   if t["series"] == "grid" and t["stage"] == stage]
        numbers[f"l2_changes_decrease[{stage}]"] = bool(np.all(np.diff(changes) < 0))
        numbers[f"l2_last_change_pct[{stage}]"] = changes[-1]
    stiff = [r for r, _ in loaded.values() if _in_series(r, rows, "stiffness")]
    for stage in SERIES_STAGES:
        curves = [(r, profiles[r["case"]][stage]) for r in stiff
                  if profiles[r["case"]][stage] is not None]
        spread = {"": 0.0, "cone": 0.0, "bin": 0.0}
        for i, (ra, (s, pa)) in enumerate(curves):
            s_t = float(geometry.transition_arc_length(loaded[ra["case"]][1].config.hopper))
            below = s < s_t
            for rb, (_, pb) in curves[i + 1:]:
                pair = bin_by_bin(loaded[ra["case"]][1], loaded[rb["case"]][1], stage)
                spread[""] = max(spread[""], pair["l2_change_pct"] / 100)
                spread["cone"] = max(spread["cone"], relative_l2(pa[below], pb[below]))
                spread["bin"] = max(spread["bin"], relative_l2(pa[~below], pb[~below]))
                table.append({"series": "stiffness", "stage": stage,
                              "pair": f"E {ra['youngs_modulus_Pa'] / 1e6:g} / "
                                      f"{rb['youngs_modulus_Pa'] / 1e6:g} MPa",
                              **pair, "l2_from_finest_pct": math.nan})
        if len(curves) >= 2:
            numbers[f"E_spread_pct[{stage}]"] = 100 * spread[""]
            # the wall below and above the transition
            numbers[f"E_spread_pct[{stage}|cone]"] = 100 * spread["cone"]
            numbers[f"E_spread_pct[{stage}|bin]"] = 100 * spread["bin"]
    for r in stiff:           # the bin's stress state at rest and in discharge (time series)
        rest, flowing = bin_lateral_ratio(loaded[r["case"]][1])
        label = f"{r['youngs_modulus_Pa'] / 1e6:g} MPa"
        numbers[f"bin_k_rest[{label}]"] = rest
        numbers[f"bin_k_discharge[{label}]"] = flowing
    residuals = [float(res.summary.get("fill_equilibrium_residual", math.nan))
                 for _, res in loaded.values()]
    numbers["fill_equilibrium_residual_max_pct"] = 100 * float(np.nanmax(residuals)) \
        if residuals else math.nan
    return table, numbers, profiles


#: the transition's forces of a run's summary.json (N/m; the ring's in N)
FORCES = (("hopper_meridional_tension_N_m", "hopper tension, at rest"),
          ("bin_wall_axial_compression_N_m", "bin wall compression, at rest"),
          ("transition_ring_compression_N", "ring compression, at rest"),
          ("hopper_meridional_tension_discharge_N_m", "hopper tension, discharge"),
          ("bin_wall_axial_compression_discharge_N_m", "bin wall compression, discharge"))


def forces_analysis(rows: list) -> tuple:
    """The forces in the wall at the transition (``summary.json``): per case with Janssen's
    n_z beside the bin wall's compression at rest, their successive changes under refinement
    and their spread over E (largest difference over the E = 5 MPa value): ``(table rows,
    numbers)``.  Runs written before the summaries had them are left out."""
    table, numbers = [], {}
    have = [r for r in rows if _sweep.finite(r.get("bin_wall_axial_compression_N_m"))
            and r.get("series") != "rest"]
    for row in have:
        janssen = row.get("janssen_wall_axial_compression_N_m", math.nan)
        table.append({"case": row["case"], **{key: row.get(key, math.nan) for key, _ in FORCES},
                      "janssen_wall_axial_compression_N_m": janssen,
                      "bin_wall_vs_janssen_pct": _sweep.pct(
                          row["bin_wall_axial_compression_N_m"], janssen)})
        numbers[f"bin_wall_vs_janssen_pct[{row['case']}]"] = table[-1]["bin_wall_vs_janssen_pct"]
    grid = sorted((r for r in have if _in_series(r, rows, "grid")),
                  key=lambda r: -r["cell_size_m"])
    stiff = [r for r in have if _in_series(r, rows, "stiffness")]
    for key, _ in FORCES:
        values = [float(r.get(key, math.nan)) for r in grid]
        if len(values) >= 2 and all(map(math.isfinite, values)):
            numbers[f"force_changes_pct[{key}]"] = [
                abs(_sweep.pct(b, a)) for a, b in zip(values[:-1], values[1:])]
        values = {r["youngs_modulus_Pa"]: float(r.get(key, math.nan)) for r in stiff}
        if len(values) >= 2 and all(map(math.isfinite, values.values())):
            middle = values.get(5.0e6, sorted(values.values())[len(values) // 2])
            numbers[f"force_E_spread_pct[{key}]"] = 100 * (max(values.values())
                                                          - min(values.values())) / middle
    return table, numbers


#: the part of the discharge (s after the opening) over which the bin's K is averaged
BIN_K_WINDOW = (0.5, 1.5)


def bin_lateral_ratio(res) -> tuple:
    """The bin's lateral stress ratio (``timeseries.csv``'s ``bin_lateral_stress_ratio``): at
    the opening (the filled state at rest) and its mean over :data:`BIN_K_WINDOW` of the
    discharge; NaN for runs written before the time series carried it."""
    series = res.timeseries
    if "bin_lateral_stress_ratio" not in series:
        return math.nan, math.nan
    t, k = series["t_s"], series["bin_lateral_stress_ratio"]
    window = (t >= BIN_K_WINDOW[0]) & (t <= BIN_K_WINDOW[1]) & np.isfinite(k)
    return float(k[0]), (float(np.mean(k[window])) if window.any() else math.nan)


def _in_series(row, rows, series) -> bool:
    """A case belongs to the grid series at the reference angle and E, to the stiffness
    series at the reference angle and cell size (one case can be in both); a case at rest
    to neither."""
    ref = [r for r in rows if r.get("series") == series]
    if not ref or row.get("series") == "rest":
        return False
    theta = ref[0]["half_angle_deg"]
    if row["half_angle_deg"] != theta:
        return False
    if series == "grid":
        E = [r["youngs_modulus_Pa"] for r in ref][0]
        return row["youngs_modulus_Pa"] == E
    h = [r["cell_size_m"] for r in ref][0]
    return row["cell_size_m"] == h


def plot_series(rows, profiles, width):
    """The filled and envelope profiles on the runs' shared bins of ``width`` m: the grid
    series (left two) and the stiffness series (right)."""
    fig = _sweep.figure(13.0, 4.2)
    axes = fig.subplots(1, 3)
    grid = sorted((r for r in rows if _in_series(r, rows, "grid")
                   and r["case"] in profiles), key=lambda r: -r["cell_size_m"])
    stiff = sorted((r for r in rows if _in_series(r, rows, "stiffness")
                    and r["case"] in profiles), key=lambda r: r["youngs_modulus_Pa"])
    s_t = float(geometry.transition_arc_length(load_case((grid + stiff)[0]).config.hopper))
    for ax, stage, title in ((axes[0], "filling", "at rest"),
                             (axes[1], "discharge_envelope", "discharge envelope")):
        for k, r in enumerate(grid):
            prof = profiles[r["case"]][stage]
            if prof is not None:
                ax.plot(*broken(prof[0], prof[1] / 1e3, s_t), "o-", ms=3, lw=1.0,
                        color=f"C{k}", label=f"h = {1000 * r['cell_size_m']:g} mm")
        ax.set_title(f"{title}: cell size", fontsize=9)
    for k, r in enumerate(stiff):
        for stage, ls in (("filling", "-"), ("discharge_envelope", "--")):
            prof = profiles[r["case"]][stage]
            if prof is not None:
                axes[2].plot(*broken(prof[0], prof[1] / 1e3, s_t), ls, marker="o", ms=3, lw=1.0,
                             color=f"C{k}", label=f"E = {r['youngs_modulus_Pa'] / 1e6:g} MPa"
                             + (" (envelope)" if stage != "filling" else ""))
    axes[2].set_title("stiffness (solid: at rest, dashed: envelope)", fontsize=9)
    for ax in axes:
        ax.set_xlabel(f"s (m), {1000 * width:g} mm bins")
        ax.set_ylim(bottom=0.0)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("p_n (kPa)")
    return fig


# ---------------------------------------------------------------- figures
def plot_estimates(ax, rows, marker, colour, label, s_t):
    """A stage's profile rows on ``ax`` (kPa): the recovered traction as a line with markers,
    broken at the transition ``s_t`` (one spline per stretch of wall), the plain binning of
    the reaction as small grey dots, the stress-sampled estimate as open markers."""
    s = np.array([p["s_m"] for p in rows])
    ax.plot(s, [p["p_n_raw_Pa"] / 1e3 for p in rows], ".", color="0.55", ms=3,
            label="reaction binned node by node")
    ax.plot(s, [p["p_n_stress_Pa"] / 1e3 for p in rows], marker, mfc="none", mew=0.8,
            color=colour, ms=5, alpha=0.7, label="stress-sampled")
    ax.plot(*broken(s, [p["p_n_sim_Pa"] / 1e3 for p in rows], s_t), "-", marker=marker,
            color=colour, ms=3, lw=1.2, label=label)


def broken(s, p, s_t):
    """``(s, p)`` with a NaN between the stretches below and above ``s_t``: a plotted line
    breaks at the transition, where the recovered traction, one spline per stretch, jumps."""
    k = int(np.searchsorted(s, s_t))
    return np.insert(np.asarray(s, float), k, np.nan), np.insert(np.asarray(p, float), k, np.nan)


def plot_rest(rest, profiles, smoothness):
    """The hoppers at rest (:func:`rest_cases`), one panel each: the three estimates along the
    wall, with the hopper wall's smoothness in the title."""
    fig = _sweep.figure(3.4 * max(1, len(rest)), 3.6)
    axes = fig.subplots(1, max(1, len(rest)), squeeze=False)[0]
    for ax, row in zip(axes, rest):
        rows = [p for p in profiles if p["case"] == row["case"] and p["stage"] == "filling"]
        s_t = float(geometry.transition_arc_length(load_case(row).config.hopper))
        plot_estimates(ax, rows, "o", "C0", "recovered traction", s_t)
        ax.axvline(s_t, color="0.5", lw=0.8, ls=":")
        m = next(m for m in smoothness if m["case"] == row["case"] and m["stage"] == "filling")
        ax.set_title(f"{row['half_angle_deg']:g} deg {_shape_word(row)} at rest: RMS from a "
                     f"cubic\nrecovered {m['rms_recovered_pct']:.1f} %, node by node "
                     f"{m['rms_raw_pct']:.1f} %, stress {m['rms_stress_pct']:.1f} %", fontsize=8)
        ax.set_xlabel("arc length from the outlet lip, s (m)")
        ax.set_ylim(bottom=0.0)
    axes[0].set_ylabel("normal wall pressure p_n (kPa)")
    axes[0].legend(fontsize=6, loc="best")
    return fig


def _shape_word(row) -> str:
    return "wedge" if row.get("shape") == "wedge" else "cone"


STAGE_STYLE = {"filling": ("o", "C0", "recovered traction, filled at rest"),
               "early_discharge": ("s", "C1", "recovered traction, discharge, 90 % left"),
               "mid_discharge": ("^", "C3", "recovered traction, discharge, 50 % left")}
THEORY_STYLE = (("Janssen", "k", "-"), ("EN 1991-4 bin filling", "0.45", "--"),
                ("EN 1991-4 bin discharge", "0.45", ":"), ("Walker slice, filling", "C0", "-"),
                ("Walker slice, discharge", "C3", "-"), ("EN 1991-4 hopper", "C2", "--"))


def plot_case(row, profiles, switch):
    res = load_case(row)
    cfg = res.config
    s_t = float(geometry.transition_arc_length(cfg.hopper))
    stages = [st for st in STAGES if any(p["case"] == row["case"] and p["stage"] == st
                                         for p in profiles)]
    fig = _sweep.figure(4.6 * max(1, len(stages)), 4.6)
    axes = fig.subplots(1, max(1, len(stages)), sharey=True, squeeze=False)[0]
    tops = []
    for ax, stage in zip(axes, stages):
        rows = [p for p in profiles if p["case"] == row["case"] and p["stage"] == stage]
        marker, colour, label = STAGE_STYLE[stage]
        plot_estimates(ax, rows, marker, colour, label, s_t)
        fill = stage_fill(res, stage)
        s_fine = np.linspace(0.0, float(geometry.arc_length(cfg.hopper.cone_height + fill,
                                                           cfg.hopper)), 300)
        curves = theory_curves(cfg, s_fine, fill, stage)
        sim = np.sort([p["p_n_sim_Pa"] for p in rows])
        top = max([np.nanmax(v) for v in curves.values() if np.isfinite(v).any()]
                  + [sim[-2] if len(sim) > 1 else sim[-1]]) * 1.25
        tops.append(top)
        for p in rows:                          # e.g. the outlet lip: marked, not scaled to
            if p["p_n_sim_Pa"] > top:
                ax.annotate(f"{p['p_n_sim_Pa'] / 1e3:.1f} kPa", (p["s_m"], top / 1e3 * 0.97),
                            ha="left", va="top", fontsize=7, color=colour,
                            arrowprops={"arrowstyle": "->", "color": colour})
        for name, v in curves.items():
            col, ls = next(((c, l) for key, c, l in THEORY_STYLE if name.startswith(key)),
                           ("0.6", "-"))
            ax.plot(s_fine, v / 1e3, ls, color=col, lw=1.2, label=name)
        for sw in switch:
            if sw["case"] == row["case"] and sw["stage"] == stage:
                ax.plot([sw["peak_s_m"]], [sw["peak_sim_Pa"] / 1e3], "*", color="k", ms=11,
                        label=f"switch peak {sw['peak_sim_Pa'] / 1e3:.2f} kPa")
                ax.plot([s_t], [sw["walker_hopper_Pa"] / 1e3], "P", color="C3", ms=8,
                        label=f"Walker F_e sigma_vt = {sw['walker_hopper_Pa'] / 1e3:.2f} kPa")
        ax.axvline(s_t, color="0.5", lw=0.8, ls=":")
        ax.set_xlabel("arc length from the outlet lip, s (m)")
        title = {"filling": "filled, at rest", "early_discharge": "discharge, 90 % left",
                 "mid_discharge": "discharge, 50 % left"}[stage]
        ax.set_title(f"{title} (equivalent fill {fill:.3f} m)", fontsize=9)
        ax.set_xlim(left=0.0)
        ax.legend(fontsize=6, loc="best")
    if tops:
        axes[0].set_ylim(0.0, max(tops) / 1e3)
    axes[0].set_ylabel("normal wall pressure p_n (kPa)")
    fig.suptitle(f"{row['case']}: theta = {cfg.hopper.half_angle_deg:g} deg, phi = "
                 f"{cfg.material.friction_angle_deg:g} deg, phi_w = "
                 f"{cfg.wall.friction_angle_deg:g} deg, h = {1000 * cfg.numerics.cell_size:g} mm"
                 " (dotted: transition)", fontsize=9)
    return fig


# ---------------------------------------------------------------- outputs
def write_outputs(out, rows, profiles, comparison, switch, numbers, options, setting,
                  argv=None, series=None, smoothness=()):
    out = Path(out)
    width = float(options["wall_bin_width"])
    _sweep.write_rows_csv(out / "profiles.csv", profiles)
    _sweep.write_rows_csv(out / "comparison.csv", comparison)
    _sweep.write_rows_csv(out / "switch.csv", switch)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "half_angle_deg", "wall_friction_deg", "cell_size_m", "youngs_modulus_Pa",
        "series", "end_time_s", "flow_mode", "steady_discharge_rate_kg_s", "fill_at_rest",
        "fill_equilibrium_residual", "wall_k_bin", "switch_peak_Pa",
        "walker_switch_pressure_Pa", "overpressure_factor_bin_max",
        "overpressure_factor_cone_max", "wall_time_s", "error"))
    figures = []
    series_table, series_numbers, common = series if series is not None else ([], {}, {})
    estimates = estimates_analysis(rows)
    if estimates:
        _sweep.write_rows_csv(out / "estimates.csv", estimates)
    numbers = {**numbers, **series_numbers}
    if series_table:
        _sweep.write_rows_csv(out / "convergence.csv", series_table)
        _sweep.save(plot_series(rows, common, width), out / "convergence.png")
        figures.append({"file": "convergence.png", "caption": (
            f"The recovered wall pressure on the runs' shared {1000 * width:g} mm bins: at rest "
            "and the discharge envelope at each cell size, and at rest and enveloped for each "
            "E.")})
    rest = rest_cases(rows, options)
    if smoothness:
        _sweep.write_rows_csv(out / "smoothness.csv", smoothness)
    if rest and smoothness:
        _sweep.save(plot_rest(rest, profiles, smoothness), out / "rest_profiles.png")
        figures.append({"file": "rest_profiles.png", "caption": (
            f"At rest, {1000 * options['cell_size']:g} mm cells, {1000 * width:g} mm bins: p_n "
            "along the wall of each hopper at rest, the traction recovered from the wall's "
            "reaction (line), the reaction binned node by node (grey dots) and the "
            "stress-sampled estimate (open markers); dotted: the transition.")})
    import shutil
    for row in rows:
        picture = Path(row.get("run_dir", "")) / "stress_pattern.png"
        if picture.is_file() and (row.get("series") == "grid"
                                  and row["cell_size_m"] == options["cell_size"]):
            name = f"stress_pattern_{row['case']}.png"
            shutil.copyfile(picture, out / name)
            figures.append({"file": name, "caption": (
                f"{row['case']}: major principal stress trajectories over the mobilised "
                "friction, at rest (sigma1 near vertical: active) and in discharge (sigma1 "
                "across the flow: passive, arched).")})
            forces = Path(row["run_dir"]) / "wall_forces.png"
            if forces.is_file():
                name = f"wall_forces_{row['case']}.png"
                shutil.copyfile(forces, out / name)
                figures.append({"file": name, "caption": (
                    f"{row['case']}: the forces in the wall per metre of circumference, the "
                    "hoop force and the meridional force (the hopper hung from the "
                    "transition, the bin's wall standing on it), against Janssen's p_n R and "
                    "n_z.")})
    for row in rows:
        if (row.get("error") and not Path(row.get("run_dir", "")).is_dir()
                or row.get("series") == "rest"):
            continue
        name = f"wall_pressure_{row['case']}.png"
        _sweep.save(plot_case(row, profiles, switch), out / name)
        figures.append({"file": name, "caption": f"{row['case']}: p_n along the wall, the "
                        "traction recovered from the wall's reaction (line), the reaction "
                        "binned node by node (grey dots) and the stress-sampled estimate (open "
                        "markers), against Janssen, Walker's slice method and EN 1991-4, "
                        "filled and in discharge."})
    findings = []
    for case in dict.fromkeys(c["case"] for c in comparison):
        for stage in STAGES:
            parts = [f"{c['theory']} {c['diff_pct']:+.0f} %" for c in comparison
                     if c["case"] == case and c["stage"] == stage]
            if parts:
                findings.append(f"{case}, {stage.replace('_', ' ')}: mean simulated p_n vs "
                                + "; ".join(parts) + ".")
    for sw in switch:
        findings.append(
            f"{sw['case']}, {sw['stage'].replace('_', ' ')}: switch peak {sw['peak_sim_Pa']:.0f}"
            f" Pa at s = {sw['peak_s_m']:.3f} m (transition {sw['transition_s_m']:.3f} m), "
            f"{sw['sim_ratio_discharge_to_filling']:.2f} x the filled peak there; Walker's "
            f"F_e sigma_vt = {sw['walker_hopper_Pa']:.0f} Pa ({sw['diff_peak_vs_walker_pct']:+.0f}"
            f" %), F_e/K = {sw['walker_ratio_Fe_over_K']:.2f}.")
    smooth_findings, smooth_numbers = smoothness_findings(smoothness, rows, rest, options)
    findings += smooth_findings
    numbers.update(smooth_numbers)
    deficits = {k[len("corner_deficit_pct["):-1]: v for k, v in numbers.items()
                if k.startswith("corner_deficit_pct[")}
    if deficits:
        findings.append("At rest the bin wall's first bin above the transition carries less "
                        "than the next one up (the corner's node takes the cone's load along "
                        "the cone's normal): by " + ", ".join(
                            f"{v:.1f} % at {h}" for h, v in deficits.items()) + ".")
    for stage in SERIES_STAGES:
        pairs = [t for t in series_table if t["series"] == "grid" and t["stage"] == stage]
        if pairs:
            findings.append(
                f"Bin by bin under refinement, {STAGE_WORDS[stage]} ({1000 * width:g} mm bins; "
                f"the lip's {LIP_BINS} bins and those above the surface aside): the largest "
                "relative difference of a bin " + ", ".join(
                    f"{t['pair']} {t['max_diff_pct']:.1f} % (s = {t['at_s_m']:.3f} m, "
                    f"{t['where']})" for t in pairs)
                + "; on the cone " + ", ".join(
                    f"{t['pair']} {t['cone_max_diff_pct']:.1f} %" for t in pairs)
                + "; on the bin wall, its first bin and the top one aside " + ", ".join(
                    f"{t['pair']} {t['bin_wall_max_diff_pct']:.1f} %" for t in pairs)
                + "; relative L2 over the whole wall " + ", ".join(
                    f"{t['pair']} {t['l2_change_pct']:.1f} %" for t in pairs)
                + (" (decreasing)." if numbers.get(f"l2_changes_decrease[{stage}]")
                   else " (not decreasing)."))
        if f"E_spread_pct[{stage}]" in numbers:
            findings.append(f"Stiffness, {stage.replace('_', ' ')}: largest relative L2 "
                            f"difference between E = 2, 5 and 20 MPa "
                            f"{numbers[f'E_spread_pct[{stage}]']:.2f} % (the cone, below "
                            f"the transition, {numbers[f'E_spread_pct[{stage}|cone]']:.2f} %; "
                            f"the bin above it {numbers[f'E_spread_pct[{stage}|bin]']:.2f} %).")
    moduli = sorted((k[len("bin_k_rest["):-1] for k in numbers if k.startswith("bin_k_rest[")),
                    key=lambda m: float(m.split()[0]))
    if moduli and all(math.isfinite(numbers[f"bin_k_discharge[{m}]"]) for m in moduli):
        findings.append(
            "The bin's lateral stress ratio (mean sigma_rr / sigma_zz of its full cells) at "
            "E = " + " / ".join(moduli) + ": at rest "
            + " / ".join(f"{numbers[f'bin_k_rest[{m}]']:.3f}" for m in moduli)
            + " (the elastic fill's nu/(1 - nu)), averaged over "
            f"{BIN_K_WINDOW[0]:g}-{BIN_K_WINDOW[1]:g} s of discharge "
            + " / ".join(f"{numbers[f'bin_k_discharge[{m}]']:.2f}" for m in moduli)
            + ": when the bin flows its stress turns towards isotropy, and the bin's "
            "discharge loads follow it.")
    if math.isfinite(numbers.get("fill_equilibrium_residual_max_pct", math.nan)):
        findings.append("At rest, the wall's and the plate's vertical reactions equal the "
                        "weight to within "
                        f"{numbers['fill_equilibrium_residual_max_pct']:.3f} % in every case.")
    forces, force_numbers = forces_analysis(rows)
    numbers.update(force_numbers)
    if forces:
        _sweep.write_rows_csv(out / "forces.csv", forces)
        findings.append(
            "Forces in the wall at the transition, at rest (per metre of circumference): "
            + "; ".join(f"{f['case']} hopper tension {f['hopper_meridional_tension_N_m']:.0f} "
                        f"N/m, bin wall compression {f['bin_wall_axial_compression_N_m']:.1f} "
                        f"N/m ({f['bin_wall_vs_janssen_pct']:+.1f} % from Janssen's n_z with "
                        "the measured K)" for f in forces) + ".")
        moving = [(label, numbers[f"force_changes_pct[{key}]"]) for key, label in FORCES
                  if f"force_changes_pct[{key}]" in numbers]
        if moving:
            steps = "; ".join(f"{label} " + " / ".join(f"{c:.1f}" for c in ch) + " %"
                              for label, ch in moving)
            findings.append("Under refinement (the grid series, coarse to fine) the "
                            f"transition's forces change by {steps}.")
        spread = [(label, numbers[f"force_E_spread_pct[{key}]"]) for key, label in FORCES
                  if f"force_E_spread_pct[{key}]" in numbers]
        if spread:
            findings.append("Over E = 2-20 MPa they spread by " + "; ".join(
                f"{label} {v:.1f} %" for label, v in spread) + ".")
    if numbers["missing_stages"]:
        findings.append("Stages not reached: " + ", ".join(numbers["missing_stages"]) + ".")
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    tables = [
        {"title": "Region means (diff = 100 (simulated - theory) / theory)",
         "columns": ["case", "stage", "region", "theory", "sim (Pa)", "theory (Pa)", "diff %",
                     "rms %"],
         "rows": [[c["case"], c["stage"], c["region"], c["theory"], round(c["mean_sim_Pa"]),
                   round(c["mean_theory_Pa"]), round(c["diff_pct"], 1),
                   round(c["rms_rel_diff_pct"], 1)] for c in comparison]},
        {"title": "Switch peak in discharge",
         "columns": ["case", "stage", "peak sim (Pa)", "filled there (Pa)", "ratio",
                     "Walker F_e sigma_vt (Pa)", "diff %", "F_e/K"],
         "rows": [[sw["case"], sw["stage"], round(sw["peak_sim_Pa"]),
                   round(sw["peak_filling_sim_Pa"]),
                   round(sw["sim_ratio_discharge_to_filling"], 2),
                   round(sw["walker_hopper_Pa"]), round(sw["diff_peak_vs_walker_pct"], 1),
                   round(sw["walker_ratio_Fe_over_K"], 2)] for sw in switch]}]
    if estimates:
        tables.append({"title": "The two estimates at rest: the wall's reaction and the stress "
                                "of the cells next to the wall (diff = stress-sampled against "
                                "reaction)",
                       "columns": ["case", "region", "reaction (Pa)", "stress-sampled (Pa)",
                                   "diff %"],
                       "rows": [[e["case"], e["region"], round(e["reaction_Pa"]),
                                 round(e["stress_sampled_Pa"]), round(e["diff_pct"], 1)]
                                for e in estimates]})
        findings.append(
            "The stress-sampled estimate reads the stress 0.5 to 2.5 cells from the wall, the "
            "reaction the force on the wall itself: they differ most where the stress varies "
            "over that distance (" + "; ".join(
                f"{e['region']} {e['diff_pct']:+.0f} %" for e in estimates
                if e["case"] == estimates[0]["case"]) + f", {estimates[0]['case']}).")
    if forces:
        tables.append({"title": "Forces in the wall at the transition (N/m per metre of "
                                "circumference; the ring's in N)",
                       "columns": ["case"] + [label for _, label in FORCES]
                       + ["Janssen n_z at rest", "bin wall vs Janssen %"],
                       "rows": [[f["case"]] + [round(f[key], 1) for key, _ in FORCES]
                                + [round(f["janssen_wall_axial_compression_N_m"], 1),
                                   round(f["bin_wall_vs_janssen_pct"], 1)] for f in forces]})
    if smoothness:
        tables.append({"title": SMOOTHNESS_TABLE,
                       "columns": ["case", "stage"] + [f"{m} {e} %" for m in ("RMS", "scatter")
                                                       for e, _ in ESTIMATES],
                       "rows": [[m["case"], m["stage"]]
                                + [_sweep.rounded(m[f"{k}_{e}_pct"], 1)
                                   for k in ("rms", "scatter") for e, _ in ESTIMATES]
                                for m in smoothness]})
    if series_table:
        tables.append({"title": CONVERGENCE_TABLE,
                       "columns": ["series", "stage", "pair", "largest bin diff %", "at s (m)",
                                   "where", "cone %", "bin wall inside %", "L2 change %",
                                   "L2 from finest %"],
                       "rows": [[t["series"], t["stage"], t["pair"], round(t["max_diff_pct"], 1),
                                 round(t["at_s_m"], 3), t["where"],
                                 _sweep.rounded(t["cone_max_diff_pct"], 1),
                                 _sweep.rounded(t["bin_wall_max_diff_pct"], 1),
                                 round(t["l2_change_pct"], 2),
                                 _sweep.rounded(t["l2_from_finest_pct"], 2)]
                                for t in series_table]})
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    settings["regions"] = ("bin: 5-85 % of the equivalent fill depth; cone: 20-80 % of the "
                           "slant length; switch window: the quarter of the slant length below "
                           "the transition to 2 cells above it")
    settings["smoothness"] = (f"the hopper wall's bins (below the transition): RMS relative "
                              f"deviation from a cubic over them, {100 * FIT_MARGIN:g} cm left "
                              "out at each end; bin-to-bin scatter mean |p_i - (p_(i-1) + "
                              "p_(i+1))/2| / p_i over them")
    _sweep.write_study_json(out, NAME, TITLE, setting, settings,
                            {k: v for k, v in numbers.items()}, findings, figures, tables,
                            rows, argv, headline=headline(numbers, comparison, switch, rows))


STAGE_WORDS = {"filling": "filled", "early_discharge": "90 % left",
               "mid_discharge": "50 % left", "discharge_envelope": "envelope"}
#: the report's tables that studies/headline.py and docs/physics_and_numerics.md point to
SMOOTHNESS_TABLE = ("Smoothness of p_n along the hopper wall (RMS deviation from a cubic over "
                    "its bins, 2 cm left out at each end; bin-to-bin scatter; raw: the "
                    "reaction binned node by node)")
CONVERGENCE_TABLE = "Convergence and stiffness, bin by bin on the shared bins"


def _pct(values) -> str:
    """``a / b / c`` of percentages (one decimal; n/a for a missing one)."""
    return " / ".join(f"{v:.1f}" if _sweep.finite(v) else "n/a" for v in values)


def smoothness_findings(smoothness: list, rows: list, rest: list, options: dict) -> tuple:
    """Sentences and numbers of the smoothness table: the hoppers at rest, and each stage of
    the grid series; ``(findings, numbers)``."""
    findings, numbers = [], {}
    names = [e for e, _ in ESTIMATES]
    of = {(m["case"], m["stage"]): m for m in smoothness}
    for m in smoothness:
        for kind in ("rms", "scatter"):
            numbers[f"{kind}_pct[{m['case']}|{m['stage']}]"] = {
                e: _sweep.rounded(m[f"{kind}_{e}_pct"], 2) for e in names}
    at_rest = [(r, of[(r["case"], "filling")]) for r in rest if (r["case"], "filling") in of]
    if at_rest:
        head = (f"At rest, {1000 * options['cell_size']:g} mm cells, "
                f"{1000 * options['wall_bin_width']:g} mm bins, p_n along the hopper wall, "
                "recovered / raw (node by node) / stress-sampled: ")
        for kind, what in (("rms", f"RMS deviation from a cubic over its bins "
                                   f"({100 * FIT_MARGIN:g} cm left out at each end) "),
                           ("scatter", "bin-to-bin scatter ")):
            findings.append(head + what + "; ".join(
                f"{r['half_angle_deg']:g} deg {_shape_word(r)} "
                + _pct(m[f"{kind}_{e}_pct"] for e in names) + " %" for r, m in at_rest) + ".")
            for e in names:
                values = [m[f"{kind}_{e}_pct"] for _, m in at_rest]
                numbers[f"rest_{kind}_max_pct[{e}]"] = _sweep.rounded(max(values), 2)
    grid = sorted((r for r in rows if _in_series(r, rows, "grid")),
                  key=lambda r: -r["cell_size_m"])
    cells = " / ".join(f"{1000 * r['cell_size_m']:g}" for r in grid)
    for stage in SERIES_STAGES:
        ms = [of[(r["case"], stage)] for r in grid if (r["case"], stage) in of]
        if len(ms) < 2:
            continue
        findings.append(
            f"Smoothness under refinement, {STAGE_WORDS[stage]} ({cells} mm), p_n along the "
            "hopper wall: RMS deviation from a cubic " + "; ".join(
                f"{e} {_pct(m[f'rms_{e}_pct'] for m in ms)} %" for e in names)
            + "; bin-to-bin scatter " + "; ".join(
                f"{e} {_pct(m[f'scatter_{e}_pct'] for m in ms)} %" for e in names) + ".")
    return findings, numbers


def headline(numbers: dict, comparison: list, switch: list, rows: list) -> str:
    """One line: the hopper wall's smoothness at rest, the last refinement bin by bin and the
    E spread per stage, the equilibrium at rest, and the first grid case's filled means and
    early switch peak against the theories."""
    parts = []
    if _sweep.finite(numbers.get("rest_rms_max_pct[recovered]")):
        parts.append("at rest the hopper wall's p_n deviates from a cubic by at most "
                     f"{numbers['rest_rms_max_pct[recovered]']:.1f} % RMS (node by node up to "
                     f"{numbers['rest_rms_max_pct[raw]']:.1f} %)")
    last = {}
    for key, value in numbers.items():
        if key.startswith("cone_max_diff_pct["):
            stage, pair = key[len("cone_max_diff_pct["):-1].split("|")
            last[stage] = (pair, value, numbers[f"l2_change_pct[{stage}|{pair}]"])
    if last:
        parts.append(f"last refinement ({next(iter(last.values()))[0]}), the cone's largest "
                     "bin difference / L2 over the wall: " + ", ".join(
                         f"{STAGE_WORDS[st]} {d:.1f} / {l2:.1f} %"
                         for st, (_, d, l2) in last.items()))
    spread = [f"{STAGE_WORDS[st]} {numbers[f'E_spread_pct[{st}]']:.1f} % (cone "
              f"{numbers[f'E_spread_pct[{st}|cone]']:.1f}, bin "
              f"{numbers[f'E_spread_pct[{st}|bin]']:.1f} %)"
              for st in SERIES_STAGES if f"E_spread_pct[{st}]" in numbers]
    if spread:
        parts.append("E spread: " + ", ".join(spread))
    if math.isfinite(numbers.get("fill_equilibrium_residual_max_pct", math.nan)):
        parts.append(f"reactions at rest within "
                     f"{numbers['fill_equilibrium_residual_max_pct']:.2f} % of the weight")
    reference = next((r["case"] for r in rows if _in_series(r, rows, "stiffness")
                      and _in_series(r, rows, "grid")), rows[0]["case"] if rows else None)
    parts += [f"{c['case']} filled {c['region']} {c['diff_pct']:+.0f} % from {c['theory']}"
              for c in comparison if c["case"] == reference and c["stage"] == "filling"
              and c["theory"].startswith(("Janssen", "Walker"))]
    parts += [f"switch peak {sw['peak_sim_Pa'] / 1e3:.2f} kPa vs Walker "
              f"{sw['walker_hopper_Pa'] / 1e3:.2f} kPa ({sw['diff_peak_vs_walker_pct']:+.0f} %)"
              for sw in switch if sw["case"] == reference and sw["stage"] == "early_discharge"]
    return "; ".join(parts) + "."


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    parser.add_argument("--cell-sizes", type=float, nargs="+",
                        help="m, the grid series (default 0.0075 0.005 0.00375 0.0025)")
    parser.add_argument("--half-angles", type=float, nargs="+", help="deg (default 20 30)")
    parser.add_argument("--youngs-moduli", type=float, nargs="+",
                        help="Pa, the stiffness series at --cell-size (default 2e6 5e6 20e6)")
    parser.add_argument("--end-time", type=float, help="s of discharge (default: 0.65 of the "
                        "Beverloo x Rose-Tanaka emptying time)")
    parser.add_argument("--wall-bin-width", type=float,
                        help="m, the wall bins of every case (default 0.015)")
    parser.add_argument("--rest-angles", type=float, nargs="*",
                        help="deg, cones at rest at --cell-size (default 10 20 35 60)")
    parser.add_argument("--rest-wedges", type=float, nargs="*",
                        help="deg, wedges at rest at --cell-size (default 20)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ('cell_size', 'cell_sizes', 'half_angles',
                                          'youngs_moduli', 'end_time', 'wall_bin_width',
                                          'rest_angles', 'rest_wedges'))
    for key in ("cell_sizes", "youngs_moduli", "rest_angles", "rest_wedges"):
        if key in options:
            options[key] = tuple(options[key])
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    profiles, comparison, switch, numbers = analyse(rows, study["options"])
    series = series_analysis(rows)
    write_outputs(args.out, rows, profiles, comparison, switch, numbers, study["options"],
                  study["setting"], argv, series=series, smoothness=smoothness_analysis(rows))
    for key, value in series[1].items():
        print(f"{key}: {value}")
    for sw in switch:
        print(f"{sw['case']} {sw['stage']}: switch peak {sw['peak_sim_Pa']:.0f} Pa, Walker "
              f"{sw['walker_hopper_Pa']:.0f} Pa ({sw['diff_peak_vs_walker_pct']:+.0f} %)")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
