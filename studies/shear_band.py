"""The law's length: the shear band against a rough wall moving past the material, in grains.

A plane layer of the default material under gravity, its bottom held and its top moved
sideways at ``speed`` (:func:`fipy_hopper.material.element_tests.shear_layer`): the top is a
rough wall sliding past the material under the wall's normal pressure ``top_pressure``, as
the bin wall of a silo in discharge slides past the plug (a plug speed of 0.1-0.5 m/s, a wall
pressure of 1-3 kPa in the reference silo).  The plain Mohr–Coulomb law puts the whole shear in
one cell, whatever the cell; the grain size of the law's rate dependence gives the band a
width of its own.  For ``d`` = 0.5 to 3 mm and two cell sizes a factor 2 apart, the band's
width (the depth below the wall over which the speed falls to 5 % of the wall's) in m and in
grains, beside the 5-20 grain diameters measured along rough silo walls (docs/references.md).

Written to ``--out`` (default ``studies/output/shear_band``): ``results.csv``,
``shear_band.png``, ``study.json``.

Usage::

    python studies/shear_band.py [--out DIR] [--quick]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

from fipy_hopper.config import HopperConfig  # noqa: E402
from fipy_hopper.material import MohrCoulomb  # noqa: E402
from fipy_hopper.material.element_tests import shear_layer  # noqa: E402
from fipy_hopper.material.rate import InertialRheology  # noqa: E402

_r = _sweep.rounded
NAME = "shear_band"
TITLE = "The law's length: the shear band against a rough moving wall, in grains"
DEFAULTS = {"grains": (0.0005, 0.001, 0.002, 0.003), "cells": (0.002, 0.001),
            "depth": 0.06, "speeds": (0.1, 0.5), "top_pressure": 1000.0, "duration": 0.3}
QUICK = {"grains": (0.001, 0.003), "cells": (0.004, 0.002), "speeds": (0.5,),
         "duration": 0.15}


def law(grain_diameter):
    """The default material's law (E, nu, rho, phi, psi, c from :class:`HopperConfig`), with
    the rate dependence of grain size ``grain_diameter`` (None: the plain law)."""
    m = HopperConfig().material
    rate = None if grain_diameter is None else InertialRheology(
        grain_diameter=grain_diameter, grain_density=m.grain_density,
        friction_rise=m.friction_rise, inertial_number_i0=m.inertial_number_i0)
    return MohrCoulomb(E=m.youngs_modulus, nu=m.poisson_ratio, rho=m.density,
                       phi=m.friction_angle_deg, psi=m.dilation_angle_deg, c=m.cohesion,
                       rate=rate)


def measure(options) -> list:
    rows = []
    for speed in options["speeds"]:
        for d in (None, *options["grains"]):
            for h in options["cells"]:
                cells = int(round(options["depth"] / h))
                started = time.perf_counter()
                res = shear_layer(law(d), options["depth"], cells, speed,
                                  options["top_pressure"], duration=options["duration"])
                w = res.band_width()
                rows.append({"law": "plain" if d is None else "mu_I", "grain_mm":
                             0.0 if d is None else 1000.0 * d, "speed_m_s": speed,
                             "cell_mm": 1000.0 * h, "band_mm": 1000.0 * w,
                             "band_grains": w / d if d else math.nan,
                             "band_cells": w / h, "wall_shear_Pa": float(res.tau[-1]),
                             "wall_time_s": time.perf_counter() - started,
                             "profile": (res.y.tolist(), (res.u / speed).tolist())})
    return rows


def analyse(rows, options):
    numbers = {}
    for speed in options["speeds"]:
        for d in options["grains"]:
            sel = sorted([r for r in rows if r["law"] == "mu_I" and r["speed_m_s"] == speed
                          and r["grain_mm"] == 1000.0 * d], key=lambda r: -r["cell_mm"])
            widths = [r["band_mm"] for r in sel]
            key = f"v{speed:g}_d{1000 * d:g}mm"
            numbers[f"band_mm_{key}"] = [_r(w, 3) for w in widths]
            numbers[f"band_grains_{key}"] = [_r(r["band_grains"], 2) for r in sel]
            numbers[f"band_change_pct_{key}"] = _r(100 * abs(widths[-1] - widths[0])
                                                   / widths[0], 2)
        plain = sorted([r for r in rows if r["law"] == "plain" and r["speed_m_s"] == speed],
                       key=lambda r: -r["cell_mm"])
        numbers[f"plain_band_cells_v{speed:g}"] = [_r(r["band_cells"], 2) for r in plain]
    return numbers


def plot(rows, options):
    fig = _sweep.figure(11.0, 4.4)
    ax_u, ax_w = fig.subplots(1, 2)
    speed = options["speeds"][-1]
    fine = min(options["cells"])
    for k, r in enumerate(r for r in rows if r["speed_m_s"] == speed and r["cell_mm"] ==
                          1000.0 * fine):
        y, u = (np.asarray(v) for v in r["profile"])
        label = "plain law" if r["law"] == "plain" else f"d = {r['grain_mm']:g} mm"
        ax_u.plot(u, (y[-1] - y) * 1000.0, color="k" if r["law"] == "plain" else f"C{k}",
                  label=label)
    ax_u.invert_yaxis()
    ax_u.set_xlabel("speed / the wall's")
    ax_u.set_ylabel("depth below the moving wall (mm)")
    ax_u.set_ylim(40, 0)
    ax_u.legend(fontsize=7)
    ax_u.set_title(f"Speed profiles, {1000 * fine:g} mm cells, wall at {speed:g} m/s",
                   fontsize=9)
    for c, h in enumerate(options["cells"]):
        for m, v in enumerate(options["speeds"]):
            sel = [r for r in rows if r["law"] == "mu_I" and r["cell_mm"] == 1000.0 * h
                   and r["speed_m_s"] == v]
            ax_w.plot([r["grain_mm"] for r in sel], [r["band_grains"] for r in sel],
                      "os"[c] + "-:"[m], color=f"C{m}",
                      label=f"{1000 * h:g} mm cells, {v:g} m/s")
    ax_w.axhspan(5, 20, color="0.9", label="5-20 grains (rough silo walls)")
    ax_w.set_xlabel("grain diameter d (mm)")
    ax_w.set_ylabel("band width (grains)")
    ax_w.legend(fontsize=7)
    ax_w.set_title("The band's width in grains", fontsize=9)
    return fig


def write_outputs(out, rows, numbers, options, setting, argv=None):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    flat = [{k: v for k, v in r.items() if k != "profile"} for r in rows]
    _sweep.write_rows_csv(out / "results.csv", flat)
    _sweep.save(plot(rows, options), out / "shear_band.png")
    figures = [{"file": "shear_band.png",
                "caption": "Left: the speed below a rough wall sliding past the material, for "
                           "the plain law and the grain sizes; right: the band's width in "
                           "grains at both cell sizes and wall speeds."}]
    findings = []
    for speed in options["speeds"]:
        for d in options["grains"]:
            key = f"v{speed:g}_d{1000 * d:g}mm"
            findings.append(
                f"Wall at {speed:g} m/s, d = {1000 * d:g} mm: the band is "
                f"{', '.join(f'{w:g}' for w in numbers['band_mm_' + key])} mm wide at "
                f"{', '.join(f'{1000 * h:g}' for h in options['cells'])} mm cells = "
                f"{', '.join(f'{g:g}' for g in numbers['band_grains_' + key])} grains "
                f"(change {numbers['band_change_pct_' + key]:g} %).")
        findings.append(f"Wall at {speed:g} m/s, the plain law: the band is "
                        f"{', '.join(f'{c:g}' for c in numbers[f'plain_band_cells_v{speed:g}'])}"
                        f" cells wide at the same cells (the cell, not the material, sets it).")
    table = {"title": "Layers", "columns": ["law", "d (mm)", "wall speed (m/s)", "cell (mm)",
                                           "band (mm)", "band (grains)", "band (cells)"],
             "rows": [[r["law"], r["grain_mm"], r["speed_m_s"], r["cell_mm"],
                       _r(r["band_mm"], 3), _r(r["band_grains"], 2), _r(r["band_cells"], 2)]
                      for r in rows]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            [table], [], argv)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HERE / "output" / NAME)
    parser.add_argument("--quick", action="store_true", help="test-sized layers")
    args = parser.parse_args(argv)
    options = _sweep.resolve_options(DEFAULTS, {}, QUICK if args.quick else None)
    rows = measure(options)
    numbers = analyse(rows, options)
    write_outputs(args.out, rows, numbers, options,
                  _sweep.setting_label(args.quick, {}), argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
