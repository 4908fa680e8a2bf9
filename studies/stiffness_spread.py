"""Stiffness spread: how the discharge depends on E, without and with the grid or bulk viscosity.

Two hoppers, each discharged at several Young's moduli E and dampings: pairs of the grid
viscosity b and the bulk viscosity b_1 (``numerics.grid_viscosity`` and ``bulk_viscosity``, 0
and 0.06 by default: ``docs/physics_and_numerics.md`` §4); each run sets both:

* the funnel-flow hopper (the reference with a 60 deg cone and phi_w = 25 deg) for its first
  ``funnel_time`` s of discharge: the mass discharged, whose spread over E measures how much
  the stiffness decides the flow pattern;
* the reference hopper (mass flow) for ``reference_time`` s, the wall-pressure study's
  discharge: the steady rate and the wall loads from the wall's reaction, filled, at 90 % of
  the mass left and their envelope over the discharge, compared between the moduli by the
  relative L2 difference bin by bin (the runs' own bins, the same at every E:
  ``wall_pressure.stage_profile``).

Written to ``--out`` (default ``studies/output/stiffness_spread``): ``results.csv`` (one row per
run), ``spread.csv`` (the spreads per hopper, damping and stage), ``study.json`` and
``stiffness_spread.png``.

Default cost (2 cores, 2026-12-02): 15 runs, about 1 500 core-seconds (13 minutes).

Usage::

    python studies/stiffness_spread.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                       [--moduli 2e6 5e6 2e7] [--dampings 0,0 0.25,0 0,0.06]
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
import wall_pressure  # noqa: E402

from fipy_hopper import geometry  # noqa: E402
from fipy_hopper.diagnostics import relative_l2  # noqa: E402

NAME = "stiffness_spread"
TITLE = "How the discharge depends on the stiffness, without and with the grid or bulk viscosity"
DEFAULTS = {
    "moduli": (2.0e6, 5.0e6, 20.0e6),          # Pa, the funnel hopper
    "reference_moduli": (2.0e6, 20.0e6),       # Pa, the reference hopper (the extremes)
    "dampings": ((0.0, 0.0), (0.25, 0.0), (0.0, 0.06)),   # (b, b_1)
    "cell_size": 0.005,                        # m
    "funnel_time": 3.0,                        # s of discharge
    "reference_time": 8.78,                    # s: the wall-pressure study's discharge
    "hopper": {},                              # changes to both hoppers (the quick setting)
    "case_plots": False,
}
QUICK = {"moduli": (2.0e6, 20.0e6), "reference_moduli": (2.0e6, 20.0e6),
         "dampings": ((0.0, 0.0), (0.5, 0.0), (0.0, 0.1)), "cell_size": 0.01, "funnel_time": 0.4,
         "reference_time": 0.4,
         "hopper": {"bin_diameter": 0.2, "fill_height": 0.1, "bin_height": 0.12}}
HOPPERS = {"funnel": {"hopper": {"half_angle_deg": 60.0}, "wall": {"friction_angle_deg": 25.0}},
           "reference": {}}
STAGES = ("filling", "early_discharge", "discharge_envelope")


def damping_label(damping) -> str:
    """``"b=0.25,b1=0"``: the key of a (grid viscosity, bulk viscosity) pair in the numbers."""
    return f"b={damping[0]:g},b1={damping[1]:g}"


def damping_text(damping) -> str:
    """``"b = 0.25, b1 = 0"``: the pair as the figure and the findings show it."""
    return damping_label(damping).replace("=", " = ").replace(",", ", ")


def of_damping(rows, hopper, damping):
    """The rows of ``hopper`` run with ``damping``."""
    return [r for r in rows if r["hopper"] == hopper and r["grid_viscosity"] == damping[0]
            and r["bulk_viscosity"] == damping[1]]


def case_for(opts, hopper, modulus, damping):
    b, b1 = damping
    extra = HOPPERS[hopper]
    end = opts["funnel_time"] if hopper == "funnel" else opts["reference_time"]
    config = {"hopper": {**opts["hopper"], **extra.get("hopper", {})},
              "material": {"youngs_modulus": float(modulus)},
              "wall": dict(extra.get("wall", {})),
              "numerics": {"cell_size": float(opts["cell_size"]), "grid_viscosity": float(b),
                           "bulk_viscosity": float(b1)},
              "run": {"end_time": float(end), "output_interval": 0.05,
                      "markers_per_side": 0}}
    name = _sweep.case_name((hopper, ""), ("E", round(modulus / 1e6, 4)), ("b", float(b)),
                            ("bulk", float(b1)))
    return _sweep.make_case(name, {"hopper": hopper, "youngs_modulus_MPa": modulus / 1e6,
                                   "grid_viscosity": float(b), "bulk_viscosity": float(b1)},
                            config, plots=opts["case_plots"])


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    cases = [case_for(opts, "funnel", E, d) for d in opts["dampings"] for E in opts["moduli"]]
    cases += [case_for(opts, "reference", E, d) for d in opts["dampings"]
              for E in opts["reference_moduli"]]
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


def damping_pair(text: str) -> tuple:
    """``"0.25,0"`` -> ``(0.25, 0.0)``: a ``--dampings`` pair (b, b_1)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r}: expected B,B1 (grid and bulk viscosity)")
    try:
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected two numbers B,B1") from None


# ---------------------------------------------------------------- analysis
def _results(row):
    from fipy_hopper.api import read_results

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_results(row["run_dir"])


def analyse(rows, options) -> tuple:
    """``(spread rows, numbers, envelopes)``: per hopper and damping, the spread of the funnel's
    discharged mass over E ((max - min) / mean, %) and the reference hopper's largest L2
    difference (%) of each stage's wall profile between two moduli; ``envelopes`` maps each
    reference run's case to ``(centres, p_n envelope, transition arc length)`` for the
    figure."""
    spread, numbers, envelopes = [], {}, {}
    for damping in options["dampings"]:
        key = damping_label(damping)
        funnel = of_damping(rows, "funnel", damping)
        masses = [float(r.get("discharged_kg", math.nan)) for r in funnel]
        ok = [m for m in masses if _sweep.finite(m)]
        if len(ok) >= 2:
            value = 100.0 * (max(ok) - min(ok)) / float(np.mean(ok))
            spread.append({"hopper": "funnel", "damping": key,
                           "measure": f"kg discharged in {options['funnel_time']:g} s",
                           "spread_pct": value})
            numbers[f"funnel_mass_spread_pct[{key}]"] = value
            numbers[f"funnel_mass_kg[{key}]"] = {
                f"{r['youngs_modulus_MPa']:g} MPa": m for r, m in zip(funnel, masses)}
        ref = of_damping(rows, "reference", damping)
        loaded = []
        for r in ref:
            try:
                loaded.append((r, _results(r)))
            except FileNotFoundError:
                continue
        numbers[f"reference_rate_kg_s[{key}]"] = {
            f"{r['youngs_modulus_MPa']:g} MPa": r.get("steady_discharge_rate_kg_s", math.nan)
            for r in ref}
        for r, res in loaded:
            envelope = wall_pressure.stage_profile(res, "discharge_envelope")
            if envelope is not None:
                envelopes[r["case"]] = (*envelope, float(
                    geometry.transition_arc_length(res.config.hopper)))
        for stage in STAGES:
            profiles = [wall_pressure.stage_profile(res, stage) for _, res in loaded]
            profiles = [p for p in profiles if p is not None]
            if len(profiles) < 2:
                continue
            worst = 0.0
            for i, (_, pa) in enumerate(profiles):
                for _, pb in profiles[i + 1:]:
                    n = min(len(pa), len(pb))
                    worst = max(worst, relative_l2(pa[:n], pb[:n]))
            spread.append({"hopper": "reference", "damping": key,
                           "measure": f"wall profile L2, {stage.replace('_', ' ')}",
                           "spread_pct": 100.0 * worst})
            numbers[f"reference_wall_l2_pct[{key}|{stage}]"] = 100.0 * worst
    numbers["failed"] = [r["case"] for r in rows if r.get("error")]
    return spread, numbers, envelopes


# ---------------------------------------------------------------- figure
def plot(rows, envelopes, options):
    fig = _sweep.figure(11.0, 4.2)
    a1, a2 = fig.subplots(1, 2)
    for k, damping in enumerate(options["dampings"]):
        label = damping_text(damping)
        funnel = sorted(of_damping(rows, "funnel", damping),
                        key=lambda r: r["youngs_modulus_MPa"])
        if funnel:
            a1.semilogx([r["youngs_modulus_MPa"] for r in funnel],
                        [r.get("discharged_kg", math.nan) for r in funnel], "o-",
                        color=f"C{k}", label=label)
        for j, r in enumerate(sorted((r for r in of_damping(rows, "reference", damping)
                                      if r["case"] in envelopes),
                                     key=lambda r: r["youngs_modulus_MPa"])):
            centres, p_n, _ = envelopes[r["case"]]
            a2.plot(centres, p_n / 1e3, ("-", "--", ":")[j % 3], color=f"C{k}", marker=".",
                    label=f"{label}, E = {r['youngs_modulus_MPa']:g} MPa")
    moduli = sorted({r["youngs_modulus_MPa"] for r in rows if r["hopper"] == "funnel"})
    if moduli:
        a1.minorticks_off()
        a1.set_xticks(moduli)
        a1.set_xticklabels([f"{m:g}" for m in moduli])
    a1.set_xlabel("Young's modulus E (MPa)")
    a1.set_ylabel(f"mass discharged in {options['funnel_time']:g} s (kg)")
    a1.set_title("Funnel-flow hopper (60 deg cone, phi_w = 25 deg)", fontsize=9)
    a1.legend(fontsize=7)
    if envelopes:
        a2.axvline(next(iter(envelopes.values()))[2], color="0.5", lw=0.8, ls=":")
        a2.legend(fontsize=6)
    a2.set_xlabel("arc length from the outlet lip, s (m)")
    a2.set_ylabel("discharge envelope of p_n (kPa)")
    a2.set_title("Reference hopper: envelope of the wall pressure over the discharge",
                 fontsize=9)
    return fig


def write_outputs(out, rows, spread, numbers, envelopes, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "hopper", "youngs_modulus_MPa", "grid_viscosity", "bulk_viscosity",
        "discharged_kg",
        "steady_discharge_rate_kg_s", "flow_mode", "mass_balance_error", "steps", "wall_time_s",
        "error"))
    _sweep.write_rows_csv(out / "spread.csv", spread)
    _sweep.save(plot(rows, envelopes, options), out / "stiffness_spread.png")
    figures = [{"file": "stiffness_spread.png",
                "caption": "Left: the funnel-flow hopper's discharged mass against E, per "
                           "damping (grid viscosity b, bulk viscosity b1). Right: the "
                           "reference hopper's envelope of the wall pressure over the "
                           "discharge, per damping and E."}]
    findings = []
    for damping in options["dampings"]:
        key, label = damping_label(damping), damping_text(damping)
        masses = numbers.get(f"funnel_mass_kg[{key}]")
        if masses:
            findings.append(
                f"Funnel-flow hopper, {label}: " + ", ".join(
                    f"{k} {v:.3f} kg" for k, v in masses.items())
                + f" in {options['funnel_time']:g} s; spread "
                f"{numbers[f'funnel_mass_spread_pct[{key}]']:.1f} %.")
        parts = [f"{stage.replace('_', ' ')} {numbers[name]:.2f} %" for stage in STAGES
                 if (name := f"reference_wall_l2_pct[{key}|{stage}]") in numbers]
        rates = numbers.get(f"reference_rate_kg_s[{key}]", {})
        if parts:
            findings.append(
                f"Reference hopper, {label}: wall-profile L2 between the moduli: "
                + ", ".join(parts) + "; steady rates " + ", ".join(
                    f"{k} {v:.3f} kg/s" for k, v in rates.items()) + ".")
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    tables = [{"title": "Spread over E",
               "columns": ["hopper", "damping", "measure", "spread %"],
               "rows": [[s["hopper"], s["damping"], s["measure"],
                         round(s["spread_pct"], 2)] for s in spread]}]
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables, rows, argv, headline=headline(numbers, options["dampings"]))


def headline(numbers: dict, dampings) -> str:
    """Per damping: the funnel's spread over E and the reference hopper's L2 between the
    moduli at 90 % left and for the envelope."""
    parts = []
    for damping in dampings:
        key = damping_label(damping)
        said = []
        if f"funnel_mass_spread_pct[{key}]" in numbers:
            said.append(f"funnel {numbers[f'funnel_mass_spread_pct[{key}]']:.1f} %")
        for stage, word in (("early_discharge", "90 % left"), ("discharge_envelope", "envelope")):
            if (name := f"reference_wall_l2_pct[{key}|{stage}]") in numbers:
                said.append(f"{word} {numbers[name]:.1f} %")
        if said:
            parts.append(f"{damping_text(damping)}: " + ", ".join(said))
    return "Spread over E: " + "; ".join(parts) + "." if parts else "No runs."


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--moduli", type=float, nargs="+", help="Pa, the funnel hopper")
    parser.add_argument("--dampings", type=damping_pair, nargs="+", metavar="B,B1",
                        help="pairs of grid viscosity b and bulk viscosity b_1")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("moduli", "dampings"))
    if "moduli" in options:
        options["moduli"] = tuple(options["moduli"])
    if "dampings" in options:
        options["dampings"] = tuple(options["dampings"])
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    spread, numbers, envelopes = analyse(rows, study["options"])
    write_outputs(args.out, rows, spread, numbers, envelopes, study["options"],
                  study["setting"], argv)
    for s in spread:
        print(f"{s['hopper']}, {s['damping']}, {s['measure']}: "
              f"{s['spread_pct']:.2f} %")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
