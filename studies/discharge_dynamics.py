"""Discharge dynamics: how the stress in the bin fluctuates during discharge, against stiffness.

The filled wall loads do not depend on Young's modulus E; the discharge loads do (the
``wall_pressure`` study).  This study measures why.  The reference hopper is discharged at
E = 2, 5 and 20 MPa (7.5 mm cells by default) and, during the discharge, the state
is read (never changed) after every transport (the model's ``after_transport`` hook, about
every millisecond): the mean vertical stress -sigma_zz of the bin's upper plug (the cells
between 40 % and 80 % of the bin's fill depth above the transition, r < 0.8 R), the plastic
strain accumulated there, and the discharged mass.  Reported per E and per discharge window:
the mean and the standard deviation of that stress (the fluctuation), the dominant frequency,
the plug's plastic strain at the end, the steady rate and the early-discharge wall pressure
(90 % left) of the wall bins beside the plug.

Written to ``--out`` (default ``studies/output/discharge_dynamics``): ``results.csv`` (one row
per E), ``series.csv`` (the sampled stress), ``study.json`` and ``discharge_dynamics.png``.

Usage::

    python studies/discharge_dynamics.py [--out DIR] [--quick] [--moduli 2e6 5e6 2e7]
                                         [--cell-size 0.0075]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

from fipy_hopper.config import HopperConfig  # noqa: E402
from fipy_hopper.model import HopperModel  # noqa: E402
from fipy_hopper.simulation import Simulation  # noqa: E402

NAME = "discharge_dynamics"
TITLE = "Stress fluctuations in the bin during discharge, against stiffness"
DEFAULTS = {"moduli": (2.0e6, 5.0e6, 20.0e6), "cell_size": 0.0075, "end_time": 2.0,
            "windows": ((0.0, 0.2), (0.2, 0.6), (0.6, 1.2),
                                                   (1.2, 2.0))}
QUICK = {"cell_size": 0.01, "end_time": 0.4,
         "windows": ((0.0, 0.2), (0.2, 0.4))}


def plug_cells(model: HopperModel):
    """Mask of the bin's upper plug: 40-80 % of the bin's fill depth, r < 0.8 R."""
    g, hop = model.grid, model.cfg.hopper
    z_lo = hop.cone_height + 0.4 * (hop.fill_level - hop.cone_height)
    z_hi = hop.cone_height + 0.8 * (hop.fill_level - hop.cone_height)
    return (((g.z_cells >= z_lo) & (g.z_cells <= z_hi))[:, None]
            & (g.r_cells < 0.8 * hop.bin_radius)[None, :])


def run_one(opts: dict, modulus: float) -> dict:
    """Discharge the reference hopper at ``modulus``; the sampled series and the numbers."""
    cfg = HopperConfig.from_dict({
        "material": {"youngs_modulus": float(modulus)},
        "numerics": {"cell_size": opts["cell_size"]},
        "run": {"end_time": opts["end_time"], "markers_per_side": 0,
                "output_interval": min(0.05, opts["end_time"] / 4)}})
    model = HopperModel(cfg, threads=1)
    sim = Simulation(model, progress=False)
    plug = plug_cells(model)
    samples = []

    def sample(state):
        if state.stage == "discharge":
            samples.append((state.t, -float(np.mean(state.sigma[..., 1][plug])),
                            float(np.mean(state.eps_p[plug])), state.discharged))

    model.after_transport.append(sample)
    start = time.perf_counter()
    sim.run()
    series = np.array(samples)
    series[:, 0] -= series[0, 0]
    t, stress = series[:, 0], series[:, 1]
    windows = []
    for lo, hi in opts["windows"]:
        inside = (t >= lo) & (t < hi)
        if inside.sum() > 2:
            windows.append((lo, hi, float(stress[inside].mean()), float(stress[inside].std())))
    late = t >= opts["windows"][1][0]
    # the transports are not evenly spaced: the spectrum is taken on an even resampling
    spacing = float(np.median(np.diff(t[late]))) if late.sum() > 2 else 1.0
    even = np.arange(t[late][0], t[late][-1], spacing) if late.sum() > 2 else np.array([])
    wiggle = np.interp(even, t[late], stress[late])
    if len(wiggle) > 4:                      # the slow fall of the mean is not the oscillation:
        wiggle = wiggle - np.polyval(np.polyfit(even, wiggle, 2), even)   # a quadratic trend
        freq = np.fft.rfftfreq(len(wiggle), spacing)
        above = freq >= 5.0                  # Hz; the column's lowest mode is above 15 Hz
        dominant = float(freq[above][np.argmax(np.abs(np.fft.rfft(wiggle))[above])])
    else:
        dominant = math.nan
    summary = sim.summary()
    hop = cfg.hopper
    upper = {}
    if "early_discharge" in sim.record.wall:
        _, s, r, z, p, _ = sim.record.wall["early_discharge"]
        _, _, _, _, p_fill, _ = sim.record.wall["filling"]
        beside = (z >= hop.cone_height + 0.4 * (hop.fill_level - hop.cone_height)) & \
                 (z <= hop.cone_height + 0.8 * (hop.fill_level - hop.cone_height))
        upper = {"p_early_beside_plug_Pa": float(np.mean(p[beside])),
                 "p_filled_beside_plug_Pa": float(np.mean(p_fill[beside]))}
    return {"youngs_modulus_MPa": modulus / 1e6, "column_period_s": cfg.column_period,
            "steady_rate_kg_s": summary.get("steady_discharge_rate_kg_s"),
            "plug_stress_mean_Pa": float(stress[late].mean()),
            "plug_stress_std_Pa": float(stress[late].std()),
            "fluctuation": float(stress[late].std() / stress[late].mean()),
            "dominant_frequency_Hz": dominant,
            "plug_plastic_strain_end": float(series[-1, 2]), "sample_spacing_s": spacing,
            "windows": windows, **upper, "wall_time_s": time.perf_counter() - start,
            "series": series}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=HERE / "output" / NAME)
    parser.add_argument("--quick", action="store_true", help="test-sized run")
    parser.add_argument("--moduli", type=float, nargs="+", default=None, metavar="PA")
    parser.add_argument("--cell-size", type=float, default=None, metavar="M")
    parser.add_argument("--serial", action="store_true",
                        help="accepted for symmetry with the other studies (always serial)")
    args = parser.parse_args(argv)
    opts = dict(DEFAULTS, **(QUICK if args.quick else {}))
    given = {k: v for k, v in (("moduli", args.moduli), ("cell_size", args.cell_size))
             if v is not None}
    opts.update(given)
    args.out.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore")
    rows = []
    for modulus in opts["moduli"]:
        row = run_one(opts, modulus)
        rows.append(row)
        print(f"E = {row['youngs_modulus_MPa']:g} MPa: plug stress {row['plug_stress_mean_Pa']:.0f}"
              f" +- {row['plug_stress_std_Pa']:.0f} Pa, plastic strain "
              f"{row['plug_plastic_strain_end']:.4f}, rate {row['steady_rate_kg_s']:.3f} kg/s"
              f" ({row['wall_time_s']:.0f} s)", flush=True)
    columns = ("youngs_modulus_MPa", "column_period_s", "steady_rate_kg_s",
               "plug_stress_mean_Pa", "plug_stress_std_Pa", "fluctuation",
               "dominant_frequency_Hz", "plug_plastic_strain_end", "p_early_beside_plug_Pa",
               "p_filled_beside_plug_Pa", "wall_time_s")
    _sweep.write_rows_csv(args.out / "results.csv", [{c: r.get(c) for c in columns}
                                                      for r in rows])
    series_rows = [{"youngs_modulus_MPa": r["youngs_modulus_MPa"], "t_discharge_s": s[0],
                    "plug_stress_Pa": s[1], "plug_plastic_strain": s[2], "discharged_kg": s[3]}
                   for r in rows for s in r["series"]]
    _sweep.write_rows_csv(args.out / "series.csv", series_rows)

    fig = _sweep.figure(12, 3.8)
    ax_zoom, ax_std, ax_e = fig.subplots(1, 3, width_ratios=(1.3, 1.3, 1))
    zoom = (opts["windows"][1][0], opts["windows"][1][0] + 0.1)
    for k, r in reversed(list(enumerate(rows))):
        t, stress = r["series"][:, 0], r["series"][:, 1]
        inside = (t >= zoom[0]) & (t <= zoom[1])
        ax_zoom.plot(t[inside], stress[inside], lw=0.9, color=f"C{k}",
                     label=f"E = {r['youngs_modulus_MPa']:g} MPa")
        width = 0.1                                   # s, the running window
        starts = np.arange(t[0], t[-1] - width, width / 2)
        running = [stress[(t >= s0) & (t < s0 + width)] for s0 in starts]
        ax_std.plot(starts + width / 2, [x.std() / x.mean() for x in running], color=f"C{k}",
                    label=f"E = {r['youngs_modulus_MPa']:g} MPa")
    ax_zoom.set_xlabel("time since the outlet opened (s)")
    ax_zoom.set_ylabel("mean $-\\sigma_{zz}$ of the bin's upper plug (Pa)")
    ax_zoom.set_title("the plug's stress, 0.1 s", fontsize=9)
    ax_zoom.legend(fontsize=8)
    ax_std.set_xlabel("time since the outlet opened (s)")
    ax_std.set_ylabel("std / mean over 0.1 s")
    ax_std.set_ylim(bottom=0)
    ax_std.set_title("its fluctuation", fontsize=9)
    E = [r["youngs_modulus_MPa"] for r in rows]
    ax_e.plot(E, [r["fluctuation"] for r in rows], "o-", color="C0",
              label=f"plug std / mean after {opts['windows'][1][0]:g} s")
    if all("p_early_beside_plug_Pa" in r for r in rows):
        ax_e.plot(E, [r["p_early_beside_plug_Pa"] / r["p_filled_beside_plug_Pa"] for r in rows],
                  "^:", color="C2", label="wall p beside the plug, 90 % left / filled")
    ax_e.set_ylim(bottom=0)
    ax_e.set_xscale("log")
    ax_e.set_xticks(E, [f"{e:g}" for e in E])
    ax_e.minorticks_off()
    ax_e.set_xlabel("E (MPa)")
    twin = ax_e.twinx()
    twin.plot(E, [r["plug_plastic_strain_end"] for r in rows], "s--", color="C3",
              label="plug plastic strain at the end")
    twin.set_ylabel("plastic strain", color="C3")
    twin.set_ylim(bottom=0)
    handles = ax_e.get_legend_handles_labels()
    more = twin.get_legend_handles_labels()
    ax_e.legend(handles[0] + more[0], handles[1] + more[1], fontsize=7, loc="lower right")
    _sweep.save(fig, args.out / f"{NAME}.png")

    findings = [
        "Bin plug stress in discharge, mean +- std per window (s): " + "; ".join(
            f"E = {r['youngs_modulus_MPa']:g} MPa: " + ", ".join(
                f"[{lo:g}, {hi:g}] {mean:.0f} +- {std:.0f} Pa" for lo, hi, mean, std in
                r["windows"]) for r in rows) + ".",
        "Plastic strain accumulated in the plug (mass flow: it should slide as an elastic "
        "plug): " + ", ".join(f"{r['plug_plastic_strain_end']:.4f}" for r in rows)
        + " at E = " + ", ".join(f"{e:g}" for e in E) + " MPa.",
        "Dominant frequency of the plug's stress (after a quadratic trend): " + ", ".join(
            f"{r['dominant_frequency_Hz']:.0f}" for r in rows) + " Hz, against the filled "
        "column's lowest elastic mode 1/T1 = " + ", ".join(
            f"{1.0 / r['column_period_s']:.0f}" for r in rows) + " Hz.",
        "Steady rate: " + ", ".join(f"{r['steady_rate_kg_s']:.3f}" for r in rows)
        + " kg/s at E = " + ", ".join(f"{e:g}" for e in E) + " MPa.",
    ]
    if all("p_early_beside_plug_Pa" in r for r in rows):
        findings.append("Wall pressure beside the plug, 90 % left / filled: " + ", ".join(
            f"{r['p_early_beside_plug_Pa']:.0f} / {r['p_filled_beside_plug_Pa']:.0f} Pa"
            for r in rows) + " at E = " + ", ".join(f"{e:g}" for e in E) + " MPa.")
    headline = ("The bin's plug swings by " + " / ".join(
        f"{100 * r['fluctuation']:.0f}" for r in rows) + " % (std / mean after "
        f"{opts['windows'][1][0]:g} s) at E = " + " / ".join(f"{e:g}" for e in E)
        + " MPa, and its plastic strain reaches " + " / ".join(
            f"{r['plug_plastic_strain_end']:.2f}" for r in rows)
        + "; its mean stress (" + " / ".join(f"{r['plug_stress_mean_Pa']:.0f}" for r in rows)
        + " Pa) and the rate do not depend on E.")
    table = {"title": "The bin plug's vertical stress in discharge",
             "columns": ["E (MPa)", "window (s)", "mean -sigma_zz (Pa)", "std (Pa)",
                         "std / mean"],
             "rows": [[r["youngs_modulus_MPa"], f"{lo:g}-{hi:g}", round(mean), round(std),
                       round(std / mean, 3)] for r in rows for lo, hi, mean, std in
                      r["windows"]]}
    numbers = {f"E{r['youngs_modulus_MPa']:g}MPa": {c: r.get(c) for c in columns}
               for r in rows}
    _sweep.write_study_json(
        args.out, NAME, TITLE, "quick" if args.quick else ("custom" if given else "default"),
        {k: v for k, v in opts.items()}, numbers, findings,
        [{"file": f"{NAME}.png", "caption": "Left: the mean vertical stress of the bin's upper "
          "plug over 0.1 s of discharge, per E. Middle: its standard deviation over its mean "
          "in running 0.1 s windows. Right: that fluctuation after the opening, the wall "
          "pressure beside the plug relative to the filled value, and the plug's plastic "
          "strain at the end, against E."}],
        tables=[table], headline=headline, rows=[{"wall_time_s": r["wall_time_s"]} for r in rows], argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
