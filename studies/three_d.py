"""Three dimensions: the reference hopper in 3D against its section, and off-centre outlets.

Two parts, each an ordinary run directory per case (``hopper.dimensions = 3``,
:mod:`fipy_hopper.space`), run by ``fipy_hopper.api.run`` through :mod:`_sweep`:

**(a) The reference hopper in 3D against its axisymmetric section.** The reference hopper
(``studies/configs/reference.toml``: a 0.3 m bin on a 20 deg cone to a 0.06 m outlet, 0.3 m of
fill) computed whole in 3D (``reference_3d``: cubes of ``reference_cell_size``, 1 cm, by the
default mirror planes, a quarter) and as its axisymmetric section on square cells of the same
size (``reference_section``), both filled to rest and emptied (``reference_end_time``,
``"empty"``), without markers (passive in the section, none in 3D), field snapshots every
``reference_field_interval`` (1 s; the 3D snapshots hold the whole silo).  Set side by side:

* the fill's mass and the steady discharge rate (the loop's plateau rule);
* the wall pressure (the traction recovered from the wall's reaction) per height bin of the
  section's bins, at rest, at 90 % and 50 % of the mass left and the discharge envelope: the
  3D mean around the circumference (the sectors of a centred silo have equal areas) against
  the section's, the RMS of their relative differences over the bins above the lip's bin
  and the lip's bin apart (where the plate meets the cone: ``docs/three_d.md``); around the
  circumference the largest over the smallest pressure of each bin; both over the bins whose
  section pressure is at least ``loaded_fraction`` (5 %) of the stage's largest (in
  discharge the bins at the fill's sinking surface carry next to nothing);
* the flow pattern: the flow mode, the wall slip ratio (3D: per sector), the mass-flow index
  and the stagnant fraction of the summaries; the downward speed in the plane through the axis
  (the 3D cells next to ``y = 0``, ``x > 0``; the section's cells) at the heights
  ``profile_heights`` (fractions of the transition's height) in the discharge snapshot
  nearest the 50 % stage of each run, each row's speed over its largest: the RMS of the
  difference across the row, and the speed of the cell next to the wall over the axis's.

**(b) Off-centre outlets: a flat-bottomed circular silo and an eccentric cone**
(``families``), the bin ``bin_diameter`` (0.64 m), the outlet ``outlet_diameter`` (0.12 m),
filled level to ``fill_level`` (1.28 m above the outlet plane: H/D = 2), the cone's (centred)
half-angle ``half_angle_deg`` (30 deg: steeper than Jenike's 36.9 deg for phi_w = 15 deg,
so mass flow when centred), the reference's material and wall; the outlet's centre at
``eccentricities`` e/R = 0, 0.25, 0.5 and 0.75 along +x (``hopper.outlet_offset = e``; the
eccentric cone's sections are circles sliding from the outlet's centre to the axis at the
bin wall's foot), cubes of ``cell_size`` (2 cm: 3 cells across the outlet's radius, the least
the configuration accepts), by the default mirror planes (a quarter when centred, else the
half ``y >= 0``), ``wall_sectors`` (12) sectors.  The bin's radius is 16 cells so that every
offset (0.08, 0.16 and 0.24 m) is a whole number of cells (the near wall's cells the same
for every offset), and 1 cell of floor is left beside the outlet at e/R = 0.75.  Each runs
``end_time`` s of discharge: by default the time Beverloo's rate (:func:`fipy_hopper.api.expected_quantities`)
takes to discharge ``drained_fraction`` (0.15) of the fill, rounded up to half a second: past
the 90 % stage and its load window, with the loop's steady rate measured from 90 % left on.
Measured per case:

* the steady rate, against the centred case of its family and Beverloo's;
* the wall pressure around the circumference per height bin (``wall_pressure.csv``; the
  walls that rise, a flat floor left out) at rest, at 90 % and 50 % left and the discharge
  envelope: the largest and the smallest over the sectors, where they are (theta, 0 towards
  the outlet's offset) and their ratio; the largest ratio over the bin wall and over the
  cone, over the bins whose mean pressure is at least ``loaded_fraction`` (5 %) of the
  stage's largest;
* the flow channel per window of the discharge (the run's ``channel_windows.csv``: the loop
  measures it on each load window's mean field, the nodes' downward speed left out where
  their open cells hold less than half material, at every node plane of the bin, by
  :func:`fipy_hopper.space.channel.field_channel`; the edge at 1/10 of each plane's largest
  downward speed): theta_c, r_c, e_c, the contact's angle and the channel's area per
  height; summarised by the median over the middle half of the bin's fill (from a quarter to
  three quarters of the height between the bin wall's foot and the material's surface) of
  every window, pooled, with the range of the windows' own medians.  A run made before the
  loop measured windows (or a ``channel_fraction`` other than 1/10) is measured on its
  discharge snapshots instead (``fields/fields_NNNN.vtu``, instantaneous fields), summarised
  at the last one; ``channel.csv``'s ``source`` says which.  Against EN 1991-4's channel
  (:func:`fipy_hopper.theory.en1991_eccentric_channel`, G = 0.25, 0.4, 0.6, mu = tan phi_w,
  phi_i = phi);
* the flow mode (per sector), the mass balance and the fill's equilibrium residual.

**Cost of the default** (``python studies/three_d.py --estimate`` prints it from the settings,
nothing run): :func:`fipy_hopper.space.estimate.time_estimate` per 3D case, one thread at its
``COST_PER_LOADED_CELL_STEP`` (1.0 us a loaded cell and step: the figure that gives the
3D reference's measured end-to-end time; its compiled steps alone 0.56 us), the fill 1.2
gravity ramps, the reference's discharge Beverloo's time to empty (14.4 s) with its loaded
cells falling steadily, each family's discharge with all its loaded cells: the reference in
3D 1,115 s (17 x 17 x 75 cubes, 8,198 loaded, 264,000 steps; measured end to end 1,107 s);
the flat silo centred (a quarter, 13,568 loaded) 1,015 s and off centre (a half, 27,136
loaded) 2,031 s each, 7.5 s of discharge, 74,800 steps; the eccentric cone centred (10,822
loaded) 569 s and off centre (21,650 loaded) 1,139 s each, 5.0 s of discharge, 52,600 steps:
11,100 s for the eight, 12,200 s (3.4 hours) with the reference, so about 1.7 hours on two
cores kept busy (the longest case, 2,031 s, a sixth of the total: the two workers share it
evenly).  The section
at 1 cm (2D, 1,275 cells) about a minute by the demo's cost per cell and step
(``docs/performance.md``): an order of magnitude.  Memory 0.42 GB a worker at most
(``space.estimate.memory_estimate``).  An estimate from the settings, not a measurement of
this study.

**Quick** (``--quick``, the tests): 2 cm cubes, the small conical silo of
:func:`fipy_hopper.space.config.small_silo` (0.28 m bin, 30 deg cone, 0.12 m outlet, 0.1 m of
fill) as the reference and its section, 0.3 s of discharge; the families in a 0.32 m bin with
the 0.12 m outlet filled to 0.26 m at e/R = 0 and 0.5 (0.08 m: 4 cells), 0.4 s of
discharge; about 30 s on one thread by the estimate.

Written to ``--out`` (default ``studies/output/three_d``): ``results.csv`` (one row per case),
``reference_bins.csv`` (the reference's bins: section, 3D mean, extremes, per stage),
``reference_profiles.csv`` (the plane's speed rows), ``circumference.csv`` (per case, stage
and height bin: the largest and smallest pressure, where, their ratio), ``channel.csv`` (per
case, discharge snapshot and height), ``reference.png``, ``<family>_summary.png``,
``<family>_channels.png``, copies of the runs' own 3D pictures, ``study.json`` and
``cases/<name>/``.

Usage::

    python studies/three_d.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                              [--cell-size 0.02] [--reference-cell-size 0.01]
                              [--end-time SECONDS] [--estimate]
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from types import SimpleNamespace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _sweep  # noqa: E402

_r = _sweep.rounded
NAME = "three_d"
TITLE = "Three dimensions: the reference hopper against its section, and off-centre outlets"
REFERENCE = HERE / "configs" / "reference.toml"
FAMILIES = ("flat", "cone")
FAMILY_TITLES = {"flat": "flat-bottomed circular silo", "cone": "eccentric cone"}
STAGES = ("filling", "early_discharge", "mid_discharge", "discharge_envelope")
STAGE_WORDS = {"filling": "at rest", "early_discharge": "at 90 % left",
               "mid_discharge": "at 50 % left", "discharge_envelope": "the envelope"}
SMALL_SILO = {"bin_diameter": 0.28, "half_angle_deg": 30.0, "outlet_diameter": 0.12,
              "bin_height": 0.16, "fill_height": 0.1}
DEFAULTS = {
    "reference_cell_size": 0.01, "reference_hopper": {}, "reference_end_time": "empty",
    "reference_field_interval": 1.0, "mirror_planes": "auto",
    "cell_size": 0.02, "bin_diameter": 0.64, "outlet_diameter": 0.12, "half_angle_deg": 30.0,
    "fill_level": 1.28, "headroom": 0.05, "eccentricities": (0.0, 0.25, 0.5, 0.75),
    "families": FAMILIES, "drained_fraction": 0.15, "end_time": None, "field_interval": 0.5,
    "wall_sectors": 12, "channel_fraction": 0.1, "loaded_fraction": 0.05,
    "profile_heights": (0.3, 0.5, 0.7, 1.2), "case_plots": True,
}
QUICK = {"reference_cell_size": 0.02, "reference_hopper": SMALL_SILO,
         "reference_end_time": 0.3, "reference_field_interval": 0.1, "cell_size": 0.02,
         "bin_diameter": 0.32, "outlet_diameter": 0.12, "fill_level": 0.26,
         "eccentricities": (0.0, 0.5), "end_time": 0.4, "field_interval": 0.1}


def num(value, spec: str = ".3g") -> str:
    """``value`` formatted by ``spec``, or "n/a" for a missing or non-finite number."""
    return format(value, spec) if _sweep.finite(value) else "n/a"


def _nums(values, spec: str = ".2f") -> str:
    return ", ".join(num(v, spec) for v in values)


def _span(pair, spec: str = ".2f") -> str:
    """``lo-hi`` of a pair, or n/a."""
    return f"{num(pair[0], spec)}-{num(pair[1], spec)}" if pair else "n/a"


# ---------------------------------------------------------------- the cases
def _reference_base() -> dict:
    try:  # Python >= 3.11
        import tomllib
    except ModuleNotFoundError:  # pragma: no cover
        import tomli as tomllib
    with open(REFERENCE, "rb") as fh:
        return tomllib.load(fh)


def reference_configs(opts) -> dict:
    """``{"reference_3d": config, "reference_section": config}``: the reference hopper (with
    ``reference_hopper``'s keys replaced) in 3D and as its axisymmetric section, the same
    cell size, discharge and snapshots, no markers."""
    base = _reference_base()
    hopper = {**base["hopper"], **opts["reference_hopper"]}
    numerics = {**base["numerics"], "cell_size": float(opts["reference_cell_size"])}
    run = {**base["run"], "end_time": opts["reference_end_time"],
           "field_interval": float(opts["reference_field_interval"]), "markers_per_side": 0}
    common = {"material": dict(base["material"]), "wall": dict(base["wall"])}
    return {
        "reference_3d": {**common, "hopper": {**hopper, "dimensions": 3},
                         "numerics": {**numerics, "mirror_planes": opts["mirror_planes"]},
                         "run": {**run, "wall_sectors": int(opts["wall_sectors"])}},
        "reference_section": {**common, "hopper": dict(hopper), "numerics": dict(numerics),
                              "run": dict(run)},
    }


def cone_height(opts) -> float:
    """The (centred) cone's height from the outlet plane to the bin wall's foot (m)."""
    return (0.5 * (opts["bin_diameter"] - opts["outlet_diameter"])
            / math.tan(math.radians(opts["half_angle_deg"])))


def family_hopper(family: str, e_over_r: float, opts) -> dict:
    """The ``[hopper]`` of a family's silo with its outlet at ``e_over_r`` of the bin's
    radius off the axis: a flat floor (a ``profile``) or the conical shorthand, filled level
    to ``fill_level`` above the outlet plane, the walls ``headroom`` higher."""
    R, R0 = 0.5 * opts["bin_diameter"], 0.5 * opts["outlet_diameter"]
    level, top = opts["fill_level"], opts["fill_level"] + opts["headroom"]
    e = round(float(e_over_r) * R, 12)
    if family == "flat":
        hopper = {"shape": "profile", "wall": [[R0, 0.0], [R, 0.0], [R, top]],
                  "fill_level": level}
    elif family == "cone":
        z_b = cone_height(opts)
        if not level > z_b:
            raise ValueError(f"fill_level {level:g} m must lie above the cone's "
                             f"{z_b:.3g} m")
        hopper = {"bin_diameter": opts["bin_diameter"], "outlet_diameter": opts["outlet_diameter"],
                  "half_angle_deg": opts["half_angle_deg"], "fill_height": level - z_b,
                  "bin_height": top - z_b}
    else:
        raise ValueError(f"unknown family {family!r}; known: {FAMILIES}")
    return {**hopper, "dimensions": 3, "outlet_offset": e}


def family_config(family: str, e_over_r: float, opts) -> dict:
    base = _reference_base()
    config = {"hopper": family_hopper(family, e_over_r, opts),
              "material": dict(base["material"]), "wall": dict(base["wall"]),
              "numerics": {"cell_size": float(opts["cell_size"]),
                           "mirror_planes": opts["mirror_planes"]},
              "run": {"output_interval": 0.05, "field_interval": float(opts["field_interval"]),
                      "wall_sectors": int(opts["wall_sectors"])}}
    config["run"]["end_time"] = end_time(config, opts)
    return config


def end_time(config: dict, opts) -> float:
    """The discharge to run (s): ``end_time``, or Beverloo's time for ``drained_fraction``
    of the fill rounded up to half a second."""
    if opts["end_time"] is not None:
        return float(opts["end_time"])
    from fipy_hopper.api import expected_quantities

    expected = expected_quantities(_sweep._config(config))
    return 0.5 * math.ceil(2.0 * opts["drained_fraction"]
                           * expected["expected_discharge_time_s"])


def offset_cells(e_over_r: float, opts) -> float:
    """The outlet's offset in cells (the default's are whole numbers: the near wall's cells
    are then the same for every offset)."""
    return float(e_over_r) * 0.5 * opts["bin_diameter"] / opts["cell_size"]


def case_of(family: str, e_over_r: float) -> str:
    return _sweep.case_name((f"{family}_e", float(e_over_r)))


def setup(quick: bool = False, **options) -> dict:
    """The cases and options (``{"options", "cases", "setting"}``); unknown options raise."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    unknown = set(opts["families"]) - set(FAMILIES)
    if unknown:
        raise ValueError(f"unknown families {sorted(unknown)}; known: {FAMILIES}")
    cases = []
    for name, config in reference_configs(opts).items():
        cases.append(_sweep.make_case(name, {"part": "reference", "family": "reference",
                                             "dimensions": config["hopper"].get("dimensions", 2),
                                             "e_over_R": 0.0}, config,
                                      plots=opts["case_plots"]))
    for family in opts["families"]:
        for e in opts["eccentricities"]:
            config = family_config(family, e, opts)
            cases.append(_sweep.make_case(case_of(family, e), {
                "part": "eccentric", "family": family, "dimensions": 3,
                "e_over_R": float(e), "outlet_offset_m": config["hopper"]["outlet_offset"],
                "outlet_offset_cells": _r(offset_cells(e, opts), 6),
                "end_time_s": config["run"]["end_time"]}, config, plots=opts["case_plots"],
                track_wall_windows=True))     # the windows' extremes, read by eccentric.py
    return {"options": opts, "cases": cases, "setting": _sweep.setting_label(quick, options)}


def estimate(study) -> list:
    """Per 3D case of a study (:func:`setup`): its grid, loaded cells, steps, memory and wall
    time (one thread, s) from :mod:`fipy_hopper.space.estimate`, from the settings alone: the
    fill 1.2 gravity ramps; a discharge to empty the expected discharge time with the loaded
    cells falling steadily, a discharge of ``end_time`` with all of them."""
    from fipy_hopper.api import expected_quantities
    from fipy_hopper.space import estimate as est
    from fipy_hopper.space.config import SpaceConfig

    rows = []
    for case in study["cases"]:
        cfg = _sweep._config(case["config"])
        if cfg.hopper.dimensions != 3:
            rows.append({"case": case["name"], "dimensions": 2, "cells": cfg.n_cells})
            continue
        space = SpaceConfig.from_config(cfg)
        emptied = cfg.run.end_time == "empty"
        t = (expected_quantities(cfg)["expected_discharge_time_s"] if emptied
             else float(cfg.run.end_time))
        time = est.time_estimate(space, t, emptied=emptied)
        memory = est.memory_estimate(space)
        rows.append({"case": case["name"], "dimensions": 3,
                     "grid": "x".join(str(n) for n in est.grid_shape(space)),
                     "cells": memory["cells"], "loaded_cells": time["loaded_cells"],
                     "discharge_s": t, "emptied": emptied,
                     "steps": int(round(time["fill_steps"] + time["discharge_steps"])),
                     "memory_GB": memory["bytes"] / 1e9, "seconds": time["seconds"]})
    return rows


def print_estimate(rows) -> float:
    """Print a line per case of :func:`estimate`'s ``rows``; returns the 3D cases' summed
    time on one thread (s)."""
    for r in rows:
        if r["dimensions"] == 2:
            print(f"{r['case']}: a section, {r['cells']:,} cells")
        else:
            print(f"{r['case']}: {r['grid']} cubes ({r['cells']:,}), {r['loaded_cells']:,} "
                  f"loaded, {r['discharge_s']:.3g} s of discharge"
                  f"{' (to empty)' if r['emptied'] else ''}, {r['steps']:,} steps, "
                  f"{r['memory_GB']:.2f} GB, about {r['seconds']:,.0f} s on one thread")
    return float(sum(r.get("seconds", 0.0) for r in rows))


def cost_text(seconds: float) -> str:
    """``about N s on one thread (h; h on two cores kept busy)`` of an estimate's total."""
    return (f"about {seconds:,.0f} s on one thread ({seconds / 3600:.1f} h; "
            f"{seconds / 7200:.1f} h on two cores kept busy)")


# ---------------------------------------------------------------- reading a run
def _config_of(row):
    import warnings

    from fipy_hopper.config import HopperConfig, ResolutionWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResolutionWarning)
        return HopperConfig.from_toml(Path(row["run_dir"]) / "config.toml")


def _wall(row) -> dict:
    from fipy_hopper.io import read_csv

    return read_csv(Path(row["run_dir"]) / "wall_pressure.csv")


def stage_bins(wall: dict, stage: str) -> dict | None:
    """A 3D run's stage of ``wall_pressure.csv`` per height bin: ``s``, ``z``, ``r``,
    ``segment`` (n_bins,), ``theta`` (n_sectors,) and ``p`` (n_bins, n_sectors) (Pa); bins
    in the file's order; ``None`` when the stage was not recorded."""
    on = np.asarray(wall["stage"]) == stage
    if not on.any():
        return None
    theta = np.asarray(wall["theta_deg"], float)[on]
    sectors = np.unique(theta)
    n = len(sectors)
    get = {k: np.asarray(wall[c], float)[on] for k, c in (
        ("s", "s_m"), ("z", "z_m"), ("r", "r_m"), ("segment", "segment"), ("p", "p_n_Pa"))}
    return {"s": get["s"][::n], "z": get["z"][::n], "r": get["r"][::n],
            "segment": get["segment"][::n], "theta": theta[:n], "p": get["p"].reshape(-1, n)}


def rising(bins: dict) -> np.ndarray:
    """The bins on walls that rise (a flat floor's, at ``z = 0``, left out)."""
    return bins["z"] > 1e-9


def extremes(bins: dict) -> dict:
    """Per height bin the largest and smallest pressure around the circumference, their
    sectors' angles and their ratio (:func:`fipy_hopper.space.wall.circumference_extremes`)."""
    from fipy_hopper.space.wall import circumference_extremes

    p = bins["p"]
    big, small, ratio = circumference_extremes(p)
    finite = np.isfinite(p).any(axis=1)
    where_big = np.full(len(p), np.nan)
    where_small = np.full(len(p), np.nan)
    where_big[finite] = bins["theta"][np.nanargmax(p[finite], axis=1)]
    where_small[finite] = bins["theta"][np.nanargmin(p[finite], axis=1)]
    return {"max": big, "min": small, "ratio": ratio, "theta_max": where_big,
            "theta_min": where_small}


def discharge_snapshots(run_dir) -> list:
    from fipy_hopper import plotting

    return [e for e in plotting.snapshots(run_dir) if e["stage"] == "discharge"]


def snapshot_near(run_dir, t):
    """The discharge snapshot nearest ``t`` s after the opening (the last one if ``t`` is
    NaN), or ``None``."""
    entries = discharge_snapshots(run_dir)
    if not entries:
        return None
    if not math.isfinite(t):
        return entries[-1]
    return min(entries, key=lambda e: abs(e["discharge_time_s"] - t))


def stage_times(wall) -> dict:
    """``{stage: t_s}`` of ``wall_pressure.csv``'s stages (s since the opening)."""
    stages = np.asarray(wall["stage"])
    return {str(s): float(np.asarray(wall["t_s"], float)[stages == s][0])
            for s in np.unique(stages)}


def snapshot_nodes(vtu_path, full: float = 0.5) -> tuple:
    """The node grid of a 3D snapshot (the whole silo): ``(x, y, z, down)``, ``down``
    (nz + 1, ny + 1, nx + 1) the nodes' downward speed ``-v_z`` (m/s), NaN at nodes whose open
    cells hold less than ``full`` material (:func:`fipy_hopper.space.channel.node_material`):
    the arrays :func:`fipy_hopper.space.channel.model_channel` reads of a model's state."""
    from fipy_hopper.io import read_vtu
    from fipy_hopper.space.channel import node_material

    mesh = read_vtu(vtu_path)
    pts = np.asarray(mesh.points, float)
    axes = [np.unique(np.round(pts[:, a], 9)) for a in range(3)]
    idx = [np.searchsorted(axes[a], np.round(pts[:, a], 9)) for a in range(3)]
    shape = tuple(len(axes[a]) for a in (2, 1, 0))
    down = np.full(shape, np.nan)
    down[idx[2], idx[1], idx[0]] = -np.asarray(mesh.point_data["node_velocity"], float)[:, 2]
    hexes = mesh.cells_dict["hexahedron"]
    low = pts[hexes].min(axis=1)
    cell = [np.searchsorted(axes[a], np.round(low[:, a], 9)) for a in range(3)]
    cells = tuple(n - 1 for n in shape)
    alpha, kappa = np.zeros(cells), np.zeros(cells)
    alpha[cell[2], cell[1], cell[0]] = mesh.cell_data_dict["alpha"]["hexahedron"]
    kappa[cell[2], cell[1], cell[0]] = mesh.cell_data_dict["kappa"]["hexahedron"]
    material = node_material(alpha, kappa)
    down = np.where(material >= full, down, np.nan)
    return axes[0], axes[1], axes[2], down


def snapshot_channel(vtu_path, radius: float, bin_foot: float,
                     fraction: float = 0.1):
    """The flow channel (:func:`fipy_hopper.space.channel.channel_profile`) at every node
    plane of the bin (``z >= bin_foot``, above the outlet plane) of a 3D snapshot, the
    section the bin's circle about the axis: :func:`~fipy_hopper.space.channel.model_channel`
    read from the written file."""
    from fipy_hopper.space.channel import channel_profile

    x, y, z, down = snapshot_nodes(vtu_path)
    keep = (z > 0.0) & (z >= bin_foot - 1e-12) & np.isfinite(down).any(axis=(1, 2))
    return channel_profile(x, y, z[keep], down[keep], radius, (0.0, 0.0), fraction)


def channel_band(profile, bin_foot: float) -> np.ndarray:
    """The heights of a channel profile in the middle half of the bin's fill: from a quarter
    to three quarters of the way from the bin wall's foot to the highest plane with
    material."""
    if not len(profile.z):
        return np.zeros(0, bool)
    top = float(np.max(profile.z))
    lo, hi = bin_foot + 0.25 * (top - bin_foot), bin_foot + 0.75 * (top - bin_foot)
    return (profile.z >= lo - 1e-12) & (profile.z <= hi + 1e-12)


def _median(values) -> float:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else math.nan


def _quartiles(values) -> tuple:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return tuple(float(q) for q in np.percentile(v, [25, 75])) if v.size else (math.nan,) * 2


# ---------------------------------------------------------------- (a) the reference
def section_stage(wall: dict, stage: str):
    """The section's ``(s, z, p_n)`` of a stage on its wall (Pa), or ``None``."""
    on = (np.asarray(wall["stage"]) == stage) & (np.asarray(wall["wall"]) == "wall")
    if not on.any():
        return None
    return (np.asarray(wall["s_m"], float)[on], np.asarray(wall["z_m"], float)[on],
            np.asarray(wall["p_n_Pa"], float)[on])


def reference_bins(row3, row2, loaded_fraction: float = 0.05) -> tuple:
    """Per stage and height bin: the section's pressure, the 3D mean around the
    circumference, their difference and the 3D extremes around it; ``(rows, numbers)``.  The
    numbers (the RMS difference above the lip's bin, the largest ratio around) over the bins
    whose section pressure is at least ``loaded_fraction`` of the stage's largest (a bin at
    the fill's surface carries next to nothing, and any difference or ratio there is noise:
    relative differences of 10^5 % at 50 % left)."""
    w3, w2 = _wall(row3), _wall(row2)
    rows, numbers = [], {}
    for stage in STAGES:
        b3, b2 = stage_bins(w3, stage), section_stage(w2, stage)
        if b3 is None or b2 is None:
            continue
        s2, _, p2 = b2
        mean3 = np.nanmean(b3["p"], axis=1)
        same = len(s2) == len(b3["s"]) and np.allclose(s2, b3["s"], atol=1e-9)
        sec = p2 if same else np.interp(b3["s"], s2, p2)
        rel = 100.0 * (mean3 / sec - 1.0)
        ext = extremes(b3)
        loaded = sec >= loaded_fraction * np.nanmax(sec)
        for k in range(len(mean3)):
            rows.append({"stage": stage, "bin": k, "s_m": b3["s"][k], "z_m": b3["z"][k],
                         "section_Pa": sec[k], "three_d_mean_Pa": mean3[k],
                         "diff_pct": rel[k], "three_d_max_Pa": ext["max"][k],
                         "three_d_min_Pa": ext["min"][k], "max_over_min": ext["ratio"][k],
                         "loaded": bool(loaded[k])})
        above = rel[1:][np.isfinite(rel[1:]) & loaded[1:]]
        ratio = np.where(loaded, ext["ratio"], np.nan)
        numbers[stage] = {
            "bins_interpolated": not same, "loaded_bins": int(loaded.sum()),
            "rms_above_lip_pct": _r(float(np.sqrt(np.mean(above ** 2))), 2) if above.size
            else None,
            "lip_pct": _r(float(rel[0]), 2), "diff_pct": [_r(v, 2) for v in rel],
            "max_over_min": [_r(v, 4) for v in ext["ratio"]],
            "max_over_min_largest": _r(float(np.nanmax(ratio)), 4)
            if np.isfinite(ratio).any() else None}
    return rows, numbers


def section_plane(run_dir, entry) -> dict:
    """A section's snapshot as the plane: ``x`` (the cells' r), ``z``, ``down`` (-v_z) and
    ``alpha`` (nz, nr)."""
    from fipy_hopper import plotting
    from fipy_hopper.io import RunDirectory, read_vtu

    snap = plotting.load_snapshot(run_dir, entry)
    mesh = read_vtu(Path(run_dir) / RunDirectory.FIELDS / entry["file"])
    shape = snap["alpha"].shape
    vz = np.asarray(mesh.cell_data["velocity"][0], float)[:, 1].reshape(shape)
    r, z = snap["r_nodes"], snap["z_nodes"]
    return {"x": 0.5 * (r[1:] + r[:-1]), "z": 0.5 * (z[1:] + z[:-1]), "down": -vz,
            "alpha": snap["alpha"]}


def space_plane(run_dir, entry) -> dict:
    """A 3D snapshot's cells next to the plane through the axis and the outlet
    (:func:`fipy_hopper.space.pictures.plane_cells`): ``x``, ``z``, ``down``, ``alpha``."""
    from fipy_hopper.io import RunDirectory
    from fipy_hopper.space.pictures import plane_cells

    f = plane_cells(Path(run_dir) / RunDirectory.FIELDS / entry["file"])
    return {"x": f["x"], "z": f["z"], "down": -f["vz"], "alpha": f["alpha"]}


def plane_row(plane: dict, z: float, h: float):
    """``(x, down / its largest)`` of the plane's row nearest ``z`` with material (x > 0, the
    cells more than half full), or ``None``."""
    k = int(np.argmin(np.abs(plane["z"] - z)))
    if abs(plane["z"][k] - z) > h:
        return None
    x = plane["x"]
    ok = (x > 0) & (plane["alpha"][k] > 0.5) & np.isfinite(plane["down"][k])
    if ok.sum() < 2:
        return None
    down = plane["down"][k][ok]
    top = float(np.max(down))
    if not top > 0:
        return None
    return x[ok], down / top


def reference_profiles(row3, row2, options) -> tuple:
    """The downward speed across the plane through the axis at ``profile_heights`` in each
    run's discharge snapshot nearest its 50 % stage: ``(rows, numbers)``."""
    cfg = _config_of(row3)
    h = cfg.numerics.cell_size
    z_b = cfg.boundary.transition_height("wall")
    planes, times, at = {}, {}, {}
    for key, row, read in (("three_d", row3, space_plane), ("section", row2, section_plane)):
        t_mid = stage_times(_wall(row)).get("mid_discharge", math.nan)
        entry = snapshot_near(row["run_dir"], t_mid)
        if entry is None:
            return [], {}
        planes[key], times[key] = read(row["run_dir"], entry), entry["discharge_time_s"]
        at[key] = "50 % left" if math.isfinite(t_mid) else "the last snapshot"
    rows, per_height = [], []
    for frac in options["profile_heights"]:
        z = frac * z_b
        a, b = plane_row(planes["three_d"], z, h), plane_row(planes["section"], z, h)
        if a is None or b is None:
            continue
        common = np.intersect1d(np.round(a[0] / h, 3), np.round(b[0] / h, 3))
        if not len(common):
            continue
        pa = a[1][np.isin(np.round(a[0] / h, 3), common)]
        pb = b[1][np.isin(np.round(b[0] / h, 3), common)]
        rms = float(np.sqrt(np.mean((pa - pb) ** 2)))
        per_height.append({"z_m": _r(z, 4), "fraction_of_transition": frac,
                           "rms_difference": _r(rms, 3),
                           "wall_over_axis_3d": _r(pa[-1] / pa[0], 3),
                           "wall_over_axis_section": _r(pb[-1] / pb[0], 3), "cells": len(common)})
        for x, u, v in zip(common * h, pa, pb):
            rows.append({"z_m": z, "x_m": x, "three_d": u, "section": v})
    return rows, {"snapshot_s": {k: _r(v, 3) for k, v in times.items()},
                  "snapshot_at": at, "heights": per_height}


def reference_numbers(row3, row2, options) -> tuple:
    bins, loads = reference_bins(row3, row2, options["loaded_fraction"])
    prof_rows, prof = reference_profiles(row3, row2, options)
    numbers = {"cell_size_m": _config_of(row3).numerics.cell_size,
               "loaded_fraction": options["loaded_fraction"],
               "mirror_factor": row3.get("mirror_factor"), "loads": loads, "plane": prof}
    for key, row in (("three_d", row3), ("section", row2)):
        numbers[key] = {k: (_r(row.get(k), 5) if isinstance(row.get(k), float) else row.get(k))
                        for k in ("initial_mass_kg", "steady_discharge_rate_kg_s",
                                  "steady_discharge_rate_spread", "flow_mode", "wall_slip_ratio",
                                  "mass_flow_index", "stagnant_fraction", "discharge_time_s",
                                  "stop_reason", "mass_balance_error",
                                  "fill_equilibrium_residual", "fill_time_s", "steps", "cells",
                                  "wall_time_s")}
    numbers["three_d"]["flow_mode_by_sector"] = row3.get("flow_mode_by_sector")
    ratio = row3.get("wall_slip_ratio_by_sector")
    numbers["three_d"]["wall_slip_ratio_by_sector_range"] = (
        [_r(min(ratio), 3), _r(max(ratio), 3)] if ratio else None)
    numbers["fill_mass_diff_pct"] = _r(_sweep.pct(row3.get("initial_mass_kg"),
                                                  row2.get("initial_mass_kg")), 3)
    numbers["rate_diff_pct"] = _r(_sweep.pct(row3.get("steady_discharge_rate_kg_s"),
                                             row2.get("steady_discharge_rate_kg_s")), 2)
    return numbers, bins, prof_rows


# ---------------------------------------------------------------- (b) the families
def circumference_rows(row, loaded_fraction: float = 0.05) -> tuple:
    """Per stage and height bin of a 3D case (the walls that rise): the extremes around the
    circumference; ``(rows, {stage: summary})``, the summary's largest ratio over the bin
    wall's and over the hopper's bins whose mean pressure is at least ``loaded_fraction`` of
    the stage's largest (the pressure of a bin that carries next to nothing, at the fill's
    surface, makes any ratio)."""
    wall = _wall(row)
    R = 0.5 * _config_of(row).hopper.bin_diameter
    rows, out = [], {}
    for stage in STAGES:
        bins = stage_bins(wall, stage)
        if bins is None:
            continue
        ext = extremes(bins)
        up = rising(bins)
        mean = np.nanmean(np.where(np.isfinite(bins["p"]), bins["p"], np.nan), axis=1)
        peak = float(np.nanmax(np.where(up, ext["max"], np.nan))) if up.any() else math.nan
        loaded = up & (mean >= loaded_fraction * peak)
        bin_wall = up & (np.abs(bins["r"] - R) < 1e-6)
        hopper = up & ~bin_wall
        for k in np.flatnonzero(up):
            rows.append({"case": row["case"], "family": row["family"], "e_over_R": row["e_over_R"],
                         "stage": stage, "s_m": bins["s"][k], "z_m": bins["z"][k],
                         "r_m": bins["r"][k], "part": "bin wall" if bin_wall[k] else "hopper",
                         "p_max_Pa": ext["max"][k], "theta_max_deg": ext["theta_max"][k],
                         "p_min_Pa": ext["min"][k], "theta_min_deg": ext["theta_min"][k],
                         "max_over_min": ext["ratio"][k], "mean_Pa": mean[k],
                         "loaded": bool(loaded[k])})
        summary = {}
        for part, on in (("bin_wall", bin_wall & loaded), ("hopper", hopper & loaded)):
            ratio = np.where(on, ext["ratio"], np.nan)
            if not np.isfinite(ratio).any():
                continue
            k = int(np.nanargmax(ratio))
            summary[part] = {"largest": _r(float(ratio[k]), 3), "z_m": _r(float(bins["z"][k]), 3),
                             "theta_max_deg": _r(float(ext["theta_max"][k]), 1),
                             "theta_min_deg": _r(float(ext["theta_min"][k]), 1),
                             "median": _r(_median(ratio), 3)}
        out[stage] = summary
    return rows, out


def window_channels(run_dir) -> list:
    """A run's flow channel per window of the discharge (``channel_windows.csv``: the
    channel of each load window's mean field, measured by the loop): ``[(t_start, t_end,
    profile)]``, ``profile`` the window's heights as arrays named as
    :class:`fipy_hopper.space.channel.ChannelProfile`'s; ``[]`` for a run without the file
    (made before the loop measured it)."""
    from fipy_hopper.io import RunDirectory, read_csv
    from fipy_hopper.space.channel import PROFILE_COLUMNS

    path = Path(run_dir) / RunDirectory.CHANNEL_WINDOWS
    if not path.is_file():
        return []
    table = read_csv(path)
    windows = np.asarray(table["window"], float)
    out = []
    for w in np.unique(windows):
        on = windows == w
        # a measure the run's version did not write yet (the outline's extent): NaN
        prof = SimpleNamespace(**{attr: np.asarray(table[name], float)[on] if name in table
                                  else np.full(int(on.sum()), np.nan)
                                  for name, attr in PROFILE_COLUMNS})
        out.append((float(np.asarray(table["t_start_s"], float)[on][0]),
                    float(np.asarray(table["t_end_s"], float)[on][0]), prof))
    return out


def _channel_source(row, options) -> tuple:
    """``(source, [(t_start, t, profile)])``: the run's windows (:func:`window_channels`)
    when it has them and the study's edge is the loop's (``channel_fraction`` =
    :data:`fipy_hopper.space.channel.DEFAULT_FRACTION`); else each discharge snapshot
    (:func:`snapshot_channel`, an instantaneous field, ``t_start = t``)."""
    from fipy_hopper.io import RunDirectory
    from fipy_hopper.space.channel import DEFAULT_FRACTION

    if options["channel_fraction"] == DEFAULT_FRACTION:
        windows = window_channels(row["run_dir"])
        if windows:
            return "windows", windows
    cfg = _config_of(row)
    R = 0.5 * cfg.hopper.bin_diameter
    z_b = max(cfg.boundary.transition_height("wall"), 0.0)
    out = []
    for entry in discharge_snapshots(row["run_dir"]):
        t = float(entry["discharge_time_s"])
        if t > 0:
            out.append((t, t, snapshot_channel(
                Path(row["run_dir"]) / RunDirectory.FIELDS / entry["file"], R, z_b,
                options["channel_fraction"])))
    return "snapshots", out


def channel_rows(row, options) -> tuple:
    """The channel per window of the discharge (or, for a run without windows, per
    discharge snapshot: :func:`_channel_source`) and height of a 3D case; ``(rows,
    summary)``.  The summary: over the windows, the medians and quartiles of every height in
    :func:`channel_band` of every window (the whole discharge's channel), the range of the
    windows' own medians and each window's medians (``history``); over snapshots, the last
    snapshot's medians and quartiles, and each snapshot's medians."""
    cfg = _config_of(row)
    R = 0.5 * cfg.hopper.bin_diameter
    z_b = max(cfg.boundary.transition_height("wall"), 0.0)
    source, profiles = _channel_source(row, options)
    rows, history, pooled = [], [], {key: [] for key in ("theta_c", "r_c", "e_c",
                                                         "contact_angle")}
    heights = []
    for t0, t, prof in profiles:
        band = channel_band(prof, z_b)
        for k in range(len(prof.z)):
            rows.append({"case": row["case"], "family": row["family"],
                         "e_over_R": row["e_over_R"], "source": source, "t_start_s": t0,
                         "t_s": t, "z_m": prof.z[k], "in_band": bool(band[k]),
                         "area_m2": prof.area[k], "theta_c_deg": prof.theta_c[k],
                         "contact_angle_deg": prof.contact_angle[k],
                         "r_c_m": prof.r_c[k], "e_c_m": prof.e_c[k], "r_eq_m": prof.r_eq[k],
                         "centroid_x_m": prof.centroid_x[k], "fit_rms_m": prof.fit_rms[k]})
        if not band.any():
            continue
        history.append({"t_start_s": _r(t0, 3), "t_s": _r(t, 3),
                        "theta_c_deg": _r(_median(prof.theta_c[band]), 2),
                        "r_c_over_R": _r(_median(prof.r_c[band]) / R, 3),
                        "e_c_over_R": _r(_median(prof.e_c[band]) / R, 3)})
        if source == "snapshots":
            pooled = {key: [] for key in pooled}
            heights = []
        for key in pooled:
            pooled[key].append(np.asarray(getattr(prof, key), float)[band])
        heights.append(prof.z[band])
    if not history:
        return rows, {}
    theta, r_c, e_c, angle = (np.concatenate(pooled[k]) for k in
                              ("theta_c", "r_c", "e_c", "contact_angle"))
    z = np.concatenate(heights)
    summary = {
        "source": source, "windows": len(history) if source == "windows" else None,
        "window_s": _r(_median([h["t_s"] - h["t_start_s"] for h in history]), 3)
        if source == "windows" else None,
        "snapshot_s": history[-1]["t_s"], "heights": int(len(z)),
        "band_m": [_r(float(z.min()), 3), _r(float(z.max()), 3)],
        "touching": int(np.sum((theta > 0) & (theta < 180))),
        "whole_wall": int(np.sum(theta >= 180)),
        "theta_c_deg": _r(_median(theta), 2),
        "theta_c_quartiles": [_r(q, 2) for q in _quartiles(theta)],
        "r_c_over_R": _r(_median(r_c) / R, 3),
        "r_c_quartiles": [_r(q / R, 3) for q in _quartiles(r_c)],
        "e_c_over_R": _r(_median(e_c) / R, 3),
        "e_c_quartiles": [_r(q / R, 3) for q in _quartiles(e_c)],
        "contact_angle_deg": _r(_median(angle), 1),
        "history": history}
    if source == "windows":
        for key in ("theta_c_deg", "r_c_over_R", "e_c_over_R"):
            values = [h[key] for h in history if _sweep.finite(h[key])]
            summary[f"{key}_window_range"] = ([min(values), max(values)] if values
                                              else None)
    return rows, summary


def channel_when(summary) -> str:
    """Words for what a channel summary (:func:`channel_rows`) is taken over."""
    if summary.get("source") == "windows":
        return (f"over the discharge's {summary['windows']} windows of "
                f"{num(summary['window_s'], 'g')} s (the channel of each window's mean field; "
                f"medians over the heights and the windows)")
    return (f"at the last snapshot, {num(summary.get('snapshot_s'), 'g')} s (medians over "
            f"the heights)")


def window_spread(summary) -> str:
    """``; the windows' theta_c lo-hi deg``: the range of the windows' own medians of a
    channel summary over windows (nothing for a snapshot's)."""
    pair = summary.get("theta_c_deg_window_range")
    return f"; the windows' theta_c {_span(pair, '.0f')} deg" if pair else ""


def en_channels(cfg) -> list:
    """EN 1991-4's channel for its three G (mu = tan phi_w, phi_i = phi)."""
    from fipy_hopper import theory

    R = 0.5 * cfg.hopper.bin_diameter
    mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
    out = []
    for G in theory.EN1991_ECCENTRIC_G:
        ch = theory.en1991_eccentric_channel(R, G, mu, cfg.material.friction_angle_deg)
        out.append({"G": G, "theta_c_deg": _r(float(ch.theta_c), 2),
                    "e_c_over_R": _r(float(ch.e_c) / R, 3)})
    return out


def family_numbers(rows, options) -> tuple:
    """Per eccentric case its numbers; the circumference and channel rows."""
    numbers, circ, chan = {}, [], []
    for row in rows:
        c_rows, c_sum = circumference_rows(row, options["loaded_fraction"])
        h_rows, h_sum = channel_rows(row, options)
        circ += c_rows
        chan += h_rows
        numbers[row["case"]] = {
            "family": row["family"], "e_over_R": row["e_over_R"],
            "outlet_offset_m": row.get("outlet_offset_m"), "end_time_s": row.get("end_time_s"),
            "steady_rate": _r(row.get("steady_discharge_rate_kg_s"), 4),
            "beverloo_rate": _r(row.get("beverloo_rate_kg_s",
                                        row.get("beverloo_flat_rate_kg_s")), 4),
            "initial_mass_kg": _r(row.get("initial_mass_kg"), 3),
            "discharged_fraction": _r(1.0 - row.get("remaining_mass_fraction", math.nan), 4),
            "flow_mode": row.get("flow_mode"),
            "flow_mode_by_sector": row.get("flow_mode_by_sector"),
            "mass_balance_error": row.get("mass_balance_error"),
            "fill_equilibrium_residual": _r(row.get("fill_equilibrium_residual"), 5),
            "mirror_factor": row.get("mirror_factor"),
            "wall_time_s": _r(row.get("wall_time_s"), 1),
            "circumference": c_sum, "channel": h_sum}
    for case, n in numbers.items():
        centred = [m for m in numbers.values() if m["family"] == n["family"]
                   and m["e_over_R"] == 0.0]
        n["rate_vs_centred_pct"] = (_r(_sweep.pct(n["steady_rate"], centred[0]["steady_rate"]), 2)
                                    if centred else None)
    return numbers, circ, chan


def analyse(rows, options) -> tuple:
    """``(numbers, tables)``: the study's numbers and the rows of its CSV files."""
    ok = [r for r in rows if not r.get("error") and r.get("run_dir")]
    by = {r["case"]: r for r in ok}
    numbers, tables = {}, {"reference_bins": [], "reference_profiles": [],
                           "circumference": [], "channel": []}
    if "reference_3d" in by and "reference_section" in by:
        ref, bins, prof = reference_numbers(by["reference_3d"], by["reference_section"], options)
        numbers["reference"] = ref
        tables["reference_bins"], tables["reference_profiles"] = bins, prof
    eccentric = [r for r in ok if r.get("part") == "eccentric"]
    if eccentric:
        fam, circ, chan = family_numbers(eccentric, options)
        numbers["eccentric"] = fam
        numbers["en1991_channel"] = en_channels(_config_of(eccentric[0]))
        tables["circumference"], tables["channel"] = circ, chan
    for row in rows:
        case = numbers.get("eccentric", {}).get(row["case"])
        if case:
            row["rest_max_over_min_bin_wall"] = case["circumference"].get(
                "filling", {}).get("bin_wall", {}).get("largest")
            row["early_max_over_min_bin_wall"] = case["circumference"].get(
                "early_discharge", {}).get("bin_wall", {}).get("largest")
            row["theta_c_deg"] = case["channel"].get("theta_c_deg")
            row["r_c_over_R"] = case["channel"].get("r_c_over_R")
    return numbers, tables


# ---------------------------------------------------------------- pictures
def plot_reference(numbers, tables):
    """The reference in 3D against its section: the wall pressure per height bin at rest and
    at 90 % left (the section's, the 3D mean around the circumference and its range), the
    ratio around the circumference per bin and stage, and the plane's speed rows."""
    fig = _sweep.figure(11.0, 8.0)
    axes = fig.subplots(2, 2)
    rows = tables["reference_bins"]
    for ax, stage in zip(axes[0], ("filling", "early_discharge")):
        on = [r for r in rows if r["stage"] == stage]
        if not on:
            continue
        z = np.array([r["z_m"] for r in on])
        ax.plot([r["section_Pa"] / 1e3 for r in on], z, "k--o", ms=3, label="section")
        ax.plot([r["three_d_mean_Pa"] / 1e3 for r in on], z, "C0-o", ms=3,
                label="3D, mean around")
        ax.fill_betweenx(z, [r["three_d_min_Pa"] / 1e3 for r in on],
                         [r["three_d_max_Pa"] / 1e3 for r in on], color="C0", alpha=0.25,
                         label="3D, smallest to largest around")
        ax.set_xlabel("wall pressure p_n (kPa)")
        ax.set_ylabel("z (m)")
        ax.set_title(f"Wall pressure {STAGE_WORDS[stage]}", fontsize=9)
        ax.legend(fontsize=7)
    ax = axes[1, 0]
    for k, stage in enumerate(STAGES):
        on = [r for r in rows if r["stage"] == stage]
        if on:
            ax.plot([r["max_over_min"] for r in on], [r["z_m"] for r in on], "-o", ms=3,
                    color=f"C{k}", label=STAGE_WORDS[stage])
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xlabel("largest / smallest p_n around the circumference (-)")
    ax.set_ylabel("z (m)")
    ax.set_title("3D: the pressure around the circumference", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    prof = tables["reference_profiles"]
    for k, z in enumerate(sorted({r["z_m"] for r in prof})):
        on = [r for r in prof if r["z_m"] == z]
        x = [r["x_m"] for r in on]
        ax.plot(x, [r["three_d"] for r in on], "-", color=f"C{k}", label=f"z = {z:.3g} m, 3D")
        ax.plot(x, [r["section"] for r in on], "--", color=f"C{k}", label="section")
    ax.set_xlabel("distance from the axis (m)")
    ax.set_ylabel("downward speed / the row's largest (-)")
    snap = numbers.get("plane", {}).get("snapshot_s", {})
    ax.set_title(f"The plane through the axis (3D at {num(snap.get('three_d'))} s, "
                 f"section at {num(snap.get('section'))} s)", fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    return fig


def _family_cases(numbers, family):
    return sorted([(n["e_over_R"], case, n) for case, n in numbers["eccentric"].items()
                   if n["family"] == family])


def plot_family(family, numbers, tables, options):
    """A family's summary: the largest over the smallest pressure around the circumference
    against height at rest and in discharge for each e/R, and the channel's theta_c, r_c/R
    and e_c/R against e/R beside EN 1991-4's channels."""
    fig = _sweep.figure(11.0, 8.0)
    axes = fig.subplots(2, 2)
    cases = _family_cases(numbers, family)
    circ = tables["circumference"]
    for ax, stages in zip(axes[0], (("filling",), ("early_discharge", "discharge_envelope"))):
        for k, (e, case, _) in enumerate(cases):
            for stage, style in zip(stages, ("-o", ":")):
                on = [r for r in circ if r["case"] == case and r["stage"] == stage]
                if on:
                    ax.plot([r["max_over_min"] for r in on], [r["z_m"] for r in on], style,
                            ms=3, color=f"C{k}",
                            label=f"e/R = {e:g}" + ("" if stage == stages[0] else
                                                    f", {STAGE_WORDS[stage]}"))
        ax.axvline(1.0, color="k", lw=0.8)
        if family == "cone":
            ax.axhline(cone_height(options), color="0.5", ls="--", lw=0.8)
        ax.set_xlabel("largest / smallest p_n around the circumference (-)")
        ax.set_ylabel("z (m)")
        ax.set_title(f"{STAGE_WORDS[stages[0]]}" + (" (dotted: the envelope)"
                                                     if len(stages) > 1 else "")
                     + ("; dashed: the bin wall's foot" if family == "cone" else ""),
                     fontsize=9)
        ax.legend(fontsize=7)
    en = numbers.get("en1991_channel", [])
    es = [e for e, _, _ in cases]
    ax = axes[1, 0]
    theta = [n["channel"].get("theta_c_deg") for _, _, n in cases]
    quart = [n["channel"].get("theta_c_quartiles") or [None, None] for _, _, n in cases]
    _errorbar(ax, es, theta, quart, "C0", "measured (median over the band)")
    for k, ch in enumerate(en):
        ax.axhline(ch["theta_c_deg"], color=f"C{k + 1}", ls="--", lw=1,
                   label=f"EN 1991-4, G = {ch['G']:g}")
    ax.set_xlabel("e/R of the outlet (-)")
    ax.set_ylabel("theta_c (deg): half the wall arc in contact")
    ax.set_title("The channel's contact with the wall", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    for key, colour, label in (("r_c", "C0", "r_c / R"), ("e_c", "C3", "e_c / R")):
        vals = [n["channel"].get(f"{key}_over_R") for _, _, n in cases]
        quart = [n["channel"].get(f"{key}_quartiles") or [None, None] for _, _, n in cases]
        _errorbar(ax, es, vals, quart, colour, f"measured {label}")
    for k, ch in enumerate(en):
        ax.axhline(ch["G"], color=f"C{k + 1}", ls="--", lw=1,
                   label=f"EN G = {ch['G']:g} (e_c/R {ch['e_c_over_R']:.2f})")
    ax.set_xlabel("e/R of the outlet (-)")
    ax.set_ylabel("r_c / R, e_c / R (-)")
    ax.set_title("The channel's radius and centre (EN: r_c = G R)", fontsize=9)
    ax.legend(fontsize=7)
    fig.suptitle(f"The {FAMILY_TITLES[family]}", fontsize=10)
    return fig


def _errorbar(ax, x, y, quartiles, colour, label):
    y = np.array([math.nan if v is None else v for v in y], float)
    lo = np.array([math.nan if q[0] is None else q[0] for q in quartiles], float)
    hi = np.array([math.nan if q[1] is None else q[1] for q in quartiles], float)
    err = np.vstack([np.where(np.isfinite(lo), y - lo, 0.0),
                     np.where(np.isfinite(hi), hi - y, 0.0)])
    ax.errorbar(x, y, yerr=np.clip(np.nan_to_num(err), 0.0, None), fmt="o-", color=colour,
                capsize=3, label=label)


def plot_channels(family, numbers, rows, options):
    """A family's flow in discharge at its last snapshot, one column per e/R: the speed in
    the plane through the axis and the outlet (top) and the channel's outline in horizontal
    slices of the bin (bottom: the band's lowest, middle and highest planes)."""
    from fipy_hopper.io import RunDirectory

    cases = _family_cases(numbers, family)
    by = {r["case"]: r for r in rows}
    fig = _sweep.figure(3.0 * max(len(cases), 1) + 1.0, 8.5)
    axes = fig.subplots(2, max(len(cases), 1), squeeze=False)
    mesh = None
    for col, (e, case, n) in enumerate(cases):
        row = by[case]
        entries = discharge_snapshots(row["run_dir"])
        if not entries:
            continue
        entry = entries[-1]
        plane = space_plane(row["run_dir"], entry)
        ax = axes[0, col]
        h = plane["x"][1] - plane["x"][0] if len(plane["x"]) > 1 else 1.0
        filled = plane["alpha"] > 0.05
        speed = np.ma.masked_where(~filled, plane["down"])
        above = filled & (plane["z"] > 0)[:, None] & np.isfinite(plane["down"])
        top = float(np.max(plane["down"][above])) if above.any() else None
        mesh = ax.pcolormesh(np.append(plane["x"] - 0.5 * h, plane["x"][-1] + 0.5 * h),
                             np.append(plane["z"] - 0.5 * h, plane["z"][-1] + 0.5 * h), speed,
                             cmap="viridis", shading="flat", vmin=0.0, vmax=top)
        ax.set_aspect("equal")
        ax.set_title(f"e/R = {e:g}, {entry['discharge_time_s']:.3g} s", fontsize=9)
        ax.set_xlabel("x (m)")
        if col == 0:
            ax.set_ylabel("z (m)")
        fig.colorbar(mesh, ax=ax, label="downward speed (m/s), above the outlet",
                     shrink=0.7, extend="max")
        cfg = _config_of(row)
        R = 0.5 * cfg.hopper.bin_diameter
        z_b = max(cfg.boundary.transition_height("wall"), 0.0)
        prof = snapshot_channel(Path(row["run_dir"]) / RunDirectory.FIELDS / entry["file"],
                                R, z_b, options["channel_fraction"])
        band = np.flatnonzero(channel_band(prof, z_b))
        ax = axes[1, col]
        t = np.linspace(0, 2 * np.pi, 200)
        ax.plot(R * np.cos(t), R * np.sin(t), "k-", lw=1)
        e_m = cfg.hopper.outlet_offset
        r0 = 0.5 * cfg.hopper.outlet_diameter
        ax.plot(e_m + r0 * np.cos(t), r0 * np.sin(t), "k:", lw=0.8, label="outlet")
        if band.size:
            for k, j in enumerate(np.unique(band[[0, band.size // 2, -1]])):
                outline = prof.outlines[j]
                if len(outline):
                    ax.plot(outline[:, 0], outline[:, 1], color=f"C{k}",
                            label=f"z = {prof.z[j]:.2f} m, theta_c {prof.theta_c[j]:.0f}")
        ax.set_aspect("equal")
        ax.set_xlim(-1.05 * R, 1.05 * R)
        ax.set_ylim(-1.05 * R, 1.05 * R)
        ax.set_xlabel("x (m): towards the outlet")
        ax.legend(fontsize=6, loc="lower left")
    fig.suptitle(f"The {FAMILY_TITLES[family]}: the speed in the plane through the axis and "
                 "the outlet,\nand the flow channel in slices of the bin", fontsize=10)
    return fig


# ---------------------------------------------------------------- findings
def reference_findings(ref) -> list:
    out = []
    a, b = ref["three_d"], ref["section"]
    h_mm = 1000 * ref["cell_size_m"]
    sectors = a.get("flow_mode_by_sector") or []
    calls = sorted(set(sectors))
    slip = a.get("wall_slip_ratio_by_sector_range") or [None, None]
    out.append(
        f"The reference hopper in 3D ({h_mm:g} mm cubes, computed as 1/"
        f"{num(ref.get('mirror_factor'), 'g')} of the silo) against its axisymmetric section "
        f"at {h_mm:g} mm: fill {num(a['initial_mass_kg'], '.3f')} against "
        f"{num(b['initial_mass_kg'], '.3f')} kg ({num(ref['fill_mass_diff_pct'], '+.2f')} %), "
        f"steady rate {num(a['steady_discharge_rate_kg_s'], '.3f')} against "
        f"{num(b['steady_discharge_rate_kg_s'], '.3f')} kg/s ({num(ref['rate_diff_pct'], '+.1f')}"
        f" %); {a.get('flow_mode')} flow against {b.get('flow_mode')} (3D: "
        f"{'/'.join(calls) or 'n/a'} in {len(sectors)} sectors, wall slip ratio "
        f"{num(slip[0], '.3f')}-{num(slip[1], '.3f')} around the circumference, the section's "
        f"{num(b.get('wall_slip_ratio'), '.3f')}); mass-flow index "
        f"{num(a.get('mass_flow_index'), '.2f')} against {num(b.get('mass_flow_index'), '.2f')}, "
        f"stagnant fraction {num(a.get('stagnant_fraction'), '.3f')} against "
        f"{num(b.get('stagnant_fraction'), '.3f')}; stopped by {a.get('stop_reason')} after "
        f"{num(a.get('discharge_time_s'), '.2f')} s against "
        f"{num(b.get('discharge_time_s'), '.2f')} s.")
    parts = []
    for stage, n in ref["loads"].items():
        parts.append(f"{STAGE_WORDS[stage]} {num(n['rms_above_lip_pct'], '.1f')} % RMS above "
                     f"the lip's bin (lip {num(n['lip_pct'], '+.0f')} %), largest / smallest "
                     f"around {num(n['max_over_min_largest'], '.3f')}")
    if parts:
        out.append("Reference, wall pressure per height bin, the 3D mean around the "
                   "circumference against the section's (over the bins carrying at least "
                   f"{100 * ref['loaded_fraction']:g} % of the stage's largest pressure): "
                   + "; ".join(parts) + ".")
    plane = ref.get("plane", {}).get("heights", [])
    if plane:
        parts = [f"z = {p['z_m']:.3g} m: RMS {num(p['rms_difference'], '.3f')}, wall / axis "
                 f"{num(p['wall_over_axis_3d'], '.2f')} against "
                 f"{num(p['wall_over_axis_section'], '.2f')}" for p in plane]
        snap, at = ref["plane"]["snapshot_s"], ref["plane"]["snapshot_at"]
        out.append(f"Reference, the downward speed across the plane through the axis (each "
                   f"row over its largest), 3D at {num(snap.get('three_d'), '.3g')} s "
                   f"({at['three_d']}) against the section at "
                   f"{num(snap.get('section'), '.3g')} s ({at['section']}): "
                   + "; ".join(parts) + ".")
    return out


def _mode_text(n) -> str:
    """A case's flow mode with its sectors' calls (mass where the wall slides)."""
    calls = n.get("flow_mode_by_sector") or []
    known = [c for c in calls if c in ("mass", "funnel")]
    if not known:
        return f"{n['flow_mode']} (no wall-slip sample)"
    return (f"{n['flow_mode']} ({sum(c == 'mass' for c in known)} of {len(calls)} sectors "
            "sliding)")


def family_findings(numbers, options) -> list:
    out = []
    en = numbers.get("en1991_channel", [])
    en_text = ", ".join(f"{c['theta_c_deg']:.1f} deg (e_c/R {c['e_c_over_R']:.2f}) for G = "
                        f"{c['G']:g}" for c in en)
    for family in FAMILIES:
        cases = _family_cases(numbers, family)
        if not cases:
            continue
        es = _nums([e for e, _, _ in cases], "g")
        first = cases[0][2]
        rates = _nums([n["steady_rate"] for _, _, n in cases], ".2f")
        out_pct = [100 * n["discharged_fraction"] if _sweep.finite(n["discharged_fraction"])
                   else None for _, _, n in cases]
        diffs = _nums([n["rate_vs_centred_pct"] for _, _, n in cases], "+.1f")
        modes = "; ".join(_mode_text(n) for _, _, n in cases)
        out.append(
            f"The {FAMILY_TITLES[family]} ({options['bin_diameter']:g} m bin, "
            f"{options['outlet_diameter']:g} m outlet, filled to {options['fill_level']:g} m, "
            f"{1000 * options['cell_size']:g} mm cubes) with its outlet at e/R = {es}: steady "
            f"rate {rates} kg/s ({diffs} % from the centred; Beverloo "
            f"{num(first['beverloo_rate'], '.2f')} kg/s), {_nums(out_pct, '.0f')} "
            f"% discharged in {_nums([n['end_time_s'] for _, _, n in cases], 'g')} s; flow "
            f"mode {modes}.")
        parts = []
        for stage in STAGES:
            vals = [n["circumference"].get(stage, {}).get("bin_wall") for _, _, n in cases]
            if not any(vals):
                continue
            parts.append(f"{STAGE_WORDS[stage]} " + ", ".join(
                "n/a" if v is None else f"{v['largest']:.2f} (z = {v['z_m']:.2f} m, largest at "
                f"{v['theta_max_deg']:.0f} deg, smallest at {v['theta_min_deg']:.0f} deg)"
                for v in vals))
        hop = [n["circumference"].get("filling", {}).get("hopper") for _, _, n in cases]
        hop_d = [n["circumference"].get("early_discharge", {}).get("hopper") for _, _, n in cases]
        hopper_text = ""
        if any(hop):
            hopper_text = (f"; on the cone the largest ratio at rest "
                           f"{_nums([v and v['largest'] for v in hop])}, at 90 % left "
                           f"{_nums([v and v['largest'] for v in hop_d])}")
        if parts:
            out.append(f"The {FAMILY_TITLES[family]}, the bin wall's largest / smallest "
                       f"pressure around the circumference (its largest over the heights) at "
                       f"e/R = {es}: " + "; ".join(parts) + hopper_text + ".")
        ch = [n["channel"] for _, _, n in cases]
        if any(ch):
            parts = [f"e/R {e:g}: theta_c {num(c.get('theta_c_deg'), '.1f')} deg, r_c/R "
                     f"{num(c.get('r_c_over_R'), '.2f')}, e_c/R {num(c.get('e_c_over_R'), '.2f')}"
                     f" ({c.get('touching', 0)} of {c.get('heights', 0)} "
                     f"{'window heights' if c.get('source') == 'windows' else 'planes'} "
                     f"touching the wall in part, {c.get('whole_wall', 0)} all round"
                     f"{window_spread(c)})"
                     for (e, _, _), c in zip(cases, ch) if c]
            first = next(c for c in ch if c)
            no_circle = any(c and c.get("r_c_over_R") is None for c in ch)
            out.append(f"The {FAMILY_TITLES[family]}, the flow channel in the bin's middle half "
                       f"{channel_when(first)}: " + "; ".join(parts)
                       + (" (r_c n/a: at most heights the channel flows all round or its area "
                          "is more than any circle through its contact's ends gives: it fills "
                          "the section)" if no_circle else "")
                       + f". EN 1991-4 (mu = tan phi_w, phi_i = phi) takes theta_c = {en_text}.")
    return out


def headline_of(numbers) -> str:
    """One line for the report's overview: the reference's rate and wall pressure at rest
    against the section, and each family's largest ratio around the bin wall at 90 % left
    at its largest e/R."""
    parts = []
    ref = numbers.get("reference")
    if ref:
        rest = ref["loads"].get("filling", {})
        parts.append(f"3D reference against its section: rate {num(ref['rate_diff_pct'], '+.1f')}"
                     f" %, wall pressure at rest {num(rest.get('rms_above_lip_pct'), '.1f')} % "
                     "RMS above the lip's bin")
    for family in FAMILIES:
        cases = _family_cases(numbers, family) if "eccentric" in numbers else []
        if len(cases) > 1:
            (e0, _, n0), (e1, _, n1) = cases[0], cases[-1]
            ratio = [n["circumference"].get("early_discharge", {}).get("bin_wall", {}).get(
                "largest") for n in (n0, n1)]
            parts.append(f"{FAMILY_TITLES[family]}: the bin wall's largest / smallest pressure "
                         f"at 90 % left {num(ratio[0], '.2f')} at e/R = {e0:g}, "
                         f"{num(ratio[1], '.2f')} at {e1:g}")
    return "; ".join(parts) + "." if parts else ""


# ---------------------------------------------------------------- outputs
def write_outputs(out, rows, numbers, tables, options, setting, argv=None):
    out = Path(out)
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "case", "part", "family", "dimensions", "e_over_R", "outlet_offset_m", "end_time_s",
        "steady_discharge_rate_kg_s", "flow_mode", "rest_max_over_min_bin_wall",
        "early_max_over_min_bin_wall", "theta_c_deg", "r_c_over_R", "mass_balance_error",
        "wall_time_s", "error"))
    for name in ("reference_bins", "reference_profiles", "circumference", "channel"):
        _sweep.write_rows_csv(out / f"{name}.csv", tables[name])
    figures = []
    if "reference" in numbers:
        _sweep.save(plot_reference(numbers["reference"], tables), out / "reference.png")
        figures.append({"file": "reference.png", "caption": (
            "The reference hopper in 3D against its axisymmetric section at the same cell "
            "size. Top: the wall pressure per height bin at rest and at 90 % left (the "
            "section's dashed; the 3D mean around the circumference and its range). Bottom "
            "left: the 3D largest over smallest pressure around the circumference per bin and "
            "stage. Bottom right: the downward speed across the plane through the axis, each "
            "row over its largest, near 50 % left (3D solid, section dashed).")})
    if "eccentric" in numbers:
        for family in FAMILIES:
            if not _family_cases(numbers, family):
                continue
            _sweep.save(plot_family(family, numbers, tables, options),
                        out / f"{family}_summary.png")
            figures.append({"file": f"{family}_summary.png", "caption": (
                f"The {FAMILY_TITLES[family]} with its outlet at each e/R: the largest over "
                "the smallest wall pressure around the circumference against height at rest "
                "and at 90 % left (dotted: the discharge envelope); the flow channel's "
                "contact half-angle theta_c, radius r_c and centre e_c (medians over the "
                "middle half of the bin's fill at the last snapshot, bars the quartiles) "
                "against e/R beside EN 1991-4's channels.")})
            _sweep.save(plot_channels(family, numbers, rows, options),
                        out / f"{family}_channels.png")
            figures.append({"file": f"{family}_channels.png", "caption": (
                f"The {FAMILY_TITLES[family]} at its last snapshot of the discharge: the "
                "downward speed in the plane through the axis and the outlet, and the flow "
                "channel's outline in three horizontal slices of the bin (the outlet dotted).")})
    copies = [("reference_3d", "flow_plane.png", "the reference in 3D: the flow in the plane "
               "through the axis (the run's picture)."),
              ("reference_3d", "wall_unrolled.png", "the reference in 3D: the wall pressure "
               "over the unrolled wall at rest and in discharge (the run's picture)."),
              ("reference_section", "flow_pattern.png", "the reference's section: the flow "
               "pattern (the run's picture).")]
    for family in FAMILIES:
        cases = _family_cases(numbers, family) if "eccentric" in numbers else []
        if cases:
            e, case, _ = cases[-1]
            copies += [(case, "wall_unrolled.png", f"the {FAMILY_TITLES[family]} at e/R = "
                        f"{e:g}: the wall pressure over the unrolled wall (the run's picture)."),
                       (case, "wall_circumference.png", f"the {FAMILY_TITLES[family]} at e/R = "
                        f"{e:g}: the wall pressure around the circumference (the run's "
                        "picture).")]
    by = {r["case"]: r for r in rows}
    for case, picture, caption in copies:
        source = Path(by.get(case, {}).get("run_dir", "")) / picture
        if source.is_file():
            name = f"{Path(picture).stem}_{case}.png"
            shutil.copyfile(source, out / name)
            figures.append({"file": name, "caption": caption[:1].upper() + caption[1:]})
    tables_out = []
    ref = numbers.get("reference")
    if ref:
        tables_out.append({"title": "Reference: 3D against the section", "columns": [
            "run", "fill (kg)", "rate (kg/s)", "flow mode", "mass-flow index", "stagnant",
            "discharge (s)", "steps", "wall time (s)"], "rows": [
            [name, n["initial_mass_kg"], n["steady_discharge_rate_kg_s"], n["flow_mode"],
             n["mass_flow_index"], n["stagnant_fraction"], n["discharge_time_s"], n["steps"],
             n["wall_time_s"]] for name, n in (("3D", ref["three_d"]),
                                               ("section", ref["section"]))]})
        tables_out.append({"title": "Reference: wall pressure per height bin", "columns": [
            "stage", "z (m)", "section (Pa)", "3D mean (Pa)", "diff (%)", "3D max / min"],
            "rows": [[r["stage"], _r(r["z_m"], 3), _r(r["section_Pa"], 0),
                      _r(r["three_d_mean_Pa"], 0), _r(r["diff_pct"], 1),
                      _r(r["max_over_min"], 3)] for r in tables["reference_bins"]]})
    ecc = numbers.get("eccentric", {})
    if ecc:
        tables_out.append({"title": "Off-centre outlets", "columns": [
            "case", "e/R", "end (s)", "rate (kg/s)", "vs centred (%)", "flow mode",
            "bin wall max/min at rest", "at 90 % left", "envelope", "theta_c (deg)",
            "r_c / R", "e_c / R", "wall time (s)"], "rows": [
            [case, n["e_over_R"], n["end_time_s"], n["steady_rate"], n["rate_vs_centred_pct"],
             n["flow_mode"],
             n["circumference"].get("filling", {}).get("bin_wall", {}).get("largest"),
             n["circumference"].get("early_discharge", {}).get("bin_wall", {}).get("largest"),
             n["circumference"].get("discharge_envelope", {}).get("bin_wall", {}).get("largest"),
             n["channel"].get("theta_c_deg"), n["channel"].get("r_c_over_R"),
             n["channel"].get("e_c_over_R"), n["wall_time_s"]] for case, n in ecc.items()]})
        tables_out.append({"title": "EN 1991-4's eccentric channels", "columns": [
            "G = r_c / R", "theta_c (deg)", "e_c / R"], "rows": [
            [c["G"], c["theta_c_deg"], c["e_c_over_R"]] for c in numbers["en1991_channel"]]})
    findings = (reference_findings(ref) if ref else []) + family_findings(numbers, options)
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers, findings, figures,
                            tables_out, rows, argv, headline=headline_of(numbers))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m, the off-centre families' cubes")
    parser.add_argument("--reference-cell-size", type=float,
                        help="m, the reference's cubes and its section's cells")
    parser.add_argument("--end-time", type=float,
                        help="s of discharge for every off-centre case (default: Beverloo's "
                             "time for drained_fraction of each fill)")
    parser.add_argument("--estimate", action="store_true",
                        help="print each case's grid, memory and time estimate and stop")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_size", "reference_cell_size", "end_time"))
    study = setup(quick=args.quick, **options)
    if args.estimate:
        total = print_estimate(estimate(study))
        print(f"3D cases: {cost_text(total)}")
        return 0
    rows = _sweep.run_study(NAME, study, args)
    numbers, tables = analyse(rows, study["options"])
    write_outputs(args.out, rows, numbers, tables, study["options"], study["setting"], argv)
    print(f"{NAME}: written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
