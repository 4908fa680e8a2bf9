"""Flow-mode map: mass or funnel flow over cone half-angle x wall friction angle, against Jenike.

Each case is a short discharge of a conical hopper (default: a 0.2 m bin, 0.06 m outlet,
0.15 m fill above the transition, phi = 30 deg, 5 mm cells, 0.8 s of discharge) classified
``mass`` or ``funnel`` by the package's own rule (``summary.json`` ``flow_mode``:
:class:`fipy_hopper.diagnostics.FlowModeRule`, the near-wall to axis speed ratio in the cone
and the stagnant fraction, medians over the discharge).  The classification is compared with
Jenike's boundary for conical hoppers, ``theta_c(delta = phi, phi_w)``
(:func:`fipy_hopper.theory.jenike_critical_half_angle`): mass flow for ``theta < theta_c``, and
no mass flow at all where ``phi_w >= phi``.

Written to ``--out`` (default ``studies/output/flow_mode_map``):

* ``results.csv``: one row per case (angles, theta_c, both classifications, the index and
  stagnant fraction, the steady rate, timing) and ``study.json`` (settings, numbers, findings);
* ``flow_mode_map.png``: the cases on the (phi_w, theta) plane over Jenike's curve;
* ``mass_flow_index.png``: the mass-flow index against the distance from Jenike's boundary;
* ``thumbnails.png``: the layers at the end of the discharge for a few cases;
* ``cases/<name>/``: the run directory of every case (results and fields; its own pictures
  with ``--case-plots``, or later with ``fipy-hopper plot cases/<name>``, about 3 s each).

Default cost (measured on this machine, 2026-12-02, one core per case): 5-12 s of simulation
per case at 5 mm, 201 core-seconds for the 30 cases, 109 s on 2 cores without the cases' own
pictures and 154 s with them (``tests/benchmarks``).

Usage::

    python studies/flow_mode_map.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                    [--cell-size 0.005] [--end-time 0.8]
                                    [--half-angles 10 20 ...] [--wall-angles 10 15 ...]
                                    [--case-plots]
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
}
QUICK = {"pairs": ((15.0, 12.0), (60.0, 25.0)), "cell_size": 0.01, "end_time": 0.6,
         "case_plots": False}


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
    for theta, wall in pairs:
        theta, wall = float(theta), float(wall)
        cases.append(_sweep.make_case(
            _sweep.case_name(("theta", theta), ("wall", wall)),
            {"half_angle_deg": theta, "wall_friction_deg": wall},
            _sweep.merge(base, hopper={"half_angle_deg": theta},
                         wall={"friction_angle_deg": wall}),
            plots=opts["case_plots"]))
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


def analyse(rows: list, options: dict) -> dict:
    """Adds ``theta_c_deg``, ``jenike_mode``, ``agrees``, ``distance_deg`` to each row and
    returns the numbers (agreement with Jenike as a fraction of the classified cases)."""
    phi = options["friction_angle"]
    shape = geometry_of(options.get("shape", "conical"))
    for r in rows:
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
        "disagreeing": [r["case"] for r in judged if not r["agrees"]],
        "failed": [r["case"] for r in rows if r.get("error")],
    }


def disagreements(rows, numbers, noun="cases") -> str:
    """The finding that lists the cases that disagree with Jenike (simulated mode, index,
    distance from the boundary)."""
    return f"Disagreeing {noun}: " + ", ".join(
        f"{r['case']} (sim {r['flow_mode']}, index {r['mass_flow_index']:.2f}, "
        + (f"theta - theta_c = {r['distance_deg']:+.1f} deg)"
           if math.isfinite(r["distance_deg"]) else "phi_w >= phi: no theta_c)")
        for r in rows if r["case"] in numbers["disagreeing"]) + "."


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
        idx = r.get("mass_flow_index")
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
                 f"Jenike ({100 * frac:.0f} %)\nred edge: disagrees; numbers: mass-flow index",
                 fontsize=9)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7)
    return fig


def plot_index(rows, options):
    from fipy_hopper.diagnostics import FlowModeRule

    fig = _sweep.figure(6.0, 4.0)
    ax = fig.add_subplot()
    for mode, marker, colour in (("mass", "o", "C0"), ("funnel", "^", "C1")):
        sel = [r for r in rows if r.get("flow_mode") == mode and math.isfinite(r["distance_deg"])]
        ax.scatter([r["distance_deg"] for r in sel], [r["mass_flow_index"] for r in sel],
                   marker=marker, color=colour, label=f"simulated {mode} flow")
    nan_rows = [r for r in rows if not math.isfinite(r["distance_deg"]) and
                _sweep.finite(r.get("mass_flow_index"))]
    if nan_rows:
        x = max([r["distance_deg"] for r in rows if math.isfinite(r["distance_deg"])] + [0]) + 8
        ax.scatter([x] * len(nan_rows), [r["mass_flow_index"] for r in nan_rows], marker="s",
                   color="0.5", label="phi_w >= phi (no theta_c), drawn at the right")
    ax.axhline(FlowModeRule().index_threshold, color="k", ls=":", lw=1,
               label="index threshold of the mass/funnel rule")
    ax.axvline(0.0, color="k", lw=1, label="Jenike boundary")
    ax.set_xlabel("theta - theta_c (deg)")
    ax.set_ylabel("mass-flow index (wall / axis speed)")
    ax.legend(fontsize=7)
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
def write_outputs(out, rows, numbers, options, setting, argv=None) -> list:
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "half_angle_deg", "wall_friction_deg", "theta_c_deg", "jenike_mode",
        "flow_mode", "agrees", "distance_deg", "mass_flow_index", "stagnant_fraction",
        "steady_discharge_rate_kg_s", "cell_size_m", "discharge_time_s", "wall_time_s",
        "error"))
    figures = [{"file": "flow_mode_map.png",
                "caption": "Simulated flow mode of every case on the (phi_w, theta) plane over "
                           "Jenike's boundary theta_c(delta = phi); a red edge marks a case "
                           "that disagrees with Jenike; the numbers are the mass-flow index."}]
    _sweep.save(plot_map(rows, options, numbers), out / "flow_mode_map.png")
    _sweep.save(plot_index(rows, options), out / "mass_flow_index.png")
    figures.append({"file": "mass_flow_index.png",
                    "caption": "Mass-flow index (near-wall / axis downward speed in the cone) "
                               "against the distance from Jenike's boundary."})
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
        f"agreement fraction {frac:.2f}.",
        f"Away from the boundary (|theta - theta_c| > 5 deg, or phi_w >= phi): "
        f"{frac_clear:.2f} of {numbers['clear_cases']} cases agree.",
        f"Simulated: {numbers['mass_cases']} mass, {numbers['funnel_cases']} funnel; Jenike: "
        f"{numbers['jenike_mass_cases']} mass.",
    ]
    if numbers["disagreeing"]:
        findings.append(disagreements(rows, numbers))
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    table = {"title": "Cases", "columns": ["theta (deg)", "phi_w (deg)", "theta_c (deg)",
                                          "Jenike", "simulated", "index", "stagnant", "agrees"],
             "rows": [[r["half_angle_deg"], r["wall_friction_deg"], _r(r["theta_c_deg"], 1),
                       r["jenike_mode"], r.get("flow_mode"), _r(r.get("mass_flow_index"), 2),
                       _r(r.get("stagnant_fraction"), 2), r["agrees"]] for r in rows]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()
                if k != "pairs" or v}
    settings["classification"] = ("summary.json flow_mode (FlowModeRule: mass when the "
                                  "near-wall/axis speed ratio >= 0.2 and the stagnant "
                                  "fraction <= 0.15)")
    _sweep.write_study_json(out, NAME, TITLE, setting, settings,
                            {k: v for k, v in numbers.items()}, findings, figures, [table],
                            rows, argv)
    return figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    parser.add_argument("--end-time", type=float, help="s of discharge (default 0.8)")
    parser.add_argument("--half-angles", type=float, nargs="+", help="deg")
    parser.add_argument("--wall-angles", type=float, nargs="+", help="deg")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ('cell_size', 'end_time', 'half_angles', 'wall_angles'))
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
