"""Eccentric discharge in 3D against EN 1991-4 and AS 3774: a flat-bottomed circular silo with
its outlet off the axis, and a square silo on a centred and an off-centre pyramidal hopper.

Two parts, each case an ordinary 3D run directory (``hopper.dimensions = 3``,
:mod:`fipy_hopper.space`) run by ``fipy_hopper.api.run`` through :mod:`_sweep`, filled to rest
and discharged; every case also records the smallest and the largest wall pressure of each
patch over the discharge's consecutive load windows (``wall_windows.json``,
:class:`_sweep._WallWindows`).

**(a) The circular silo** is ``studies/three_d.py``'s flat family, made by its own functions
(:func:`three_d.family_config`, :func:`three_d.case_of`), so that equal settings are the same
cases with the same names: a 0.64 m bin on a flat floor with a 0.12 m outlet, filled level to
1.28 m (H/D = 2), the reference's material and wall (phi = 30 deg, phi_w = 15 deg,
1500 kg/m^3), 2 cm cubes (the half ``y >= 0`` off centre, a quarter centred), 12 sectors,
the outlet's centre at ``eccentricities`` e/R = 0, 0.25, 0.5 and 0.75 along +x (whole cells),
each discharged for the time Beverloo's rate takes to discharge ``drained_fraction`` (15 %) of
the fill (7.5 s).  ``--runs-from DIR`` runs (or reads) these cases in ``DIR/cases/`` (e.g.
``studies/output/three_d``) instead of ``--out``: by ``_sweep``'s restart rule a finished case
there whose ``config.toml`` equals this study's is read, not recomputed; an unfinished one is
resumed, a missing one run there (for ``three_d.py`` to read in turn), and a finished one of
another configuration stops the study before anything runs.  ``three_d.py`` records the
windows of these cases too; a run without window records (made before it did) has its
"in discharge windows" stage from the loop's discharge envelope for the largest pressure,
and no smallest.

Measured per case:

* the flow channel per window of the discharge (:func:`three_d.channel_rows`: r_c, theta_c,
  e_c per node plane of the bin of each load window's mean field, ``channel_windows.csv`` of
  the run; the medians over the middle half of the bin's fill of every window, pooled over the
  windows, and the range of the windows' own medians) beside EN 1991-4's channels for
  G = 0.25, 0.4, 0.6 (:func:`three_d.en_channels`);
* the wall pressure around the circumference (``wall_pressure.csv``, 12 sectors, theta 0 on
  the outlet's side) at three heights of the bin wall, the bins nearest ``height_fractions``
  (a quarter, a half and three quarters) of the fill's height above the floor, per stage: at
  rest (``filling``), in the load windows at 90 % and 50 % of the mass left
  (``early_discharge``, ``mid_discharge``, when reached) and over all the discharge's windows
  (``discharge_windows``: the largest of each sector's largest, the smallest of its smallest);
* **the factors**: the largest overpressure and underpressure factor at each height, the
  largest and the smallest of ``p(theta) / p_hf``, with ``p_hf`` **the centred case's mean
  pressure around the circumference at that height at rest**.  EN 1991-4 sets its eccentric
  discharge pressures against the filling pressure ``p_hf`` of the symmetric silo (the channel's
  ``p_hce`` below it, the adjacent zones' ``p_hae = 2 p_hf - p_hce`` above it), so the
  simulated filling pressure of the symmetric silo is the base that makes the measured factors
  and EN's (``p_hae / p_hf``, ``p_hce / p_hf``) the same kind of number; a factor above 1 in
  discharge therefore holds the symmetric discharge's own rise as well as the eccentricity's
  (the centred case's factors in the same stage show that rise alone).  Beside them the
  largest and smallest over the case's own mean around in that stage (the unevenness around
  the circumference alone).  Without a centred case each case's own mean at rest is the base;
* **the codes** at each height (:func:`fipy_hopper.space.pictures.code_curves`, on a 0.5 deg
  grid of theta): EN 1991-4's large-eccentricity pattern
  (:func:`fipy_hopper.theory.en1991_eccentric_wall_pressure`) for its three G and for the
  measured G = r_c / R (the channel's median), as the code's own factors (``p_hce / p_hf``,
  ``p_hae / p_hf``, both of EN's formulas) on the simulated ``p_hf`` above, the depth below
  the fill's level, ``mu = tan phi_w``, ``phi_i = phi``, ``gamma = rho g`` and ``K`` the
  centred case's measured at the bin wall at rest (``wall_k_bin``; EN's ``1.1 (1 - sin phi)``
  without one); AS 3774's eccentric outlet
  (:func:`fipy_hopper.theory.as3774_eccentric_increment`, ``h`` the height above the outlet)
  on its symmetric flow pressure ``p_nf``, taken as the centred case's mean around at that
  height in the same stage (at rest its filling pressure), as a factor over the same ``p_hf``.
  EN's pattern is evaluated at every offset; the findings say at which the standard calls for
  its large-eccentricity case (above ``e_o = 0.25 d_c``,
  :func:`fipy_hopper.theory.en1991_large_eccentricity`, as recalled [M]) and at which it is
  drawn for comparison only.  The codes' coefficients are
  as coded in :mod:`fipy_hopper.theory` (``docs/correlations.md`` section e: not checked
  against the standards' texts).

**(b) The square silo**: a ``square_bin`` (0.48 m) on a pyramidal hopper (30 deg across x when
centred) to a 0.12 m square outlet (``plan = "rectangular"``,
:mod:`fipy_hopper.space.rectangular`), filled 0.96 m above the transition (H/B = 2 in the bin),
the same material, wall, cubes, mirror planes and discharge rule, ``square_sectors`` (6)
sectors across each face, the outlet at each of ``square_offsets`` (0 and 0.12 m, 6 cells, two
thirds of the room along +x; the hopper's faces then run from the offset outlet's edges to the
bin's).  Measured per case and stage: each face's pressure per height bin (the mean across its
width, its largest and smallest), the pressure at the bin's four vertical corners
(``summary.json``); the off-centre case against the centred: each face's mean over the centred
case's mean at rest at the same height (the same base as (a)), and the far face's (``x_minus``)
mean over the near face's (``x_plus``, the outlet's side) per height (the far face
interpolated to the near face's bins; over the discharge's windows the ratio of their
largest), on the bin and on the hopper; the largest and the smallest pressure over the bin's
faces over ``p_hf``; at the same three fractions of the bin's fill (the near face's bins
nearest them).

Written to ``--out`` (default ``studies/output/eccentric``): ``results.csv`` (one row per case),
``circumference.csv`` (per circular case, stage and height: the factors, EN's and AS's),
``pressure_theta.csv`` (per circular case, stage, height and sector: the pressure, over
``p_hf``, the windows' range), ``channel.csv``, ``square_faces.csv`` (per square case, stage,
face and height bin), ``square.csv`` (per square case, stage and height: far over near, over
the centred, the corners), ``circumference_e<e/R>.png`` per off-centre circular case,
``factors.png``, ``square.png``, copies of the runs' own wall pictures (with ``case_plots``),
``study.json`` and ``cases/<name>/`` (the circular ones in ``--runs-from``'s, if given).

**Cost of the default** (``python studies/eccentric.py --estimate`` prints it from the
settings, nothing run; :func:`three_d.estimate`: :mod:`fipy_hopper.space.estimate` at its 1.0 us
a loaded cell and step, one thread, the fill 1.2 gravity ramps and the discharge with all its
loaded cells): the circular silo centred (a quarter, 18 x 18 x 74 cubes, 13,568 loaded) 1,015 s
and off centre (a half, 36 x 18 x 74, 27,136 loaded) 2,031 s each, 7.5 s of discharge, 74,800
steps: 7,110 s for the four, what ``three_d.py``'s flat family takes (nothing when read from its
runs); the square silo centred (a quarter, 14 x 14 x 74 cubes, 8,076 loaded) 317 s and off
centre (a half, 28 x 14 x 74, 16,179 loaded) 635 s, 3.5 s of discharge, 39,200 steps: 951 s
for the two.  In all 8,060 s (2.2 hours) on one thread, about 1.1 hours on two cores kept
busy (the longest case, 2,031 s, a quarter of the total); 951 s with the circular runs read
from ``three_d.py``'s; 0.42 GB a worker at most.  An estimate from the settings, not a
measurement of this study.

**Quick** (``--quick``, the tests): ``three_d.py``'s quick flat family (a 0.32 m bin, the 0.12 m
outlet, filled to 0.26 m, 2 cm cubes, e/R = 0 and 0.5, 0.4 s of discharge, the same cases) and
a 0.24 m square bin on its 30 deg pyramid (0.12 m outlet, 0.1 m above the transition) with the
outlet at 0 and 0.04 m, 0.3 s of discharge, 4 sectors a face, no run pictures: about 20 s on
one thread by the estimate, 32 s measured on the busy machine (the kernels compiled).  Quick
numbers show that the study runs; they are not results.

Usage::

    python studies/eccentric.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                [--runs-from studies/output/three_d] [--cell-size 0.02]
                                [--end-time SECONDS] [--estimate]
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
import three_d  # noqa: E402

_r = _sweep.rounded
num = three_d.num
NAME = "eccentric"
TITLE = "Eccentric discharge in 3D against EN 1991-4 and AS 3774: a circular and a square silo"
#: the options :func:`three_d.family_config`, :func:`three_d.channel_rows` and the case names
#: read: this study's defaults and quick values of them are ``three_d.py``'s, so that the
#: flat family's cases are the same cases
SHARED = ("cell_size", "bin_diameter", "outlet_diameter", "fill_level", "headroom",
          "eccentricities", "drained_fraction", "end_time", "field_interval", "wall_sectors",
          "mirror_planes", "channel_fraction", "half_angle_deg")
FAMILY = "flat"
STAGES = ("filling", "early_discharge", "mid_discharge", "discharge_windows")
STAGE_WORDS = {"filling": "at rest", "early_discharge": "at 90 % left",
               "mid_discharge": "at 50 % left", "discharge_windows": "over the discharge's windows"}
#: the square silo: bin width, the square outlet, the centred hopper's half-angle, the fill
#: above the transition and the walls' headroom above it (m, deg)
SQUARE = {"bin_width": 0.48, "outlet_width": 0.12, "half_angle_deg": 30.0, "fill_height": 0.96,
          "headroom": 0.05}
SQUARE_QUICK = {"bin_width": 0.24, "outlet_width": 0.12, "half_angle_deg": 30.0,
                "fill_height": 0.1, "headroom": 0.04}
DEFAULTS = {**{k: three_d.DEFAULTS[k] for k in SHARED},
            "height_fractions": (0.25, 0.5, 0.75), "square": SQUARE,
            "square_offsets": (0.0, 0.12), "square_end_time": None, "square_sectors": 6,
            "case_plots": True}
QUICK = {**{k: three_d.QUICK[k] for k in SHARED if k in three_d.QUICK},
         "square": SQUARE_QUICK, "square_offsets": (0.0, 0.04), "square_end_time": 0.3,
         "square_sectors": 4, "case_plots": False}
NEAR, FAR = "x_plus", "x_minus"       # the outlet lies towards +x


# ---------------------------------------------------------------- the cases
def square_config(offset: float, opts) -> dict:
    """A square silo's configuration with its outlet ``offset`` m along +x: the
    ``opts["square"]`` bin on its pyramidal hopper, the reference's material and wall, the
    circular family's cubes, mirror planes and snapshots, ``square_sectors`` a face."""
    sq = opts["square"]
    base = three_d._reference_base()
    config = {"hopper": {"plan": "rectangular", "bin_width": sq["bin_width"],
                         "bin_length": sq["bin_width"], "outlet_width": sq["outlet_width"],
                         "half_angle_deg": sq["half_angle_deg"],
                         "bin_height": sq["fill_height"] + sq["headroom"],
                         "fill_height": sq["fill_height"], "dimensions": 3,
                         "outlet_offset": [round(float(offset), 12), 0.0]},
              "material": dict(base["material"]), "wall": dict(base["wall"]),
              "numerics": {"cell_size": float(opts["cell_size"]),
                           "mirror_planes": opts["mirror_planes"]},
              "run": {"output_interval": 0.05, "field_interval": float(opts["field_interval"]),
                      "wall_sectors": int(opts["square_sectors"])}}
    config["run"]["end_time"] = three_d.end_time(
        config, {"end_time": opts["square_end_time"],
                 "drained_fraction": opts["drained_fraction"]})
    return config


def square_case_of(offset: float) -> str:
    return _sweep.case_name(("square_e", round(1000 * float(offset), 3)))


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    cases = []
    for e in opts["eccentricities"]:
        config = three_d.family_config(FAMILY, e, opts)
        cases.append(_sweep.make_case(three_d.case_of(FAMILY, e), {
            "part": "eccentric", "family": FAMILY, "dimensions": 3, "e_over_R": float(e),
            "outlet_offset_m": config["hopper"]["outlet_offset"],
            "outlet_offset_cells": _r(three_d.offset_cells(e, opts), 6),
            "end_time_s": config["run"]["end_time"]}, config, plots=opts["case_plots"],
            track_wall_windows=True))
    for offset in opts["square_offsets"]:
        config = square_config(offset, opts)
        cases.append(_sweep.make_case(square_case_of(offset), {
            "part": "square", "family": "square", "dimensions": 3,
            "square_offset_m": float(offset),
            "offset_fraction": _r(float(offset) / (0.5 * (opts["square"]["bin_width"]
                                                          - opts["square"]["outlet_width"])), 4),
            "end_time_s": config["run"]["end_time"]}, config, plots=opts["case_plots"],
            track_wall_windows=True))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


def run(study, args) -> list:
    """Run the study's cases: all into ``args.out``, or the circular ones into
    ``args.runs_from`` (``_sweep``'s restart rule reads the finished ones of equal
    configuration there); the rows in the order of the cases."""
    args.out.mkdir(parents=True, exist_ok=True)
    cases = study["cases"]
    where = getattr(args, "runs_from", None)
    if where is None:
        print(f"{NAME}: {len(cases)} case(s) into {args.out}")
        return _sweep.sweep(cases, args)
    circular = [c for c in cases if c["params"]["family"] == FAMILY]
    square = [c for c in cases if c["params"]["family"] != FAMILY]
    print(f"{NAME}: {len(circular)} circular case(s) in {where} (read where finished with this "
          f"configuration), {len(square)} square case(s) into {args.out}")
    rows = _sweep.run_cases(circular, where, serial=args.serial, scheduler=args.scheduler,
                            workers=args.workers, force=args.force)
    rows += _sweep.sweep(square, args)
    order = {c["name"]: k for k, c in enumerate(cases)}
    return sorted(rows, key=lambda r: order[r["case"]])


# ---------------------------------------------------------------- pure measures
def extreme_factors(p, p_ref, theta=None) -> dict:
    """The largest overpressure and underpressure factor around the circumference at one
    height: ``over = max p / p_ref``, ``under = min p / p_ref`` over the finite sectors of
    ``p`` (Pa), and where they are (``theta``, deg, if given); NaN when no sector is finite
    or ``p_ref`` is not a positive number."""
    p = np.asarray(p, float)
    ok = np.isfinite(p)
    out = {"over": math.nan, "under": math.nan, "theta_over": math.nan,
           "theta_under": math.nan}
    if not ok.any() or not (math.isfinite(p_ref) and p_ref > 0):
        return out
    k_max = int(np.flatnonzero(ok)[np.argmax(p[ok])])
    k_min = int(np.flatnonzero(ok)[np.argmin(p[ok])])
    out["over"], out["under"] = float(p[k_max] / p_ref), float(p[k_min] / p_ref)
    if theta is not None:
        out["theta_over"], out["theta_under"] = float(theta[k_max]), float(theta[k_min])
    return out


def height_bins(z, on_bin_wall, bottom: float, level: float, fractions) -> list:
    """``[(fraction, z_target, k), ...]``: for each fraction of the fill's height above the
    bin wall's foot (``bottom`` to ``level``, m) the bin ``k`` of the bin wall (``on_bin_wall``)
    whose centre ``z`` is nearest; ``k`` is ``None`` without such bins."""
    z = np.asarray(z, float)
    idx = np.flatnonzero(np.asarray(on_bin_wall, bool))
    out = []
    for f in fractions:
        target = bottom + float(f) * (level - bottom)
        k = int(idx[np.argmin(np.abs(z[idx] - target))]) if idx.size else None
        out.append((float(f), target, k))
    return out


def signed_theta(theta) -> np.ndarray:
    """Angles (deg) in [-180, 180)."""
    return (np.asarray(theta, float) + 180.0) % 360.0 - 180.0


# ---------------------------------------------------------------- reading a run
def wall_windows(row, stage_rows: int):
    """The windows' ``(p_min, p_max)`` per row of a stage of ``wall_pressure.csv``
    (``wall_windows.json``), or ``None`` when the run has none."""
    import json

    path = Path(row["run_dir"]) / _sweep.WALL_WINDOWS
    if not path.is_file():
        return None
    with open(path, encoding="utf-8") as fh:
        data = json.load(fh)
    if not data.get("p_min_Pa") or len(data["p_min_Pa"]) != stage_rows:
        return None
    return (np.asarray(data["p_min_Pa"], float), np.asarray(data["p_max_Pa"], float))


def circular_stages(row) -> dict:
    """A circular case's stages per height bin: ``{stage: bins}`` of
    :func:`three_d.stage_bins`, the recorded load windows' stages and ``discharge_windows``
    (``p`` the sectors' largest over the windows, ``p_min`` their smallest; from the loop's
    discharge envelope without window records: ``p_min`` NaN, ``source`` "envelope")."""
    wall = three_d._wall(row)
    out = {}
    for stage in ("filling", "early_discharge", "mid_discharge"):
        bins = three_d.stage_bins(wall, stage)
        if bins is not None:
            out[stage] = bins
    rest = out.get("filling")
    if rest is not None:
        windows = wall_windows(row, rest["p"].size)
        if windows is not None:
            n = len(rest["theta"])
            out["discharge_windows"] = {**rest, "p": windows[1].reshape(-1, n),
                                        "p_min": windows[0].reshape(-1, n), "source": "windows"}
        else:
            env = three_d.stage_bins(wall, "discharge_envelope")
            if env is not None:
                out["discharge_windows"] = {**env, "p_min": np.full_like(env["p"], np.nan),
                                            "source": "envelope"}
    return out


def codes_of(cfg, K: float, G_measured: float) -> dict:
    """The ``codes`` of :func:`fipy_hopper.space.pictures.code_curves` for a circular case:
    EN's three G, and the measured G apart (``G_measured``, NaN for none)."""
    from fipy_hopper import theory

    geom = cfg.hopper
    return {"offset": float(geom.outlet_offset), "radius": 0.5 * geom.bin_diameter,
            "surface": float(geom.fill_level), "K": float(K),
            "mu": math.tan(math.radians(cfg.wall.friction_angle_deg)),
            "phi_deg": cfg.material.friction_angle_deg,
            "gamma": cfg.material.density * theory.G, "G": theory.EN1991_ECCENTRIC_G,
            "G_measured": G_measured}


def code_factors(codes: dict, z: float, p_hf: float, p_nf: float) -> dict:
    """The codes' largest and smallest pressure around the wall at height ``z`` over
    ``p_hf``: ``{"en": {G: (over, under)}, "en_measured": (over, under), "as": (over,
    under)}`` (NaN where a code gives none), on :data:`pictures.CODE_THETA`."""
    from fipy_hopper.space.pictures import CODE_THETA, code_curves

    nan2 = (math.nan, math.nan)

    def factors(p):
        return (float(np.max(p) / p_hf), float(np.min(p) / p_hf)) if p_hf > 0 else nan2
    curves = code_curves(CODE_THETA, z, p_hf, p_nf, codes)
    out = {"en": {}, "en_measured": nan2, "as": factors(curves["AS 3774"])
           if "AS 3774" in curves else nan2}
    for G in codes["G"]:
        p = curves.get(f"EN 1991-4, G = {G:.3g}")
        out["en"][G] = factors(p) if p is not None else nan2
    G_m = codes.get("G_measured", math.nan)
    if math.isfinite(G_m):
        p = code_curves(CODE_THETA, z, p_hf, p_nf, {**codes, "G": G_m})
        p = p.get(f"EN 1991-4, G = {G_m:.3g}")
        out["en_measured"] = factors(p) if p is not None else nan2
    return out


def code_lines(codes: dict, z: float, p_hf: float, p_nf: float) -> dict:
    """The codes' curves at height ``z`` on :data:`pictures.CODE_THETA` (EN's three G, the
    measured G, AS 3774): ``{label: p}``."""
    from fipy_hopper.space.pictures import CODE_THETA, code_curves

    out = dict(code_curves(CODE_THETA, z, p_hf, p_nf, codes))
    G_m = codes.get("G_measured", math.nan)
    if math.isfinite(G_m):
        for label, p in code_curves(CODE_THETA, z, p_hf, p_nf, {**codes, "G": G_m}).items():
            if label.startswith("EN"):
                out[f"EN 1991-4, measured G = {G_m:.2f}"] = p
    return out


# ---------------------------------------------------------------- (a) the circular silo
def circular_numbers(rows, options) -> tuple:
    """Per circular case its numbers; the rows of ``circumference.csv``,
    ``pressure_theta.csv`` and ``channel.csv``."""
    from fipy_hopper import theory

    ok = sorted(rows, key=lambda r: r["e_over_R"])
    if not ok:
        return {}, [], [], []
    stages = {r["case"]: circular_stages(r) for r in ok}
    centred = next((r for r in ok if r["e_over_R"] == 0.0), None)
    numbers, circ, theta_rows, chan = {}, [], [], []
    for row in ok:
        cfg = three_d._config_of(row)
        R = 0.5 * cfg.hopper.bin_diameter
        bottom = max(cfg.boundary.transition_height("wall"), 0.0)
        level = float(cfg.hopper.fill_level)
        base = centred if centred is not None else row
        base_stages = stages[base["case"]]
        K = base.get("wall_k_bin")
        if not _sweep.finite(K) or K <= 0:
            K = float(theory.k_en1991(cfg.material.friction_angle_deg))
        c_rows, channel = three_d.channel_rows(row, options)
        chan += c_rows
        G_m = channel.get("r_c_over_R")
        G_m = G_m if _sweep.finite(G_m) and 0.0 < G_m < 1.0 else math.nan
        codes = codes_of(cfg, K, G_m)
        per_stage = {}
        rest_base = base_stages.get("filling")
        if rest_base is not None:
            base_wall = (rest_base["z"] > 1e-9) & (np.abs(rest_base["r"] - R) < 1e-6)
        for stage in STAGES:
            bins = stages[row["case"]].get(stage)
            if bins is None or rest_base is None:
                continue
            on_wall = (bins["z"] > 1e-9) & (np.abs(bins["r"] - R) < 1e-6)
            same = base_stages.get(stage)
            entries = []
            for frac, target, k in height_bins(bins["z"], on_wall, bottom, level,
                                               options["height_fractions"]):
                if k is None:
                    continue
                z = float(bins["z"][k])
                # the centred case's bin-wall bin at that height (the same bins: one silo)
                kb = int(np.argmin(np.where(base_wall, np.abs(rest_base["z"] - z), np.inf)))
                p_hf = float(np.nanmean(rest_base["p"][kb]))
                # AS 3774's symmetric flow pressure: the centred case's in the same stage
                p_nf = float(np.nanmean(same["p"][kb])) if same is not None else math.nan
                p = bins["p"][k]
                low = bins.get("p_min")
                low = low[k] if low is not None else p
                f = extreme_factors(p, p_hf, bins["theta"])
                f_low = extreme_factors(low, p_hf, bins["theta"])
                mean = float(np.nanmean(p)) if stage != "discharge_windows" else math.nan
                own = extreme_factors(p, mean)
                codes_f = code_factors(codes, z, p_hf, p_nf) if codes["offset"] > 0 else None
                entry = {"fraction": frac, "z_target_m": _r(target, 4), "z_m": _r(z, 4),
                         "p_hf_Pa": _r(p_hf, 2), "p_nf_Pa": _r(p_nf, 2),
                         "over": _r(f["over"], 4), "under": _r(f_low["under"], 4),
                         "theta_over_deg": _r(f["theta_over"], 1),
                         "theta_under_deg": _r(f_low["theta_under"], 1),
                         "over_own_mean": _r(own["over"], 4),
                         "under_own_mean": _r(own["under"], 4)}
                if codes_f is not None:
                    entry["en"] = {f"{G:g}": [_r(v, 4) for v in codes_f["en"][G]]
                                   for G in codes["G"]}
                    entry["en_measured"] = [_r(v, 4) for v in codes_f["en_measured"]]
                    entry["as3774"] = [_r(v, 4) for v in codes_f["as"]]
                entries.append(entry)
                flat = {"case": row["case"], "e_over_R": row["e_over_R"], "stage": stage,
                        "source": bins.get("source", "stage"),
                        **{k_: v for k_, v in entry.items()
                           if k_ not in ("en", "en_measured", "as3774")}}
                if codes_f is not None:
                    for G in codes["G"]:
                        flat[f"en_G{G:g}_over"], flat[f"en_G{G:g}_under"] = codes_f["en"][G]
                    flat["en_measured_G"] = G_m
                    flat["en_measured_over"], flat["en_measured_under"] = codes_f["en_measured"]
                    flat["as3774_over"], flat["as3774_under"] = codes_f["as"]
                circ.append(flat)
                for j, t in enumerate(bins["theta"]):
                    theta_rows.append({"case": row["case"], "e_over_R": row["e_over_R"],
                                       "stage": stage, "fraction": frac, "z_m": z,
                                       "theta_deg": float(t), "p_Pa": float(p[j]),
                                       "p_over_p_hf": float(p[j] / p_hf) if p_hf > 0
                                       else math.nan,
                                       "p_min_Pa": float(low[j])})
            per_stage[stage] = entries
        numbers[row["case"]] = {
            "e_over_R": row["e_over_R"], "outlet_offset_m": row.get("outlet_offset_m"),
            "end_time_s": row.get("end_time_s"),
            "steady_rate": _r(row.get("steady_discharge_rate_kg_s"), 4),
            "discharged_fraction": _r(1.0 - row.get("remaining_mass_fraction", math.nan), 4),
            "flow_mode": row.get("flow_mode"), "mass_balance_error": row.get("mass_balance_error"),
            "wall_k_bin": _r(row.get("wall_k_bin"), 4), "K_used": _r(K, 4),
            "base": "centred" if centred is not None else "own",
            "windows": stages[row["case"]].get("discharge_windows", {}).get("source"),
            "wall_time_s": _r(row.get("wall_time_s"), 1), "reused": row.get("reused"),
            "channel": {k: v for k, v in channel.items() if k != "history"},
            "G_measured": _r(G_m, 3), "factors": per_stage,
            "en1991_large_eccentricity": bool(theory.en1991_large_eccentricity(
                float(row.get("outlet_offset_m") or 0.0), 2.0 * R))}
    return numbers, circ, theta_rows, chan


# ---------------------------------------------------------------- (b) the square silo
def face_profiles(row, stage: str) -> dict:
    """A rectangular case's faces at a stage: ``{face: {"z", "mean", "max", "min"}}`` per
    height bin (the floor left out; the mean across the width: the sectors are equal parts of
    it); ``discharge_windows``: the largest of the windows' largest and the smallest of their
    smallest (the mean NaN), from the discharge envelope's largest without window records."""
    from fipy_hopper.io import read_csv
    from fipy_hopper.space.pictures import faces_of

    t = read_csv(Path(row["run_dir"]) / "wall_pressure.csv")
    stages = np.asarray(t["stage"])
    windows = None
    if stage == "discharge_windows":
        on = stages == "filling"
        windows = wall_windows(row, int(on.sum()))
        if windows is None:
            on = stages == "discharge_envelope"
    else:
        on = stages == stage
    if not on.any():
        return {}
    p = np.asarray(t["p_n_Pa"], float)[on]
    hi, lo = (windows[1], windows[0]) if windows is not None else (p, p)
    windowed = stage == "discharge_windows"
    out = {}
    for face, (z, _, high, low) in faces_of(np.asarray(t["wall"])[on],
                                            np.asarray(t["z_m"], float)[on],
                                            np.asarray(t["u"], float)[on], hi, lo).items():
        out[face] = {"z": z,
                     "mean": np.full(len(z), np.nan) if windowed else np.nanmean(high, axis=1),
                     "max": np.nanmax(high, axis=1),
                     "min": np.full(len(z), np.nan) if windowed and windows is None
                     else np.nanmin(low, axis=1)}
    return out


def at(profile: dict, key: str, z) -> np.ndarray:
    """A face's ``key`` interpolated to the heights ``z`` (NaN outside its bins)."""
    zz, v = profile["z"], profile[key]
    ok = np.isfinite(v)
    z = np.asarray(z, float)
    if ok.sum() < 1:
        return np.full(z.shape, np.nan)
    out = np.interp(z, zz[ok], v[ok])
    return np.where((z >= zz[ok].min() - 1e-9) & (z <= zz[ok].max() + 1e-9), out, np.nan)


def corners_of(row, stage: str) -> dict:
    """``{corner: (z, p)}`` of a rectangular case's ``summary.json`` at a stage."""
    values = row.get(f"{stage}_corner_pressure_Pa")
    z = row.get("corner_z_m")
    if not isinstance(values, dict) or not isinstance(z, list):
        return {}
    return {c: (np.asarray(z, float), np.asarray(v, float)) for c, v in values.items()}


def square_numbers(rows, options) -> tuple:
    """Per square case its numbers; the rows of ``square_faces.csv`` and ``square.csv``."""
    ok = sorted(rows, key=lambda r: r["square_offset_m"])
    if not ok:
        return {}, [], []
    centred = next((r for r in ok if r["square_offset_m"] == 0.0), None)
    base = centred if centred is not None else ok[0]
    base_rest = face_profiles(base, "filling")
    bin_faces = ("x_plus", "x_minus", "y_plus", "y_minus")
    numbers, faces_rows, table = {}, [], []
    for row in ok:
        cfg = three_d._config_of(row)
        H = cfg.hopper.cone_height
        level = float(cfg.hopper.fill_level)
        per_stage = {}
        for stage in STAGES:
            prof = face_profiles(row, stage)
            if not prof:
                continue
            for face, f in prof.items():
                for k in range(len(f["z"])):
                    ref = (at(base_rest[face], "mean", [f["z"][k]])[0] if face in base_rest
                           else math.nan)
                    faces_rows.append({"case": row["case"], "offset_m": row["square_offset_m"],
                                       "stage": stage, "face": face, "z_m": f["z"][k],
                                       "mean_Pa": f["mean"][k], "max_Pa": f["max"][k],
                                       "min_Pa": f["min"][k], "centred_rest_mean_Pa": ref})
            corners = corners_of(row, stage) if stage != "discharge_windows" else {}
            base_corners = corners_of(base, "filling")
            entries = []
            for frac in options["height_fractions"]:
                z = H + float(frac) * (level - H)
                near_z = prof[NEAR]["z"] if NEAR in prof else np.zeros(0)
                if near_z.size:      # the near face's bin nearest the height
                    on_bin = near_z >= H - 1e-9
                    idx = np.flatnonzero(on_bin)
                    if idx.size:
                        z = float(near_z[idx[np.argmin(np.abs(near_z[idx] - z))]])
                ref = np.nanmean([at(base_rest[f], "mean", [z])[0] for f in bin_faces
                                  if f in base_rest])
                e = {"fraction": float(frac), "z_m": _r(z, 4), "p_hf_Pa": _r(float(ref), 2)}
                key = "max" if stage == "discharge_windows" else "mean"
                for face in bin_faces:
                    if face in prof:
                        e[f"{face}_{key}_over_p_hf"] = _r(float(at(prof[face], key, [z])[0]
                                                              / ref), 4)
                if NEAR in prof and FAR in prof:
                    e["far_over_near"] = _r(float(at(prof[FAR], key, [z])[0]
                                                  / at(prof[NEAR], key, [z])[0]), 4)
                faces_here = [prof[f] for f in bin_faces if f in prof]
                big = np.nanmax([at(f, "max", [z])[0] for f in faces_here])
                small = np.nanmin([at(f, "min", [z])[0] for f in faces_here])
                e["over"], e["under"] = _r(float(big / ref), 4), _r(float(small / ref), 4)
                base_c = [at({"z": zc, "v": pc}, "v", [z])[0]
                          for zc, pc in base_corners.values()]
                c_ref = float(np.nanmean(base_c)) if base_c else math.nan
                for corner, (zc, pc) in corners.items():
                    e[f"corner_{corner}_over_centred"] = _r(float(
                        at({"z": zc, "v": pc}, "v", [z])[0] / c_ref), 4)
                entries.append(e)
                table.append({"case": row["case"], "offset_m": row["square_offset_m"],
                              "stage": stage, **e})
            ratio_rows = []
            for near, far in ((NEAR, FAR), ("hopper_" + NEAR, "hopper_" + FAR)):
                if near in prof and far in prof and stage != "discharge_windows":
                    r_ = at(prof[far], "mean", prof[near]["z"]) / prof[near]["mean"]
                    ratio_rows.append({"part": "bin" if near == NEAR else "hopper",
                                       "z_m": [_r(v, 4) for v in prof[near]["z"]],
                                       "far_over_near": [_r(v, 4) for v in r_]})
            per_stage[stage] = {"heights": entries, "far_over_near_by_bin": ratio_rows}
        numbers[row["case"]] = {
            "outlet_offset_m": row["square_offset_m"],
            "offset_fraction": row.get("offset_fraction"), "end_time_s": row.get("end_time_s"),
            "steady_rate": _r(row.get("steady_discharge_rate_kg_s"), 4),
            "flow_mode": row.get("flow_mode"), "mass_balance_error": row.get("mass_balance_error"),
            "wall_k_bin": _r(row.get("wall_k_bin"), 4), "hopper_height_m": _r(H, 4),
            "wall_time_s": _r(row.get("wall_time_s"), 1), "stages": per_stage}
    return numbers, faces_rows, table


def analyse(rows, options) -> tuple:
    """``(numbers, tables)``: the study's numbers and the rows of its CSV files."""
    ok = [r for r in rows if not r.get("error") and r.get("run_dir")]
    circular = [r for r in ok if r.get("family") == FAMILY]
    square = [r for r in ok if r.get("family") == "square"]
    numbers, tables = {}, {}
    circ, circ_rows, theta_rows, chan = circular_numbers(circular, options)
    if circ:
        numbers["circular"] = circ
        numbers["en1991_channel"] = three_d.en_channels(three_d._config_of(circular[0]))
    sq, face_rows, sq_rows = square_numbers(square, options)
    if sq:
        numbers["square"] = sq
    tables.update(circumference=circ_rows, pressure_theta=theta_rows, channel=chan,
                  square_faces=face_rows, square=sq_rows)
    for row in rows:
        case = circ.get(row["case"])
        if case:
            early = case["factors"].get("early_discharge", [])
            row["theta_c_deg"] = case["channel"].get("theta_c_deg")
            row["r_c_over_R"] = case["channel"].get("r_c_over_R")
            row["early_over"] = " ".join(str(e["over"]) for e in early)
            row["early_under"] = " ".join(str(e["under"]) for e in early)
        case = sq.get(row["case"])
        if case:
            early = case["stages"].get("early_discharge", {}).get("heights", [])
            row["early_far_over_near"] = " ".join(str(e.get("far_over_near")) for e in early)
    return numbers, tables


# ---------------------------------------------------------------- pictures
def _circular_cases(numbers):
    return sorted(((n["e_over_R"], case, n) for case, n in numbers.get("circular", {}).items()),
                  key=lambda t: t[0])


def plot_circumference(case: str, numbers, tables, rows):
    """An off-centre circular case: per stage (rows: at rest, the recorded windows) and
    height (columns) the measured p(theta) / p_hf beside the centred case's, the windows'
    range, EN 1991-4's pattern (three G and the measured) and AS 3774's rule with its band."""
    from fipy_hopper.space.pictures import CODE_THETA

    n = numbers["circular"][case]
    by = {r["case"]: r for r in rows}
    cfg = three_d._config_of(by[case])
    codes = codes_of(cfg, n["K_used"], n["G_measured"] if _sweep.finite(n["G_measured"])
                     else math.nan)
    centred = next((c for e, c, _ in _circular_cases(numbers) if e == 0.0), None)
    stages = [s for s in STAGES if n["factors"].get(s)]
    fractions = [e["fraction"] for e in n["factors"][stages[0]]] if stages else []
    fig = _sweep.figure(4.0 * max(len(fractions), 1) + 1.0, 3.2 * max(len(stages), 1) + 0.8)
    axes = fig.subplots(max(len(stages), 1), max(len(fractions), 1), squeeze=False)
    pt = tables["pressure_theta"]
    colours = {"EN 1991-4, G = 0.25": "C1", "EN 1991-4, G = 0.4": "C2",
               "EN 1991-4, G = 0.6": "C4"}
    handles, labels = [], []
    for i, stage in enumerate(stages):
        for j, entry in enumerate(n["factors"][stage]):
            ax = axes[i, j]
            frac = entry["fraction"]
            for who, style, colour, label in ((case, "-o", "C0", "this case"),
                                              (centred, "-", "0.5", "centred")):
                if who is None:
                    continue
                on = [r for r in pt if r["case"] == who and r["stage"] == stage
                      and r["fraction"] == frac]
                if not on:
                    continue
                t = signed_theta([r["theta_deg"] for r in on])
                order = np.argsort(t)
                t = np.append(t[order], t[order][0] + 360.0)
                v = np.array([r["p_over_p_hf"] for r in on])[order]
                v = np.append(v, v[0])
                ax.plot(t, v, style, ms=3, color=colour, lw=1.2 if who == case else 0.8,
                        label=f"{label}{' (largest)' if stage == 'discharge_windows' else ''}")
                if stage == "discharge_windows" and who == case:
                    lo = np.array([r["p_min_Pa"] for r in on])[order] / entry["p_hf_Pa"]
                    lo = np.append(lo, lo[0])
                    if np.isfinite(lo).any():
                        ax.fill_between(t, lo, v, color="C0", alpha=0.2,
                                        label="the windows' range")
            if stage != "filling":
                lines = code_lines(codes, entry["z_m"], entry["p_hf_Pa"],
                                   entry["p_nf_Pa"] if _sweep.finite(entry["p_nf_Pa"])
                                   else math.nan)
                for label, p in lines.items():
                    v = p / entry["p_hf_Pa"]
                    if label == "AS 3774":
                        ax.plot(CODE_THETA, v, "k:", lw=1.2, label="AS 3774 (p_nf + increment)")
                        ax.fill_between(CODE_THETA, entry["p_nf_Pa"] / entry["p_hf_Pa"], v,
                                        color="0.5", alpha=0.15, label="AS 3774's band")
                    elif label.startswith("EN 1991-4, measured"):
                        ax.plot(CODE_THETA, v, "--", color="C3", lw=1.6, label=label)
                    else:
                        ax.plot(CODE_THETA, v, "--", color=colours.get(label, "C5"), lw=0.9,
                                label=label)
            ax.axhline(1.0, color="k", lw=0.5)
            ax.set_xlim(-180, 180)
            ax.set_xticks(range(-180, 181, 60))
            ax.set_title(f"{STAGE_WORDS[stage]}, z = {entry['z_m']:.3g} m "
                         f"({frac:g} of the fill)", fontsize=8)
            if j == 0:
                ax.set_ylabel("p_n / p_hf (the centred at rest)")
            if i == len(stages) - 1:
                ax.set_xlabel("theta (deg), 0 the outlet's side")
            if (i, j) == (min(1, len(stages) - 1), 0):
                handles, labels = ax.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncol=5, fontsize=7)
    fig.suptitle(f"The circular silo, e/R = {n['e_over_R']:g}: the wall pressure around the "
                 "circumference against EN 1991-4 and AS 3774", fontsize=10)
    return fig


def plot_factors(numbers):
    """The largest overpressure and underpressure factor at each height against e/R at 90 %
    left and over the discharge's windows, beside EN 1991-4's (G = 0.4 and the measured G)
    and AS 3774's."""
    cases = _circular_cases(numbers)
    fractions = sorted({e["fraction"] for _, _, n in cases
                        for e in n["factors"].get("filling", [])})
    fig = _sweep.figure(4.0 * max(len(fractions), 1) + 0.5, 4.2)
    axes = fig.subplots(1, max(len(fractions), 1), squeeze=False)[0]
    es = [e for e, _, _ in cases]

    def series(stage, frac, getter):
        out = []
        for _, _, n in cases:
            entry = next((x for x in n["factors"].get(stage, []) if x["fraction"] == frac),
                         None)
            v = getter(entry) if entry else None
            out.append(math.nan if v is None else v)
        return np.array(out, float)
    for ax, frac in zip(axes, fractions):
        for stage, marker, fill in (("early_discharge", "o", "full"),
                                    ("discharge_windows", "s", "none")):
            for key, colour in (("over", "C3"), ("under", "C0")):
                v = series(stage, frac, lambda e, k=key: e.get(k))
                ax.plot(es, v, marker=marker, fillstyle=fill, color=colour, ls="-",
                        label=f"measured {key}, {STAGE_WORDS[stage]}")
        for idx, key in ((0, "over"), (1, "under")):
            en = series("early_discharge", frac,
                        lambda e, i=idx: (e.get("en") or {}).get("0.4", [None, None])[i])
            ax.plot(es, en, "--^", color="C2", ms=5, label=f"EN G = 0.4, {key}")
            enm = series("early_discharge", frac,
                         lambda e, i=idx: (e.get("en_measured") or [None, None])[i])
            ax.plot(es, enm, "--v", color="C3" if idx == 0 else "C0", lw=0.8, ms=5,
                    label=f"EN measured G, {key}")
            as_ = series("early_discharge", frac,
                         lambda e, i=idx: (e.get("as3774") or [None, None])[i])
            ax.plot(es, as_, ":D", color="k", ms=4, label=f"AS 3774, {key}")
        ax.axhline(1.0, color="k", lw=0.5)
        ax.set_xlabel("e/R of the outlet (-)")
        ax.set_ylabel("p_n / p_hf (the centred at rest)")
        ax.set_title(f"{frac:g} of the fill's height", fontsize=9)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=5, fontsize=6)
    fig.suptitle("The circular silo: the largest and the smallest wall pressure around the "
                 "circumference over p_hf", fontsize=10)
    return fig


def plot_square(numbers, tables):
    """The square silo: each bin face's and hopper face's mean pressure against height at
    rest and at 90 % left, centred (grey) and off centre; the far over the near face per
    height; the corners over the centred case's."""
    fig = _sweep.figure(11.0, 8.0)
    axes = fig.subplots(2, 2)
    faces = tables["square_faces"]
    cases = sorted(numbers.get("square", {}).items(), key=lambda t: t[1]["outlet_offset_m"])
    colours = {"x_plus": "C3", "x_minus": "C0", "y_plus": "C2", "y_minus": "C1"}
    for ax, stage in zip(axes[0], ("filling", "early_discharge")):
        for case, n in cases:
            centred = n["outlet_offset_m"] == 0.0
            for face in ("x_plus", "x_minus", "y_plus", "y_minus"):
                for part in ("", "hopper_"):
                    on = [r for r in faces if r["case"] == case and r["stage"] == stage
                          and r["face"] == part + face]
                    if not on:
                        continue
                    ax.plot([r["mean_Pa"] for r in on], [r["z_m"] for r in on],
                            "-", color="0.6" if centred
                            else colours[face], lw=0.8 if centred else 1.2,
                            marker="" if centred else "o", ms=2,
                            label=(("centred" if face == "x_plus" else None) if centred
                                   else f"e = {n['outlet_offset_m']:g} m, {face}")
                            if part == "" else None)
        ax.set_xlabel("mean p_n across the face (Pa)")
        ax.set_ylabel("z (m)")
        ax.set_title(f"{STAGE_WORDS[stage]}: the faces (bin above, hopper below)", fontsize=9)
        ax.legend(fontsize=6)
    ax = axes[1, 0]
    for case, n in cases:
        if n["outlet_offset_m"] == 0.0:
            continue
        for k, stage in enumerate(("filling", "early_discharge", "mid_discharge")):
            for part in n["stages"].get(stage, {}).get("far_over_near_by_bin", []):
                ax.plot(part["far_over_near"], part["z_m"], marker="o", ms=2, color=f"C{k}",
                        ls="-" if part["part"] == "bin" else "--",
                        label=f"{STAGE_WORDS[stage]}, {part['part']}")
    ax.axvline(1.0, color="k", lw=0.6)
    ax.set_xlabel("far face (x_minus) / near face (x_plus), the mean p_n")
    ax.set_ylabel("z (m) of the near face's bin")
    ax.set_title("Off centre: the far over the near face per height", fontsize=9)
    ax.legend(fontsize=6)
    ax = axes[1, 1]
    for case, n in cases:
        for k, stage in enumerate(("filling", "early_discharge")):
            heights = n["stages"].get(stage, {}).get("heights", [])
            for corner, style in (("x_plus_y_plus", "-o"), ("x_minus_y_plus", "--s")):
                v = [e.get(f"corner_{corner}_over_centred") for e in heights]
                z = [e["z_m"] for e in heights]
                if any(_sweep.finite(x) for x in v):
                    ax.plot([math.nan if x is None else x for x in v], z, style, ms=3,
                            color=f"C{k}" if n["outlet_offset_m"] else f"{0.4 + 0.3 * k}",
                            label=f"e = {n['outlet_offset_m']:g} m, {corner}, "
                                  f"{STAGE_WORDS[stage]}")
    ax.axvline(1.0, color="k", lw=0.6)
    ax.set_xlabel("corner pressure / the centred case's at rest")
    ax.set_ylabel("z (m)")
    ax.set_title("The bin's corners (near: x_plus, far: x_minus)", fontsize=9)
    ax.legend(fontsize=6)
    fig.suptitle("The square silo on a centred and an off-centre pyramidal hopper", fontsize=10)
    return fig


# ---------------------------------------------------------------- findings
def _pair(v, spec=".2f") -> str:
    """``over/under`` of a code's factors, "n/a" without them."""
    if not v or not any(_sweep.finite(x) for x in v):
        return "n/a"
    return "/".join(num(x, spec) for x in v)


def circular_findings(numbers, options) -> list:
    out = []
    cases = _circular_cases(numbers)
    if not cases:
        return out
    en = numbers.get("en1991_channel", [])
    en_text = ", ".join(f"r_c/R {c['G']:g}: theta_c {c['theta_c_deg']:.1f} deg" for c in en)
    parts = [f"e/R {e:g}: theta_c {num(n['channel'].get('theta_c_deg'), '.1f')} deg, r_c/R "
             f"{num(n['channel'].get('r_c_over_R'), '.2f')}, e_c/R "
             f"{num(n['channel'].get('e_c_over_R'), '.2f')}"
             f"{three_d.window_spread(n['channel'])}" for e, _, n in cases]
    reused = sum(1 for _, _, n in cases if n.get("reused"))
    out.append(
        f"The circular silo ({options['bin_diameter']:g} m bin on a flat floor, "
        f"{options['outlet_diameter']:g} m outlet, filled to {options['fill_level']:g} m, "
        f"{1000 * options['cell_size']:g} mm cubes; {reused} of {len(cases)} runs read, not "
        f"rerun): steady rate {', '.join(num(n['steady_rate'], '.2f') for _, _, n in cases)}"
        f" kg/s at e/R = {', '.join(f'{e:g}' for e, _, _ in cases)}; the flow channel in the "
        f"bin's middle half {three_d.channel_when(cases[0][2]['channel'])}: " + "; ".join(parts)
        + f". EN 1991-4: {en_text}.")
    large = [f"{e:g}" for e, _, n in cases if n.get("en1991_large_eccentricity")]
    small = [f"{e:g}" for e, _, n in cases if not n.get("en1991_large_eccentricity") and e > 0]
    out.append(
        "EN 1991-4 calls for its large-eccentricity case above e_o = 0.25 d_c (e/R = 0.5; "
        "theory.en1991_large_eccentricity, as recalled [M]): at e/R = "
        + (", ".join(large) if large else "none of these offsets")
        + (f"; at e/R = {', '.join(small)} its pattern is drawn for comparison only (the "
           "standard covers those offsets with its symmetrical and patch loads)" if small
           else "") + ".")
    for stage in ("filling", "early_discharge", "discharge_windows"):
        parts = []
        for e, _, n in cases:
            entries = n["factors"].get(stage, [])
            if not entries:
                continue
            heights = ", ".join(
                f"z {x['z_m']:.2f} m {num(x['over'], '.2f')}/{num(x['under'], '.2f')}"
                + (f" (EN G 0.4 {_pair((x.get('en') or {}).get('0.4'))}, measured G "
                   f"{_pair(x.get('en_measured'))}; AS {_pair(x.get('as3774'))})"
                   if stage != "filling" and x.get("en") else "")
                for x in entries)
            parts.append(f"e/R {e:g}: {heights}")
        if parts:
            whose = "centred case" if cases[0][2]["base"] == "centred" else "case"
            out.append(
                f"The circular silo {STAGE_WORDS[stage]}, the largest/smallest wall pressure "
                f"around the circumference over p_hf (the {whose}'s mean at rest at that "
                f"height) at a quarter, half and three quarters of the fill"
                + (" (EN 1991-4's largest/smallest for G = 0.4 and the measured G, and AS "
                   "3774's)" if stage != "filling" else "") + ": " + "; ".join(parts) + ".")
    return out


def square_findings(numbers, options) -> list:
    out = []
    cases = sorted(numbers.get("square", {}).items(), key=lambda t: t[1]["outlet_offset_m"])
    if not cases:
        return out
    sq = options["square"]
    offsets = ", ".join(f"{n['outlet_offset_m']:g}" for _, n in cases)
    rates = ", ".join(num(n["steady_rate"], ".2f") for _, n in cases)
    out.append(
        f"The square silo ({sq['bin_width']:g} m bin on a {sq['half_angle_deg']:g} deg pyramid to "
        f"a {sq['outlet_width']:g} m square outlet, filled {sq['fill_height']:g} m above the "
        f"transition) with its outlet at {offsets} m: steady rate {rates} kg/s, "
        f"flow mode {', '.join(str(n['flow_mode']) for _, n in cases)}.")
    for stage in ("filling", "early_discharge", "discharge_windows"):
        parts = []
        for _, n in cases:
            entries = n["stages"].get(stage, {}).get("heights", [])
            if not entries:
                continue
            parts.append(f"e = {n['outlet_offset_m']:g} m: " + ", ".join(
                f"z {x['z_m']:.2f} m far/near {num(x.get('far_over_near'), '.2f')}, "
                f"largest/smallest over p_hf {num(x['over'], '.2f')}/{num(x['under'], '.2f')}"
                + (f", corners near {num(x.get('corner_x_plus_y_plus_over_centred'), '.2f')} "
                   f"far {num(x.get('corner_x_minus_y_plus_over_centred'), '.2f')} of the "
                   f"centred's at rest" if stage != "discharge_windows" else "")
                for x in entries))
        if parts:
            out.append(f"The square silo {STAGE_WORDS[stage]} (the bin's faces; p_hf the "
                       "centred case's mean at rest at that height): " + "; ".join(parts) + ".")
    return out


# ---------------------------------------------------------------- outputs
def write_outputs(out, rows, numbers, tables, options, setting, argv=None):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "part", "family", "e_over_R", "outlet_offset_m", "square_offset_m", "end_time_s",
        "steady_discharge_rate_kg_s", "flow_mode", "theta_c_deg", "r_c_over_R", "early_over",
        "early_under", "early_far_over_near", "mass_balance_error", "wall_time_s", "reused",
        "error"))
    for name in ("circumference", "pressure_theta", "channel", "square_faces", "square"):
        _sweep.write_rows_csv(out / f"{name}.csv", tables[name])
    figures = []
    for e, case, _ in _circular_cases(numbers):
        if e == 0.0:
            continue
        name = f"circumference_e{_sweep.fmt(float(e))}.png"
        _sweep.save(plot_circumference(case, numbers, tables, rows), out / name)
        figures.append({"file": name, "caption": (
            f"The circular silo with its outlet at e/R = {e:g}: the wall pressure around the "
            "circumference over p_hf (the centred case's mean at rest at that height) at a "
            "quarter, half and three quarters of the fill (columns), at rest and in the "
            "discharge's windows (rows); grey the centred case; dashed EN 1991-4's "
            "large-eccentricity pattern for G = 0.25, 0.4, 0.6 and (thick) the measured "
            "r_c / R; dotted AS 3774's rule on the centred case's pressure, its band shaded.")})
    if _circular_cases(numbers):
        _sweep.save(plot_factors(numbers), out / "factors.png")
        figures.append({"file": "factors.png", "caption": (
            "The circular silo: the largest overpressure and underpressure factor (the largest "
            "and the smallest p_n around the circumference over the centred case's at rest) at "
            "three heights against e/R, at 90 % left and over the discharge's windows, beside "
            "EN 1991-4's (G = 0.4 and the measured G) and AS 3774's.")})
    if numbers.get("square"):
        _sweep.save(plot_square(numbers, tables), out / "square.png")
        figures.append({"file": "square.png", "caption": (
            "The square silo on a centred and an off-centre pyramidal hopper: each face's mean "
            "pressure against height at rest and at 90 % left (the centred grey), the far face "
            "over the near face per height, the bin's corners over the centred case's.")})
    by = {r["case"]: r for r in rows}
    copies = []
    cases = _circular_cases(numbers)
    if cases and cases[-1][0] > 0:
        copies.append((cases[-1][1], "wall_circumference.png",
                       f"The circular silo at e/R = {cases[-1][0]:g}: the run's own picture of "
                       "the wall pressure around the circumference with the codes' patterns."))
    for case, n in numbers.get("square", {}).items():
        copies.append((case, "wall_faces.png", f"The square silo with its outlet at "
                       f"{n['outlet_offset_m']:g} m: the run's own picture of its faces."))
    for case, picture, caption in copies:
        source = Path(by.get(case, {}).get("run_dir", "")) / picture
        if source.is_file():
            name = f"{Path(picture).stem}_{case}.png"
            shutil.copyfile(source, out / name)
            figures.append({"file": name, "caption": caption})
    tables_out = []
    if cases:
        tables_out.append({"title": "Circular silo: the factors at 90 % left", "columns": [
            "e/R", "z (m)", "over", "under", "EN G 0.4 over/under", "EN measured G over/under",
            "AS 3774 over/under"], "rows": [
            [e, x["z_m"], x["over"], x["under"], _pair((x.get("en") or {}).get("0.4")),
             _pair(x.get("en_measured")), _pair(x.get("as3774"))]
            for e, _, n in cases for x in n["factors"].get("early_discharge", [])]})
    if numbers.get("square"):
        tables_out.append({"title": "Square silo at 90 % left", "columns": [
            "offset (m)", "z (m)", "far / near", "over", "under"], "rows": [
            [n["outlet_offset_m"], x["z_m"], x.get("far_over_near"), x["over"], x["under"]]
            for _, n in sorted(numbers["square"].items(), key=lambda t: t[1]["outlet_offset_m"])
            for x in n["stages"].get("early_discharge", {}).get("heights", [])]})
    findings = circular_findings(numbers, options) + square_findings(numbers, options)
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables_out, rows, argv)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m, the cubes of every case")
    parser.add_argument("--end-time", type=float,
                        help="s of discharge for every circular case (default: Beverloo's "
                             "time for drained_fraction of the fill)")
    parser.add_argument("--runs-from", type=Path, default=None, metavar="DIR",
                        help="run (or read, where finished with the same configuration) the "
                             "circular cases in DIR/cases, e.g. studies/output/three_d")
    parser.add_argument("--estimate", action="store_true",
                        help="print each case's grid, memory and time estimate and stop")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_size", "end_time"))
    study = setup(quick=args.quick, **options)
    if args.estimate:
        rows = three_d.estimate(study)
        total = three_d.print_estimate(rows)
        square = sum(r["seconds"] for r, c in zip(rows, study["cases"])
                     if c["params"]["family"] != FAMILY)
        print(f"all: {three_d.cost_text(total)}; the square silo alone {square:,.0f} s (the "
              "circular cases read from three_d.py's runs)")
        return 0
    rows = run(study, args)
    numbers, tables = analyse(rows, study["options"])
    write_outputs(args.out, rows, numbers, tables, study["options"], study["setting"], argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
