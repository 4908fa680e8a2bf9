"""A design envelope of the wall pressure: a silo over a range of outlet offsets and its
material's properties at their characteristic extremes, the largest and the smallest wall
pressure at each height and sector over all of them.

A silo (``--config``: any 3D configuration, a circular or a rectangular plan; default a
square bin on a pyramidal hopper, below) is run, as a Dask sweep (:mod:`_sweep`), for every
outlet offset in ``offset_fractions`` (fractions of the room the outlet has along ``+x``: a
circular silo's ``R - R0``, a rectangular bin's ``B/2 - ox/2``) and every combination of

* the wall friction ``mu_w = tan(phi_w)`` at its lower and upper characteristic values,
  ``mu_m / a_mu`` and ``a_mu mu_m`` (``mu_m`` the configuration's);
* the angle of internal friction at ``phi_m / a_phi`` and ``a_phi phi_m`` (``phi_m`` the
  configuration's), which is also how the lateral pressure ratio ``K`` moves in this model: a
  Mohr-Coulomb continuum has no ``K`` of its own to set, so ``K`` follows from ``phi`` (the
  lower ``phi`` gives the upper ``K``, the pairing of EN 1991-4's Table 3.1 for the largest
  wall pressure); each case's ``K`` measured at the bin wall at rest (``wall_k_bin``) is
  reported beside EN 1991-4's characteristic range ``K_m / a_K .. a_K K_m`` with ``K_m =
  1.1 (1 - sin phi_m)``.

The conversion factors are EN 1991-4's (Annex E, Table E.1, the row "default material":
``a_phi = 1.30``, ``a_K = 1.50``, ``a_mu = 1.40``) as remembered, not checked against the
standard's text (unverified); give a material's own with ``--a-phi``, ``--a-k``, ``--a-mu``.
The characteristic values are the mean times or over the factor (EN 1991-4, 4.2.3, as
remembered: ``X_u = a_X X_m``, ``X_l = X_m / a_X``; unverified).

Every case is filled to rest and discharged for ``end_time``; its loads are the ones recovered
from the wall's reaction (the run's ``wall_pressure.csv``): at rest, and over consecutive
windows of the run's ``load_window`` through the discharge, whose smallest and largest per
patch each case records (``wall_windows.json``, :class:`_sweep._WallWindows`).  The envelope
per patch (a wall's height bin times a sector: around the circumference, or across a
rectangular plan's face) is the largest and the smallest over every case and window, with the
case and the window (``filling`` or ``discharge``) where each occurs.  Patches are matched
between cases by their wall (face), their bin's place up that wall and their sector: on a
circular silo's bin wall and a rectangular bin's faces the bins are the same in every case;
the hopper's (an eccentric cone's, a sheared pyramid's) move a little with the offset, and
``z_m`` is then the mean of the cases' heights (``z_min_m``, ``z_max_m`` their range).

Written to ``--out`` (default ``studies/output/envelope``): ``results.csv`` (a row per case),
``envelope.csv`` (a row per patch), ``envelope.png`` and ``study.json``.

Usage::

    python studies/envelope.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                               [--config SILO.toml] [--offset-fractions 0 0.4 0.8]
                               [--a-phi 1.3] [--a-k 1.5] [--a-mu 1.4] [--end-time 1.0]
                               [--estimate]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

from fipy_hopper.config import HopperConfig  # noqa: E402

_r = _sweep.rounded
NAME = "envelope"
TITLE = "A design envelope of the wall pressure over outlet offsets and material extremes"
#: EN 1991-4 Table E.1, "default material": a_phi, a_K, a_mu (as remembered: unverified)
EN1991_DEFAULT_FACTORS = {"a_phi": 1.30, "a_K": 1.50, "a_mu": 1.40}
#: the default silo: a square bin (0.4 m) on a pyramidal hopper (30 deg, a 0.12 m square
#: outlet), filled 0.3 m above the transition, 2 cm cells
SILO = {"hopper": {"plan": "rectangular", "bin_width": 0.4, "bin_length": 0.4,
                   "outlet_width": 0.12, "half_angle_deg": 30.0, "bin_height": 0.4,
                   "fill_height": 0.3, "dimensions": 3},
        "numerics": {"cell_size": 0.02}}
DEFAULTS = {"silo": SILO, "offset_fractions": (0.0, 0.4, 0.8),
            "combinations": (("lower", "lower"), ("lower", "upper"), ("upper", "lower"),
                             ("upper", "upper")),
            **EN1991_DEFAULT_FACTORS, "end_time": 1.0, "wall_sectors": 12,
            "output_interval": 0.02, "field_interval": 0.25, "case_plots": False}
#: a flat-bottomed square bin 0.24 m wide, 0.1 m of material, two offsets, two extremes
QUICK = {"silo": {"hopper": {"plan": "rectangular", "bin_width": 0.24, "bin_length": 0.24,
                             "outlet_width": 0.12, "half_angle_deg": 90.0,
                             "bin_height": 0.14, "fill_height": 0.1, "dimensions": 3},
                  "numerics": {"cell_size": 0.02}},
         "offset_fractions": (0.0, 0.5), "combinations": (("lower", "lower"),
                                                         ("upper", "upper")),
         "end_time": 0.04, "wall_sectors": 4, "field_interval": 0.04}


def _resolved(silo: dict) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict(silo)


def offset_room(cfg: HopperConfig) -> float:
    """How far (m) the outlet's centre can move along ``+x``: a circular silo's ``R - R0``
    (its widest radius less the lip's), a rectangular bin's ``B/2 - ox/2``."""
    geom = cfg.hopper
    if geom.rectangular:
        return 0.5 * (geom.bin_width - geom.outlet_size[0])
    return max(r for r, _ in geom.wall_points) - geom.wall_points[0][0]


def characteristic(options: dict, cfg: HopperConfig) -> dict:
    """The material's characteristic values: ``phi`` and ``mu`` (and the wall friction angle)
    lower and upper, EN's ``K`` range from ``phi_m``."""
    phi_m = cfg.material.friction_angle_deg
    mu_m = math.tan(math.radians(cfg.wall.friction_angle_deg))
    a_phi, a_k, a_mu = options["a_phi"], options["a_K"], options["a_mu"]
    k_m = 1.1 * (1.0 - math.sin(math.radians(phi_m)))
    return {"phi": {"lower": phi_m / a_phi, "upper": min(phi_m * a_phi, 89.0)},
            "mu": {"lower": mu_m / a_mu, "upper": mu_m * a_mu},
            "phi_m": phi_m, "mu_m": mu_m, "K_m": k_m, "K_lower": k_m / a_k,
            "K_upper": k_m * a_k}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting", "values"}``); unknown options
    raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    base = _resolved(opts["silo"])
    values = characteristic(opts, base)
    room = offset_room(base)
    cases = []
    for frac in opts["offset_fractions"]:
        e = round(float(frac) * room, 6)
        for mu_key, phi_key in opts["combinations"]:
            phi = values["phi"][phi_key]
            mu = values["mu"][mu_key]
            material = {"friction_angle_deg": round(phi, 6),
                        "dilation_angle_deg": min(base.material.dilation_angle_deg,
                                                  round(phi, 6))}
            hopper = dict(opts["silo"]["hopper"])
            hopper["outlet_offset"] = [e, 0.0] if base.hopper.rectangular else e
            config = _sweep.merge(
                opts["silo"], hopper=hopper, material=material,
                wall={"friction_angle_deg": round(math.degrees(math.atan(mu)), 6)},
                run={"end_time": opts["end_time"], "output_interval": opts["output_interval"],
                     "field_interval": opts["field_interval"],
                     "wall_sectors": opts["wall_sectors"]})
            config.get("wall", {}).pop("segment_friction_deg", None)
            name = _sweep.case_name(("e", round(1000 * e, 3)), ("mu", mu_key), ("phi", phi_key))
            cases.append(_sweep.make_case(
                name, {"offset_m": e, "offset_fraction": float(frac), "mu_w": mu_key,
                       "phi": phi_key, "mu_w_value": mu, "phi_deg": phi}, config,
                plots=opts["case_plots"], track_wall_windows=True))
    return {"options": opts, "cases": cases, "values": values,
            "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- analysis
def case_patches(run_dir) -> list:
    """The patches of a run: ``[{"key": (wall, bin, sector), "wall", "s", "z", "across",
    "filling", "window_min", "window_max"}, ...]`` from its ``wall_pressure.csv`` (the
    filling stage, the recovered ``p_n``) and ``wall_windows.json`` (NaN without windows)."""
    from fipy_hopper.io import read_csv

    run_dir = Path(run_dir)
    t = read_csv(run_dir / "wall_pressure.csv")
    stage = np.asarray(t["stage"])
    on = stage == "filling"
    wall = np.asarray(t["wall"])[on]
    across_key = "u" if "u" in t else "theta_deg"
    across = np.asarray(t[across_key], float)[on]
    s = np.asarray(t["s_m"], float)[on]
    z = np.asarray(t["z_m"], float)[on]
    p = np.asarray(t["p_n_Pa"], float)[on]
    n = len(np.unique(across))
    windows = {}
    path = run_dir / _sweep.WALL_WINDOWS
    if path.is_file():
        with open(path, encoding="utf-8") as fh:
            windows = json.load(fh)
    low = np.asarray(windows.get("p_min_Pa") or [math.nan] * len(p), float)
    high = np.asarray(windows.get("p_max_Pa") or [math.nan] * len(p), float)
    out = []
    seen = {}
    for k in range(len(p)):
        place = seen.get(wall[k], 0)
        seen[wall[k]] = place + 1
        out.append({"key": (str(wall[k]), place // n, place % n), "wall": str(wall[k]),
                    "s": s[k], "z": z[k], "across": across[k], "filling": p[k],
                    "window_min": low[k], "window_max": high[k]})
    return out


def envelope(rows) -> list:
    """The envelope per patch over the cases' ``rows`` (their ``run_dir``; failed cases left
    out): the largest and the smallest pressure over every case and window, where, the
    cases' filled range and the patch's place (module docstring)."""
    table = {}
    order = []
    for row in rows:
        if row.get("error") or not row.get("run_dir"):
            continue
        try:
            patches = case_patches(row["run_dir"])
        except (OSError, KeyError):
            continue
        for p in patches:
            key = p["key"]
            if key not in table:
                table[key] = {"wall": p["wall"], "bin": key[1], "sector": key[2],
                              "across": p["across"], "z": [], "s": [], "max": -math.inf,
                              "min": math.inf, "max_case": "", "min_case": "",
                              "max_window": "", "min_window": "", "filling": []}
                order.append(key)
            e = table[key]
            e["z"].append(p["z"])
            e["s"].append(p["s"])
            e["filling"].append(p["filling"])
            for window, value in (("filling", p["filling"]), ("discharge", p["window_max"])):
                if math.isfinite(value) and value > e["max"]:
                    e["max"], e["max_case"], e["max_window"] = value, row["case"], window
            for window, value in (("filling", p["filling"]), ("discharge", p["window_min"])):
                if math.isfinite(value) and value < e["min"]:
                    e["min"], e["min_case"], e["min_window"] = value, row["case"], window
    out = []
    for key in order:
        e = table[key]
        fill = np.asarray(e["filling"], float)
        out.append({"wall": e["wall"], "bin": e["bin"], "sector": e["sector"],
                    "across": e["across"], "s_m": float(np.mean(e["s"])),
                    "z_m": float(np.mean(e["z"])), "z_min_m": float(np.min(e["z"])),
                    "z_max_m": float(np.max(e["z"])),
                    "p_max_Pa": e["max"] if math.isfinite(e["max"]) else math.nan,
                    "p_max_case": e["max_case"], "p_max_window": e["max_window"],
                    "p_min_Pa": e["min"] if math.isfinite(e["min"]) else math.nan,
                    "p_min_case": e["min_case"], "p_min_window": e["min_window"],
                    "p_filling_max_Pa": float(np.nanmax(fill)) if np.isfinite(fill).any()
                    else math.nan,
                    "p_filling_min_Pa": float(np.nanmin(fill)) if np.isfinite(fill).any()
                    else math.nan, "cases": len(fill)})
    return out


def analyse(rows, table, values) -> dict:
    numbers = {"cases": len(rows), "cases_failed": sum(1 for r in rows if r.get("error")),
               "patches": len(table), "K_m_en1991": _r(values["K_m"], 4),
               "K_lower_en1991": _r(values["K_lower"], 4),
               "K_upper_en1991": _r(values["K_upper"], 4),
               "phi_lower_deg": _r(values["phi"]["lower"], 3),
               "phi_upper_deg": _r(values["phi"]["upper"], 3),
               "mu_w_lower": _r(values["mu"]["lower"], 4),
               "mu_w_upper": _r(values["mu"]["upper"], 4)}
    k = [r.get("wall_k_bin") for r in rows if _sweep.finite(r.get("wall_k_bin"))]
    if k:
        numbers["wall_k_bin_min"], numbers["wall_k_bin_max"] = _r(min(k), 4), _r(max(k), 4)
    for wall in dict.fromkeys(t["wall"] for t in table):
        on = [t for t in table if t["wall"] == wall]
        big = [t["p_max_Pa"] for t in on if math.isfinite(t["p_max_Pa"])]
        small = [t["p_min_Pa"] for t in on if math.isfinite(t["p_min_Pa"])]
        if big:
            top = max(on, key=lambda t: t["p_max_Pa"] if math.isfinite(t["p_max_Pa"])
                      else -math.inf)
            numbers[f"p_max_Pa[{wall}]"] = _r(max(big), 1)
            numbers[f"p_max_case[{wall}]"] = top["p_max_case"]
            numbers[f"p_max_window[{wall}]"] = top["p_max_window"]
        if small:
            numbers[f"p_min_Pa[{wall}]"] = _r(min(small), 1)
        ratios = [t["p_max_Pa"] / t["p_filling_max_Pa"] for t in on
                  if math.isfinite(t["p_max_Pa"]) and t["p_filling_max_Pa"] > 0]
        if ratios:
            numbers[f"max_over_filling_max[{wall}]"] = _r(max(ratios), 3)
    return numbers


def plot(table):
    """Three panels over every patch (rows: the walls' bins in order, labelled with the wall
    and the height; columns: the sectors): the largest pressure, the smallest, and per row
    the largest and the smallest over the sectors with the cases' filled range."""
    fig = _sweep.figure(13.0, 5.5)
    ax_hi, ax_lo, ax_p = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1, 1, 1.1]})
    rows = list(dict.fromkeys((t["wall"], t["bin"]) for t in table))
    sectors = sorted({t["sector"] for t in table})
    grid_hi = np.full((len(rows), len(sectors)), np.nan)
    grid_lo = np.full_like(grid_hi, np.nan)
    fill_hi = np.full(len(rows), np.nan)
    fill_lo = np.full(len(rows), np.nan)
    labels = [""] * len(rows)
    for t in table:
        i = rows.index((t["wall"], t["bin"]))
        j = sectors.index(t["sector"])
        grid_hi[i, j], grid_lo[i, j] = t["p_max_Pa"], t["p_min_Pa"]
        fill_hi[i] = np.fmax(fill_hi[i], t["p_filling_max_Pa"])
        fill_lo[i] = np.fmin(fill_lo[i], t["p_filling_min_Pa"])
        labels[i] = f"{t['wall']} {t['z_m']:.3f}"
    top = np.nanmax(grid_hi) if np.isfinite(grid_hi).any() else 1.0
    for ax, grid, what in ((ax_hi, grid_hi, "largest"), (ax_lo, grid_lo, "smallest")):
        mesh = ax.pcolormesh(np.arange(len(sectors) + 1) - 0.5, np.arange(len(rows) + 1) - 0.5,
                             grid, vmin=0.0, vmax=top, cmap="magma", shading="flat")
        ax.set_title(f"The {what} p_n (Pa) over the cases and windows", fontsize=9)
        ax.set_xlabel("sector")
        ax.set_yticks(np.arange(len(rows)))
        ax.set_yticklabels(labels if ax is ax_hi else [], fontsize=6)
    fig.colorbar(mesh, ax=[ax_hi, ax_lo], label="p_n (Pa)", shrink=0.8, location="bottom")
    y = np.arange(len(rows))
    ax_p.plot(np.nanmax(grid_hi, axis=1), y, "r-o", ms=3, label="largest (envelope)")
    ax_p.plot(np.nanmin(grid_lo, axis=1), y, "b-o", ms=3, label="smallest (envelope)")
    ax_p.fill_betweenx(y, fill_lo, fill_hi, color="0.85", label="at rest, over the cases")
    ax_p.set_yticks(y)
    ax_p.set_yticklabels([])
    ax_p.set_xlabel("p_n (Pa), over the sectors of each row")
    ax_p.legend(fontsize=7)
    ax_p.set_title("Per wall bin", fontsize=9)
    return fig


def write_outputs(out, rows, table, numbers, study, argv=None):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    first = ("case", "offset_m", "offset_fraction", "mu_w", "phi", "mu_w_value", "phi_deg",
             "wall_k_bin", "steady_discharge_rate_kg_s", "flow_mode",
             "fill_equilibrium_residual", "mass_balance_error", "error")
    _sweep.write_rows_csv(out / "results.csv", rows, first=first)
    _sweep.write_rows_csv(out / "envelope.csv", table)
    _sweep.save(plot(table), out / "envelope.png")
    opts, values = study["options"], study["values"]
    figures = [{"file": "envelope.png",
                "caption": "The largest and the smallest wall pressure of every patch over "
                           "every case (outlet offsets, mu_w and phi at their characteristic "
                           "extremes) and window (at rest, the discharge's load windows), and "
                           "per wall bin the extremes over its sectors beside the cases' "
                           "pressure at rest."}]
    findings = [f"{numbers['cases']} cases ({numbers['cases_failed']} failed): offsets "
                f"{', '.join(f'{f:g}' for f in opts['offset_fractions'])} of the room along +x, "
                f"mu_w {values['mu']['lower']:.3g} and {values['mu']['upper']:.3g}, phi "
                f"{values['phi']['lower']:.3g} and {values['phi']['upper']:.3g} deg "
                f"(a_mu {opts['a_mu']:g}, a_phi {opts['a_phi']:g}; EN 1991-4's default "
                "material as remembered, unverified)."]
    if "wall_k_bin_min" in numbers:
        findings.append(f"K measured at the bin wall at rest {numbers['wall_k_bin_min']:g} to "
                        f"{numbers['wall_k_bin_max']:g}, against EN 1991-4's characteristic "
                        f"range {numbers['K_lower_en1991']:g} to {numbers['K_upper_en1991']:g} "
                        f"(K_m = 1.1 (1 - sin phi_m) = {numbers['K_m_en1991']:g}, a_K "
                        f"{opts['a_K']:g}).")
    for key, value in numbers.items():
        if key.startswith("p_max_Pa["):
            wall = key[len("p_max_Pa["):-1]
            ratio = numbers.get(f"max_over_filling_max[{wall}]")
            findings.append(f"{wall}: the largest pressure {value:g} Pa (case "
                            f"{numbers[f'p_max_case[{wall}]']}, "
                            f"{numbers[f'p_max_window[{wall}]']}), the smallest "
                            f"{numbers.get(f'p_min_Pa[{wall}]')} Pa; the envelope over the "
                            f"largest at rest up to {ratio}.")
    settings = {k: v for k, v in opts.items()}
    settings["combinations"] = [list(c) for c in opts["combinations"]]
    settings["offset_fractions"] = list(opts["offset_fractions"])
    _sweep.write_study_json(out, NAME, TITLE, study["setting"], settings, numbers, findings,
                            figures, [], rows, argv)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--config", type=Path, help="a 3D silo's configuration (TOML)")
    parser.add_argument("--offset-fractions", dest="offset_fractions", type=float, nargs="+")
    parser.add_argument("--a-phi", dest="a_phi", type=float)
    parser.add_argument("--a-k", dest="a_K", type=float)
    parser.add_argument("--a-mu", dest="a_mu", type=float)
    parser.add_argument("--end-time", dest="end_time", type=float)
    parser.add_argument("--estimate", action="store_true",
                        help="print each case's grid, memory and time estimate and stop")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("offset_fractions", "a_phi", "a_K", "a_mu",
                                          "end_time"))
    if args.config is not None:
        cfg = _resolved(HopperConfig.from_toml(args.config).to_dict())
        if cfg.hopper.dimensions != 3:
            parser.error("--config: the envelope is of a 3D silo (hopper.dimensions = 3)")
        silo = cfg.to_dict()
        silo.pop("run", None)
        options["silo"] = silo
    if "offset_fractions" in options:
        options["offset_fractions"] = tuple(options["offset_fractions"])
    study = setup(quick=args.quick, **options)
    if args.estimate:
        import three_d
        total = three_d.print_estimate(three_d.estimate(study))
        print(f"all: {three_d.cost_text(total)}")
        return 0
    rows = _sweep.run_study(NAME, study, args)
    table = envelope(rows)
    numbers = analyse(rows, table, study["values"])
    write_outputs(args.out, rows, table, numbers, study, argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
