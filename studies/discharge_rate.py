"""Discharge rate against outlet diameter and cone half-angle, beside the recognised correlations.

Two sweeps of short discharges (default: a 0.24 m bin, 0.12 m fill above the transition,
phi = 30 deg, phi_w = 15 deg, 5 mm cells, 0.8 s of discharge):

* outlet diameter ``D0`` (0.04-0.08 m, five sizes, 4-8 cells across the outlet radius) in a
  30 deg cone (mass flow): the fitted exponent ``n`` of ``W = a D0^n`` (least squares in log space,
  :func:`fipy_hopper.diagnostics.fit_power_law`), the Beverloo constant
  ``C = W / (rho_b sqrt(g) D0^(5/2))`` fitted with the exponent held at 5/2 (geometric mean
  over the sizes; in a cone also divided by the Rose-Tanaka factor), and the apparent
  Beverloo offset from a straight-line fit of ``W^(2/5)`` against ``D0``
  (``W^(2/5) ~ D0 - k_h h``; the continuum has no particle size, so any offset is the grid's);
* cone half-angle ``theta`` (15-90 deg) at ``D0`` = 0.06 m.

A flat-bottomed bin (90 deg) is in the half-angle sweep but not an outlet sweep by default:
in this shallow bed (fill/diameter = 0.5, below Beverloo's 1.2) its simulated rate falls
steadily while the stagnant zones grow (measured at 5 mm, D0 = 0.06 m: 2.6 kg/s at 0.3 s,
2.0 at 0.8 s, 1.4 at 2 s), so it has no plateau; its ``steady_rate_spread`` says so.

The correlations (:mod:`fipy_hopper.theory`): Beverloo (C = 0.58, k = 1.5, the material's
grain size ``d`` = 1 mm), Beverloo
times the Rose-Tanaka factor (beta = 45 deg), Johanson (conical, m = 1; a mass-flow rate, so
compared only inside Jenike's mass-flow region, theta < theta_c(phi, phi_w)) and Brown's
minimum-energy rate.  The steady rate of a run is ``summary.json``
``steady_discharge_rate_kg_s`` (the median of W over the plateau,
:func:`fipy_hopper.diagnostics.steady_rate`).

Written to ``--out`` (default ``studies/output/discharge_rate``): ``results.csv`` (every case
with each correlation and the percent difference from it), ``fits.csv``, ``study.json``,
``rate_vs_outlet.png``, ``rate_vs_half_angle.png`` and ``cases/<name>/``.

Usage::

    python studies/discharge_rate.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                     [--cell-size 0.005] [--end-time 0.8]
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

from fipy_hopper import theory  # noqa: E402
from fipy_hopper.diagnostics import fit_power_law  # noqa: E402

_r = _sweep.rounded
NAME = "discharge_rate"
TITLE = "Discharge rate against outlet diameter and half-angle, with the correlations"
DEFAULTS = {
    "outlets": (0.04, 0.05, 0.06, 0.07, 0.08),   # D0 (m) of the outlet sweeps
    "outlet_half_angles": (30.0,),               # half-angles of the outlet sweeps (deg)
    "half_angles": (15.0, 20.0, 30.0, 45.0, 60.0, 75.0, 90.0),  # the half-angle sweep (deg)
    "reference_outlet": 0.06,                    # D0 of the half-angle sweep (m)
    "bin_diameter": 0.24,                        # m (> 2.5 D0 for every outlet)
    "fill_height": 0.12,                         # m above the transition
    "friction_angle": 30.0,                      # phi (deg)
    "wall_friction": 15.0,                       # phi_w (deg)
    "density": 1500.0,                           # kg/m3
    "youngs_modulus": 5.0e6,                     # Pa
    "grain_diameter": 0.001,                     # d (m): the default grain size
    "beverloo_k": 1.5,                           # Beverloo's k for the correlations
    "cell_size": 0.005,                          # m
    "end_time": 0.8,                             # s of discharge
    "rose_tanaka_beta": 45.0,                    # deg
    "case_plots": True,
}
QUICK = {"outlets": (0.06, 0.08, 0.1, 0.12), "outlet_half_angles": (45.0,),
         "half_angles": (45.0, 90.0), "bin_diameter": 0.3, "fill_height": 0.06,
         "cell_size": 0.01, "end_time": 0.4, "case_plots": False}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    base = {"hopper": {"bin_diameter": opts["bin_diameter"], "fill_height": opts["fill_height"],
                       "bin_height": opts["fill_height"] + 0.02},
            "material": {"friction_angle_deg": opts["friction_angle"],
                         "density": opts["density"],
                         "youngs_modulus": opts["youngs_modulus"],
                         "grain_diameter": opts["grain_diameter"]},
            "wall": {"friction_angle_deg": opts["wall_friction"]},
            "numerics": {"cell_size": opts["cell_size"]},
            "run": {"end_time": opts["end_time"], "output_interval": 0.02,
                    "field_interval": 0.25}}
    wanted = {}
    for theta in opts["outlet_half_angles"]:
        for d0 in opts["outlets"]:
            wanted[(float(theta), float(d0))] = None
    for theta in opts["half_angles"]:
        wanted[(float(theta), float(opts["reference_outlet"]))] = None
    cases = [_sweep.make_case(
        _sweep.case_name(("theta", theta), ("D0mm", round(1000 * d0, 3))),
        {"half_angle_deg": theta, "outlet_diameter_m": d0},
        _sweep.merge(base, hopper={"half_angle_deg": theta, "outlet_diameter": d0}),
        plots=opts["case_plots"]) for theta, d0 in wanted]
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- correlations
def jenike_theta_c(opts) -> float:
    """Jenike's critical half-angle for the study's material and wall (delta = phi)."""
    return float(theory.jenike_critical_half_angle(opts["friction_angle"],
                                                   opts["wall_friction"]))


def correlations(d0, theta, opts, johanson_everywhere=False) -> dict:
    """The four correlations' rates (kg/s) for one outlet and half-angle.  Johanson's is a
    mass-flow rate: NaN outside Jenike's mass-flow region (theta >= theta_c) unless
    ``johanson_everywhere``, and always for a flat bottom."""
    rho = opts["density"]
    bev = float(theory.beverloo_rate(rho, d0, k=opts["beverloo_k"], d=opts["grain_diameter"]))
    mass_flow = theta < jenike_theta_c(opts)       # False when theta_c is NaN
    out = {"beverloo_kg_s": bev,
           "beverloo_rose_tanaka_kg_s": bev * float(theory.rose_tanaka_factor(
               theta, opts["rose_tanaka_beta"])),
           "johanson_kg_s": (float(theory.johanson_rate(rho, d0, theta))
                             if theta < 90 and (mass_flow or johanson_everywhere)
                             else math.nan),
           "brown_kg_s": float(theory.brown_rate(rho, d0, theta))}
    return out


def effective(d0, opts):
    """Beverloo's effective outlet ``D0 - k d`` (m) of the study's grains."""
    return d0 - opts["beverloo_k"] * opts["grain_diameter"]


CORRELATIONS = {"beverloo_kg_s": "Beverloo (C = 0.58, k = 1.5, d = the material's)",
                "beverloo_rose_tanaka_kg_s": "Beverloo x Rose-Tanaka (beta = 45)",
                "johanson_kg_s": "Johanson (cone)",
                "brown_kg_s": "Brown (minimum energy)"}


def analyse(rows: list, options: dict) -> tuple:
    """Adds the correlations and percent differences to each row; returns ``(fits, numbers)``."""
    rho, g = options["density"], theory.G
    for r in rows:
        r.update(correlations(r["outlet_diameter_m"], r["half_angle_deg"], options))
        w = r.get("steady_discharge_rate_kg_s")
        for key in CORRELATIONS:
            r["diff_" + key.replace("_kg_s", "_pct")] = _sweep.pct(w, r[key])
        r["beverloo_C_equivalent"] = (w / (rho * math.sqrt(g) * effective(
            r["outlet_diameter_m"], options) ** 2.5) if _sweep.finite(w) else math.nan)
    fits = []
    for theta in options["outlet_half_angles"]:
        sel = sorted([r for r in rows if r["half_angle_deg"] == float(theta)
                      and r["outlet_diameter_m"] in [float(d) for d in options["outlets"]]
                      and _sweep.finite(r.get("steady_discharge_rate_kg_s"))
                      and r["steady_discharge_rate_kg_s"] > 0],
                     key=lambda r: r["outlet_diameter_m"])
        if len(sel) < 2:
            continue
        d0 = np.array([r["outlet_diameter_m"] for r in sel])
        w = np.array([r["steady_discharge_rate_kg_s"] for r in sel])
        a, n = fit_power_law(d0, w)
        c_fit = float(np.exp(np.mean(np.log(
            w / (rho * math.sqrt(g) * effective(d0, options) ** 2.5)))))
        factor = float(theory.rose_tanaka_factor(theta, options["rose_tanaka_beta"]))
        slope, intercept = np.polyfit(d0, w ** 0.4, 1)
        offset = -intercept / slope
        h = options["cell_size"]
        fits.append({"half_angle_deg": float(theta), "outlets": len(sel),
                     "D0_min_m": float(d0.min()), "D0_max_m": float(d0.max()),
                     "exponent_n": n, "prefactor_a": a,
                     "C_fit_exponent_2.5": c_fit, "rose_tanaka_factor": factor,
                     "C_beverloo_via_rose_tanaka": c_fit / factor,
                     "C_diff_from_0.58_pct": _sweep.pct(c_fit / factor, 0.58),
                     "apparent_offset_m": float(offset), "apparent_offset_cells": offset / h})
    numbers = {}
    for f in fits:
        tag = f"theta{f['half_angle_deg']:g}"
        numbers[f"exponent_n_{tag}"] = f["exponent_n"]
        numbers[f"C_{tag}"] = f["C_beverloo_via_rose_tanaka"]
        numbers[f"apparent_offset_cells_{tag}"] = f["apparent_offset_cells"]
    for key in CORRELATIONS:
        diffs = [r["diff_" + key.replace("_kg_s", "_pct")] for r in rows]
        diffs = [d for d in diffs if math.isfinite(d)]
        if diffs:
            numbers[f"mean_abs_diff_{key.replace('_kg_s', '')}_pct"] = float(np.mean(np.abs(diffs)))
            numbers[f"cases_compared_{key.replace('_kg_s', '')}"] = len(diffs)
    numbers["failed"] = [r["case"] for r in rows if r.get("error")]
    return fits, numbers


# ---------------------------------------------------------------- figures
STYLES = {"beverloo_kg_s": ("k", "-"), "beverloo_rose_tanaka_kg_s": ("C0", "--"),
          "johanson_kg_s": ("C2", "-."), "brown_kg_s": ("C3", ":")}


def plot_outlets(rows, fits, options):
    groups = [f for f in fits]
    fig = _sweep.figure(5.2 * max(1, len(groups)), 4.4)
    axes = fig.subplots(1, max(1, len(groups)), squeeze=False)[0]
    for ax, f in zip(axes, groups):
        theta = f["half_angle_deg"]
        sel = sorted([r for r in rows if r["half_angle_deg"] == theta and
                      r["outlet_diameter_m"] in [float(d) for d in options["outlets"]]],
                     key=lambda r: r["outlet_diameter_m"])
        d0 = np.array([r["outlet_diameter_m"] for r in sel])
        w = np.array([r.get("steady_discharge_rate_kg_s", math.nan) for r in sel], float)
        dd = np.geomspace(d0.min() * 0.9, d0.max() * 1.1, 60)
        for key, label in CORRELATIONS.items():
            if key == "johanson_kg_s" and theta >= 90:
                continue
            if key == "beverloo_rose_tanaka_kg_s" and theta >= 90:
                continue    # the factor is 1 on a flat bottom
            vals = [correlations(x, theta, options)[key] for x in dd]
            colour, ls = STYLES[key]
            ax.plot(dd, vals, ls, color=colour, lw=1.2, label=label)
        ax.plot(dd, f["prefactor_a"] * dd ** f["exponent_n"], "-", color="C1", lw=0.8,
                alpha=0.7, label=f"fit W = a D0^n, n = {f['exponent_n']:.2f}")
        ax.plot(d0, w, "o", color="C1", ms=7, mec="k", label="simulated steady rate")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("outlet diameter D0 (m)")
        ax.set_ylabel("discharge rate W (kg/s)")
        where = "flat-bottomed bin" if theta >= 90 else f"cone, theta = {theta:g} deg"
        ax.set_title(f"{where}: n = {f['exponent_n']:.2f}, "
                     f"C = {f['C_beverloo_via_rose_tanaka']:.3f}", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
    return fig


def plot_half_angle(rows, options):
    d0 = float(options["reference_outlet"])
    sel = sorted([r for r in rows if r["outlet_diameter_m"] == d0 and
                  r["half_angle_deg"] in [float(t) for t in options["half_angles"]]],
                 key=lambda r: r["half_angle_deg"])
    fig = _sweep.figure(6.4, 4.6)
    ax = fig.add_subplot()
    th = np.linspace(5.0, 90.0, 200)
    for key, label in CORRELATIONS.items():
        colour, ls = STYLES[key]
        if key == "johanson_kg_s":
            t = th[th < 85.0]
            ax.plot(t, [correlations(d0, x, options, True)[key] for x in t], ls, color=colour,
                    lw=0.8, alpha=0.4)                  # outside the mass-flow region: faint
            label += " (mass-flow region)"
        ax.plot(th, [correlations(d0, x, options)[key] for x in th], ls, color=colour, lw=1.2,
                label=label)
    theta_c = jenike_theta_c(options)
    if math.isfinite(theta_c):
        ax.axvline(theta_c, color="0.5", lw=0.8, ls="--")
        ax.text(theta_c, 0.02, f" Jenike theta_c = {theta_c:.1f} deg",
                transform=ax.get_xaxis_transform(), fontsize=7, va="bottom", color="0.3")
    colours = ["C0" if r.get("flow_mode") == "mass" else "C1" for r in sel]
    ax.scatter([r["half_angle_deg"] for r in sel],
               [r.get("steady_discharge_rate_kg_s", math.nan) for r in sel], c=colours, s=50,
               edgecolor="k", zorder=3, label="simulated (blue: mass, orange: funnel flow)")
    ax.set_xlabel("cone half-angle theta (deg; 90 = flat bottom)")
    ax.set_ylabel("discharge rate W (kg/s)")
    ax.set_ylim(bottom=0.0)
    ax.set_title(f"Rate against half-angle, D0 = {d0:g} m", fontsize=9)
    ax.legend(fontsize=7)
    return fig


# ---------------------------------------------------------------- outputs
def write_outputs(out, rows, fits, numbers, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "half_angle_deg", "outlet_diameter_m", "steady_discharge_rate_kg_s",
        "steady_rate_spread", "flow_mode", *CORRELATIONS,
        *["diff_" + k.replace("_kg_s", "_pct") for k in CORRELATIONS],
        "beverloo_C_equivalent", "cell_size_m", "wall_time_s", "error"))
    _sweep.write_rows_csv(out / "fits.csv", fits)
    figures = []
    if fits:
        _sweep.save(plot_outlets(rows, fits, options), out / "rate_vs_outlet.png")
        figures.append({"file": "rate_vs_outlet.png",
                        "caption": "Steady rate against outlet diameter (log-log) with the "
                                   "fitted power law and the correlations."})
    _sweep.save(plot_half_angle(rows, options), out / "rate_vs_half_angle.png")
    figures.append({"file": "rate_vs_half_angle.png",
                    "caption": f"Steady rate against cone half-angle at D0 = "
                               f"{options['reference_outlet']:g} m with the correlations; "
                               "the dashed line is Jenike's mass-flow boundary."})
    findings = []
    for f in fits:
        where = ("flat-bottomed bin" if f["half_angle_deg"] >= 90
                 else f"{f['half_angle_deg']:g} deg cone")
        findings.append(
            f"{where}: W ~ D0^{f['exponent_n']:.3f} over {f['outlets']} outlets "
            f"({f['D0_min_m']:g}-{f['D0_max_m']:g} m; the continuum's dimensional analysis "
            f"gives 2.5: {_sweep.pct(f['exponent_n'], 2.5):+.1f} %); Beverloo C = "
            f"{f['C_beverloo_via_rose_tanaka']:.3f} with the exponent held at 5/2"
            + ("" if f["half_angle_deg"] >= 90 else
               f" and the Rose-Tanaka factor {f['rose_tanaka_factor']:.3f} divided out")
            + f" ({f['C_diff_from_0.58_pct']:+.1f} % from 0.58); apparent offset "
            f"k_h h = {1000 * f['apparent_offset_m']:.2f} mm = "
            f"{f['apparent_offset_cells']:.2f} cells.")
    for key, label in CORRELATIONS.items():
        k = f"mean_abs_diff_{key.replace('_kg_s', '')}_pct"
        if k in numbers:
            n = numbers[f"cases_compared_{key.replace('_kg_s', '')}"]
            scope = (" (a flat-bottom correlation, shown for scale in the cones)"
                     if key == "beverloo_kg_s" else
                     " (only cases inside Jenike's mass-flow region)"
                     if key == "johanson_kg_s" else "")
            findings.append(f"Mean |difference| from {label} over {n} cases{scope}: "
                            f"{numbers[k]:.1f} %.")
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    table = {"title": "Cases (percent differences of the simulated rate from each correlation)",
             "columns": ["theta (deg)", "D0 (m)", "W sim (kg/s)", "flow", "Beverloo %",
                         "Bev x R-T %", "Johanson %", "Brown %"],
             "rows": [[r["half_angle_deg"], r["outlet_diameter_m"],
                       _r(r.get("steady_discharge_rate_kg_s"), 3), r.get("flow_mode"),
                       _r(r["diff_beverloo_pct"], 1), _r(r["diff_beverloo_rose_tanaka_pct"], 1),
                       _r(r["diff_johanson_pct"], 1), _r(r["diff_brown_pct"], 1)]
                      for r in sorted(rows, key=lambda r: (r["half_angle_deg"],
                                                           r["outlet_diameter_m"]))]}
    fit_table = {"title": "Fits of the outlet sweeps",
                 "columns": ["theta (deg)", "outlets", "exponent n", "C (n = 2.5)",
                             "Rose-Tanaka F", "C / F", "offset (cells)"],
                 "rows": [[f["half_angle_deg"], f["outlets"], _r(f["exponent_n"], 3),
                           _r(f["C_fit_exponent_2.5"], 3), _r(f["rose_tanaka_factor"], 3),
                           _r(f["C_beverloo_via_rose_tanaka"], 3),
                           _r(f["apparent_offset_cells"], 2)] for f in fits]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    settings["steady_rate"] = ("median of W over the samples >= 0.1 s after opening with "
                               "20-90 % of the initial mass left (last 75 % of the run if "
                               "fewer than 3)")
    headline = "; ".join(
        f"theta {f['half_angle_deg']:g} deg: exponent n = {f['exponent_n']:.2f}, Beverloo C = "
        f"{f['C_beverloo_via_rose_tanaka']:.3f}" for f in fits)
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            [fit_table, table], rows, argv, headline=headline)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    parser.add_argument("--end-time", type=float, help="s of discharge (default 0.8)")
    parser.add_argument("--outlets", type=float, nargs="+", help="D0 values (m)")
    parser.add_argument("--half-angles", type=float, nargs="+", help="deg")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ('cell_size', 'end_time', 'outlets', 'half_angles'))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    fits, numbers = analyse(rows, study["options"])
    write_outputs(args.out, rows, fits, numbers, study["options"], study["setting"], argv)
    for f in fits:
        print(f"theta = {f['half_angle_deg']:g} deg: exponent n = {f['exponent_n']:.3f}, "
              f"Beverloo C = {f['C_beverloo_via_rose_tanaka']:.3f}")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
