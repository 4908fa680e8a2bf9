"""Cohesive arching: the simulated critical outlet against Jenike's, and a rathole case.

For a cohesive Mohr-Coulomb powder (unconfined yield strength
``sigma_c = 2 c cos(phi) / (1 - sin(phi))``, :func:`fipy_hopper.theory.unconfined_yield_strength`)
the critical outlet ``D_crit`` is found by bisection on the outlet diameter ``D0`` at fixed
cohesion: the bracket ``[D_arch, D_flow]`` is the largest ``D0`` that arched and the smallest
that flowed, narrowed until ``D_flow / D_arch <= tolerance`` (default 1.05; at most
1.10, a 10 % bracket).  Cases: three cohesions, given as the length ``sigma_c / (rho g)``
(default 55, 80, 110 mm), times two cones (20 and 30 deg) and a flat-bottomed bin
(90 deg);
default hopper a 0.48 m bin filled 0.2 m above the transition, phi = 30 deg, phi_w = 15 deg,
rho = 1500 kg/m3, E = 5 MPa, 5 mm cells (4.5 across the outlet radius at the smallest D0
tried, 45 mm; the bin is 2.5 x the largest D0 allowed, 192 mm).  At 7.5 mm the smallest
outlets were under-resolved: the 30 deg cone's critical outlets were 10-18 % smaller than at
5 mm and its exponent 1.20, and E = 2 MPa moved one bracket.

The outlet opens gradually, from the axis outwards over ``opening_periods`` (10) periods of
the filled column's lowest elastic mode (``run.opening_time``, the same measure as the fill's
gravity ramp; 0: at once): Jenike's critical outlet is a static criterion, and a plate removed
at once breaks near-critical arches by its dynamics, more easily at lower E (measured: the 20
deg cone at 80 mm arched up to 90.3 mm at E = 2 and 5 MPa and up to 99.6 mm at 20 MPa when
opened at once; opened over ten periods, the three moduli arched at 97.9 mm and flowed at
102.9 mm; ``docs/notes.md``).

Outcome of a run (``summary.json``; the discharge runs with ``end_time = "empty"`` and is
capped at ``max_discharge_time`` (default 1.2 s) after the outlet is fully open):

* ``arches``: the flow stopped (``flow_stopped_time_s`` finite: the package's at-rest rule,
  checked from 0.5 s after the outlet is fully open) with more than 90 % of the mass left (the
  bar of ``flow_mode = "no_flow"``; every ``no_flow`` of a cone here has more than 99.9 % left);
* ``flows``: otherwise: still flowing at the cap (a flowing run need not empty), or the flow
  stopped after more than 10 % of the mass had left (funnel flow that drained its channel and
  stopped: not an arch over the outlet; the table names these ``stopped late``).

Each bisection starts at ``guess_ratio`` (0.5) times the theory's outlet and steps by
``hunt_factor`` (1.3) until the outcome changes, then halves the bracket geometrically (D0
rounded to 0.1 mm).  Bisections are sequential; the cases are independent Dask tasks, each
doing its own bisection (``--serial``: one after the other in this process).  Every run is an
ordinary run directory ``cases/<case>_D0mm<D0>``, run with one numba thread (also with
``--serial``: these grids are small, and on a loaded machine a multi-threaded run of a few
thousand cells is many times slower than a single-threaded one), read, not rerun, when it
has finished (the restart rule of ``_sweep``): a restarted study replays the bisections from the
finished runs.

Compared with: Jenike's ``D_crit = H(theta) sigma_c / (rho g)``, ``H = 2 + theta/60``, for
the cones (:func:`fipy_hopper.theory.jenike_critical_outlet`) and the simplified
``2 sigma_c / (rho g)`` for the flat bottom (:func:`fipy_hopper.theory.
critical_outlet_simplified`; Jenike's H is for mass-flow hoppers).  Reported: every case's
bracket and the ratio simulated / theory (at the bracket's geometric mid-point, with its
range), the ratio's spread across cases, the exponent ``n`` of ``D_crit ~ (sigma_c/(rho
g))^n`` per geometry (least squares in log space; 1 for a rate-independent continuum by
dimensional analysis), and the E check: one case bisected at E = 2 and 20 MPa.

The rathole case: a funnel-flow hopper (60 deg cone, phi_w = 25 deg, default 0.48 m bin,
0.18 m outlet, 0.3 m fill) with ``sigma_c / (rho g)`` = 0.12 m, so that Jenike's critical
rathole diameter ``G(phi) sigma_c / (rho g)`` (:func:`fipy_hopper.theory.
jenike_rathole_diameter`, 0.283 m) is larger than the outlet: Jenike expects a stable
rathole.  The outlet sits between two measured limits of this hopper, opened over ten column
periods at 5 mm: at 0.16 m the outlet arches, at 0.2 m a narrower rathole stands with a third
of the mass, and at 0.22 m the bin empties down to dead zones on the cone (opened at once,
0.16 m left a rathole).  Run until empty or at rest (capped at
``rathole_max_time``, 6 s) beside the same hopper without cohesion; reported: the outcome, the
mass left, when the flow stopped, and the empty channel of the final state
(:func:`fipy_hopper.diagnostics.empty_channel`) against Jenike's diameter.

Written to ``--out`` (default ``studies/output/arching``): ``results.csv`` (every run),
``brackets.csv`` (every bisection), ``study.json``, ``critical_outlet.png``,
``outcomes.png`` (the final states of an arching and a flowing run and of the rathole case)
and ``cases/``.

Default cost: see ``study.json`` (``study_wall_time_s``; a 2-worker local cluster); a
restart that finds every run finished takes seconds.

Usage::

    python studies/arching.py [--out DIR] [--quick] [--serial | --scheduler ADDRESS]
                              [--cell-size 0.005] [--heads 0.055 0.08 0.11]
                              [--half-angles 20 30 90] [--tolerance 1.05]
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

from fipy_hopper import theory  # noqa: E402
from fipy_hopper.diagnostics import fit_power_law  # noqa: E402

_r = _sweep.rounded
NAME = "arching"
TITLE = "Cohesive arching: simulated critical outlet against Jenike, and a rathole case"
ARCH_LEFT = 0.9            # an arch: the flow stopped with more than this fraction left
DEFAULTS = {
    "heads": (0.055, 0.08, 0.11),   # sigma_c / (rho g) (m): the cohesions
    "half_angles": (20.0, 30.0, 90.0),  # cone half-angles (deg); 90 = flat bottom
    "friction_angle": 30.0,         # phi (deg)
    "wall_friction": 15.0,          # phi_w (deg)
    "density": 1500.0,              # kg/m3
    "youngs_modulus": 5.0e6,        # Pa
    "bin_diameter": 0.48,           # m (2.5 x the largest D0 tried; 96 cells of 5 mm)
    "fill_height": 0.2,             # m above the transition
    "cell_size": 0.005,             # m (4.5 cells across the radius of a 45 mm outlet)
    "max_discharge_time": 1.2,      # s: the cap of a discharge (a flow still running = flows)
    "opening_periods": 10.0,        # the outlet opens over this many column periods (0: at once)
    "tolerance": 1.05,              # bracket D_flow / D_arch at the end of a bisection
    "guess_ratio": 0.5,             # first D0 of a bisection, times the theory's D_crit
    "hunt_factor": 1.3,             # step of D0 until the outcome changes
    "e_check_half_angle": 20.0,     # the E check: this geometry ...
    "e_check_head": 0.08,           # ... and cohesion (m), bisected at each modulus
    "e_check_moduli": (2.0e6, 2.0e7),
    "rathole_half_angle": 60.0,     # deg
    "rathole_wall_friction": 25.0,  # deg
    "rathole_bin_diameter": 0.48,   # m
    "rathole_outlet": 0.18,         # m
    "rathole_fill_height": 0.3,     # m above the transition
    "rathole_head": 0.12,           # sigma_c / (rho g) (m)
    "rathole_max_time": 6.0,        # s
    "case_plots": False,            # each run draws its own pictures (many short runs: off)
}
QUICK = {"heads": (0.06, 0.08), "half_angles": (20.0,), "bin_diameter": 0.3,
         "fill_height": 0.1, "cell_size": 0.01, "max_discharge_time": 0.8, "tolerance": 1.1,
         "e_check_head": 0.06, "e_check_moduli": (2.0e7,), "rathole_bin_diameter": 0.3,
         "rathole_outlet": 0.1,
         "rathole_fill_height": 0.12, "rathole_head": 0.06, "rathole_max_time": 0.8}


# ---------------------------------------------------------------- theory
def cohesion_of(head: float, opts: dict) -> float:
    """The cohesion c (Pa) whose unconfined yield strength is ``head * rho g``."""
    phi = math.radians(opts["friction_angle"])
    sigma_c = head * opts["density"] * theory.G
    return sigma_c * (1.0 - math.sin(phi)) / (2.0 * math.cos(phi))


def theory_outlet(theta: float, head: float, opts: dict) -> float:
    """Jenike's ``H(theta) sigma_c / (rho g)`` for a cone, the simplified ``2 sigma_c / (rho g)``
    for a flat bottom (m)."""
    sigma_c = head * opts["density"] * theory.G
    if theta >= 90.0:
        return float(theory.critical_outlet_simplified(sigma_c, opts["density"]))
    return float(theory.jenike_critical_outlet(sigma_c, opts["density"], theta))


def theory_name(theta: float) -> str:
    return "simplified 2 sigma_c/(rho g)" if theta >= 90.0 else "Jenike H(theta) sigma_c/(rho g)"


def geometry_label(theta: float) -> str:
    return "flat bottom" if theta >= 90.0 else f"{theta:g} deg cone"


# ---------------------------------------------------------------- cases
def _config(opts, theta, d0, head, modulus, wall=None, bin_diameter=None, fill=None,
            max_time=None) -> dict:
    fill = opts["fill_height"] if fill is None else fill
    return {"hopper": {"bin_diameter": opts["bin_diameter"] if bin_diameter is None
                       else bin_diameter,
                       "half_angle_deg": theta, "outlet_diameter": d0,
                       "fill_height": fill, "bin_height": round(fill + 0.02, 6)},
            "material": {"density": opts["density"], "friction_angle_deg": opts["friction_angle"],
                         "youngs_modulus": modulus, "cohesion": cohesion_of(head, opts)},
            "wall": {"friction_angle_deg": opts["wall_friction"] if wall is None else wall},
            "numerics": {"cell_size": opts["cell_size"]},
            "run": {"end_time": "empty",
                    "max_time": opts["max_discharge_time"] if max_time is None else max_time,
                    "output_interval": 0.02, "field_interval": 0.25}}


def with_opening(config: dict, periods: float) -> dict:
    """``config`` with the outlet opening over ``periods`` periods of its filled column's
    lowest mode (``HopperConfig.column_period``) and the discharge cap moved on by as much."""
    if periods <= 0.0:
        return config
    opening = round(periods * _sweep._config(config).column_period, 6)
    return _sweep.merge(config, run={"opening_time": opening,
                                     "max_time": round(config["run"]["max_time"] + opening, 6)})


def bisection(opts, theta, head, modulus, label="main") -> dict:
    """A bisection task: the fixed sections of its runs and how to search D0."""
    h = opts["cell_size"]
    key = (f"theta{_sweep.fmt(theta)}_s{_sweep.fmt(round(1000 * head, 3))}mm"
           f"_E{_sweep.fmt(round(modulus / 1e6, 3))}MPa")
    d_theory = theory_outlet(theta, head, opts)
    return {"kind": "bisection", "key": key, "label": label,
            "params": {"half_angle_deg": theta, "head_m": head,
                       "cohesion_pa": cohesion_of(head, opts), "youngs_modulus_pa": modulus},
            "config": _config(opts, theta, 0.0, head, modulus),
            "d_theory": d_theory,
            "d_min": math.ceil(6.0 * h * 1e4 - 1e-6) / 1e4,        # 3 cells across the radius
            "d_max": math.floor(opts["bin_diameter"] / 2.5 * 1e4 + 1e-6) / 1e4,
            "guess": opts["guess_ratio"] * d_theory,
            "hunt": opts["hunt_factor"], "tolerance": opts["tolerance"],
            "opening_periods": opts["opening_periods"], "plots": opts["case_plots"]}


def rathole_task(opts) -> dict:
    """The rathole case and its cohesionless twin (two plain runs)."""
    theta, wall = opts["rathole_half_angle"], opts["rathole_wall_friction"]
    d0, head = opts["rathole_outlet"], opts["rathole_head"]
    cases = []
    for label, s in (("cohesive", head), ("cohesionless", 0.0)):
        name = _sweep.case_name(("rathole_theta", theta), ("wall", wall),
                                ("D0mm", round(1000 * d0, 3)), ("s", round(1000 * s, 3)))
        cfg = _config(opts, theta, d0, s, opts["youngs_modulus"], wall=wall,
                      bin_diameter=opts["rathole_bin_diameter"],
                      fill=opts["rathole_fill_height"], max_time=opts["rathole_max_time"])
        cases.append(_sweep.make_case(name, {"rathole_run": label, "half_angle_deg": theta,
                                             "wall_friction_deg": wall, "outlet_diameter_m": d0,
                                             "head_m": s, "cohesion_pa": cohesion_of(s, opts)},
                                      with_opening(cfg, opts["opening_periods"]),
                                      plots=opts["case_plots"]))
    return {"kind": "runs", "key": "rathole", "label": "rathole", "cases": cases}


def setup(quick: bool = False, **options) -> dict:
    """The tasks and options: ``{"options", "tasks", "setting"}`` (each task a bisection or
    the rathole pair); unknown options raise ``TypeError``."""
    opts = _sweep.resolve_options(DEFAULTS, options, QUICK if quick else None)
    if not opts["tolerance"] <= 1.1:
        raise ValueError(f"tolerance = {opts['tolerance']}: at most 1.1 (a 10 % bracket)")
    tasks = []
    for theta in opts["half_angles"]:
        for head in opts["heads"]:
            tasks.append(bisection(opts, float(theta), float(head), opts["youngs_modulus"]))
    for modulus in opts["e_check_moduli"]:
        task = bisection(opts, float(opts["e_check_half_angle"]), float(opts["e_check_head"]),
                         float(modulus), label="e_check")
        if task["key"] not in [t["key"] for t in tasks]:
            tasks.append(task)
    for task in tasks:                 # every D0 a bisection may try is a valid configuration
        for d0 in (task["d_min"], task["d_max"]):
            _sweep.make_case("check", {}, _sweep.merge(task["config"],
                                                       hopper={"outlet_diameter": d0}))
    tasks.append(rathole_task(opts))
    return {"options": opts, "tasks": tasks, "setting": _sweep.setting_label(quick, options)}


# ---------------------------------------------------------------- one task (runs on a worker)
def _number(value) -> float:
    """``value`` as a float; NaN for a run that failed or did not measure it (None)."""
    return math.nan if value is None else float(value)


def outcome(row: dict) -> str:
    """``"arches"``, ``"flows"`` or ``"failed"`` of a run's row (see the module docstring)."""
    if row.get("error") or not _sweep.finite(row.get("remaining_mass_fraction")):
        return "failed"
    stopped = _sweep.finite(row.get("flow_stopped_time_s"))
    return "arches" if stopped and row["remaining_mass_fraction"] > ARCH_LEFT else "flows"


def _run_line(name: str, row: dict, text: str) -> str:
    """The progress line of one run: ``text``, or the run's error when it failed."""
    return f"  {name}: " + (f"FAILED: {row['error']}" if row.get("error") else text)


def run_task(task: dict, root, force: bool = False, threads=1, log=None) -> dict:
    """Run one task: a bisection on D0 (each of its runs through ``_sweep.run_case``, so a
    finished run is read, not rerun) or a list of plain runs.  Never raises for a failed run."""
    started = time.perf_counter()
    if task["kind"] == "runs":
        rows = []
        for case in task["cases"]:
            row = _sweep.run_case(case, root, force=force, threads=threads)
            row["outcome"] = outcome(row)
            rows.append(row)
            if log:
                log(_run_line(case["name"], row, f"{row.get('flow_mode')}, "
                              f"{_number(row.get('remaining_mass_fraction')):.3f} left"))
        return {"key": task["key"], "kind": "runs", "label": task["label"], "runs": rows,
                "task_wall_time_s": time.perf_counter() - started}
    runs = {}

    def probe(d0):
        d0 = round(d0, 4)
        if d0 not in runs:
            case = _sweep.make_case(
                f"{task['key']}_D0mm{_sweep.fmt(round(1000 * d0, 1))}",
                {**task["params"], "outlet_diameter_m": d0},
                with_opening(_sweep.merge(task["config"], hopper={"outlet_diameter": d0}),
                             task["opening_periods"]),
                plots=task["plots"])
            row = _sweep.run_case(case, root, force=force, threads=threads)
            row["outcome"] = outcome(row)
            row["step"] = len(runs)
            runs[d0] = row
            if log:
                log(_run_line(case["name"], row, f"{row['outcome']} ({row.get('flow_mode')}, "
                              f"{_number(row.get('remaining_mass_fraction')):.4f} left"
                              + (", reused" if row.get("reused") else "") + ")"))
        return runs[d0]["outcome"]

    lo = hi = None          # the largest D0 that arched, the smallest that flowed
    status = "bracketed"
    d = min(max(task["guess"], task["d_min"]), task["d_max"])
    while True:                                        # hunt: step until the outcome changes
        o = probe(d)
        d = round(d, 4)
        if o == "failed":
            status = f"a run failed at D0 = {d:g} m"
            break
        if o == "arches":
            lo = d if lo is None else max(lo, d)
            if hi is not None:
                break
            if d >= task["d_max"]:
                status = "arches at the largest D0 allowed"
                break
            d = min(d * task["hunt"], task["d_max"])
        else:
            hi = d if hi is None else min(hi, d)
            if lo is not None:
                break
            if d <= task["d_min"]:
                status = "flows at the smallest D0 allowed"
                break
            d = max(d / task["hunt"], task["d_min"])
    while status == "bracketed" and hi / lo > task["tolerance"] + 1e-12:   # bisect
        mid = round(math.sqrt(lo * hi), 4)
        if mid in (lo, hi):
            break
        o = probe(mid)
        if o == "failed":
            status = f"a run failed at D0 = {mid:g} m"
            break
        if o == "arches":
            lo = mid
        else:
            hi = mid
    order = sorted(runs.values(), key=lambda r: r["step"])
    return {"key": task["key"], "kind": "bisection", "label": task["label"],
            "params": task["params"], "d_theory": task["d_theory"], "status": status,
            "d_arch": lo, "d_flow": hi, "runs": order,
            "task_wall_time_s": time.perf_counter() - started}


# ---------------------------------------------------------------- running the tasks
def run_tasks(tasks: list, args, log=print) -> list:
    """Run the tasks (Dask local cluster, ``--scheduler`` or ``--serial``); results in order."""
    root = Path(args.out).resolve()
    (root / _sweep.CASES).mkdir(parents=True, exist_ok=True)
    results = {}
    started = time.perf_counter()

    def report(k, res):
        if res["kind"] == "bisection":
            text = (f"[{res['d_arch']}, {res['d_flow']}] m ({res['status']}), "
                    f"{len(res['runs'])} runs")
        else:
            text = ", ".join(f"{r['case']}: {r.get('flow_mode')}" for r in res["runs"])
        log(f"[{k}/{len(tasks)}] {res['key']}: {text} "
            f"({time.perf_counter() - started:.0f} s elapsed)")

    if args.serial:
        for k, task in enumerate(tasks, 1):
            log(f"{task['key']}:")
            res = run_task(task, root, force=args.force, threads=1, log=log)
            results[res["key"]] = res
            report(k, res)
    else:
        import cloudpickle

        module = sys.modules.get(__name__)
        if module is not None and __name__ != "__main__":
            cloudpickle.register_pickle_by_value(module)   # the workers need no studies/
        order = sorted(tasks, key=_task_cost, reverse=True)
        with _sweep._client(args.scheduler, args.workers, len(tasks), log) as client:
            from dask.distributed import as_completed

            futures = client.map(run_task, order, root=str(root), force=args.force, pure=False)
            task_of = dict(zip(futures, order))
            for k, fut in enumerate(as_completed(futures), 1):
                try:
                    res = fut.result()
                except Exception as exc:      # the worker died: keep going
                    t = task_of[fut]
                    res = {"key": t["key"], "kind": t["kind"], "label": t["label"],
                           "params": t.get("params", {}), "d_theory": t.get("d_theory"),
                           "status": f"worker lost: {type(exc).__name__}: {exc}",
                           "d_arch": None, "d_flow": None, "runs": []}
                results[res["key"]] = res
                report(k, res)
    return [results[t["key"]] for t in tasks]


def _task_cost(task) -> float:
    """A relative cost to start the longest tasks first (stiffer and longer runs)."""
    case = task["cases"][0] if task["kind"] == "runs" else {"config": _sweep.merge(
        task["config"], hopper={"outlet_diameter": task["d_max"]})}
    cost = _sweep.estimated_cost(case["config"])
    return cost * (len(task["cases"]) if task["kind"] == "runs" else 5)


# ---------------------------------------------------------------- analysis
def analyse(results: list, options: dict) -> dict:
    """Per-bisection numbers (added to each result), the ratio spread, the exponent fits,
    the E check and the rathole case; returns ``numbers``."""
    for res in results:
        if res["kind"] != "bisection":
            continue
        lo, hi, dt = res["d_arch"], res["d_flow"], res["d_theory"]
        ok = lo is not None and hi is not None and res["status"] == "bracketed"
        res["d_crit"] = math.sqrt(lo * hi) if ok else math.nan
        res["bracket_width"] = hi / lo - 1.0 if ok else math.nan
        res["ratio"] = res["d_crit"] / dt if ok else math.nan
        res["ratio_low"] = lo / dt if lo is not None else math.nan
        res["ratio_high"] = hi / dt if hi is not None else math.nan
        res["new_runs"] = sum(1 for r in res["runs"] if not r.get("reused"))
        res["late_stops"] = [r["outlet_diameter_m"] for r in res["runs"]
                             if r["outcome"] == "flows"
                             and _sweep.finite(r.get("flow_stopped_time_s"))]
    modulus = options["youngs_modulus"]
    main = [r for r in results if r["kind"] == "bisection"
            and r["params"]["youngs_modulus_pa"] == modulus and r["label"] == "main"]
    good = [r for r in main if math.isfinite(r["d_crit"])]
    ratios = np.array([r["ratio"] for r in good])
    numbers = {"cases": len(main), "bracketed": len(good),
               "runs": sum(len(r["runs"]) for r in results),
               "runs_new": sum(1 for r in results for x in r["runs"] if not x.get("reused")),
               "largest_bracket_width": max([r["bracket_width"] for r in good], default=math.nan)}
    if len(ratios):
        numbers.update(ratio_min=float(ratios.min()), ratio_max=float(ratios.max()),
                       ratio_mean=float(ratios.mean()),
                       ratio_spread_max_over_min=float(ratios.max() / ratios.min()),
                       ratio_cv=float(ratios.std() / ratios.mean()))
    fits = []
    for theta in options["half_angles"]:
        sel = sorted([r for r in good if r["params"]["half_angle_deg"] == float(theta)],
                     key=lambda r: r["params"]["head_m"])
        tag = f"theta{float(theta):g}"
        rs = np.array([r["ratio"] for r in sel])
        if len(rs):
            numbers[f"ratio_mean_{tag}"] = float(rs.mean())
            numbers[f"ratio_spread_{tag}"] = float(rs.max() / rs.min())
        if len(sel) < 2:
            continue
        x = np.array([r["params"]["head_m"] for r in sel])
        a, n = fit_power_law(x, [r["d_crit"] for r in sel])
        _, n_lo = fit_power_law(x, [r["d_arch"] for r in sel])
        _, n_hi = fit_power_law(x, [r["d_flow"] for r in sel])
        # the steepest and flattest power laws through the brackets of the two ends
        n_max = math.log(sel[-1]["d_flow"] / sel[0]["d_arch"]) / math.log(x[-1] / x[0])
        n_min = math.log(sel[-1]["d_arch"] / sel[0]["d_flow"]) / math.log(x[-1] / x[0])
        fits.append({"half_angle_deg": float(theta), "cases": len(sel), "exponent_n": n,
                     "prefactor_a": a, "exponent_fit_lower_ends": n_lo,
                     "exponent_fit_upper_ends": n_hi, "exponent_min_end_brackets": n_min,
                     "exponent_max_end_brackets": n_max})
        numbers[f"exponent_n_{tag}"] = n
        numbers[f"exponent_range_{tag}"] = [n_min, n_max]
    numbers["exponent_within_1pm0.1"] = bool(fits) and all(
        abs(f["exponent_n"] - 1.0) <= 0.1 for f in fits)
    # E check
    theta_e, head_e = float(options["e_check_half_angle"]), float(options["e_check_head"])
    e_rows = sorted([r for r in results if r["kind"] == "bisection"
                     and r["params"]["half_angle_deg"] == theta_e
                     and r["params"]["head_m"] == head_e], key=lambda r:
                    r["params"]["youngs_modulus_pa"])
    checked = e_rows                  # the moduli of the check and the study's own
    numbers["e_check"] = {f"E{r['params']['youngs_modulus_pa'] / 1e6:g}MPa":
                          [r["d_arch"], r["d_flow"]] for r in e_rows}
    if len(checked) >= 2 and all(r["d_arch"] is not None and r["d_flow"] is not None
                                 for r in checked):
        same = all((r["d_arch"], r["d_flow"]) == (checked[0]["d_arch"], checked[0]["d_flow"])
                   for r in checked)
        overlap = max(r["d_arch"] for r in checked) < min(r["d_flow"] for r in checked)
        numbers["e_check_same_bracket"] = same
        numbers["e_check_brackets_overlap"] = overlap
    # rathole
    rat = next((r for r in results if r["kind"] == "runs"), None)
    if rat is not None:
        numbers["rathole"] = rathole_numbers(rat, options)
    numbers["failed"] = [r["key"] for r in results
                         if r["kind"] == "bisection" and r["status"] != "bracketed"]
    numbers["failed_runs"] = [x["case"] for r in results for x in r["runs"] if x.get("error")]
    return numbers, fits


def final_state(run_dir):
    """The last discharge snapshot of a run (``plotting.load_snapshot``), or ``None``."""
    from fipy_hopper import plotting

    snaps = [e for e in plotting.snapshots(run_dir) if e["stage"] == "discharge"]
    return plotting.load_snapshot(run_dir, snaps[-1]) if snaps else None


class _Grid:
    def __init__(self, snap):
        self.r_cells = 0.5 * (snap["r_nodes"][1:] + snap["r_nodes"][:-1])
        self.z_nodes = snap["z_nodes"]
        self.z_cells = 0.5 * (snap["z_nodes"][1:] + snap["z_nodes"][:-1])
        self.kappa = snap["open_fraction"]


class _Holder:
    def __init__(self, **kw):
        self.__dict__.update(kw)


def rathole_numbers(rat: dict, options: dict) -> dict:
    """Outcome, mass left, stop time and the empty channel of the final state of the rathole
    case, beside Jenike's rathole diameter and the cohesionless twin."""
    from fipy_hopper import diagnostics

    head = options["rathole_head"]
    sigma_c = head * options["density"] * theory.G
    out = {"jenike_rathole_diameter_m": float(theory.jenike_rathole_diameter(
        sigma_c, options["density"], options["friction_angle"])),
        "jenike_critical_outlet_m": theory_outlet(options["rathole_half_angle"], head, options),
        "bin_diameter_m": options["rathole_bin_diameter"],
        "outlet_diameter_m": options["rathole_outlet"]}
    for r in rat["runs"]:
        tag = r["rathole_run"]
        d, h = math.nan, math.nan
        snap = final_state(r["run_dir"]) if Path(r["run_dir"]).is_dir() else None
        if snap is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                d, h = diagnostics.empty_channel(_Holder(grid=_Grid(snap)),
                                                 _Holder(alpha=snap["alpha"]))
        out[tag] = {"flow_mode": r.get("flow_mode"), "stop_reason": r.get("stop_reason"),
                    "remaining_mass_fraction": r.get("remaining_mass_fraction"),
                    "flow_stopped_time_s": r.get("flow_stopped_time_s"),
                    "rathole_diameter_m": r.get("rathole_diameter_m"),
                    "final_channel_diameter_m": d, "final_channel_height_m": h,
                    "mass_flow_index": r.get("mass_flow_index"),
                    "discharge_time_s": r.get("discharge_time_s")}
    return out


# ---------------------------------------------------------------- figures
COLOURS = {20.0: "C0", 30.0: "C1", 90.0: "C2"}


def plot_critical_outlet(results, fits, options):
    fig = _sweep.figure(11.0, 4.6)
    ax, bx = fig.subplots(1, 2)
    main = [r for r in results if r["kind"] == "bisection" and r["label"] == "main"]
    heads = np.array(sorted({r["params"]["head_m"] for r in main}))
    if len(heads) == 0:
        return fig
    xx = np.linspace(0.0, heads.max() * 1.15, 50)
    for k, theta in enumerate(options["half_angles"]):
        theta = float(theta)
        colour = COLOURS.get(theta, f"C{k + 3}")
        sel = sorted([r for r in main if r["params"]["half_angle_deg"] == theta],
                     key=lambda r: r["params"]["head_m"])
        th = [theory_outlet(theta, x, options) for x in xx]
        ax.plot(xx, th, "--", color=colour, lw=1.0,
                label=f"{geometry_label(theta)}: {theory_name(theta)}")
        x = np.array([r["params"]["head_m"] for r in sel])
        lo = np.array([r["d_arch"] if r["d_arch"] is not None else np.nan for r in sel], float)
        hi = np.array([r["d_flow"] if r["d_flow"] is not None else np.nan for r in sel], float)
        mid = np.sqrt(lo * hi)
        ax.errorbar(x, mid, yerr=[mid - lo, hi - mid], fmt="o", color=colour, mec="k",
                    capsize=3, label=f"{geometry_label(theta)}: simulated bracket")
        fit = next((f for f in fits if f["half_angle_deg"] == theta), None)
        if fit:
            xf = np.linspace(x.min() * 0.9, x.max() * 1.1, 20)
            ax.plot(xf, fit["prefactor_a"] * xf ** fit["exponent_n"], "-", color=colour, lw=0.8,
                    alpha=0.7, label=f"fit, n = {fit['exponent_n']:.2f}")
        bx.errorbar(x, [r["ratio"] for r in sel],
                    yerr=[[r["ratio"] - r["ratio_low"] for r in sel],
                          [r["ratio_high"] - r["ratio"] for r in sel]],
                    fmt="o-", color=colour, mec="k", capsize=3, label=geometry_label(theta))
    e_rows = [r for r in results if r["kind"] == "bisection" and r["label"] == "e_check"]
    for k, r in enumerate(e_rows):
        if r["d_arch"] is None or r["d_flow"] is None:
            continue
        x = r["params"]["head_m"] * (1.0 + 0.025 * (k + 1))
        mid = math.sqrt(r["d_arch"] * r["d_flow"])
        ax.errorbar([x], [mid], yerr=[[mid - r["d_arch"]], [r["d_flow"] - mid]], fmt="s",
                    color="0.4", mfc="w", capsize=3,
                    label=f"E = {r['params']['youngs_modulus_pa'] / 1e6:g} MPa "
                          f"({geometry_label(r['params']['half_angle_deg'])})")
    ax.set_xlim(0.0, xx[-1])
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("sigma_c / (rho g) (m)")
    ax.set_ylabel("critical outlet D_crit (m)")
    ax.set_title("Critical outlet: simulated brackets (largest D0 that arches, smallest that "
                 "flows) and theory", fontsize=8)
    ax.legend(fontsize=6, loc="upper left")
    bx.set_xlabel("sigma_c / (rho g) (m)")
    bx.set_ylabel("D_crit simulated / theory")
    bx.set_ylim(bottom=0.0)
    bx.axhline(1.0, color="k", lw=0.8, ls=":")
    bx.set_title("Ratio to Jenike (cones) or the simplified rule (flat); bars: the bracket",
                 fontsize=8)
    bx.legend(fontsize=7)
    return fig


def plot_outcomes(results, options):
    """The final states of the arching and flowing runs that bound one bracket, and of the
    rathole case with its cohesionless twin."""
    from fipy_hopper import geometry, plotting
    from fipy_hopper.api import load_config

    picked = []
    main = [r for r in results if r["kind"] == "bisection" and r["d_arch"] is not None
            and r["d_flow"] is not None]
    if main:
        res = main[len(main) // 2]
        for d, what in ((res["d_arch"], "largest that arches"),
                        (res["d_flow"], "smallest that flows")):
            run = next(x for x in res["runs"] if x["outlet_diameter_m"] == d)
            picked.append((run, f"{geometry_label(res['params']['half_angle_deg'])}, "
                                f"s = {1000 * res['params']['head_m']:g} mm\nD0 = "
                                f"{1000 * d:g} mm ({what})"))
    rat = next((r for r in results if r["kind"] == "runs"), None)
    if rat:
        for run in rat["runs"]:
            picked.append((run, f"rathole case, {run['rathole_run']}\n"
                                f"{run.get('flow_mode')}, "
                                f"{100 * _number(run.get('remaining_mass_fraction')):.0f} % left"))
    picked = [(run, t) for run, t in picked if Path(run.get("run_dir", "")).is_dir()]
    if not picked:
        return None
    fig = _sweep.figure(2.6 * len(picked) + 0.4, 4.2)
    axes = fig.subplots(1, len(picked), squeeze=False)[0]
    for ax, (run, title) in zip(axes, picked):
        snap = final_state(run["run_dir"])
        if snap is None:
            ax.set_axis_off()
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cfg = load_config(Path(run["run_dir"]) / "config.toml")
        rr = snap["r_nodes"]
        wall = geometry.wall_polyline(cfg.hopper, rr[-1], cfg.hopper.top)
        for sign in (-1.0, 1.0):
            plotting.draw_layers(ax, snap, side=sign)
            ax.plot(sign * wall[:, 0], wall[:, 1], "k-", lw=0.8)
        ax.set_aspect("equal")
        ax.set_xlim(-rr[-1], rr[-1])
        ax.set_ylim(-0.03, cfg.hopper.fill_level + 0.01)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{title}\nt = {snap['discharge_time_s']:.2f} s", fontsize=7)
    fig.suptitle("Final states (layers; cells with alpha < 1/2 blank where there are no "
                 "markers)", fontsize=9)
    return fig


# ---------------------------------------------------------------- outputs
def _bracket_text(r) -> str:
    return (f"[{1000 * r['d_arch']:.1f}, {1000 * r['d_flow']:.1f}] mm"
            if r["d_arch"] is not None and r["d_flow"] is not None else
            f"({r['status']})")


def write_outputs(out, results, numbers, fits, options, setting, argv=None):
    out = Path(out)
    rows = [{"task": res["key"], **x} for res in results for x in res["runs"]]
    _sweep.write_rows_csv(out / "results.csv", rows, first=(
        "task", "case", "half_angle_deg", "head_m", "cohesion_pa", "youngs_modulus_pa",
        "outlet_diameter_m", "outcome", "flow_mode", "remaining_mass_fraction",
        "flow_stopped_time_s", "stop_reason", "discharge_time_s", "fill_at_rest", "step",
        "reused", "wall_time_s", "error"))
    bis = [r for r in results if r["kind"] == "bisection"]
    _sweep.write_rows_csv(out / "brackets.csv", [
        {"task": r["key"], "label": r["label"], **r["params"], "status": r["status"],
         "d_arch_m": r["d_arch"], "d_flow_m": r["d_flow"], "d_crit_m": r["d_crit"],
         "bracket_width": r["bracket_width"], "d_theory_m": r["d_theory"],
         "theory": theory_name(r["params"]["half_angle_deg"]), "ratio": r["ratio"],
         "ratio_low": r["ratio_low"], "ratio_high": r["ratio_high"], "runs": len(r["runs"]),
         "late_stops_d0_m": r["late_stops"],
         "task_wall_time_s": r.get("task_wall_time_s", math.nan)} for r in bis])
    _sweep.write_rows_csv(out / "fits.csv", fits)
    figures = []
    _sweep.save(plot_critical_outlet(results, fits, options), out / "critical_outlet.png")
    figures.append({"file": "critical_outlet.png",
                    "caption": "Left: simulated critical outlet (bars: the bracket, largest D0 "
                               "that arches to smallest that flows) against sigma_c/(rho g), "
                               "with Jenike's H(theta) sigma_c/(rho g) for the cones and "
                               "2 sigma_c/(rho g) for the flat bottom (dashed), the power-law "
                               "fits, and the E check (squares, drawn slightly to the right). "
                               "Right: the ratio simulated / theory."})
    thumbs = plot_outcomes(results, options)
    if thumbs is not None:
        _sweep.save(thumbs, out / "outcomes.png")
        figures.append({"file": "outcomes.png",
                        "caption": "Final states: the two runs bounding one bracket (an arch "
                                   "over the outlet; a flow still running at the cap) and the "
                                   "rathole case beside the same hopper without cohesion."})
    cap = options["max_discharge_time"]
    opts_periods = options.get("opening_periods", 0.0)
    findings = []
    if "ratio_mean" in numbers:
        findings.append(
            f"Simulated critical outlet / theory over {numbers['bracketed']} cases: "
            f"{numbers['ratio_min']:.2f} to {numbers['ratio_max']:.2f} (mean "
            f"{numbers['ratio_mean']:.2f}, max/min {numbers['ratio_spread_max_over_min']:.2f}, "
            f"CV {100 * numbers['ratio_cv']:.0f} %); per geometry: " + "; ".join(
                f"{geometry_label(float(t))} {numbers[f'ratio_mean_theta{float(t):g}']:.2f} "
                f"(spread x{numbers[f'ratio_spread_theta{float(t):g}']:.2f})"
                for t in options["half_angles"]
                if f"ratio_mean_theta{float(t):g}" in numbers) + ".")
    for f in fits:
        findings.append(
            f"{geometry_label(f['half_angle_deg'])}: D_crit ~ (sigma_c/(rho g))^n with n = "
            f"{f['exponent_n']:.3f} (fit to the brackets' mid-points; "
            f"{f['exponent_fit_lower_ends']:.3f}"
            f" to the lower ends, {f['exponent_fit_upper_ends']:.3f} to the upper ends; any "
            f"power law through the end brackets has n in [{f['exponent_min_end_brackets']:.2f},"
            f" {f['exponent_max_end_brackets']:.2f}]).")
    for r in bis:
        if r["label"] != "main":
            continue
        p = r["params"]
        findings.append(
            f"{geometry_label(p['half_angle_deg'])}, sigma_c/(rho g) = {1000 * p['head_m']:g} mm "
            f"(c = {p['cohesion_pa']:.0f} Pa): bracket {_bracket_text(r)}"
            + (f" (width {100 * r['bracket_width']:.1f} %)" if math.isfinite(r["bracket_width"])
               else "")
            + f", theory {1000 * r['d_theory']:.1f} mm, ratio {r['ratio']:.3f} "
              f"[{r['ratio_low']:.3f}, {r['ratio_high']:.3f}]"
            + (f"; flowed then stopped (stop after > 10 % out, counted as flows) at D0 = "
               + ", ".join(f"{1000 * d:g}" for d in r["late_stops"]) + " mm"
               if r["late_stops"] else "") + ".")
    e_rows = [r for r in bis if r["params"]["half_angle_deg"] == float(
        options["e_check_half_angle"]) and r["params"]["head_m"] == float(options["e_check_head"])]
    if e_rows:
        verdict = ("the same bracket" if numbers.get("e_check_same_bracket") else
                   "overlapping brackets" if numbers.get("e_check_brackets_overlap") else
                   "brackets that do not overlap")
        findings.append(
            f"E check ({geometry_label(float(options['e_check_half_angle']))}, "
            f"sigma_c/(rho g) = {1000 * float(options['e_check_head']):g} mm): " + "; ".join(
                f"E = {r['params']['youngs_modulus_pa'] / 1e6:g} MPa {_bracket_text(r)}"
                for r in sorted(e_rows, key=lambda r: r["params"]["youngs_modulus_pa"]))
            + f": {verdict} at " + " and ".join(
                f"{float(m) / 1e6:g}" for m in options["e_check_moduli"]) + " MPa.")
    rat = numbers.get("rathole")
    if rat:
        co, c0 = rat.get("cohesive", {}), rat.get("cohesionless", {})

        def mm(x):
            return f"{1000 * x:.0f} mm" if _sweep.finite(x) else "none"

        findings.append(
            f"Rathole case ({options['rathole_half_angle']:g} deg cone, phi_w = "
            f"{options['rathole_wall_friction']:g} deg, {1000 * options['rathole_bin_diameter']:g}"
            f" mm bin, D0 = {1000 * options['rathole_outlet']:g} mm, sigma_c/(rho g) = "
            f"{1000 * options['rathole_head']:g} mm; Jenike's rathole diameter "
            f"{mm(rat['jenike_rathole_diameter_m'])}, larger than the outlet, so Jenike expects a "
            f"stable rathole): outcome {co.get('flow_mode')} ({co.get('stop_reason')}), "
            f"{100 * _number(co.get('remaining_mass_fraction')):.1f} % of the mass left, flow "
            f"stopped at {_number(co.get('flow_stopped_time_s')):.2f} s, reported rathole "
            f"diameter {mm(co.get('rathole_diameter_m'))}, empty channel through the final "
            f"state {mm(co.get('final_channel_diameter_m'))}; without cohesion "
            f"{c0.get('flow_mode')} ({c0.get('stop_reason')}), "
            f"{100 * _number(c0.get('remaining_mass_fraction')):.1f} % left.")
    runs = [x for r in results for x in r["runs"]]
    unsettled = [x for x in runs if x.get("fill_at_rest") is False]
    if unsettled:
        worst = max(float(x.get("fill_equilibrium_residual", math.nan)) for x in unsettled)
        findings.append(
            f"Fills that reached max_fill_time without passing the at-rest test: "
            f"{len(unsettled)} of {len(runs)} runs (cohesive cones); their walls and plate "
            f"carry the weight to within {worst:.1e} of it. In the case traced, a wall node "
            f"whose only open cell is a small cut cell at the cohesive apex is pulled off the "
            f"wall and kept at a terminal velocity by the fill's damping, moving no material "
            f"(docs/physics_and_numerics.md, section 6); the discharge starts from that state.")
    findings.append(
        f"Outcome rule: arches = the flow stopped (at-rest rule, from 0.5 s after the outlet is "
        f"fully open) with more than {100 * ARCH_LEFT:g} % of the mass left; every other run "
        f"flows. The outlet opens over {opts_periods:g} column periods (0: at once); the "
        f"discharge is capped at {cap:g} s after it is open: a flow still running then counts "
        f"as flowing, and an arch that would fail later than the at-rest rule's check counts as "
        f"an arch.")
    if numbers["failed"] or numbers["failed_runs"]:
        findings.append("Not bracketed or failed: " + ", ".join(
            numbers["failed"] + numbers["failed_runs"]) + ".")
    table = {"title": "Critical outlet brackets (mm) and the ratio to the theory",
             "columns": ["geometry", "sigma_c/(rho g) (mm)", "c (Pa)", "E (MPa)",
                         "D_arch", "D_flow", "width %", "theory", "theory (mm)", "ratio",
                         "ratio range", "runs"],
             "rows": [[geometry_label(r["params"]["half_angle_deg"]),
                       1000 * r["params"]["head_m"], _r(r["params"]["cohesion_pa"], 1),
                       r["params"]["youngs_modulus_pa"] / 1e6,
                       _r(1000 * r["d_arch"], 1) if r["d_arch"] else None,
                       _r(1000 * r["d_flow"], 1) if r["d_flow"] else None,
                       _r(100 * r["bracket_width"], 1),
                       "Jenike" if r["params"]["half_angle_deg"] < 90 else "simplified",
                       _r(1000 * r["d_theory"], 1), _r(r["ratio"], 3),
                       [_r(r["ratio_low"], 3), _r(r["ratio_high"], 3)], len(r["runs"])]
                      for r in bis]}
    fit_table = {"title": "Exponent of D_crit ~ (sigma_c/(rho g))^n",
                 "columns": ["geometry", "cases", "n (mid-points)", "n (lower ends)",
                             "n (upper ends)", "n range through the end brackets"],
                 "rows": [[geometry_label(f["half_angle_deg"]), f["cases"],
                           _r(f["exponent_n"], 3), _r(f["exponent_fit_lower_ends"], 3),
                           _r(f["exponent_fit_upper_ends"], 3),
                           [_r(f["exponent_min_end_brackets"], 2),
                            _r(f["exponent_max_end_brackets"], 2)]] for f in fits]}
    run_table = {"title": "Every run of the bisections",
                 "columns": ["task", "D0 (mm)", "outcome", "flow_mode", "mass left",
                             "flow stopped (s)", "stop"],
                 "rows": [[res["key"], _r(1000 * x.get("outlet_diameter_m", math.nan), 1),
                           x["outcome"], x.get("flow_mode"),
                           _r(x.get("remaining_mass_fraction"), 4),
                           _r(x.get("flow_stopped_time_s"), 2), x.get("stop_reason")]
                          for res in bis for x in res["runs"]]}
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}
    settings["outcome_rule"] = (f"arches: flow stopped (at-rest rule) with > {ARCH_LEFT} of the "
                                "mass left; flows otherwise (discharge capped at "
                                f"{cap:g} s)")
    settings["theory"] = ("cones: Jenike D = (2 + theta/60) sigma_c/(rho g); flat: "
                          "2 sigma_c/(rho g); sigma_c = 2 c cos(phi)/(1 - sin(phi))")
    numbers_out = {k: v for k, v in numbers.items()}
    numbers_out["brackets_m"] = {r["key"]: [r["d_arch"], r["d_flow"]] for r in bis}
    numbers_out["ratios"] = {r["key"]: r["ratio"] for r in bis}
    headline = ""
    if "ratio_mean" in numbers:
        headline = (f"D_crit simulated / theory {numbers['ratio_min']:.2f}-"
                    f"{numbers['ratio_max']:.2f} over {numbers['bracketed']} cases; exponent n = "
                    + ", ".join(f"{f['exponent_n']:.2f} ({geometry_label(f['half_angle_deg'])})"
                                for f in fits))
        if "e_check_same_bracket" in numbers:
            headline += ("; E 2-20 MPa: same bracket" if numbers["e_check_same_bracket"] else
                         "; E 2-20 MPa: bracket moves")
        if rat:
            headline += f"; rathole case: {rat.get('cohesive', {}).get('flow_mode')}"
    _sweep.write_study_json(out, NAME, TITLE, setting, settings, numbers_out, findings,
                            figures, [table, fit_table, run_table], rows, argv,
                            headline=headline)
    return figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    _sweep.add_arguments(parser, NAME)
    parser.add_argument("--cell-size", type=float, help="m (default 0.005)")
    parser.add_argument("--heads", type=float, nargs="+",
                        help="sigma_c / (rho g) of the cohesions (m)")
    parser.add_argument("--half-angles", type=float, nargs="+", help="deg (90: flat bottom)")
    parser.add_argument("--tolerance", type=float, help="final D_flow / D_arch (<= 1.1)")
    args = parser.parse_args(argv)
    options = _sweep.study_options(args, ("cell_size", "heads", "half_angles", "tolerance"))
    study = setup(quick=args.quick, **options)
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    print(f"{NAME}: {len(study['tasks'])} task(s) (bisections and the rathole pair) into "
          f"{args.out}")
    results = run_tasks(study["tasks"], args)
    numbers, fits = analyse(results, study["options"])
    numbers["study_wall_time_s"] = time.perf_counter() - started
    write_outputs(args.out, results, numbers, fits, study["options"], study["setting"], argv)
    for r in results:
        if r["kind"] == "bisection":
            print(f"{r['key']}: {_bracket_text(r)}, ratio {r['ratio']:.3f}")
    for f in fits:
        print(f"{geometry_label(f['half_angle_deg'])}: exponent n = {f['exponent_n']:.3f}")
    print(f"written to {args.out} ({numbers['study_wall_time_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
