"""Funnel flow under refinement: the flow channel's edge and the rate, phase by phase.

The funnel-flow hopper of ``robustness.py`` (the reference hopper with a 60 deg cone and
phi_w = 25 deg, E = 5 MPa) and the reference hopper itself (20 deg, phi_w = 15 deg, mass flow)
are discharged for ``end_time`` (3 s) at the cell sizes ``cell_sizes`` (7.5 to 1.875 mm),
each with the package's default law (``default``: the mu(I) rate dependence with the grain
size d = 1 mm) and, for the funnel, with the plain rate-independent law of the published method
(``rate_independent``: ``material.rate_dependence = "none"``, no length).  Measured from each
run directory:

* the rate ``W(t)`` (``timeseries.csv``) and the mass discharged in ``end_time``;
* the mean rate over ``early`` (0.5-1.5 s) and ``late`` (2.5 s to the end) from the
  discharged mass, and the summary's steady rate (the median over the plateau);
* from the field snapshots (every ``field_interval``), the flow channel: at every cell row,
  the radius at which the speed of the material (``alpha > 1/2``) falls below half and a tenth
  of the speed in the axis cell (linear between cell centres), and the edge's angle from the
  vertical (least squares of the tenth's radius against the height over the rows from the
  outlet to ``edge_top``, 0.25 m, at the snapshot nearest ``edge_time``, 1 s);
* ``core_open_s``: the first snapshot at which the axis cell holds ``alpha <= 1/2`` in every
  row from ``core_rows_from`` (0.1 m) to the material's top: the channel has emptied from the
  top down to there (NaN when it has not).

Written to ``--out`` (default ``studies/output/funnel_channel``): ``results.csv``,
``channel.csv`` (the edges per snapshot), ``funnel_channel.png`` and ``study.json``.

Usage::

    python studies/funnel_channel.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                                     [--cell-sizes 0.0075 0.005 0.00375]
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
NAME = "funnel_channel"
TITLE = "Funnel flow under refinement: the flow channel's edge and the rate"
_REF = HopperConfig()
DEFAULTS = {
    "hoppers": {"funnel": (60.0, 25.0), "reference": (20.0, 15.0)},   # (theta, phi_w) deg
    "variants": {"default": {}, "rate_independent": {"rate_dependence": "none"}},
    "funnel_only_variants": ("rate_independent",),
    "cell_sizes": (0.0075, 0.005, 0.00375, 0.0025, 0.001875),
    "end_time": 3.0, "field_interval": 0.25,
    "early": (0.5, 1.5), "late_from": 2.5,
    "edge_time": 1.0, "edge_top": 0.25, "core_rows_from": 0.1,
    "bin_diameter": _REF.hopper.bin_diameter, "outlet_diameter": _REF.hopper.outlet_diameter,
    "fill_height": _REF.hopper.fill_height, "bin_height": _REF.hopper.bin_height,
    "case_plots": False,
}
QUICK = {"hoppers": {"funnel": (60.0, 25.0)}, "variants": {"default": {}},
         "cell_sizes": (0.01, 0.0075), "end_time": 0.6, "field_interval": 0.2,
         "early": (0.2, 0.4), "late_from": 0.4, "edge_time": 0.4, "bin_diameter": 0.16,
         "fill_height": 0.1, "bin_height": 0.12, "edge_top": 0.1, "core_rows_from": 0.05}


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    cases = []
    for (hopper, (theta, wall)), (variant, material), h in (
            (a, b, c) for a in opts["hoppers"].items() for b in opts["variants"].items()
            for c in opts["cell_sizes"]):
        if hopper != "funnel" and variant in opts["funnel_only_variants"]:
            continue
        config = {"hopper": {"bin_diameter": opts["bin_diameter"],
                             "outlet_diameter": opts["outlet_diameter"],
                             "half_angle_deg": float(theta),
                             "fill_height": opts["fill_height"],
                             "bin_height": opts["bin_height"]},
                  "material": {"youngs_modulus": 5.0e6, **material},
                  "wall": {"friction_angle_deg": float(wall)},
                  "numerics": {"cell_size": float(h)},
                  "run": {"end_time": opts["end_time"], "output_interval": 0.05,
                          "field_interval": opts["field_interval"]}}
        cases.append(_sweep.make_case(
            f"{hopper}_{variant}_cell{_sweep.fmt(round(1000 * h, 4))}mm",
            {"hopper": hopper, "variant": variant, "cell_size_mm": 1000 * float(h)}, config,
            plots=opts["case_plots"]))
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- analysis
def edge_radius(r_cells, speed, alpha, fraction):
    """Per row of ``speed`` (nz, nr): the radius (m) at which the speed of the cells with
    ``alpha > 1/2`` first falls below ``fraction`` of the axis cell's (linear between cell
    centres); NaN where the axis cell holds no moving material."""
    moving = np.where(alpha > 0.5, speed, 0.0)
    axis = moving[:, 0]
    out = np.full(len(axis), math.nan)
    for j in np.flatnonzero(axis > 1e-6):
        below = np.flatnonzero(moving[j] < fraction * axis[j])
        if below.size == 0:
            continue
        k = below[0]
        s0, s1 = moving[j, k - 1], moving[j, k]
        out[j] = r_cells[k - 1] + (fraction * axis[j] - s0) / (s1 - s0) * (
            r_cells[k] - r_cells[k - 1])
    return out


def channel_of(run_dir, options):
    """``(rows of channel.csv, edge angle (deg), core_open_s)`` from a run's snapshots."""
    from fipy_hopper import plotting

    rows, angle, core_open, widths = [], math.nan, math.nan, []
    entries = [e for e in plotting.snapshots(run_dir) if e["stage"] == "discharge"]
    best = min(entries, key=lambda e: abs(e["discharge_time_s"] - options["edge_time"]),
               default=None)
    for e in entries:
        snap = plotting.load_snapshot(run_dir, e)
        r = 0.5 * (snap["r_nodes"][1:] + snap["r_nodes"][:-1])
        z = 0.5 * (snap["z_nodes"][1:] + snap["z_nodes"][:-1])
        half = edge_radius(r, snap["speed"], snap["alpha"], 0.5)
        tenth = edge_radius(r, snap["speed"], snap["alpha"], 0.1)
        t = e["discharge_time_s"]
        rows += [{"t_s": t, "z_m": float(z[j]), "r_half_m": float(half[j]),
                  "r_tenth_m": float(tenth[j])} for j in np.flatnonzero(z > 0)]
        filled = np.flatnonzero((snap["alpha"] > 0.5).any(axis=1) & (z > 0))
        band = (z >= options["core_rows_from"]) & (z > 0)
        if filled.size:
            band &= z <= z[filled[-1]]
        if math.isnan(core_open) and band.any() and np.all(snap["alpha"][band, 0] <= 0.5):
            core_open = float(t)
        if options["early"][0] <= t <= options["late_from"]:
            sel = (z > 0) & (z <= options["edge_top"]) & np.isfinite(tenth) & np.isfinite(half)
            widths += list(tenth[sel] - half[sel])
        if e is best:
            sel = (z > 0) & (z <= options["edge_top"]) & np.isfinite(tenth)
            if sel.sum() >= 3:
                slope = np.polyfit(z[sel], tenth[sel], 1)[0]
                angle = math.degrees(math.atan(slope))
    width = float(np.median(widths)) if widths else math.nan
    return rows, angle, core_open, width


def mean_rate(t, discharged, start, end):
    """The mean rate (kg/s) over ``[start, end]`` from the discharged mass."""
    t, m = np.asarray(t, float), np.asarray(discharged, float)
    end = min(end, float(t[-1]))
    if not end > start:
        return math.nan
    return float((np.interp(end, t, m) - np.interp(start, t, m)) / (end - start))


def _grain_diameter(run_dir) -> float:
    """The grain diameter (m) of a run's configuration."""
    from fipy_hopper.config import HopperConfig
    return HopperConfig.from_toml(Path(run_dir) / "config.toml").material.grain_diameter


def groups(rows):
    """``{(hopper, variant): rows from the coarsest to the finest cells}``."""
    out = {}
    for r in rows:
        out.setdefault((r.get("hopper", "funnel"), r.get("variant", "default")), []).append(r)
    return {k: sorted(v, key=lambda r: -r["cell_size_mm"]) for k, v in out.items()}


RATES = ("steady_discharge_rate_kg_s", "discharged_in_run_kg", "early_rate_kg_s",
         "late_rate_kg_s")


def analyse(rows, options):
    """Adds the rates, the edge angle and ``core_open_s`` to each row; returns, per hopper
    and variant (``"<hopper>_<variant>"``), every rate by cell size and its changes under
    refinement (each relative to the finer grid), the edge angles and the core times."""
    from fipy_hopper.io import read_csv

    channel = []
    for r in rows:
        if r.get("error") or not r.get("run_dir"):
            continue
        ts = read_csv(Path(r["run_dir"]) / "timeseries.csv")
        t, out = ts["t_s"], ts["discharged_kg"]
        r["discharged_in_run_kg"] = float(out[-1])
        r["early_rate_kg_s"] = mean_rate(t, out, *options["early"])
        r["late_rate_kg_s"] = mean_rate(t, out, options["late_from"], options["end_time"])
        edges, r["edge_angle_deg"], r["core_open_s"], r["edge_width_m"] = channel_of(
            r["run_dir"], options)
        grain = _grain_diameter(r["run_dir"])
        r["edge_width_grains"] = r["edge_width_m"] / grain if grain > 0 else math.nan
        channel += [{"case": r["case"], "cell_size_mm": r["cell_size_mm"], **e} for e in edges]
    numbers = {}
    for (hopper, variant), members in groups(rows).items():
        done = [r for r in members if "early_rate_kg_s" in r]
        entry = {"cell_sizes_mm": [r["cell_size_mm"] for r in done]}
        for key in RATES:
            entry[key] = [_r(r.get(key), 4) for r in done]
            entry[f"{key}_changes"] = [
                _r(abs(b[key] - a[key]) / abs(b[key]), 4) if _sweep.finite(a.get(key))
                and _sweep.finite(b.get(key)) else None for a, b in zip(done, done[1:])]
        entry["edge_angle_deg"] = [_r(r["edge_angle_deg"], 1) for r in done]
        entry["edge_width_mm"] = [_r(1000 * r["edge_width_m"], 1) for r in done]
        entry["edge_width_grains"] = [_r(r["edge_width_grains"], 1) for r in done]
        entry["core_open_s"] = [_r(r["core_open_s"], 2) for r in done]
        numbers[f"{hopper}_{variant}"] = entry
    return numbers, channel


def plot(rows, channel, options):
    from fipy_hopper.io import read_csv

    funnel = {k: v for k, v in groups(rows).items() if k[0] == "funnel"}
    fig = _sweep.figure(11.0, 4.2 * max(1, len(funnel)))
    axes = fig.subplots(max(1, len(funnel)), 2, squeeze=False)
    for (ax_w, ax_e), ((hopper, variant), members) in zip(axes, funnel.items()):
        for k, r in enumerate(r for r in members if r.get("run_dir") and not r.get("error")):
            ts = read_csv(Path(r["run_dir"]) / "timeseries.csv")
            ax_w.step(ts["t_s"], ts["discharge_rate_kg_s"], where="pre", color=f"C{k}",
                      label=f"{r['cell_size_mm']:g} mm")
            mine = [c for c in channel if c["case"] == r["case"]]
            times = sorted({c["t_s"] for c in mine})
            if times:
                t1 = min(times, key=lambda t: abs(t - options["edge_time"]))
                sel = [c for c in mine if c["t_s"] == t1]
                z = [c["z_m"] for c in sel]
                ax_e.plot([c["r_half_m"] for c in sel], z, "--", color=f"C{k}")
                ax_e.plot([c["r_tenth_m"] for c in sel], z, "-", color=f"C{k}",
                          label=f"{r['cell_size_mm']:g} mm, t = {t1:.2f} s")
        ax_w.set_title(f"{hopper} hopper, {variant}", fontsize=9)
        ax_e.set_title(f"{hopper} hopper, {variant}: the flow channel's edge", fontsize=9)
        ax_w.set_xlabel("time since the outlet opened (s)")
        ax_w.set_ylabel("discharge rate W (kg/s)")
        ax_w.legend(fontsize=7)
        ax_e.set_xlabel("radius where the speed falls to 1/10 (solid), 1/2 (dashed) of the "
                        "axis's (m)")
        ax_e.set_ylabel("z (m)")
        ax_e.legend(fontsize=7)
    return fig


def write_outputs(out, rows, numbers, channel, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "hopper", "variant", "cell_size_mm", "steady_discharge_rate_kg_s",
        "discharged_in_run_kg", "early_rate_kg_s", "late_rate_kg_s", "edge_angle_deg",
        "edge_width_m", "edge_width_grains", "core_open_s", "error"))
    _sweep.write_rows_csv(out / "channel.csv", channel)
    _sweep.save(plot(rows, channel, options), out / "funnel_channel.png")
    figures = [{"file": "funnel_channel.png",
                "caption": "The funnel hopper with the default law (mu(I), d = 1 mm) and the "
                           "rate-independent one: "
                           "W(t) at each cell size (left) and the flow channel's edge, where "
                           "the speed falls to a tenth (solid) and half (dashed) of the axis's, "
                           f"at the snapshot nearest {options['edge_time']:g} s (right)."}]
    findings = []
    for name, entry in numbers.items():
        def listed(key, scale=1.0, spec=".3f", entry=entry):
            return ", ".join("n/a" if v is None else format(scale * v, spec)
                             for v in entry[key])

        sizes = ", ".join(f"{h:g}" for h in entry["cell_sizes_mm"])
        text = (f"{name.replace('_', ', ')} ({sizes} mm): steady rate (summary, median over the "
                f"plateau) {listed('steady_discharge_rate_kg_s')} kg/s, changes "
                f"{listed('steady_discharge_rate_kg_s_changes', 100, '.1f')} %; out in "
                f"{options['end_time']:g} s {listed('discharged_in_run_kg')} kg, changes "
                f"{listed('discharged_in_run_kg_changes', 100, '.1f')} %; mean rate "
                f"{options['early'][0]:g}-{options['early'][1]:g} s "
                f"{listed('early_rate_kg_s')} kg/s (changes "
                f"{listed('early_rate_kg_s_changes', 100, '.1f')} %), from "
                f"{options['late_from']:g} s {listed('late_rate_kg_s')} kg/s (changes "
                f"{listed('late_rate_kg_s_changes', 100, '.1f')} %)")
        if name.startswith("funnel"):
            text += (f"; the channel's edge (from half to a tenth of the axis speed, median "
                     f"over the rows to {options['edge_top']:g} m and the snapshots "
                     f"{options['early'][0]:g}-{options['late_from']:g} s) is "
                     f"{listed('edge_width_mm', 1, '.1f')} mm wide = "
                     f"{listed('edge_width_grains', 1, '.1f')} grains of its d")
            text += (f"; the channel's edge (a tenth of the axis speed) leans "
                     f"{listed('edge_angle_deg', 1, '.1f')} deg from the vertical at "
                     f"{options['edge_time']:g} s, and the axis column has emptied from the "
                     f"top down to {options['core_rows_from']:g} m at "
                     f"{listed('core_open_s', 1, '.2f')} s (n/a: not in the run)")
        findings.append(text + ".")
    table = {"title": "Runs", "columns": ["hopper", "variant", "cell (mm)", "steady W (kg/s)",
                                         "out (kg)", "early W (kg/s)", "late W (kg/s)",
                                         "edge angle (deg)", "edge width (mm)",
                                         "core open (s)"],
             "rows": [[r.get("hopper"), r.get("variant"), r["cell_size_mm"],
                       _r(r.get("steady_discharge_rate_kg_s"), 4),
                       _r(r.get("discharged_in_run_kg"), 3), _r(r.get("early_rate_kg_s"), 4),
                       _r(r.get("late_rate_kg_s"), 4), _r(r.get("edge_angle_deg"), 1),
                       _r(1000 * r["edge_width_m"], 1) if _sweep.finite(r.get("edge_width_m"))
                       else None, _r(r.get("core_open_s"), 2)] for r in rows]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    sizes = " to ".join(f"{1000 * h:g}" for h in sorted(options["cell_sizes"], reverse=True))
    headline = f"Steady-rate changes from {sizes} mm: " + "; ".join(
        f"{name.replace('_', ', ')} " + ", ".join(
            "n/a" if v is None else f"{100 * v:.1f} %"
            for v in entry["steady_discharge_rate_kg_s_changes"])
        for name, entry in numbers.items()) + "."
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
    numbers, channel = analyse(rows, study["options"])
    write_outputs(args.out, rows, numbers, channel, study["options"], study["setting"], argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
