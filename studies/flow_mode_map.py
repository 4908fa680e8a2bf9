"""Flow-mode map: mass or funnel flow over cone half-angle x wall friction angle, against Jenike.

Each case is a short discharge of a conical hopper (default: a 0.2 m bin, 0.06 m outlet,
0.15 m fill above the transition, phi = 30 deg, 5 mm cells, 0.8 s of discharge) classified
``mass`` or ``funnel`` by the package's own rule (``summary.json`` ``flow_mode``:
:class:`fipy_hopper.diagnostics.FlowModeRule`, whether the material slides along the hopper
wall: the wall slip ratio, the load-weighted slip speed of the hopper wall's contacts over the
axis speed at their height, against 0.2; medians over the discharge).  The classification is
compared with Jenike's boundary for conical hoppers, ``theta_c(delta = phi, phi_w)``
(:func:`fipy_hopper.theory.jenike_critical_half_angle`): mass flow for ``theta < theta_c``, and
no mass flow at all where ``phi_w >= phi``.

Grid check: the cases within ``grid_check_within`` (6 deg) of Jenike's boundary are run again
on ``fine_cell_size`` (2.5 mm) cells; the report lists both calls (the call should not hang on
the grid).  ``fine_cell_size = 0`` leaves it out.

Written to ``--out`` (default ``studies/output/flow_mode_map``):

* ``results.csv``: one row per case (angles, theta_c, both classifications, the wall slip
  ratio and fraction, the index and stagnant fraction, the steady rate, timing; the grid
  check's runs flagged ``grid_check``) and ``study.json`` (settings, numbers, findings);
* ``flow_mode_map.png``: the cases on the (phi_w, theta) plane over Jenike's curve;
* ``wall_slip.png``: the wall slip ratio and fraction against the distance from Jenike's
  boundary, at both cell sizes where the grid check ran;
* ``thumbnails.png``: the layers at the end of the discharge for a few cases;
* ``cases/<name>/``: the run directory of every case (results and fields; its own pictures
  with ``--case-plots``, or later with ``fipy-hopper plot cases/<name>``, about 3 s each).

Default cost: 5-12 s of simulation per case at 5 mm (201 core-seconds for the 30 cases,
2026-12-02), and about ten times that for each of the grid check's 2.5 mm runs.

Usage::

    python studies/flow_mode_map.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                    [--cell-size 0.005] [--end-time 0.8]
                                    [--half-angles 10 20 ...] [--wall-angles 10 15 ...]
                                    [--fine-cell-size 0.0025] [--case-plots]
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
from fipy_hopper.diagnostics import FlowModeRule  # noqa: E402

_r = _sweep.rounded
NAME = "flow_mode_map"
TITLE = "Mass vs funnel flow: the flow-mode map against Jenike's boundary"
DEFAULTS = {
    "half_angles": (10.0, 20.0, 30.0, 40.0, 50.0, 60.0),   # cone half-angle theta (deg)
    "wall_angles": (10.0, 15.0, 20.0, 25.0, 30.0),         # wall friction angle phi_w (deg)
    "pairs": None,            # explicit (theta, phi_w) pairs instead of the grid
    "friction_angle": 30.0,   # phi (deg); Jenike's delta = phi for c = 0
    "bin_diameter": 0.2,      # m
    "outlet_diameter": 0.06,  # m
    "fill_height": 0.15,      # m above the transition
    "cell_size": 0.005,       # m: 6 cells across the outlet radius
    "end_time": 0.8,          # s of discharge
    "youngs_modulus": 5.0e6,  # Pa
    "shape": "conical",       # or "wedge": bin_diameter and outlet_diameter are then the
                              # bin width B and the slot width B0 (plane flow, per metre)
    "case_plots": False,      # each run draws its own pictures (30 runs: off, --case-plots)
    "thumbnails": 8,          # layer pictures in thumbnails.png
    "fine_cell_size": 0.0025,  # m: the grid check's cells (0: no grid check)
    "grid_check_within": 6.0,  # deg: the cases this near Jenike's boundary are checked
}
QUICK = {"pairs": ((15.0, 12.0), (60.0, 25.0)), "cell_size": 0.01, "end_time": 0.6,
         "case_plots": False, "fine_cell_size": 0.0}
FINE = "_fine"                # suffix of a grid-check case's name


def setup(quick: bool = False, **options) -> dict:
    """The cases and options: ``{"options", "cases", "setting"}``; ``quick`` starts from the
    tiny setting (two clear cases on a 1 cm grid).  Unknown options raise ``TypeError``."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    pairs = opts["pairs"] or [(t, w) for w in opts["wall_angles"] for t in opts["half_angles"]]
    sizes = ({"bin_diameter": opts["bin_diameter"], "outlet_diameter": opts["outlet_diameter"]}
             if opts["shape"] == "conical" else
             {"shape": opts["shape"], "bin_width": opts["bin_diameter"],
              "outlet_width": opts["outlet_diameter"]})
    base = {"hopper": {**sizes, "fill_height": opts["fill_height"],
                       "bin_height": opts["fill_height"] + 0.02},
            "material": {"friction_angle_deg": opts["friction_angle"],
                         "youngs_modulus": opts["youngs_modulus"]},
            "numerics": {"cell_size": opts["cell_size"]},
            "run": {"end_time": opts["end_time"], "output_interval": 0.02,
                    "field_interval": 0.2}}
    cases = []
    shape = geometry_of(opts["shape"])
    for theta, wall in pairs:
        theta, wall = float(theta), float(wall)
        name = _sweep.case_name(("theta", theta), ("wall", wall))
        config = _sweep.merge(base, hopper={"half_angle_deg": theta},
                              wall={"friction_angle_deg": wall})
        params = {"half_angle_deg": theta, "wall_friction_deg": wall}
        cases.append(_sweep.make_case(name, params, config, plots=opts["case_plots"]))
        distance = theta - float(critical_angle(opts["friction_angle"], wall, shape))
        if opts["fine_cell_size"] > 0 and abs(distance) <= opts["grid_check_within"]:
            cases.append(_sweep.make_case(
                name + FINE, {**params, "grid_check": True},
                _sweep.merge(config, numerics={"cell_size": opts["fine_cell_size"]}),
                plots=False))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- analysis
def geometry_of(shape: str) -> str:
    """Jenike's geometry for a hopper shape: ``"conical"`` or ``"plane"`` (a wedge)."""
    return "plane" if shape == "wedge" else "conical"


def critical_angle(phi, phi_w, geometry_name="conical"):
    """Jenike's critical half-angle (deg) for the geometry, NaN where there is none."""
    critical = (theory.jenike_critical_half_angle_plane if geometry_name == "plane"
                else theory.jenike_critical_half_angle)
    return critical(phi, phi_w)


def jenike(theta, phi, phi_w, geometry_name="conical"):
    """``(theta_c, mode)`` by Jenike's fit with delta = phi (theta_c NaN: no mass flow), for
    a cone or (``"plane"``) a wedge."""
    theta_c = float(critical_angle(phi, phi_w, geometry_name))
    return theta_c, str(theory.jenike_flow_mode(theta, phi, phi_w, geometry=geometry_name))


def split_grid_check(rows: list) -> tuple:
    """``(map rows, grid-check rows)``: the cases of the map and their reruns on fine cells."""
    return ([r for r in rows if not r.get("grid_check")],
            [r for r in rows if r.get("grid_check")])


def analyse(rows: list, options: dict) -> dict:
    """Adds ``theta_c_deg``, ``jenike_mode``, ``agrees``, ``distance_deg`` to each row and
    returns the numbers (agreement with Jenike as a fraction of the classified cases; cases
    within 4 deg of the boundary apart; the grid check's calls against the map's)."""
    rows, fine = split_grid_check(rows)
    phi = options["friction_angle"]
    shape = geometry_of(options.get("shape", "conical"))
    for r in rows + fine:
        theta_c, mode = jenike(r["half_angle_deg"], phi, r["wall_friction_deg"], shape)
        r["theta_c_deg"] = theta_c
        r["jenike_mode"] = mode
        sim = r.get("flow_mode")
        r["agrees"] = (sim == mode) if sim in ("mass", "funnel") and not r.get("error") else None
        r["distance_deg"] = r["half_angle_deg"] - theta_c if math.isfinite(theta_c) else math.nan
    judged = [r for r in rows if r["agrees"] is not None]
    agree = [r for r in judged if r["agrees"]]
    clear = [r for r in judged if not (abs(r["distance_deg"]) <= 5.0)]   # NaN counts as clear
    clear_agree = [r for r in clear if r["agrees"]]
    beyond4 = [r for r in judged if not (abs(r["distance_deg"]) <= 4.0)]
    coarse = {(r["half_angle_deg"], r["wall_friction_deg"]): r for r in rows}
    checked = [(coarse[(f["half_angle_deg"], f["wall_friction_deg"])], f) for f in fine
               if (f["half_angle_deg"], f["wall_friction_deg"]) in coarse]
    for c, f in checked:
        f["coarse_flow_mode"] = c.get("flow_mode")
        f["coarse_slip_ratio"] = c.get("wall_slip_ratio")
        f["same_call"] = c.get("flow_mode") == f.get("flow_mode")
    return {
        "cases": len(rows),
        "classified": len(judged),
        "mass_cases": sum(1 for r in judged if r["flow_mode"] == "mass"),
        "funnel_cases": sum(1 for r in judged if r["flow_mode"] == "funnel"),
        "jenike_mass_cases": sum(1 for r in judged if r["jenike_mode"] == "mass"),
        "agreeing": len(agree),
        "agreement_fraction": len(agree) / len(judged) if judged else math.nan,
        "clear_cases": len(clear),
        "agreement_fraction_clear": (len(clear_agree) / len(clear) if clear else math.nan),
        "cases_beyond_4deg": len(beyond4),
        "agreeing_beyond_4deg": sum(1 for r in beyond4 if r["agrees"]),
        "funnel_at_rough_walls": all(r["flow_mode"] == "funnel" for r in judged
                                     if r["wall_friction_deg"] >= phi),
        "disagreeing": [r["case"] for r in judged if not r["agrees"]],
        "grid_checked": len(checked),
        "grid_same_call": sum(1 for _, f in checked if f["same_call"]),
        "grid_changed": [f["case"] for _, f in checked if not f["same_call"]],
        "failed": [r["case"] for r in rows + fine if r.get("error")],
    }


def explain(r) -> str:
    """What was measured in a case: its distance from Jenike's boundary, the wall slip ratio
    and fraction, the mass-flow index and the stagnant fraction."""
    where = (f"theta - theta_c = {r['distance_deg']:+.1f} deg" if math.isfinite(
        r["distance_deg"]) else "phi_w >= phi: no theta_c")
    return (f"{where}; wall slip ratio {_num(r.get('wall_slip_ratio'))} (threshold "
            f"{FlowModeRule().slip_ratio:g}), the wall slides over "
            f"{_num(r.get('wall_slip_fraction'), 100, '.0f')} % of its length; stagnant "
            f"fraction {_num(r.get('stagnant_fraction'))}, mass-flow index "
            f"{_num(r.get('mass_flow_index'))}")


def _num(x, scale=1.0, spec=".2f") -> str:
    return format(scale * x, spec) if _sweep.finite(x) else "n/a"


def disagreements(rows, numbers, noun="cases") -> str:
    """The finding that lists the cases that disagree with Jenike, each with what was
    measured (:func:`explain`)."""
    return f"Disagreeing {noun}: " + "; ".join(
        f"{r['case']} (simulated {r['flow_mode']}, Jenike {r['jenike_mode']}: {explain(r)})"
        for r in rows if r["case"] in numbers["disagreeing"]) + "."


def grid_check_finding(rows, numbers, options) -> str:
    """The finding of the grid check: each checked case's call at both cell sizes."""
    _, fine = split_grid_check(rows)
    fine = [f for f in fine if "same_call" in f]
    if not fine:
        return ""
    h0, h1 = 1000 * options["cell_size"], 1000 * options["fine_cell_size"]
    return (f"Grid check: {numbers['grid_same_call']} of {numbers['grid_checked']} cases within "
            f"{options['grid_check_within']:g} deg of the boundary give the same call at "
            f"{h0:g} and {h1:g} mm: " + "; ".join(
                f"theta {f['half_angle_deg']:g}, phi_w {f['wall_friction_deg']:g} "
                f"({f['distance_deg']:+.1f} deg): {f['coarse_flow_mode']} / {f['flow_mode']} "
                f"(slip ratio {_num(f.get('coarse_slip_ratio'))} / "
                f"{_num(f.get('wall_slip_ratio'))})" for f in fine) + ".")


# ---------------------------------------------------------------- figures
def plot_map(rows, options, numbers):
    phi = options["friction_angle"]
    fig = _sweep.figure(8.8, 5.0)
    ax = fig.add_subplot()
    pw = np.linspace(0.0, phi - 1e-6, 300)
    plane = geometry_of(options.get("shape", "conical")) == "plane"
    tc = np.asarray(critical_angle(phi, pw, "plane" if plane else "conical"), float)
    walls = [r["wall_friction_deg"] for r in rows] + [phi]
    x_max = max(walls) + 2.0
    y_max = max([r["half_angle_deg"] for r in rows] + [60.0]) + 5.0
    ax.fill_between(pw, 0.0, tc, color="C0", alpha=0.12, lw=0,
                    label="Jenike: mass flow (theta < theta_c)")
    ax.plot(pw, tc, "k-", lw=1.5, label=f"Jenike {'plane-flow ' if plane else ''}boundary "
                                        f"theta_c(delta = phi = {phi:g} deg)")
    if plane:           # the conical boundary beside it: plane flow is more generous
        ax.plot(pw, np.asarray(critical_angle(phi, pw), float), "--", color="0.45", lw=1.2,
                label="Jenike conical boundary (for comparison)")
    ax.plot(pw, tc - 4.0, "k:", lw=1.0, label="theta_c - 4 deg (design margin)")
    ax.axvline(phi, color="0.4", lw=0.8, ls="--")
    ax.text(phi, 2.0, " phi_w = phi:\n no mass flow", fontsize=7, color="0.3")
    for mode, marker, colour in (("mass", "o", "C0"), ("funnel", "^", "C1")):
        sel = [r for r in rows if r.get("flow_mode") == mode and not r.get("error")]
        if not sel:
            continue
        ax.scatter([r["wall_friction_deg"] for r in sel], [r["half_angle_deg"] for r in sel],
                   marker=marker, s=70, facecolor=colour, zorder=3,
                   edgecolor=["k" if r["agrees"] else "red" for r in sel],
                   linewidth=[0.6 if r["agrees"] else 2.2 for r in sel],
                   label=f"simulated: {mode} flow")
    for r in rows:
        idx = r.get("wall_slip_ratio")
        if _sweep.finite(idx):
            ax.annotate(f"{idx:.2f}", (r["wall_friction_deg"], r["half_angle_deg"]),
                        textcoords="offset points", xytext=(6, -10), fontsize=6, color="0.3")
    failed = [r for r in rows if r.get("error")]
    if failed:
        ax.scatter([r["wall_friction_deg"] for r in failed], [r["half_angle_deg"] for r in failed],
                   marker="x", color="k", s=60, label="failed run")
    ax.set_xlim(0.0, x_max)
    ax.set_ylim(0.0, y_max)
    ax.set_xlabel("wall friction angle phi_w (deg)")
    ax.set_ylabel(f"{'wedge' if plane else 'cone'} half-angle theta from the vertical (deg)")
    frac = numbers["agreement_fraction"]
    ax.set_title(f"Flow mode: {numbers['agreeing']}/{numbers['classified']} cases agree with "
                 f"Jenike ({100 * frac:.0f} %)\nred edge: disagrees; numbers: wall slip ratio",
                 fontsize=9)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7)
    return fig


def plot_slip(rows, options):
    """The wall slip ratio (left) and fraction (right) of every case against its distance from
    Jenike's boundary; the grid check's fine runs open, joined to their map case."""
    rows, fine = split_grid_check(rows)
    rule = FlowModeRule()
    fig = _sweep.figure(10.0, 4.0)
    axes = fig.subplots(1, 2)
    finite = [r["distance_deg"] for r in rows + fine if math.isfinite(r["distance_deg"])]
    x_rough = max(finite + [0.0]) + 8.0
    coarse = {(r["half_angle_deg"], r["wall_friction_deg"]): r for r in rows}

    def x_of(r):
        return r["distance_deg"] if math.isfinite(r["distance_deg"]) else x_rough

    for ax, key, label in zip(axes, ("wall_slip_ratio", "wall_slip_fraction"),
                              ("wall slip ratio (slip / axis speed, load-weighted)",
                               "wall slip fraction (share of the hopper wall sliding)")):
        for mode, marker, colour in (("mass", "o", "C0"), ("funnel", "^", "C1")):
            sel = [r for r in rows if r.get("flow_mode") == mode and _sweep.finite(r.get(key))]
            ax.scatter([x_of(r) for r in sel], [r[key] for r in sel], marker=marker,
                       color=colour, label=f"simulated {mode} flow, "
                                           f"{1000 * options['cell_size']:g} mm")
        sel = [f for f in fine if _sweep.finite(f.get(key))]
        if sel:
            ax.scatter([x_of(f) for f in sel], [f[key] for f in sel], marker="s",
                       facecolor="none", edgecolor="k",
                       label=f"grid check, {1000 * options['fine_cell_size']:g} mm")
            for f in sel:
                c = coarse.get((f["half_angle_deg"], f["wall_friction_deg"]))
                if c is not None and _sweep.finite(c.get(key)):
                    ax.plot([x_of(f)] * 2, [c[key], f[key]], "k-", lw=0.6)
        if key == "wall_slip_ratio":
            ax.axhline(rule.slip_ratio, color="k", ls=":", lw=1,
                       label="threshold of the mass/funnel rule")
        ax.axvline(0.0, color="k", lw=1, label="Jenike boundary")
        ax.axvline(x_rough - 4.0, color="0.6", lw=0.6, ls="--")
        ax.set_xlabel(f"theta - theta_c (deg); phi_w >= phi drawn at {x_rough:.0f}")
        ax.set_ylabel(label)
    axes[0].legend(fontsize=6)
    return fig


def pick_thumbnails(rows, n):
    """A few cases: the clearest mass and funnel cases (farthest from Jenike's boundary on
    each side), then the disagreeing ones, then those nearest the boundary."""
    ok = [r for r in rows if r.get("flow_mode") in ("mass", "funnel")
          and Path(r.get("run_dir", "")).is_dir()]
    if not ok:
        return []
    finite = [r for r in ok if math.isfinite(r["distance_deg"])]
    chosen = []
    if finite:
        chosen += [min(finite, key=lambda r: r["distance_deg"]),
                   max(finite, key=lambda r: r["distance_deg"])]
    chosen += [r for r in ok if not r["agrees"]]
    chosen += sorted(finite, key=lambda r: abs(r["distance_deg"]))
    chosen += ok
    out = []
    for r in chosen:
        if r not in out:
            out.append(r)
    return sorted(out[:n], key=lambda r: (r["wall_friction_deg"], r["half_angle_deg"]))


def plot_thumbnails(rows, n):
    from fipy_hopper import plotting
    from fipy_hopper.api import load_config

    picked = pick_thumbnails(rows, n)
    if not picked:
        return None
    ncols = min(len(picked), 4)
    nrows = math.ceil(len(picked) / ncols)
    fig = _sweep.figure(2.3 * ncols + 0.4, 3.4 * nrows + 0.3)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[len(picked):]:
        ax.set_axis_off()
    with_markers = False
    for ax, r in zip(axes, picked):
        run = Path(r["run_dir"])
        snaps = [e for e in plotting.snapshots(run) if e["stage"] == "discharge"]
        if not snaps:
            ax.set_axis_off()
            continue
        snap = plotting.load_snapshot(run, snaps[-1])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cfg = load_config(run / "config.toml")
        rr = snap["r_nodes"]
        with_markers = with_markers or snap["markers"] is not None
        wall = geometry.wall_polyline(cfg.hopper, rr[-1], cfg.hopper.top)
        for sign in (-1.0, 1.0):
            plotting.draw_layers(ax, snap, side=sign)
            ax.plot(sign * wall[:, 0], wall[:, 1], "k-", lw=0.8)
        ax.set_aspect("equal")
        ax.set_xlim(-rr[-1], rr[-1])
        ax.set_ylim(-0.02, cfg.hopper.fill_level + 0.01)
        ax.set_xticks([])
        ax.set_yticks([])
        colour = "k" if r["agrees"] else "red"
        ax.set_title(f"theta {r['half_angle_deg']:g}, phi_w {r['wall_friction_deg']:g}\n"
                     f"{r['flow_mode']} (Jenike: {r['jenike_mode']})\n"
                     f"t = {snap['discharge_time_s']:.2f} s", fontsize=7, color=colour)
    how = "marker points" if with_markers else "cells with alpha < 1/2 blank"
    fig.suptitle(f"Layers at the end of the discharge ({how})", fontsize=9)
    return fig


# ---------------------------------------------------------------- outputs
RESULT_COLUMNS = ("case", "half_angle_deg", "wall_friction_deg", "theta_c_deg", "jenike_mode",
                  "flow_mode", "agrees", "distance_deg", "wall_slip_ratio",
                  "wall_slip_fraction", "stagnant_fraction", "mass_flow_index",
                  "coarse_flow_mode", "same_call", "cell_size_m")


def write_outputs(out, rows, numbers, options, setting, argv=None) -> list:
    out = Path(out)
    everything = rows
    rows, _ = split_grid_check(rows)
    _sweep.write_rows_csv(out / "results.csv", everything, first=RESULT_COLUMNS + (
        "steady_discharge_rate_kg_s", "discharge_time_s", "wall_time_s", "error"))
    figures = [{"file": "flow_mode_map.png",
                "caption": "Simulated flow mode of every case on the (phi_w, theta) plane over "
                           "Jenike's boundary theta_c(delta = phi); a red edge marks a case "
                           "that disagrees with Jenike; the numbers are the wall slip ratio."}]
    _sweep.save(plot_map(rows, options, numbers), out / "flow_mode_map.png")
    _sweep.save(plot_slip(everything, options), out / "wall_slip.png")
    figures.append({"file": "wall_slip.png",
                    "caption": "Wall slip ratio (the hopper wall's load-weighted slip speed "
                               "over the axis speed; the rule's threshold dotted) and the share "
                               "of the hopper wall that slides, against the distance from "
                               "Jenike's boundary; open squares: the grid check on finer "
                               "cells, joined to the map's case."})
    thumbs = plot_thumbnails(rows, options["thumbnails"])
    if thumbs is not None:
        _sweep.save(thumbs, out / "thumbnails.png")
        figures.append({"file": "thumbnails.png",
                        "caption": "Layer pictures at the end of the discharge of a few cases "
                                   "(the clearest mass and funnel cases, the disagreements, the "
                                   "nearest to the boundary); a red title marks a disagreement "
                                   "with Jenike."})
    frac, frac_clear = numbers["agreement_fraction"], numbers["agreement_fraction_clear"]
    findings = [
        f"{numbers['agreeing']} of {numbers['classified']} classified cases agree with "
        f"Jenike's boundary (delta = phi = {options['friction_angle']:g} deg): "
        f"agreement fraction {frac:.2f} (in-sample: the rule's threshold, a wall slip ratio "
        f"of 0.2, was placed in the gap these cases leave; the cases on other cells were "
        f"not used to place it).",
        f"Away from the boundary (|theta - theta_c| > 5 deg, or phi_w >= phi): "
        f"{frac_clear:.2f} of {numbers['clear_cases']} cases agree.",
        f"Simulated: {numbers['mass_cases']} mass, {numbers['funnel_cases']} funnel; Jenike: "
        f"{numbers['jenike_mass_cases']} mass.",
    ]
    findings.append(
        f"More than 4 deg from the boundary (or phi_w >= phi): {numbers['agreeing_beyond_4deg']} "
        f"of {numbers['cases_beyond_4deg']} agree; at phi_w >= phi every call is funnel: "
        f"{numbers['funnel_at_rough_walls']}.")
    if numbers["disagreeing"]:
        findings.append(disagreements(rows, numbers))
    check = grid_check_finding(everything, numbers, options)
    if check:
        findings.append(check)
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    table = case_table(everything, options)
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()
                if k != "pairs" or v}
    settings["classification"] = (f"summary.json flow_mode (FlowModeRule: mass when the "
                                  f"wall slip ratio >= {FlowModeRule().slip_ratio:g})")
    _sweep.write_study_json(out, NAME, TITLE, setting, settings,
                            {k: v for k, v in numbers.items()}, findings, figures, [table],
                            everything, argv)
    return figures


def case_table(rows, options, title="Cases") -> dict:
    """The report's table of the cases (the grid check's runs flagged by their cell size)."""
    return {"title": title,
            "columns": ["theta (deg)", "phi_w (deg)", "cell (mm)", "theta_c (deg)", "Jenike",
                        "simulated", "slip ratio", "slip fraction", "stagnant", "index",
                        "agrees"],
            "rows": [[r["half_angle_deg"], r["wall_friction_deg"],
                      _r(1000 * r.get("cell_size_m", math.nan), 2), _r(r["theta_c_deg"], 1),
                      r["jenike_mode"], r.get("flow_mode"), _r(r.get("wall_slip_ratio"), 2),
                      _r(r.get("wall_slip_fraction"), 2), _r(r.get("stagnant_fraction"), 2),
                      _r(r.get("mass_flow_index"), 2), r["agrees"]] for r in rows]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    parser.add_argument("--end-time", type=float, help="s of discharge (default 0.8)")
    parser.add_argument("--half-angles", type=float, nargs="+", help="deg")
    parser.add_argument("--wall-angles", type=float, nargs="+", help="deg")
    parser.add_argument("--fine-cell-size", type=float,
                        help="m: the grid check's cells (default 0.0025; 0: none)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ('cell_size', 'end_time', 'half_angles', 'wall_angles',
                                          'fine_cell_size'))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    numbers = analyse(rows, study["options"])
    write_outputs(args.out, rows, numbers, study["options"], study["setting"], argv)
    print(f"agreement with Jenike: {numbers['agreeing']}/{numbers['classified']} = "
          f"{numbers['agreement_fraction']:.2f} (away from the boundary: "
          f"{numbers['agreement_fraction_clear']:.2f}); written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
