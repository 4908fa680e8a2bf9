"""Convergence: discharge rate and wall pressure at several cell sizes and Young's moduli.

One hopper (default: a 0.2 m bin, 30 deg cone, D0 = 0.06 m, 0.15 m fill above the transition,
phi = 30 deg, phi_w = 15 deg, 0.8 s of discharge) is run at cell sizes 10, 7.5, 5 and 3.75 mm
(E = 5 MPa) and at E = 2, 5 and 20 MPa (5 mm cells).  A softened E is what makes the explicit
step affordable (``dt ~ h sqrt(rho / E)``), so the answers must not hinge on it.

Measured: the steady discharge rate (``summary.json``), and the wall pressure profile when the
fill is at rest and early in the discharge (90 % left).  Each profile is compared with the
reference profile (the finest grid for the cell-size series, E = 5 MPa for the stiffness
series) by the relative L2 difference over the wall points both share, after linear
interpolation onto the reference's points, and by its mean over the bin and over the cone
(the regions of ``wall_pressure.py``).

Written to ``--out`` (default ``studies/output/convergence``): ``results.csv``,
``profiles.csv`` (the differences), ``study.json``, ``convergence.png`` and ``cases/<name>/``.

Usage::

    python studies/convergence.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                  [--cell-sizes 0.01 0.0075 0.005 0.00375] [--moduli 2e6 5e6 2e7]
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

from fipy_hopper import geometry  # noqa: E402

_r = _sweep.rounded
NAME = "convergence"
TITLE = "Convergence of the rate and the wall pressure with cell size and stiffness"
DEFAULTS = {
    "cell_sizes": (0.01, 0.0075, 0.005, 0.00375),   # m, at base_modulus
    "moduli": (2.0e6, 5.0e6, 20.0e6),               # Pa, at base_cell
    "base_cell": 0.005,
    "base_modulus": 5.0e6,
    "half_angle": 30.0,
    "wall_friction": 15.0,
    "friction_angle": 30.0,
    "bin_diameter": 0.2,
    "outlet_diameter": 0.06,
    "fill_height": 0.15,
    "end_time": 0.8,
    "case_plots": True,
}
QUICK = {"cell_sizes": (0.01, 0.0075, 0.006), "base_cell": 0.01, "half_angle": 45.0,
         "bin_diameter": 0.16, "fill_height": 0.06, "end_time": 0.3, "case_plots": False}
STAGES = ("filling", "early_discharge")


def case_for(opts, cell, modulus):
    config = {"hopper": {"bin_diameter": opts["bin_diameter"],
                         "half_angle_deg": opts["half_angle"],
                         "outlet_diameter": opts["outlet_diameter"],
                         "fill_height": opts["fill_height"],
                         "bin_height": opts["fill_height"] + 0.02},
              "material": {"friction_angle_deg": opts["friction_angle"],
                           "youngs_modulus": float(modulus)},
              "wall": {"friction_angle_deg": opts["wall_friction"]},
              "numerics": {"cell_size": float(cell)},
              "run": {"end_time": opts["end_time"], "output_interval": 0.02,
                      "field_interval": 0.25}}
    return _sweep.make_case(
        f"cell{_sweep.fmt(round(1000 * cell, 4))}mm_E{_sweep.fmt(round(modulus / 1e6, 4))}MPa",
        {"cell_size_mm": 1000 * float(cell), "youngs_modulus_MPa": float(modulus) / 1e6},
        config, plots=opts["case_plots"])


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    pairs = {(float(c), float(opts["base_modulus"])): None for c in opts["cell_sizes"]}
    pairs.update({(float(opts["base_cell"]), float(e)): None for e in opts["moduli"]})
    cases = [case_for(opts, c, e) for c, e in pairs]
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- analysis
def profile(row, stage):
    from fipy_hopper.api import read_results

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = read_results(row["run_dir"])
    sel = res.wall_stage(stage)
    return res.config, np.asarray(sel["s_m"], float), np.asarray(sel["p_n_Pa"], float)


def compare_profiles(row, ref, stage):
    """Relative L2 difference (%) of a profile from the reference one, and both region means."""
    try:
        cfg, s, p = profile(row, stage)
        _, s_ref, p_ref = profile(ref, stage)
    except FileNotFoundError:
        return None
    if len(s) < 2 or len(s_ref) < 2:
        return None
    geom = cfg.hopper
    s_t = float(geometry.transition_arc_length(geom))
    s_fill = float(geometry.arc_length(geom.fill_level, geom))
    inside = (s_ref >= max(s.min(), s_ref.min())) & (s_ref <= min(s.max(), s_ref.max()))
    inside &= s_ref <= s_fill - 0.1 * geom.fill_height   # the free surface region is noisy
    if inside.sum() < 2:
        return None
    p_i = np.interp(s_ref[inside], s, p)
    l2 = 100.0 * float(np.linalg.norm(p_i - p_ref[inside]) / np.linalg.norm(p_ref[inside]))

    def region_means(ss, pp):
        cone = (ss >= 0.2 * s_t) & (ss <= 0.8 * s_t)
        bin_ = (ss > s_t) & (ss <= s_fill - 0.15 * geom.fill_height)
        return (float(np.mean(pp[bin_])) if bin_.any() else math.nan,
                float(np.mean(pp[cone])) if cone.any() else math.nan)

    b, c = region_means(s, p)
    b_ref, c_ref = region_means(s_ref, p_ref)
    return {"case": row["case"], "reference": ref["case"], "stage": stage,
            "cell_size_mm": row["cell_size_mm"], "youngs_modulus_MPa": row["youngs_modulus_MPa"],
            "l2_diff_pct": l2, "mean_bin_Pa": b, "mean_cone_Pa": c,
            "mean_bin_diff_pct": _sweep.pct(b, b_ref), "mean_cone_diff_pct": _sweep.pct(c, c_ref)}


def analyse(rows, options):
    base_e = float(options["base_modulus"]) / 1e6
    base_c = 1000 * float(options["base_cell"])
    cells = sorted([r for r in rows if r["youngs_modulus_MPa"] == base_e],
                   key=lambda r: -r["cell_size_mm"])
    stiff = sorted([r for r in rows if r["cell_size_mm"] == base_c],
                   key=lambda r: r["youngs_modulus_MPa"])
    w = lambda r: r.get("steady_discharge_rate_kg_s", math.nan)  # noqa: E731
    numbers = {}
    steps = []
    for a, b in zip(cells, cells[1:]):
        change = _sweep.pct(w(b), w(a))
        steps.append({"from_mm": a["cell_size_mm"], "to_mm": b["cell_size_mm"],
                      "rate_change_pct": change})
        numbers[f"rate_change_pct[{a['cell_size_mm']:g}->{b['cell_size_mm']:g} mm]"] = change
    if cells:
        numbers["rates_by_cell_kg_s"] = {f"{r['cell_size_mm']:g} mm": w(r) for r in cells}
    if stiff:
        ref = next((r for r in stiff if r["youngs_modulus_MPa"] == base_e), stiff[0])
        rates = [w(r) for r in stiff if _sweep.finite(w(r))]
        numbers["rates_by_modulus_kg_s"] = {f"{r['youngs_modulus_MPa']:g} MPa": w(r)
                                            for r in stiff}
        numbers["rate_spread_over_E_pct"] = (100.0 * (max(rates) - min(rates)) / w(ref)
                                             if rates else math.nan)
    diffs = []
    for stage in STAGES:
        if cells:
            for r in cells[:-1]:
                d = compare_profiles(r, cells[-1], stage)
                if d:
                    diffs.append({**d, "series": "cell size"})
        if stiff:
            ref = next((r for r in stiff if r["youngs_modulus_MPa"] == base_e), stiff[0])
            for r in stiff:
                if r is not ref:
                    d = compare_profiles(r, ref, stage)
                    if d:
                        diffs.append({**d, "series": "stiffness"})
    for d in diffs:
        label = (f"{d['cell_size_mm']:g} mm" if d["series"] == "cell size"
                 else f"{d['youngs_modulus_MPa']:g} MPa")
        numbers[f"wall_l2_diff_pct[{d['stage']}|{label} vs {d['reference']}]"] = d["l2_diff_pct"]
    numbers["failed"] = [r["case"] for r in rows if r.get("error")]
    return cells, stiff, steps, diffs, numbers


# ---------------------------------------------------------------- figure
def plot(cells, stiff, options):
    fig = _sweep.figure(11.0, 8.0)
    (a1, a2), (a3, a4) = fig.subplots(2, 2)
    w = lambda r: r.get("steady_discharge_rate_kg_s", math.nan)  # noqa: E731
    if cells:
        a1.plot([r["cell_size_mm"] for r in cells], [w(r) for r in cells], "o-", color="C0")
        for r in cells:
            a1.annotate(f"{w(r):.3f}", (r["cell_size_mm"], w(r)), textcoords="offset points",
                        xytext=(4, 4), fontsize=7)
        a1.set_xlim(0.0, max(r["cell_size_mm"] for r in cells) * 1.1)
    a1.set_xlabel("cell size h (mm)")
    a1.set_ylabel("steady discharge rate W (kg/s)")
    a1.set_title(f"Rate against cell size (E = {options['base_modulus'] / 1e6:g} MPa)",
                 fontsize=9)
    if stiff:
        e = [r["youngs_modulus_MPa"] for r in stiff]
        a2.semilogx(e, [w(r) for r in stiff], "s-", color="C1")
        a2.minorticks_off()
        a2.set_xticks(e)
        a2.set_xticklabels([f"{x:g}" for x in e])
        ref = next((r for r in stiff if r["youngs_modulus_MPa"] * 1e6 == options["base_modulus"]),
                   stiff[0])
        a2.axhspan(0.95 * w(ref), 1.05 * w(ref), color="C1", alpha=0.12, label="+-5 %")
        a2.legend(fontsize=7)
    a2.set_xlabel("Young's modulus E (MPa)")
    a2.set_ylabel("steady discharge rate W (kg/s)")
    a2.set_title(f"Rate against E (h = {1000 * options['base_cell']:g} mm)", fontsize=9)
    for ax, series, key, title in ((a3, cells, "cell_size_mm", "cell size"),
                                   (a4, stiff, "youngs_modulus_MPa", "E")):
        for k, r in enumerate(series):
            for stage, ls in (("filling", "-"), ("early_discharge", "--")):
                try:
                    cfg, s, p = profile(r, stage)
                except FileNotFoundError:
                    continue
                unit = "mm" if key == "cell_size_mm" else "MPa"
                ax.plot(s, p / 1e3, ls, color=f"C{k}", marker=".", ms=3, lw=1,
                        label=f"{r[key]:g} {unit}, {stage.replace('_', ' ')}")
        if series:
            try:
                cfg = profile(series[0], "filling")[0]
                ax.axvline(float(geometry.transition_arc_length(cfg.hopper)), color="0.5",
                           lw=0.8, ls=":")
            except FileNotFoundError:
                pass
        ax.set_xlabel("arc length from the outlet lip, s (m)")
        ax.set_ylabel("normal wall pressure p_n (kPa)")
        ax.set_title(f"Wall pressure against {title} (solid: filled, dashed: 90 % left)",
                     fontsize=9)
        ax.legend(fontsize=6)
    return fig


def write_outputs(out, rows, cells, stiff, steps, diffs, numbers, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "cell_size_mm", "youngs_modulus_MPa", "steady_discharge_rate_kg_s",
        "steady_rate_spread", "flow_mode", "mass_balance_error", "steps", "dt_s", "cells",
        "wall_time_s", "error"))
    _sweep.write_rows_csv(out / "profiles.csv", diffs)
    _sweep.save(plot(cells, stiff, options), out / "convergence.png")
    figures = [{"file": "convergence.png",
                "caption": "Steady rate against cell size and against E; wall pressure "
                           "profiles of each series (filled and early in the discharge)."}]
    findings = []
    if cells:
        findings.append("Steady rate by cell size: " + ", ".join(
            f"{r['cell_size_mm']:g} mm {r.get('steady_discharge_rate_kg_s', math.nan):.3f} kg/s"
            for r in cells) + "; changes on refinement: " + ", ".join(
            f"{s['from_mm']:g}->{s['to_mm']:g} mm {s['rate_change_pct']:+.1f} %" for s in steps)
            + ".")
    if stiff:
        findings.append("Steady rate by E: " + ", ".join(
            f"{r['youngs_modulus_MPa']:g} MPa {r.get('steady_discharge_rate_kg_s', math.nan):.3f}"
            " kg/s" for r in stiff) + f"; spread {numbers['rate_spread_over_E_pct']:.1f} % of "
            f"the E = {options['base_modulus'] / 1e6:g} MPa rate.")
    for series in ("cell size", "stiffness"):
        for stage in STAGES:
            part = [d for d in diffs if d["series"] == series and d["stage"] == stage]
            if part:
                findings.append(
                    f"Wall pressure ({stage.replace('_', ' ')}), {series} series, relative L2 "
                    "difference from the reference: " + ", ".join(
                        (f"{d['cell_size_mm']:g} mm" if series == "cell size" else
                         f"{d['youngs_modulus_MPa']:g} MPa") + f" {d['l2_diff_pct']:.1f} %"
                        for d in part) + f" (reference {part[0]['reference']}).")
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    tables = [{"title": "Cases",
               "columns": ["h (mm)", "E (MPa)", "W (kg/s)", "spread", "flow", "steps",
                           "wall time (s)"],
               "rows": [[r["cell_size_mm"], r["youngs_modulus_MPa"],
                         _r(r.get("steady_discharge_rate_kg_s"), 4),
                         _r(r.get("steady_rate_spread"), 3), r.get("flow_mode"), r.get("steps"),
                         _r(r.get("wall_time_s"), 0)] for r in rows]},
              {"title": "Wall pressure differences from the reference profile",
               "columns": ["series", "stage", "case", "reference", "L2 diff %",
                           "bin mean diff %", "cone mean diff %"],
               "rows": [[d["series"], d["stage"], d["case"], d["reference"],
                         _r(d["l2_diff_pct"], 1), _r(d["mean_bin_diff_pct"], 1),
                         _r(d["mean_cone_diff_pct"], 1)] for d in diffs]}]
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    headline = " ".join(findings[:2])
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables, rows, argv, headline=headline)


def _r(x, n):
    return (round(x, n) if n else int(round(x))) if _sweep.finite(x) else None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-sizes", type=float, nargs="+", help="m")
    parser.add_argument("--moduli", type=float, nargs="+", help="Pa")
    parser.add_argument("--end-time", type=float, help="s of discharge (default 0.8)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ('cell_sizes', 'moduli', 'end_time'))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    cells, stiff, steps, diffs, numbers = analyse(rows, study["options"])
    write_outputs(args.out, rows, cells, stiff, steps, diffs, numbers, study["options"],
                  study["setting"], argv)
    for s in steps:
        print(f"rate change {s['from_mm']:g} -> {s['to_mm']:g} mm: {s['rate_change_pct']:+.2f} %")
    if "rate_spread_over_E_pct" in numbers:
        print(f"rate spread over E: {numbers['rate_spread_over_E_pct']:.2f} %")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
