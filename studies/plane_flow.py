"""Plane flow: wedge hoppers with a slot outlet, per metre of length.

Two parts, both run as ordinary run directories (``hopper.shape = "wedge"``):

* **Slot exponent.**  A plane bin filled ``slot_fill`` (0.5 m) above the transition is
  discharged for ``slot_end_time`` (0.6 s) through slots of the widths
  ``slot_widths`` (60, 70, 80 and 100 mm: at 5 mm cells, at least the 6 cells across the
  slot's half-width that a discharge rate needs, as the configuration's resolution warning
  says), with a flat bottom (a bin 1 m wide: ten widths of the largest slot) and with a
  20 deg wedge (from a bin 0.6 m wide; the wedge's walls lead to the slot, whatever the
  bin).  Measured: the flat bin's width does not matter from 0.6 m on (every slot's rate
  within 0.3 % in a 0.6 m and a 1 m bin).  The
  rate per metre ``W'`` is the mean over the same window for every slot, from
  ``rate_window_start`` (0.2 s, past the opening transient) to the end, read from
  ``timeseries.csv`` (the summary's steady rate picks its plateau by the mass left, a
  different window for each slot in so short a run); it is fitted as ``W' = a B0^n`` for
  each bottom; Beverloo's slot form says ``n = 3/2``
  (:func:`fipy_hopper.theory.beverloo_slot_rate`, ``C' = 1.03``, ``k = 1.5`` with the
  material's grain size ``d`` (1 mm by default), which the flat
  bottom is also compared with; there is no plane hopper factor to compare the wedge with).
  The flat bottom's four slots are run again on ``fine_cell_size`` (2.5 mm) cells, in a
  0.6 m bin: the exponent at both cell sizes, and its extrapolation to zero cell size (first
  order), tell a resolution effect from a law.
* **Plane-flow map.**  The flow-mode map of ``flow_mode_map.py`` on wedges (bin width 0.2 m,
  slot 0.06 m, fill 0.15 m above the transition, 5 mm cells, 0.8 s): mass or funnel flow by
  the package's rule (``summary.json`` ``flow_mode``) over the half-angle and the wall
  friction angle, against Jenike's plane-flow boundary.  That boundary is the conical one plus
  10 deg (:func:`fipy_hopper.theory.jenike_critical_half_angle_plane`, a rule of thumb, [M]:
  no closed form of Jenike's plane-flow chart could be read); the conical boundary is drawn
  beside it, so the picture sets the wedge's map against the cone's.  The wedges within 6 deg
  of that boundary are run again on ``fine_cell_size`` (2.5 mm) cells (the grid check of
  ``flow_mode_map.py``).

Written to ``--out`` (default ``studies/output/plane_flow``): ``slots.csv`` and
``results.csv`` (one row per case), ``slot_exponent.png``, ``plane_flow_map.png``,
``wall_slip.png``,
``study.json`` (what ``make_report.py`` reads) and ``cases/<name>/``.

Usage::

    python studies/plane_flow.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                 [--cell-size 0.005] [--fine-cell-size 0.0025]
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
import flow_mode_map  # noqa: E402

from fipy_hopper import theory  # noqa: E402
from fipy_hopper.config import HopperConfig  # noqa: E402
from fipy_hopper.diagnostics import fit_power_law  # noqa: E402

_r = _sweep.rounded
NAME = "plane_flow"
#: the default grain size (m), which the runs and Beverloo's slot form share
GRAIN = HopperConfig().material.grain_diameter
TITLE = "Plane flow (wedge hoppers): the slot exponent and the flow-mode map against Jenike"
RATE = "steady_discharge_rate_kg_s_m"
RATE_WINDOW = "window_rate_kg_s_m"
DEFAULTS = {
    "slot_widths": (0.06, 0.07, 0.08, 0.10),    # B0 (m)
    "slot_bottoms": ((90.0, 1.0), (20.0, 0.6)),  # (half-angle (deg), bin width (m)):
                                                 # a flat bottom and a wedge
    "slot_fill": 0.5,                            # m above the transition
    "slot_end_time": 0.6,                        # s of discharge
    "rate_window_start": 0.2,                    # s after the opening
    "fine_cell_size": 0.0025,                    # m: the flat bottom's exponent refined
    "fine_widths": (0.06, 0.07, 0.08, 0.10),     # m, in a flat bin fine_bin_width wide
    "fine_bin_width": 0.6,                       # m
    "half_angles": (10.0, 20.0, 30.0, 40.0, 50.0, 60.0),
    "wall_angles": (10.0, 15.0, 20.0, 25.0, 30.0),
    "pairs": None,
    "cell_size": 0.005,                          # m
    "fine_cell_size": 0.0025,                    # m: the map's grid check (0: none)
    "case_plots": False,
}
QUICK = {"slot_widths": (0.06, 0.08), "slot_bottoms": ((90.0, 0.3),), "slot_fill": 0.1,
         "slot_end_time": 0.3, "fine_widths": (), "rate_window_start": 0.1,
         "pairs": ((20.0, 12.0), (60.0, 25.0)), "cell_size": 0.01, "fine_cell_size": 0.0}
#: the map's own settings (flow_mode_map.DEFAULTS but for the shape)
MAP = {"shape": "wedge", "end_time": 0.8, "friction_angle": 30.0, "bin_diameter": 0.2,
       "outlet_diameter": 0.06, "fill_height": 0.15, "youngs_modulus": 5.0e6}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting", "map_options"}``); unknown
    options raise ``TypeError``."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    map_options = {**MAP, "cell_size": opts["cell_size"], "case_plots": opts["case_plots"],
                   "fine_cell_size": opts["fine_cell_size"],
                   **({"pairs": opts["pairs"]} if opts["pairs"] else
                      {"half_angles": opts["half_angles"], "wall_angles": opts["wall_angles"]}),
                   **({"end_time": 0.6} if quick else {})}
    map_study = flow_mode_map.setup(**map_options)
    cases = [dict(c, params={**c["params"], "part": "map"}) for c in map_study["cases"]]
    runs = [("slot", "slot", theta, bin_width, width, opts["cell_size"])
            for theta, bin_width in opts["slot_bottoms"] for width in opts["slot_widths"]]
    runs += [("slot_fine", "fine_slot", 90.0, opts["fine_bin_width"], width,
              opts["fine_cell_size"]) for width in opts["fine_widths"]]
    for part, prefix, theta, bin_width, width, cell_size in runs:
        config = slot_config(opts, float(theta), bin_width, float(width), cell_size)
        cases.append(_sweep.make_case(
            _sweep.case_name((prefix, 1000 * width), ("theta", theta)),
            {"part": part, "slot_width_m": float(width), "half_angle_deg": float(theta),
             "density_kg_m3": HopperConfig.from_dict(config).material.density},
            config, plots=opts["case_plots"]))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options),
            "map_options": map_study["options"]}


def slot_config(opts, theta, bin_width, width, cell_size) -> dict:
    """The sections of a slot run: a plane bin ``bin_width`` wide over a bottom of half-angle
    ``theta`` (90: flat) with a slot ``width`` wide, filled ``slot_fill``, on ``cell_size``
    cells, discharged for ``slot_end_time``."""
    return {"hopper": {"shape": "wedge", "bin_width": bin_width, "outlet_width": width,
                       "half_angle_deg": theta, "fill_height": opts["slot_fill"],
                       "bin_height": opts["slot_fill"] + 0.02},
            "numerics": {"cell_size": cell_size},
            "run": {"end_time": opts["slot_end_time"], "output_interval": 0.02,
                    "field_interval": opts["slot_end_time"]}}


# ---------------------------------------------------------------- analysis
def bottom_key(theta: float) -> str:
    """The key of a slot bottom in the numbers: ``flat`` or ``wedge_<theta>deg``."""
    return "flat" if theta >= 90.0 else f"wedge_{theta:g}deg"


def label(theta: float) -> str:
    """A slot bottom in words."""
    return "flat bottom" if theta >= 90.0 else f"{theta:g} deg wedge"


def window_rate(run_dir, start: float) -> float:
    """Mean discharge rate per metre (kg/s/m) from ``start`` s after the opening to the last
    sample of ``timeseries.csv``: the discharged mass's change over that time."""
    from fipy_hopper.io import read_csv

    table = read_csv(Path(run_dir) / "timeseries.csv")
    t, out = np.asarray(table["t_s"], float), np.asarray(table["discharged_kg_m"], float)
    if len(t) < 2 or t[-1] <= start:
        return math.nan
    return float((out[-1] - np.interp(start, t, out)) / (t[-1] - start))


def analyse_slots(rows: list, options: dict) -> dict:
    """Per bottom: the window rate of each slot (``window_rate_kg_s_m``, added to the rows),
    the fitted exponent ``n`` of ``W' = a B0^n`` and each rate against Beverloo's slot rate
    (``ratio_to_beverloo``)."""
    out = {}
    for r in rows:
        if not r.get("error") and r.get("run_dir"):
            r[RATE_WINDOW] = window_rate(r["run_dir"], options["rate_window_start"])
    for theta, _ in options["slot_bottoms"]:
        sel = sorted((r for r in rows if r["half_angle_deg"] == theta and not r.get("error")
                      and _sweep.finite(r.get(RATE_WINDOW))), key=lambda r: r["slot_width_m"])
        for r in sel:
            r["beverloo_slot_kg_s_m"] = float(theory.beverloo_slot_rate(
                r["density_kg_m3"], r["slot_width_m"], d=GRAIN))
            r["ratio_to_beverloo"] = r[RATE_WINDOW] / r["beverloo_slot_kg_s_m"]
        key = bottom_key(theta)
        if len(sel) >= 2:
            _, n = fit_power_law([r["slot_width_m"] for r in sel], [r[RATE_WINDOW] for r in sel])
            out[f"slot_exponent_{key}"] = float(n)
        out[f"slot_widths_{key}"] = len(sel)
        if sel:
            ratios = [r["ratio_to_beverloo"] for r in sel]
            out[f"ratio_to_beverloo_{key}_min"] = float(min(ratios))
            out[f"ratio_to_beverloo_{key}_max"] = float(max(ratios))
        out[f"mass_balance_error_{key}_max"] = float(max(
            [r.get("mass_balance_error", math.nan) for r in sel] or [math.nan]))
    return out


def fitted_exponent(rows, widths) -> float:
    """``n`` of ``W' = a B0^n`` fitted to the rows of the slot ``widths`` (NaN unless all of
    them are there)."""
    rate = {r["slot_width_m"]: r.get(RATE_WINDOW, math.nan) for r in rows}
    if not all(_sweep.finite(rate.get(w)) for w in widths):
        return math.nan
    return float(fit_power_law(list(widths), [rate[w] for w in widths])[1])


def analyse_refinement(fine: list, slots: list, options: dict) -> dict:
    """The flat bottom's exponent over the ``fine_widths`` at the study's cells and at
    ``fine_cell_size``, and its extrapolation to zero cell size, first order in the cell size
    (``n_0 = n_fine + (n_fine - n_coarse) / (h_coarse / h_fine - 1)``)."""
    widths = tuple(options["fine_widths"])
    if len(widths) < 2:
        return {}
    for r in fine:
        if not r.get("error") and r.get("run_dir"):
            r[RATE_WINDOW] = window_rate(r["run_dir"], options["rate_window_start"])
            r["beverloo_slot_kg_s_m"] = float(theory.beverloo_slot_rate(
                r["density_kg_m3"], r["slot_width_m"], d=GRAIN))
            r["ratio_to_beverloo"] = r[RATE_WINDOW] / r["beverloo_slot_kg_s_m"]
    coarse = fitted_exponent([r for r in slots if r["half_angle_deg"] >= 90.0], widths)
    refined = fitted_exponent(fine, widths)
    ratio = options["cell_size"] / options["fine_cell_size"]
    extrapolated = refined + (refined - coarse) / (ratio - 1.0)
    return {"flat_exponent_coarse": coarse, "flat_exponent_fine": refined,
            "flat_exponent_extrapolated": extrapolated}


def plot_slots(rows, options, numbers):
    fig = _sweep.figure(6.4, 4.4)
    ax = fig.add_subplot()
    widths = np.linspace(min(options["slot_widths"]) * 0.9, max(options["slot_widths"]) * 1.1)
    rho = next((r["density_kg_m3"] for r in rows), math.nan)
    ax.loglog(widths, np.asarray(theory.beverloo_slot_rate(rho, widths, d=GRAIN)), "k--",
              label=f"Beverloo, slot (C' = 1.03, k = 1.5, d = {1000 * GRAIN:g} mm)")
    for k, (theta, _) in enumerate(options["slot_bottoms"]):
        sel = sorted((r for r in rows if r["half_angle_deg"] == theta
                      and _sweep.finite(r.get(RATE_WINDOW))), key=lambda r: r["slot_width_m"])
        if not sel:
            continue
        key = bottom_key(theta)
        n = numbers.get(f"slot_exponent_{key}", math.nan)
        ax.loglog([r["slot_width_m"] for r in sel], [r[RATE_WINDOW] for r in sel],
                  "os"[k % 2] + "-",
                  color=f"C{k}", label=f"simulated, {label(theta)}: n = {n:.3f}")
    fine = sorted((r for r in rows if r.get("part") == "slot_fine"
                   and _sweep.finite(r.get(RATE_WINDOW))), key=lambda r: r["slot_width_m"])
    if fine:
        n = numbers.get("flat_exponent_fine", math.nan)
        ax.loglog([r["slot_width_m"] for r in fine], [r[RATE_WINDOW] for r in fine], "o--",
                  mfc="none", color="C0",
                  label=f"flat bottom at {1000 * options['fine_cell_size']:g} mm cells: "
                        f"n = {n:.3f}")
    ax.set_xlabel("slot width B0 (m)")
    ax.set_ylabel(f"discharge rate W' (kg/s per m), mean from "
                  f"{options['rate_window_start']:g} s")
    ax.set_title("Slot outlets: W' ~ B0^n", fontsize=10)
    ax.legend(fontsize=7)
    return fig


# ---------------------------------------------------------------- outputs
def write_outputs(out, rows, options, map_options, setting, argv=None) -> dict:
    out = Path(out)
    slots = [r for r in rows if r.get("part") == "slot"]
    fine = [r for r in rows if r.get("part") == "slot_fine"]
    everything = [r for r in rows if r.get("part") == "map"]
    cases, _ = flow_mode_map.split_grid_check(everything)
    slot_numbers = analyse_slots(slots, options)
    slot_numbers.update(analyse_refinement(fine, slots, options))
    map_numbers = flow_mode_map.analyse(everything, map_options)
    _sweep.write_rows_csv(out / "slots.csv", slots + fine, first=(
        "case", "slot_width_m", "half_angle_deg", "cell_size_m", RATE_WINDOW, RATE,
        "beverloo_slot_kg_s_m", "ratio_to_beverloo", "mass_balance_error", "discharge_time_s",
        "wall_time_s", "error"))
    _sweep.write_rows_csv(out / "results.csv", everything,
                          first=flow_mode_map.RESULT_COLUMNS + (
                              RATE, "mass_balance_error", "wall_time_s", "error"))
    _sweep.save(plot_slots(slots + fine, options, slot_numbers), out / "slot_exponent.png")
    _sweep.save(flow_mode_map.plot_map(cases, map_options, map_numbers),
                out / "plane_flow_map.png")
    _sweep.save(flow_mode_map.plot_slip(everything, map_options), out / "wall_slip.png")
    figures = [{"file": "slot_exponent.png",
                "caption": "Steady rate per metre against the slot width, flat bottom and "
                           "wedge, with Beverloo's slot form (n = 3/2)."},
               {"file": "plane_flow_map.png",
                "caption": "Simulated flow mode of each wedge on the (phi_w, theta) plane over "
                           "Jenike's plane-flow boundary (the conical one + 10 deg, a rule of "
                           "thumb) with the conical boundary dashed beside it; a red edge "
                           "marks a case that disagrees; the numbers are the wall slip ratio."},
               {"file": "wall_slip.png",
                "caption": "The wedges' wall slip ratio (the rule's threshold dotted) and the "
                           "share of the hopper wall that slides, against the distance from "
                           "Jenike's plane-flow boundary; open squares: the grid check on "
                           "finer cells."}]
    numbers = {**slot_numbers, **{f"map_{k}": v for k, v in map_numbers.items()}}
    findings = []
    for theta, _ in options["slot_bottoms"]:
        key = bottom_key(theta)
        n = slot_numbers.get(f"slot_exponent_{key}", math.nan)
        findings.append(
            f"Slot exponent, {label(theta)}: n = {n:.3f} over {slot_numbers[f'slot_widths_{key}']} "
            f"slot widths (Beverloo's slot form: 1.5); W' / Beverloo slot "
            f"{slot_numbers.get(f'ratio_to_beverloo_{key}_min', math.nan):.3f}-"
            f"{slot_numbers.get(f'ratio_to_beverloo_{key}_max', math.nan):.3f}; mass balance "
            f"error at most {slot_numbers[f'mass_balance_error_{key}_max']:.1e}.")
    if "flat_exponent_fine" in slot_numbers:
        widths = ", ".join(f"{1000 * w:g}" for w in options["fine_widths"])
        trend = ("falls" if slot_numbers["flat_exponent_fine"]
                 < slot_numbers["flat_exponent_coarse"] else "rises")
        findings.append(
            f"The flat bottom's exponent {trend} as the cells shrink: over the {widths} mm "
            f"slots n = "
            f"{slot_numbers['flat_exponent_coarse']:.3f} at "
            f"{1000 * options['cell_size']:g} mm cells, "
            f"{slot_numbers['flat_exponent_fine']:.3f} at "
            f"{1000 * options['fine_cell_size']:g} mm, "
            f"{slot_numbers['flat_exponent_extrapolated']:.3f} extrapolated to "
            f"zero cell size (first order, from two cell sizes): a resolution effect of the "
            f"slot's edges.")
    findings.append(
        f"Plane-flow map: {map_numbers['agreeing']} of {map_numbers['classified']} classified "
        f"wedges agree with Jenike's plane-flow boundary ({map_numbers['agreement_fraction']:.2f}"
        f", in-sample: the slip-ratio threshold 0.2 was placed in the gap these cases leave"
        f"; away from it, |theta - theta_c| > 5 deg: "
        f"{map_numbers['agreement_fraction_clear']:.2f} of {map_numbers['clear_cases']}); "
        f"simulated {map_numbers['mass_cases']} mass, {map_numbers['funnel_cases']} funnel; "
        f"Jenike {map_numbers['jenike_mass_cases']} mass.")
    findings.append(
        f"Plane-flow map, more than 4 deg from the boundary (or phi_w >= phi): "
        f"{map_numbers['agreeing_beyond_4deg']} of {map_numbers['cases_beyond_4deg']} agree; at "
        f"phi_w >= phi every call is funnel: {map_numbers['funnel_at_rough_walls']}.")
    if map_numbers["disagreeing"]:
        findings.append(flow_mode_map.disagreements(cases, map_numbers, noun="wedges"))
    check = flow_mode_map.grid_check_finding(everything, map_numbers, map_options)
    if check:
        findings.append(check)
    failed = [r["case"] for r in rows if r.get("error")]
    if failed:
        findings.append("Failed runs: " + ", ".join(failed) + ".")
    tables = [
        {"title": "Slot outlets (per metre)",
         "columns": ["B0 (mm)", "theta (deg)", "cell (mm)", "W' window (kg/s/m)",
                     "W' steady, summary (kg/s/m)", "Beverloo slot (kg/s/m)", "ratio",
                     "mass balance"],
         "rows": [[1000 * r["slot_width_m"], r["half_angle_deg"],
                   _r(1000 * r.get("cell_size_m", math.nan), 2), _r(r.get(RATE_WINDOW), 2),
                   _r(r.get(RATE), 2),
                   _r(r.get("beverloo_slot_kg_s_m"), 2), _r(r.get("ratio_to_beverloo"), 3),
                   _r(r.get("mass_balance_error"), 15)] for r in slots + fine]},
        flow_mode_map.case_table(everything, map_options, title="Plane-flow map")]
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()
                if k != "pairs" or v}
    settings["map"] = {k: v for k, v in MAP.items()}
    exponents = "; ".join(
        f"{label(theta)} {slot_numbers.get('slot_exponent_' + bottom_key(theta), math.nan):.3f}"
        for theta, _ in options["slot_bottoms"])
    if "flat_exponent_extrapolated" in slot_numbers:
        exponents += (f" (flat: {slot_numbers['flat_exponent_fine']:.3f} at "
                      f"{1000 * options['fine_cell_size']:g} mm cells, "
                      f"{slot_numbers['flat_exponent_extrapolated']:.3f} extrapolated to zero "
                      f"cell size)")
    headline = (f"Slot exponent n (Beverloo 1.5): {exponents}. Plane-flow map: "
                f"{map_numbers['agreeing']} of {map_numbers['classified']} wedges agree with "
                f"Jenike's plane-flow boundary.")
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables, rows, argv, headline=headline)
    return numbers


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    parser.add_argument("--fine-cell-size", type=float,
                        help="m: the map's grid check (default 0.0025; 0: none)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_size", "fine_cell_size"))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    numbers = write_outputs(args.out, rows, study["options"], study["map_options"],
                            study["setting"], argv)
    print(f"slot exponent: flat {numbers.get('slot_exponent_flat', math.nan):.3f}; plane-flow "
          f"map agreement {numbers['map_agreement_fraction']:.2f}; written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
