"""Robustness: does the discharge rate hinge on stiffness, cell size or hourglass control?

The reference hopper (``HopperConfig()``: D = 0.3 m, 20 deg cone, D0 = 0.06 m, 0.3 m fill,
phi = 30 deg, phi_w = 15 deg, E = 5 MPa, 5 mm cells, hourglass coefficient 0.1) and the
funnel-flow case (the same hopper with a 60 deg cone and phi_w = 25 deg) are each emptied
completely (``run.end_time = "empty"``) at

* E = 2, 5 and 20 MPa (5 mm cells),
* cell sizes 7.5, 5 and 3.75 mm (E = 5 MPa; 4, 6 and 8 cells across the outlet radius),
* the hourglass coefficient halved and doubled (5 mm, 5 MPa),

seven runs per hopper.  Every run records the smallest and largest ``alpha`` after every
transport step (the only place ``alpha`` changes), so the bounds hold at all times, and its
mass-balance error ``|M + discharged - M0| / M0`` at the end.

The robustness bands, evaluated per hopper (``bands.csv``, PASS/FAIL with the numbers):

1. **stiffness**: ``(max - min) / W(5 MPa)`` of the steady rates at the three E < 5 %;
2. **cell size**: with ``d1 = |W(5) - W(7.5)| / W(5)`` and ``d2 = |W(3.75) - W(5)| / W(3.75)``
   (each change relative to the finer grid): ``d2 < d1`` and ``d2 < 5 %``;
3. **hourglass**: ``|W(kappa/2) / W(kappa) - 1|`` and ``|W(2 kappa) / W(kappa) - 1|`` < 3 %;
4. **alpha bounds**: ``alpha`` in ``[0, 1 + 1e-3]`` in every run at every transport step (the
   lower bound with a round-off allowance of 1e-12);
5. **mass balance**: error < 1e-9 in every run, and every run emptied completely (stop reason
   ``empty``); when ``end_time`` is a number (``--quick``) this band is reported but not judged.

The steady rate is ``summary.json`` ``steady_discharge_rate_kg_s``: the median of ``W`` while
90 % to 20 % of the mass is left (:func:`fipy_hopper.diagnostics.steady_rate`).

Written to ``--out`` (default ``studies/output/robustness``): ``results.csv``, ``bands.csv``,
``study.json``, ``robustness.png`` (rates against each knob with the bands),
``robustness_discharge.png`` (``W(t)`` of every run) and ``cases/<name>/``.

Cost, measured on this machine (2 cores, 2026-11-22): the 14 runs took 2591 s (43 min) on a
local Dask cluster of 2 workers; a 5 mm emptying of the reference hopper 210-320 s, at 3.75 mm
930 s, at E = 20 MPa 600 s, at 7.5 mm 125 s; the funnel hopper takes about as long.  ``--quick``
runs tiny hoppers on coarse grids for 0.3 s (seconds per case).

Usage::

    python studies/robustness.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

from fipy_hopper.config import HopperConfig  # noqa: E402

_r = _sweep.rounded
NAME = "robustness"
TITLE = "Robustness of the discharge rate to stiffness, cell size and hourglass control"
_REF = HopperConfig()
DEFAULTS = {
    "hoppers": {"mass": (20.0, 15.0), "funnel": (60.0, 25.0)},   # (half-angle, phi_w) deg
    "moduli": (2.0e6, 5.0e6, 20.0e6),          # Pa, at the base cell size and hourglass
    "cell_sizes": (0.0075, 0.005, 0.00375),    # m, at the base E and hourglass
    "hourglass_factors": (0.5, 1.0, 2.0),      # times the base coefficient
    "base_modulus": 5.0e6,
    "base_cell": 0.005,
    "base_hourglass": _REF.numerics.hourglass_coefficient,
    "bin_diameter": _REF.hopper.bin_diameter,
    "outlet_diameter": _REF.hopper.outlet_diameter,
    "fill_height": _REF.hopper.fill_height,
    "bin_height": _REF.hopper.bin_height,
    "end_time": "empty",
    "max_time": 60.0,
    "case_plots": True,
}
QUICK = {"cell_sizes": (0.01, 0.0075, 0.006), "base_cell": 0.01, "bin_diameter": 0.16,
         "fill_height": 0.05, "bin_height": 0.07, "end_time": 0.3, "case_plots": False}
BANDS = {"stiffness": 0.05, "cell_size": 0.05, "hourglass": 0.03, "alpha_max": 1.0 + 1e-3,
         "alpha_min": 0.0, "alpha_roundoff": 1e-12, "mass_balance": 1e-9}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    base_e, base_h, base_k = (float(opts["base_modulus"]), float(opts["base_cell"]),
                              float(opts["base_hourglass"]))
    knobs = {(base_h, float(e), 1.0) for e in opts["moduli"]}
    knobs |= {(float(h), base_e, 1.0) for h in opts["cell_sizes"]}
    knobs |= {(base_h, base_e, float(f)) for f in opts["hourglass_factors"]}
    cases = []
    for hopper, (theta, wall) in opts["hoppers"].items():
        for h, e, f in sorted(knobs, key=lambda k: (-k[0], k[1], k[2])):
            kappa = base_k * f
            config = {"hopper": {"bin_diameter": opts["bin_diameter"],
                                 "outlet_diameter": opts["outlet_diameter"],
                                 "half_angle_deg": float(theta),
                                 "fill_height": opts["fill_height"],
                                 "bin_height": opts["bin_height"]},
                      "material": {"youngs_modulus": e},
                      "wall": {"friction_angle_deg": float(wall)},
                      "numerics": {"cell_size": h, "hourglass_coefficient": kappa},
                      "run": {"end_time": opts["end_time"], "max_time": opts["max_time"],
                              "output_interval": 0.05}}
            name = (f"{hopper}_cell{_sweep.fmt(round(1000 * h, 4))}mm"
                    f"_E{_sweep.fmt(round(e / 1e6, 4))}MPa_hg{_sweep.fmt(round(kappa, 6))}")
            cases.append(_sweep.make_case(
                name, {"hopper": hopper, "half_angle_deg": float(theta),
                       "wall_friction_deg": float(wall), "cell_size_mm": 1000 * h,
                       "youngs_modulus_MPa": e / 1e6, "hourglass_coefficient_set": kappa,
                       "hourglass_factor": f},
                config, plots=opts["case_plots"], track_alpha=True))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- the bands
def _rate(r):
    w = r.get("steady_discharge_rate_kg_s", math.nan)
    return w if _sweep.finite(w) and not r.get("error") else math.nan


def evaluate_bands(rows: list, options: dict) -> list:
    """The robustness bands for each hopper: a list of ``{"hopper", "band", "requirement",
    "value", "passed", "detail"}`` (``passed`` is None when the band cannot be judged)."""
    base_e = float(options["base_modulus"]) / 1e6
    base_h = 1000 * float(options["base_cell"])
    out = []
    for hopper in dict.fromkeys(r["hopper"] for r in rows):
        mine = [r for r in rows if r["hopper"] == hopper]
        at = lambda h=base_h, e=base_e, f=1.0: next(  # noqa: E731
            (r for r in mine if math.isclose(r["cell_size_mm"], h)
             and math.isclose(r["youngs_modulus_MPa"], e)
             and math.isclose(r["hourglass_factor"], f)), None)

        # 1. stiffness
        sel = [at(e=e / 1e6) for e in options["moduli"]]
        ref = at()
        rates = [_rate(r) if r else math.nan for r in sel]
        if ref is not None and all(math.isfinite(w) for w in rates) and len(rates) >= 2:
            spread = (max(rates) - min(rates)) / _rate(ref)
            out.append({"hopper": hopper, "band": "stiffness",
                        "requirement": f"(max - min) / W({base_e:g} MPa) < "
                                       f"{100 * BANDS['stiffness']:g} %",
                        "value": spread, "passed": spread < BANDS["stiffness"],
                        "detail": ", ".join(f"E = {e / 1e6:g} MPa: {w:.4g} kg/s"
                                            for e, w in zip(options["moduli"], rates))})
        else:
            out.append(_missing(hopper, "stiffness", "a rate at every E"))

        # 2. cell size
        sizes = sorted((1000 * float(h) for h in options["cell_sizes"]), reverse=True)
        rates = [_rate(at(h=h)) if at(h=h) else math.nan for h in sizes]
        if len(sizes) >= 3 and all(math.isfinite(w) for w in rates):
            changes = [abs(b - a) / b for a, b in zip(rates, rates[1:])]
            d1, d2 = changes[-2], changes[-1]
            out.append({"hopper": hopper, "band": "cell_size",
                        "requirement": f"d2 < d1 and d2 < {100 * BANDS['cell_size']:g} % "
                                       f"(d1: {sizes[-3]:g} -> {sizes[-2]:g} mm, d2: "
                                       f"{sizes[-2]:g} -> {sizes[-1]:g} mm)",
                        "value": d2, "passed": d2 < d1 and d2 < BANDS["cell_size"],
                        "detail": ", ".join(f"{h:g} mm: {w:.4g} kg/s" for h, w in
                                            zip(sizes, rates))
                        + f"; d1 = {100 * d1:.2f} %, d2 = {100 * d2:.2f} %"})
        else:
            out.append(_missing(hopper, "cell_size", "a rate at three cell sizes"))

        # 3. hourglass
        factors = [float(f) for f in options["hourglass_factors"] if float(f) != 1.0]
        rates = {f: _rate(at(f=f)) if at(f=f) else math.nan for f in factors}
        w0 = _rate(ref) if ref else math.nan
        if factors and math.isfinite(w0) and all(math.isfinite(w) for w in rates.values()):
            worst = max(abs(w / w0 - 1.0) for w in rates.values())
            out.append({"hopper": hopper, "band": "hourglass",
                        "requirement": f"|W(f kappa) / W(kappa) - 1| < "
                                       f"{100 * BANDS['hourglass']:g} % for f in "
                                       + ", ".join(f"{f:g}" for f in factors),
                        "value": worst, "passed": worst < BANDS["hourglass"],
                        "detail": f"kappa = {float(options['base_hourglass']):g}: {w0:.4g} kg/s; "
                        + ", ".join(f"x{f:g}: {w:.4g} kg/s ({100 * (w / w0 - 1):+.2f} %)"
                                    for f, w in rates.items())})
        else:
            out.append(_missing(hopper, "hourglass", "rates at every hourglass factor"))

        # 4. alpha bounds
        lows = [r.get("alpha_min", math.nan) for r in mine]
        highs = [r.get("alpha_max", math.nan) for r in mine]
        if mine and all(_sweep.finite(x) for x in lows + highs):
            low, high = min(lows), max(highs)
            out.append({"hopper": hopper, "band": "alpha_bounds",
                        "requirement": "0 <= alpha <= 1 + 1e-3 at every transport step of every "
                                       "run (round-off allowance 1e-12 below 0)",
                        "value": high,
                        "passed": low >= BANDS["alpha_min"] - BANDS["alpha_roundoff"]
                        and high <= BANDS["alpha_max"],
                        "detail": f"min alpha {low:.3g}, max alpha - 1 = {high - 1:.3g} over "
                                  f"{len(mine)} runs"})
        else:
            out.append(_missing(hopper, "alpha_bounds", "alpha bounds of every run"))

        # 5. mass balance through a complete emptying
        errors = [r.get("mass_balance_error", math.nan) for r in mine]
        reasons = [str(r.get("stop_reason", "")) for r in mine]
        if mine and all(_sweep.finite(x) for x in errors):
            worst = max(errors)
            emptied = all(s == "empty" for s in reasons)
            judged = options["end_time"] == "empty"
            detail = (f"largest error {worst:.3g}; stop reasons: "
                      + ", ".join(f"{s} x{reasons.count(s)}" for s in dict.fromkeys(reasons)))
            if not judged:
                detail += " (end_time is not 'empty': no complete emptying asked; not judged)"
            out.append({"hopper": hopper, "band": "mass_balance",
                        "requirement": "mass-balance error < 1e-9 in every run, each emptied "
                                       "completely (stop reason 'empty')",
                        "value": worst,
                        "passed": (worst < BANDS["mass_balance"] and emptied) if judged else None,
                        "detail": detail})
        else:
            out.append(_missing(hopper, "mass_balance", "the mass balance of every run"))
    return out


def _missing(hopper, band, what):
    return {"hopper": hopper, "band": band, "requirement": "", "value": math.nan,
            "passed": None, "detail": f"not evaluated: needs {what} (a run failed or is missing)"}


def status(passed) -> str:
    return {True: "PASS", False: "FAIL", None: "n/a"}[passed]


# ---------------------------------------------------------------- figures
def plot_bands(rows, bands, options):
    hoppers = list(dict.fromkeys(r["hopper"] for r in rows))
    fig = _sweep.figure(12.0, 3.4 * len(hoppers) + 0.4)
    axes = fig.subplots(len(hoppers), 3, squeeze=False)
    base_e = float(options["base_modulus"]) / 1e6
    base_h = 1000 * float(options["base_cell"])
    for row_axes, hopper in zip(axes, hoppers):
        mine = [r for r in rows if r["hopper"] == hopper]
        judged = {b["band"]: b for b in bands if b["hopper"] == hopper}
        ref = next((r for r in mine if math.isclose(r["cell_size_mm"], base_h) and
                    math.isclose(r["youngs_modulus_MPa"], base_e) and
                    r["hourglass_factor"] == 1.0), None)
        w0 = _rate(ref) if ref else math.nan
        series = (
            ("stiffness", "youngs_modulus_MPa", "Young's modulus E (MPa)",
             lambda r: math.isclose(r["cell_size_mm"], base_h) and r["hourglass_factor"] == 1.0,
             BANDS["stiffness"], True),
            ("cell_size", "cell_size_mm", "cell size h (mm)",
             lambda r: math.isclose(r["youngs_modulus_MPa"], base_e)
             and r["hourglass_factor"] == 1.0, BANDS["cell_size"], False),
            ("hourglass", "hourglass_coefficient_set", "hourglass coefficient kappa_hg",
             lambda r: math.isclose(r["cell_size_mm"], base_h)
             and math.isclose(r["youngs_modulus_MPa"], base_e), BANDS["hourglass"], True))
        for ax, (band, key, label, pick, tol, logx) in zip(row_axes, series):
            sel = sorted([r for r in mine if pick(r)], key=lambda r: r[key])
            x = [r[key] for r in sel]
            y = [_rate(r) for r in sel]
            if math.isfinite(w0):
                ax.axhspan(w0 * (1 - tol), w0 * (1 + tol), color="C2", alpha=0.15,
                           label=f"+-{100 * tol:g} % of the base rate")
            ax.plot(x, y, "o-", color="C0", label="steady rate")
            if logx:
                ax.set_xscale("log")
                ax.minorticks_off()
            if x:
                ax.set_xticks(x)
                ax.set_xticklabels([f"{v:g}" for v in x])
            b = judged.get(band)
            verdict = status(b["passed"]) if b else "n/a"
            ax.set_title(f"{hopper}: {band.replace('_', ' ')}: {verdict}", fontsize=9,
                         color={"PASS": "C2", "FAIL": "C3"}.get(verdict, "k"))
            ax.set_xlabel(label)
            ax.set_ylabel("W (kg/s)")
            ax.legend(fontsize=7)
    return fig


def plot_discharge(rows):
    from fipy_hopper.io import read_csv

    hoppers = list(dict.fromkeys(r["hopper"] for r in rows))
    fig = _sweep.figure(6.0 * len(hoppers), 4.2)
    axes = fig.subplots(1, len(hoppers), squeeze=False)[0]
    for ax, hopper in zip(axes, hoppers):
        for k, r in enumerate(r for r in rows if r["hopper"] == hopper):
            path = Path(r.get("run_dir", "")) / "timeseries.csv"
            if not path.is_file():
                continue
            ts = read_csv(path)
            ax.plot(ts["t_s"], ts["discharge_rate_kg_s"], lw=0.9, color=f"C{k % 10}",
                    label=f"h {r['cell_size_mm']:g} mm, E {r['youngs_modulus_MPa']:g} MPa, "
                          f"kappa {r['hourglass_coefficient_set']:g}")
        ax.set_xlabel("time since the outlet opened (s)")
        ax.set_ylabel("discharge rate W (kg/s)")
        ax.set_ylim(bottom=0.0)
        ax.set_title(f"{hopper} hopper: W(t) of every run", fontsize=9)
        ax.legend(fontsize=6)
    return fig


# ---------------------------------------------------------------- outputs
def write_outputs(out, rows, bands, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "hopper", "half_angle_deg", "wall_friction_deg", "cell_size_mm",
        "youngs_modulus_MPa", "hourglass_coefficient_set", "hourglass_factor",
        "steady_discharge_rate_kg_s", "steady_rate_spread", "flow_mode", "alpha_min",
        "alpha_max", "mass_balance_error", "stop_reason", "discharge_time_s",
        "remaining_mass_kg", "initial_mass_kg", "wall_time_s", "error"))
    _sweep.write_rows_csv(out / "bands.csv", [{**b, "status": status(b["passed"])}
                                              for b in bands])
    _sweep.save(plot_bands(rows, bands, options), out / "robustness.png")
    _sweep.save(plot_discharge(rows), out / "robustness_discharge.png")
    figures = [{"file": "robustness.png",
                "caption": "Steady rate of each hopper against E, cell size and hourglass "
                           "coefficient, with the robustness band around the base rate."},
               {"file": "robustness_discharge.png",
                "caption": "Discharge rate W(t) of every run."}]
    findings = [f"{b['hopper']} hopper, {b['band'].replace('_', ' ')}: {status(b['passed'])} "
                f"({b['requirement']}) - {b['detail']}." for b in bands]
    modes = {h: sorted({str(r.get("flow_mode")) for r in rows if r["hopper"] == h})
             for h in dict.fromkeys(r["hopper"] for r in rows)}
    findings.append("Flow mode by the package's rule: " + "; ".join(
        f"{h} hopper: {', '.join(m)}" for h, m in modes.items()) + ".")
    failed = [r["case"] for r in rows if r.get("error")]
    if failed:
        findings.append("Failed runs: " + ", ".join(failed) + ".")
    numbers = {f"{b['hopper']}|{b['band']}": {"status": status(b["passed"]), "value": b["value"]}
               for b in bands}
    numbers["bands_passed"] = sum(1 for b in bands if b["passed"] is True)
    numbers["bands_failed"] = sum(1 for b in bands if b["passed"] is False)
    numbers["bands_not_judged"] = sum(1 for b in bands if b["passed"] is None)
    tables = [{"title": "Robustness bands",
               "columns": ["hopper", "band", "status", "value", "requirement", "numbers"],
               "rows": [[b["hopper"], b["band"], status(b["passed"]),
                         (f"{b['value']:.3g}" if _sweep.finite(b["value"]) else ""),
                         b["requirement"], b["detail"]] for b in bands]},
              {"title": "Runs",
               "columns": ["hopper", "h (mm)", "E (MPa)", "kappa_hg", "W (kg/s)", "flow",
                           "alpha min", "alpha max", "mass balance", "stop", "wall time (s)"],
               "rows": [[r["hopper"], r["cell_size_mm"], r["youngs_modulus_MPa"],
                         r["hourglass_coefficient_set"], _r(r.get("steady_discharge_rate_kg_s"), 4),
                         r.get("flow_mode"), _g(r.get("alpha_min")), _g(r.get("alpha_max")),
                         _g(r.get("mass_balance_error")), r.get("stop_reason"),
                         _r(r.get("wall_time_s"), 0)] for r in rows]}]
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    settings["bands"] = BANDS
    headline = (f"{numbers['bands_passed']} band(s) PASS, {numbers['bands_failed']} FAIL, "
                f"{numbers['bands_not_judged']} not judged: " + "; ".join(
                    f"{b['hopper']} {b['band'].replace('_', ' ')} {status(b['passed'])}"
                    for b in bands) + ".")
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables, rows, argv, headline=headline)


def _r(x, n):
    return (round(x, n) if n else int(round(x))) if _sweep.finite(x) else None


def _g(x):
    return f"{x:.3g}" if _sweep.finite(x) else None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--hopper", choices=("mass", "funnel"), action="append",
                        help="run only this hopper (repeatable; default both)")
    args = parser.parse_args(argv)
    options = {}
    if args.hopper:
        hoppers = DEFAULTS["hoppers"]
        options["hoppers"] = {h: hoppers[h] for h in args.hopper}
    options.update(_sweep.study_options(args, ()))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    bands = evaluate_bands(rows, study["options"])
    write_outputs(args.out, rows, bands, study["options"], study["setting"], argv)
    for b in bands:
        print(f"{b['hopper']:>6} {b['band']:<13} {status(b['passed']):<5} {b['detail']}")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
