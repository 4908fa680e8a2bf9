"""The rate against the grain size: Beverloo's empty annulus, fitted.

Beverloo's correlation ``W = C rho_b sqrt(g) (D0 - k d)^(5/2)`` (a slot: ``(W0 - k d)^(3/2)``
per metre) says an outlet a few tens of grains wide passes less than the continuum's
``D0^(5/2)``: as if an annulus ``k d / 2`` wide at the outlet's edge were empty (``k`` about
1.3-1.6 for spheres).  The law of fipy_hopper carries the grain size ``d`` in its rate
dependence above the Mohr–Coulomb limit (``material.rate_dependence = "mu_I"``: the friction
of flowing material rises with ``I = gamma_dot d / sqrt(p / rho_s)``, most near the outlet,
where the shear rate is high and the pressure low).  This study measures the ``k`` that emerges
from it at the lip.

The reference cone (20 deg, mass flow, phi = 30 deg, phi_w = 15 deg) with a shorter bin,
short discharges at ``cell_size`` (default 5 mm; 0.8 s):

* ``d`` from 0.5 to 3 mm at each of the outlets ``D0`` = 40, 60, 80 mm (``D0/d`` = 13-160),
  and the plain law (``rate_dependence = "none"``, no grain size) at the same outlets;
* fits over the ``mu_I`` cases: ``W = A (D0 - k d)^n`` by least squares in log space (``k``,
  ``n`` and ``A`` free; the grid's own offset is in ``n``), and ``k`` with ``n`` held at the
  plain law's exponent over the same outlets (the grid's offset then cancels); the rate
  deficit per case against the plain law at its outlet as ``k = (D0 / d)(1 - (W /
  W_plain)^(1/n))``.

Written to ``--out`` (default ``studies/output/grain_size``): ``results.csv``, ``fits.csv``,
``rate_vs_grain.png``, ``study.json``.

Usage::

    python studies/grain_size.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                 [--cell-size 0.005]
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
NAME = "grain_size"
TITLE = "The rate against the grain size: Beverloo's empty annulus, fitted"
DEFAULTS = {
    "outlets": (0.04, 0.06, 0.08),               # D0 (m)
    "grains": (0.0005, 0.001, 0.002, 0.003),     # d (m)
    "half_angle": 20.0, "bin_diameter": 0.3, "bin_height": 0.2, "fill_height": 0.18,
    "cell_size": 0.005, "end_time": 0.8,
    "case_plots": False,
}
QUICK = {"outlets": (0.06, 0.08), "grains": (0.001, 0.004),
         "bin_diameter": 0.2, "bin_height": 0.1, "fill_height": 0.08, "cell_size": 0.01,
         "end_time": 0.4}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    base = {"hopper": {"bin_diameter": opts["bin_diameter"], "bin_height": opts["bin_height"],
                       "fill_height": opts["fill_height"],
                       "half_angle_deg": opts["half_angle"]},
            "numerics": {"cell_size": opts["cell_size"]},
            "run": {"end_time": opts["end_time"], "output_interval": 0.02,
                    "field_interval": max(opts["end_time"], 0.25)}}
    cases = []

    def add(name, params, material):
        d0 = params["outlet_diameter_m"]
        cases.append(_sweep.make_case(name, params, _sweep.merge(
            base, hopper={"outlet_diameter": d0}, material=material),
            plots=opts["case_plots"]))

    for d0 in opts["outlets"]:
        add(_sweep.case_name(("D0mm", round(1000 * d0, 3)), ("plain", "")),
            {"outlet_diameter_m": float(d0), "grain_mm": 0.0, "law": "plain"},
            {"rate_dependence": "none", "grain_diameter": 0.0})
        for d in opts["grains"]:
            add(_sweep.case_name(("D0mm", round(1000 * d0, 3)), ("dmm", round(1000 * d, 3))),
                {"outlet_diameter_m": float(d0), "grain_mm": 1000.0 * d, "law": "mu_I"},
                {"grain_diameter": float(d)})
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- analysis
def fit_offset(d0, d, w, n=None):
    """Least squares of ``ln W = ln A + n ln(D0 - k d)`` over the cases: ``(A, k, n)``; with
    ``n`` given, only ``A`` and ``k``.  A scan of ``k`` in [-5, 10] refined by a parabola (the
    residual is smooth and one-dimensional once ``k`` is fixed: ``A`` and ``n`` are linear)."""
    d0, d, w = (np.asarray(x, float) for x in (d0, d, w))
    lw = np.log(w)

    def solve(k):
        x = np.log(d0 - k * d)
        if n is None:
            X = np.stack([np.ones_like(x), x], axis=1)
            coef, res, *_ = np.linalg.lstsq(X, lw, rcond=None)
            a, slope = coef
        else:
            slope = n
            a = float(np.mean(lw - n * x))
        return float(np.sum((lw - a - slope * x) ** 2)), float(math.exp(a)), float(slope)

    ks = np.linspace(-5.0, min(10.0, 0.95 * float(np.min(d0 / d))), 1501)
    errs = np.array([solve(k)[0] for k in ks])
    i = int(np.clip(np.argmin(errs), 1, len(ks) - 2))
    y0, y1, y2 = errs[i - 1], errs[i], errs[i + 1]
    step = ks[1] - ks[0]
    den = y0 - 2 * y1 + y2
    k = float(ks[i] + (0.5 * step * (y0 - y2) / den if den > 0 else 0.0))
    _, a, slope = solve(k)
    return a, k, slope


def analyse(rows, options):
    """Adds each case's deficit against the plain law at its outlet; returns ``(fits,
    numbers)``."""
    ok = [r for r in rows if not r.get("error") and _sweep.finite(
        r.get("steady_discharge_rate_kg_s"))]
    plain = {r["outlet_diameter_m"]: r["steady_discharge_rate_kg_s"] for r in ok
             if r["law"] == "plain"}
    d0s = sorted(plain)
    n_plain = fit_power_law(np.array(d0s), np.array([plain[x] for x in d0s]))[1] \
        if len(d0s) >= 2 else 2.5
    for r in rows:
        w, base = r.get("steady_discharge_rate_kg_s"), plain.get(r["outlet_diameter_m"])
        d = r["grain_mm"] / 1000.0
        r["ratio_to_plain"] = w / base if _sweep.finite(w) and base else math.nan
        r["k_from_deficit"] = ((r["outlet_diameter_m"] / d)
                               * (1.0 - r["ratio_to_plain"] ** (1.0 / n_plain))
                               if d > 0 and math.isfinite(r["ratio_to_plain"]) else math.nan)
        r["beverloo_k1.5_kg_s"] = float(theory.beverloo_rate(
            1500.0, r["outlet_diameter_m"], d=d)) if d > 0 else float(
            theory.beverloo_rate(1500.0, r["outlet_diameter_m"]))
    mu = [r for r in ok if r["law"] == "mu_I"]
    fits, numbers = [], {"plain_exponent_n": n_plain}
    if len(mu) >= 3:
        args = ([r["outlet_diameter_m"] for r in mu], [r["grain_mm"] / 1000.0 for r in mu],
                [r["steady_discharge_rate_kg_s"] for r in mu])
        a, k, n = fit_offset(*args)
        fits.append({"fit": "k and n free", "k": k, "n": n, "A": a, "cases": len(mu)})
        a2, k2, _ = fit_offset(*args, n=n_plain)
        fits.append({"fit": f"n held at the plain law's {n_plain:.3f}", "k": k2, "n": n_plain,
                     "A": a2, "cases": len(mu)})
        numbers.update(k_free=k, n_free=n, k_at_plain_n=k2)
    for d0 in d0s:
        ks = [r["k_from_deficit"] for r in mu if r["outlet_diameter_m"] == d0
              and math.isfinite(r["k_from_deficit"])]
        if ks:
            numbers[f"k_deficit_D0_{1000 * d0:g}mm"] = [_r(x, 3) for x in ks]
    numbers["failed"] = [r["case"] for r in rows if r.get("error")]
    return fits, numbers


def plot(rows, fits, options):
    fig = _sweep.figure(11.0, 4.4)
    ax_w, ax_k = fig.subplots(1, 2)
    mu = [r for r in rows if r.get("law") == "mu_I" and _sweep.finite(
        r.get("steady_discharge_rate_kg_s"))]
    free = fits[0] if fits else None
    for c, d0 in enumerate(options["outlets"]):
        sel = sorted([r for r in mu if r["outlet_diameter_m"] == float(d0)],
                     key=lambda r: r["grain_mm"])
        x = [float(d0) / (r["grain_mm"] / 1000.0) for r in sel]
        ax_w.plot(x, [r["ratio_to_plain"] for r in sel], "o", color=f"C{c}",
                  label=f"D0 = {1000 * d0:g} mm")
        xx = np.geomspace(10.0, 200.0, 80)
        ax_w.plot(xx, (1.0 - 1.5 / xx) ** 2.5, ":", color="0.4",
                  label="Beverloo (1 - 1.5 d/D0)^2.5" if c == 0 else None)
        if free and c == 0:
            ax_w.plot(xx, (1.0 - free["k"] / xx) ** free["n"], "-", color="k", lw=0.8,
                      label="the fit's (1 - k d/D0)^n")
        ax_k.plot([r["grain_mm"] for r in sel], [r["k_from_deficit"] for r in sel], "o-",
                  color=f"C{c}", label=f"D0 = {1000 * d0:g} mm")
    ax_w.set_xscale("log")
    ax_w.set_xlabel("outlet in grains D0 / d")
    ax_w.set_ylabel("rate / the plain law's at the same outlet")
    ax_w.legend(fontsize=7)
    ax_w.set_title("The rate's deficit against D0/d" + (
        f" (fit: k = {free['k']:.2f}, n = {free['n']:.2f})" if free else ""), fontsize=9)
    ax_k.axhspan(1.3, 1.6, color="0.9", label="Beverloo's k for spheres")
    ax_k.set_xlabel("grain diameter d (mm)")
    ax_k.set_ylabel("k from the deficit")
    ax_k.legend(fontsize=7)
    ax_k.set_title("Beverloo's k per case", fontsize=9)
    return fig


def write_outputs(out, rows, fits, numbers, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "law", "outlet_diameter_m", "grain_mm", "steady_discharge_rate_kg_s",
        "ratio_to_plain", "k_from_deficit", "beverloo_k1.5_kg_s", "flow_mode", "error"))
    _sweep.write_rows_csv(out / "fits.csv", fits)
    _sweep.save(plot(rows, fits, options), out / "rate_vs_grain.png")
    figures = [{"file": "rate_vs_grain.png",
                "caption": "Left: the steady rate over the plain law's at the same outlet, "
                           "against the outlet in grains, with Beverloo's (1 - 1.5 d/D0)^2.5 "
                           "(dotted) and the fit (solid); right: k from each case's deficit."}]
    findings = []
    for f in fits:
        findings.append(f"W = A (D0 - k d)^n over {f['cases']} cases ({f['fit']}): "
                        f"k = {f['k']:.2f}, n = {f['n']:.3f} (Beverloo: k 1.3-1.6 for "
                        f"spheres, n = 2.5).")
    findings.append(f"The plain law's outlet exponent over the same outlets: "
                    f"{numbers['plain_exponent_n']:.3f}.")
    for key, value in numbers.items():
        if key.startswith("k_deficit_D0_"):
            findings.append(f"k from the deficit against the plain law, D0 = "
                            f"{key[len('k_deficit_D0_'):]}, d = "
                            f"{', '.join(f'{g * 1000:g}' for g in options['grains'])} mm: "
                            f"{', '.join('n/a' if v is None else f'{v:.2f}' for v in value)}.")
    if numbers["failed"]:
        findings.append("Failed runs: " + ", ".join(numbers["failed"]) + ".")
    table = {"title": "Cases", "columns": ["law", "D0 (mm)", "d (mm)", "D0/d", "W (kg/s)",
                                          "W / W_plain", "k"],
             "rows": [[r["law"], 1000 * r["outlet_diameter_m"], r["grain_mm"],
                       _r(1000 * r["outlet_diameter_m"] / r["grain_mm"], 1)
                       if r["grain_mm"] else None,
                       _r(r.get("steady_discharge_rate_kg_s"), 4), _r(r["ratio_to_plain"], 4),
                       _r(r["k_from_deficit"], 3)] for r in rows]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    headline = "; ".join(f"{f['fit']}: k = {f['k']:.2f}, n = {f['n']:.2f}" for f in fits)
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            [table], rows, argv, headline=headline)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_size",))
    study = setup(quick=args.quick, **options)
    rows = _sweep.run_study(NAME, study, args)
    fits, numbers = analyse(rows, study["options"])
    write_outputs(args.out, rows, fits, numbers, study["options"], study["setting"], argv)
    for f in fits:
        print(f"{f['fit']}: k = {f['k']:.3f}, n = {f['n']:.3f}")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
