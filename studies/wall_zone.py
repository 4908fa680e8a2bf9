"""The shear zone along a rough bin wall in discharge, in grains, under refinement.

The reference hopper (a 20 deg cone under a 0.3 m bin, phi = 30 deg, E = 5 MPa) in mass flow
(the cone's wall phi_w = 15 deg) with a *rough* bin wall (``bin_wall_friction_deg``, 35 deg,
above the material's phi: the wall holds more shear than the material next to it, so the
material shears inside itself along the wall instead of sliding on it).  Discharged for
``end_time`` (2 s) with the default law (the mu(I) rate dependence, d = 1 mm), with d = 3 mm
and with the plain rate-independent law (no length), at the cell sizes ``cell_sizes``
(``plain_cell_sizes`` for the plain law).  From the field snapshots (every
``field_interval``, from ``window_from`` to the end), at every cell row of the bin from
``rows_above_cone`` above the cone's top to ``rows_below_surface`` under the material's top:

* the plug speed: the median speed of the material (``alpha > 1/2``) out to half the bin's
  radius;
* the shear zone's width: the distance from the wall in which the speed is below
  ``fraction`` (95 %) of the plug's (linear between cell centres; 0 where even the wall's cell
  moves with the plug) -- in mm, in grains of the law's d and in cells;
* the wall cell's speed over the plug's (1: the material slides on the wall as a plug).

The widths (medians over the rows and snapshots) stand beside the 5-20 grain diameters of the
shear zones measured along rough silo walls (docs/references.md).

Written to ``--out`` (default ``studies/output/wall_zone``): ``results.csv``,
``profiles.csv`` (the mean speed over the plug's against the distance from the wall),
``wall_zone.png`` and ``study.json``.

Usage::

    python studies/wall_zone.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                [--cell-sizes 0.005 0.0025]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

from fipy_hopper.config import HopperConfig  # noqa: E402

_r = _sweep.rounded
NAME = "wall_zone"
TITLE = "The shear zone along a rough bin wall in discharge, in grains"
_REF = HopperConfig()
DEFAULTS = {
    "grains_mm": (1.0, 3.0), "cell_sizes": (0.005, 0.00375, 0.0025),
    "plain_cell_sizes": (0.005, 0.0025),
    "bin_wall_friction_deg": 35.0, "hopper_friction_deg": 15.0,
    "end_time": 2.0, "field_interval": 0.25, "window_from": 0.75,
    "rows_above_cone": 0.1, "rows_below_surface": 0.05, "fraction": 0.95,
    "bin_diameter": _REF.hopper.bin_diameter, "outlet_diameter": _REF.hopper.outlet_diameter,
    "half_angle_deg": _REF.hopper.half_angle_deg, "fill_height": _REF.hopper.fill_height,
    "bin_height": _REF.hopper.bin_height, "case_plots": False,
}
QUICK = {"grains_mm": (1.0,), "cell_sizes": (0.01, 0.0075), "plain_cell_sizes": (0.01,),
         "end_time": 0.5, "field_interval": 0.1, "window_from": 0.2, "bin_diameter": 0.16,
         "fill_height": 0.1, "bin_height": 0.12, "rows_above_cone": 0.02,
         "rows_below_surface": 0.02}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    laws = [(f"d{_sweep.fmt(float(g))}mm", {"grain_diameter": 1e-3 * float(g)},
             opts["cell_sizes"]) for g in opts["grains_mm"]]
    laws.append(("plain", {"rate_dependence": "none"}, opts["plain_cell_sizes"]))
    cases = []
    for law, material, sizes in laws:
        for h in sizes:
            config = {"hopper": {"bin_diameter": opts["bin_diameter"],
                                 "outlet_diameter": opts["outlet_diameter"],
                                 "half_angle_deg": float(opts["half_angle_deg"]),
                                 "fill_height": opts["fill_height"],
                                 "bin_height": opts["bin_height"]},
                      "material": {"youngs_modulus": 5.0e6, **material},
                      "wall": {"segment_friction_deg": [float(opts["hopper_friction_deg"]),
                                                        float(opts["bin_wall_friction_deg"])]},
                      "numerics": {"cell_size": float(h)},
                      "run": {"end_time": opts["end_time"], "output_interval": 0.05,
                              "field_interval": opts["field_interval"]}}
            cases.append(_sweep.make_case(
                f"{law}_cell{_sweep.fmt(round(1000 * h, 4))}mm",
                {"law": law, "grain_mm": 1000.0 * material.get("grain_diameter", 0.0),
                 "cell_size_mm": 1000 * float(h)}, config,
                plots=opts["case_plots"]))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- analysis
def wall_zone(r_cells, speed, wall_r, fraction=0.95):
    """One row of cell speeds ``speed`` (m/s) at the cell centres ``r_cells`` (m, increasing,
    all inside the wall at ``wall_r``): ``(plug speed, zone width (m), wall cell's speed over
    the plug's)``.  The plug speed is the median over ``r <= wall_r / 2``; the zone is the
    distance from the wall inside which the speed is below ``fraction`` of the plug's, from
    the outermost cell at or above it to the next one out (linear between cell centres); 0
    when the wall's cell itself reaches it.  NaNs when the row has no plug."""
    r, s = np.asarray(r_cells, float), np.asarray(speed, float)
    core = r <= 0.5 * wall_r
    if not core.any():
        return math.nan, math.nan, math.nan
    plug = float(np.median(s[core]))
    if not plug > 0:
        return math.nan, math.nan, math.nan
    target = fraction * plug
    reaching = np.flatnonzero(s >= target)
    k = int(reaching[-1])
    if k == len(s) - 1:
        return plug, 0.0, float(s[-1] / plug)
    r_cross = r[k] + (s[k] - target) / (s[k] - s[k + 1]) * (r[k + 1] - r[k])
    return plug, float(wall_r - r_cross), float(s[-1] / plug)


def _row_range(options):
    """The heights (m) of the rows measured: from ``rows_above_cone`` above the cone's top
    (the bin wall's foot) up; the top follows the material's surface per snapshot."""
    cone_top = (0.5 * (options["bin_diameter"] - options["outlet_diameter"])
                / math.tan(math.radians(options["half_angle_deg"])))
    return cone_top + options["rows_above_cone"]


def zone_of(run_dir, options):
    """``(widths (m), slips, plugs, profile)`` over the rows and snapshots of a run's
    discharge from ``window_from`` on; ``profile`` is ``(distance from the wall (m), mean
    speed over the plug's)`` over the same rows."""
    from fipy_hopper import plotting

    wall_r = 0.5 * options["bin_diameter"]
    z_low = _row_range(options)
    widths, slips, plugs, curves = [], [], [], []
    for e in plotting.snapshots(run_dir):
        if e["stage"] != "discharge" or e["discharge_time_s"] < options["window_from"] - 1e-9:
            continue
        snap = plotting.load_snapshot(run_dir, e)
        r = 0.5 * (snap["r_nodes"][1:] + snap["r_nodes"][:-1])
        z = 0.5 * (snap["z_nodes"][1:] + snap["z_nodes"][:-1])
        inside = r < wall_r
        filled = np.flatnonzero((snap["alpha"][:, inside] > 0.5).any(axis=1))
        if not filled.size:
            continue
        z_top = z[filled[-1]] - options["rows_below_surface"]
        for j in np.flatnonzero((z >= z_low) & (z <= z_top)):
            if not np.all(snap["alpha"][j, inside] > 0.5):
                continue
            speed = snap["speed"][j, inside]
            plug, width, slip = wall_zone(r[inside], speed, wall_r, options["fraction"])
            if not math.isfinite(plug):
                continue
            widths.append(width)
            slips.append(slip)
            plugs.append(plug)
            curves.append(speed / plug)
    profile = (wall_r - r[inside][::-1],
               np.mean(curves, axis=0)[::-1] if curves else np.full(inside.sum(), math.nan))
    return widths, slips, plugs, profile


def _grain_diameter(run_dir) -> float:
    return HopperConfig.from_toml(Path(run_dir) / "config.toml").material.grain_diameter


def analyse(rows, options):
    """Adds the zone's width (m, grains, cells; the median over the rows and snapshots, its
    quartiles, and the zone of the mean profile), the slip and the plug speed to each row;
    returns per law its widths by cell size and their changes under refinement, and the
    profiles (rows of ``profiles.csv``)."""
    profiles = []
    for r in rows:
        if r.get("error") or not r.get("run_dir"):
            continue
        widths, slips, plugs, (dist, mean) = zone_of(r["run_dir"], options)
        h = 1e-3 * r["cell_size_mm"]
        d = _grain_diameter(r["run_dir"]) if r["law"] != "plain" else math.nan
        r["samples"] = len(widths)
        r["zone_width_m"] = float(np.median(widths)) if widths else math.nan
        r["zone_width_grains"] = r["zone_width_m"] / d if d > 0 else math.nan
        r["zone_width_cells"] = r["zone_width_m"] / h
        r["zone_width_q25_m"], r["zone_width_q75_m"] = (
            [float(q) for q in np.percentile(widths, [25, 75])] if widths else [math.nan] * 2)
        wall_r = 0.5 * options["bin_diameter"]
        r["mean_profile_zone_m"] = wall_zone(wall_r - dist[::-1], mean[::-1], wall_r,
                                             options["fraction"])[1]
        r["wall_slip"] = float(np.median(slips)) if slips else math.nan
        r["plug_speed_m_s"] = float(np.median(plugs)) if plugs else math.nan
        profiles += [{"case": r["case"], "law": r["law"], "cell_size_mm": r["cell_size_mm"],
                      "distance_from_wall_m": float(x), "speed_over_plug": float(v)}
                     for x, v in zip(dist, mean)]
    numbers = {}
    for law in dict.fromkeys(r["law"] for r in rows):
        done = sorted([r for r in rows if r["law"] == law and "zone_width_m" in r],
                      key=lambda r: -r["cell_size_mm"])
        w = [r["zone_width_m"] for r in done]
        numbers[law] = {
            "cell_sizes_mm": [r["cell_size_mm"] for r in done],
            "zone_width_mm": [_r(1000 * x, 2) for x in w],
            "zone_width_grains": [_r(r["zone_width_grains"], 2) for r in done],
            "zone_width_cells": [_r(r["zone_width_cells"], 2) for r in done],
            "zone_width_quartiles_mm": [[_r(1000 * r["zone_width_q25_m"], 2),
                                         _r(1000 * r["zone_width_q75_m"], 2)] for r in done],
            "mean_profile_zone_mm": [_r(1000 * r["mean_profile_zone_m"], 2) for r in done],
            "zone_width_changes": [_r(abs(b - a) / b, 4) if b > 0 else None
                                   for a, b in zip(w, w[1:])],
            "wall_slip": [_r(r["wall_slip"], 3) for r in done],
            "plug_speed_m_s": [_r(r["plug_speed_m_s"], 4) for r in done]}
    return numbers, profiles


def _mm(x):
    """``x`` (m, or m/s) in mm rounded to 0.01, or None when it is missing."""
    return _r(1000 * x, 2) if _sweep.finite(x) else None


def plot(rows, profiles, options):
    laws = list(dict.fromkeys(r["law"] for r in rows))
    fig = _sweep.figure(4.2 * max(1, len(laws)), 4.0)
    axes = fig.subplots(1, max(1, len(laws)), squeeze=False)[0]
    reach = 0.25 * options["bin_diameter"]
    for ax, law in zip(axes, laws):
        for k, r in enumerate(sorted((r for r in rows if r["law"] == law),
                                     key=lambda r: -r["cell_size_mm"])):
            mine = [p for p in profiles if p["case"] == r["case"]
                    and p["distance_from_wall_m"] <= reach]
            if not mine:
                continue
            ax.plot([1000 * p["distance_from_wall_m"] for p in mine],
                    [p["speed_over_plug"] for p in mine], "o-", ms=3, color=f"C{k}",
                    label=f"{r['cell_size_mm']:g} mm cells")
        ax.axhline(options["fraction"], color="0.6", lw=0.8, ls=":")
        ax.set_title(f"{law}: mean speed across the bin", fontsize=9)
        ax.set_xlabel("distance from the bin wall (mm)")
        ax.set_ylabel("speed / plug speed")
        ax.set_ylim(0, 1.15)
        ax.legend(fontsize=7)
    return fig


def write_outputs(out, rows, numbers, profiles, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "law", "grain_mm", "cell_size_mm", "zone_width_m", "zone_width_grains",
        "zone_width_cells", "zone_width_q25_m", "zone_width_q75_m", "mean_profile_zone_m",
        "wall_slip", "plug_speed_m_s", "samples", "error"))
    _sweep.write_rows_csv(out / "profiles.csv", profiles)
    _sweep.save(plot(rows, profiles, options), out / "wall_zone.png")
    figures = [{"file": "wall_zone.png",
                "caption": f"The material's speed across the bin over the plug's (mean over "
                           f"the rows and the snapshots from {options['window_from']:g} s), "
                           f"against the distance from the rough bin wall (phi_w = "
                           f"{options['bin_wall_friction_deg']:g} deg), per law and cell size; "
                           f"the dotted line is {100 * options['fraction']:g} % of the plug."}]
    findings = []
    for law, e in numbers.items():
        def listed(key, scale=1.0, spec=".1f", e=e):
            return ", ".join("n/a" if v is None else format(scale * v, spec)
                             for v in e[key]) or "n/a"

        sizes = ", ".join(f"{h:g}" for h in e["cell_sizes_mm"])
        text = (f"{law} ({sizes} mm cells): the shear zone along the rough bin wall (speed "
                f"below {100 * options['fraction']:g} % of the plug's) is "
                f"{listed('zone_width_mm')} mm wide")
        if law != "plain":
            text += f" = {listed('zone_width_grains')} grains"
        quartiles = ", ".join("n/a" if None in q else f"{q[0]:.1f}-{q[1]:.1f}"
                              for q in e["zone_width_quartiles_mm"])
        text += (f" = {listed('zone_width_cells')} cells (median over the rows and snapshots; "
                 f"quartiles {quartiles} mm; the mean profile's zone "
                 f"{listed('mean_profile_zone_mm')} mm); changes under refinement "
                 f"{listed('zone_width_changes', 100)} %; the wall's cell moves at "
                 f"{listed('wall_slip', 1, '.2f')} of the plug "
                 f"({listed('plug_speed_m_s', 1000, '.1f')} mm/s)")
        findings.append(text + ".")
    findings.append("Shear zones along rough silo walls are measured at 5-20 grain diameters "
                    "(docs/references.md); a zone of a cell or two, or one that shrinks with "
                    "the cells, is decided by the grid, not by the grain.")
    table = {"title": "Runs", "columns": ["law", "cell (mm)", "zone (mm)", "zone (grains)",
                                         "zone (cells)", "quartiles (mm)",
                                         "mean profile's zone (mm)", "wall cell / plug",
                                         "plug speed (mm/s)", "samples"],
             "rows": [[r["law"], r["cell_size_mm"], _mm(r.get("zone_width_m")),
                       _r(r.get("zone_width_grains"), 2), _r(r.get("zone_width_cells"), 2),
                       f"{_mm(r.get('zone_width_q25_m'))}-{_mm(r.get('zone_width_q75_m'))}",
                       _mm(r.get("mean_profile_zone_m")), _r(r.get("wall_slip"), 3),
                       _mm(r.get("plug_speed_m_s")), r.get("samples")] for r in rows]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    headline = "Shear zone along the rough bin wall: " + "; ".join(
        f"{law} " + ", ".join("n/a" if v is None else f"{v:.1f}"
                              for v in e["zone_width_grains" if law != "plain"
                                         else "zone_width_cells"])
        + (" grains" if law != "plain" else " cells")
        for law, e in numbers.items()) + " (coarse to fine)."
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            [table], rows, argv, headline=headline)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-sizes", type=float, nargs="+", help="m")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_sizes",))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    numbers, profiles = analyse(rows, study["options"])
    write_outputs(args.out, rows, numbers, profiles, study["options"], study["setting"], argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
