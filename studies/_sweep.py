"""Run the cases of a study: each case an ordinary run directory, on Dask or serially.

A *case* is a plain dictionary::

    {"name": "theta30_wall20",              # its run directory, named from its parameters
     "params": {"half_angle_deg": 30.0, ...},  # the swept values (columns of the study's CSV)
     "config": {"hopper": {...}, ...},       # sections for HopperConfig.from_dict
     "plots": True,                          # draw the run's own pictures when it ends
     "track_alpha": False,                   # record min/max of alpha after every transport
     "track_wall_windows": False}            # the smallest and largest wall pressure per
                                             # patch over the discharge's load windows

:func:`run_cases` runs a list of them into ``ROOT/cases/<name>/`` with
:func:`fipy_hopper.api.run` and returns one row per case: the parameters, the run's
``summary.json`` and ``case``, ``run_dir``, ``reused``, ``error``.

Restart rule: a case whose directory holds a ``summary.json`` of a run that *finished* (any
stop reason but ``interrupted``, ``wall_time_limit`` and ``failed: ...``) and a ``config.toml``
equal to the case's configuration is read, not recomputed.  An unfinished case with a
checkpoint is resumed from it; anything else in its directory is overwritten.  A finished
case with a *different* configuration stops the sweep before anything runs (another ``--out``,
or ``--force`` to recompute every case).

Where the cases run (``add_arguments`` gives every study the same options):

* default: a ``dask.distributed.LocalCluster`` on this machine, one single-threaded worker
  process per core (``--workers N`` to change);
* ``--scheduler ADDRESS``: an existing Dask scheduler (e.g. ``tcp://10.0.0.5:8786``); the
  workers need ``fipy_hopper`` installed and the output folder on a shared file system
  (give ``--out`` as a path valid on the workers);
* ``--serial``: one after the other in this process (tests, debugging; Dask not needed).

Dask is imported only when a cluster is used, so the serial path works without it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

CASES = "cases"                   # sub-folder of a study's output holding the run directories
ALPHA_BOUNDS = "alpha_bounds.json"
WALL_WINDOWS = "wall_windows.json"
STUDIES_DIR = Path(__file__).resolve().parent
DEFAULT_ROOT = STUDIES_DIR / "output"   # git-ignored


# ---------------------------------------------------------------- cases
def fmt(value) -> str:
    """A number for a directory name: ``0.005`` is ``0p005``, ``-1`` is ``m1``."""
    if isinstance(value, float):
        text = f"{value:g}"
    else:
        text = str(value)
    return text.replace(".", "p").replace("-", "m").replace("+", "")


def case_name(*pairs) -> str:
    """A directory name from ``(label, value)`` pairs: ``case_name(("theta", 30.0),
    ("wall", 12.5))`` is ``"theta30_wall12p5"``."""
    return "_".join(f"{label}{fmt(value)}" for label, value in pairs)


def make_case(name: str, params: dict, config: dict, plots: bool = True,
              track_alpha: bool = False, track_wall_windows: bool = False) -> dict:
    """A case dictionary (see the module docstring); the configuration is validated now."""
    _config(config)
    out = {"name": name, "params": dict(params), "config": config, "plots": bool(plots),
           "track_alpha": bool(track_alpha)}
    if track_wall_windows:
        out["track_wall_windows"] = True
    return out


def merge(base: dict, **sections) -> dict:
    """``base`` (sections of a configuration) with the keys of ``sections`` replaced."""
    out = {k: dict(v) for k, v in base.items()}
    for name, values in sections.items():
        out.setdefault(name, {}).update(values)
    return out


def _config(config: dict):
    from fipy_hopper.config import HopperConfig, ResolutionWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResolutionWarning)
        return HopperConfig.from_dict(config)


def estimated_cost(config: dict) -> float:
    """Cells times steps of a case (a relative cost, used to start the longest cases first;
    a 3D case's cells are its computed part's cubes)."""
    cfg = _config(config)
    geom, num = cfg.hopper, cfg.numerics
    h = num.cell_size
    if geom.dimensions == 3:      # the computed part's cubes (space.estimate's grid)
        from fipy_hopper.space.config import SpaceConfig
        from fipy_hopper.space.estimate import memory_estimate

        cells = memory_estimate(SpaceConfig.from_config(cfg))["cells"]
    else:
        x_min, x_max = geom.x_extent
        cells = ((x_max - x_min) / h) * (geom.top + num.free_fall_depth
                                         * geom.outlet_diameter) / h
    dt = cfg.time_step
    if cfg.run.end_time == "empty":
        from fipy_hopper.api import expected_quantities   # any shape: Beverloo where it applies
        t_end = min(cfg.run.max_time, 1.3 * expected_quantities(cfg)["expected_discharge_time_s"])
    else:
        t_end = float(cfg.run.end_time)
    return cells * (t_end + max(cfg.ramp_time, 0.1)) / dt


# ---------------------------------------------------------------- state of a case
UNFINISHED = ("interrupted", "wall_time_limit")


def _read_json(path: Path):
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


def case_status(case: dict, root) -> str:
    """``"done"``, ``"resume"``, ``"new"`` or ``"conflict"`` (see the restart rule)."""
    from fipy_hopper.config import HopperConfig

    path = Path(root) / CASES / case["name"]
    if not path.is_dir():
        return "new"
    saved_cfg = None
    if (path / "config.toml").is_file():
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                saved_cfg = HopperConfig.from_toml(path / "config.toml")
        except ValueError:
            saved_cfg = None
    same = saved_cfg is not None and saved_cfg == _config(case["config"])
    summary = _read_json(path / "summary.json")
    finished = summary is not None and summary.get("stop_reason") not in UNFINISHED and not \
        str(summary.get("stop_reason", "")).startswith("failed")
    if finished:
        return "done" if same else "conflict"
    if same and (path / "checkpoint.npz").is_file():
        return "resume"
    return "new"


# ---------------------------------------------------------------- one case (runs on a worker)
class _AlphaBounds:
    """Smallest and largest ``alpha`` of the run, updated after every transport step (the only
    place ``alpha`` changes), written to ``alpha_bounds.json`` in the run directory."""

    def __init__(self, path: Path, resume: bool):
        self.path = path
        saved = _read_json(path) if resume else None
        self.low = saved["alpha_min"] if saved else math.inf
        self.high = saved["alpha_max"] if saved else -math.inf
        self.checks = saved["checks"] if saved else 0

    def update(self, alpha) -> None:
        self.low = min(self.low, float(alpha.min()))
        self.high = max(self.high, float(alpha.max()))
        self.checks += 1

    def attach(self, sim) -> None:
        sim.model.after_transport.append(lambda state: self.update(state.alpha))
        self.update(sim.state.alpha)
        sim.add_wall_time_callback(lambda sim_, state: self.write(), 30.0)

    def write(self) -> None:
        from fipy_hopper.io import write_json

        write_json(self.path, {"alpha_min": self.low, "alpha_max": self.high,
                               "checks": self.checks})

    def row(self) -> dict:
        return {"alpha_min": self.low, "alpha_max": self.high}


class _WallWindows:
    """The smallest and the largest wall pressure of every wall bin (a 3D run's patch) over
    the discharge's windows of the run's ``load_window`` (kept by the loop,
    :attr:`fipy_hopper.simulation.Simulation.window_extremes`, from the loads recovered from
    the wall's reaction, and checkpointed with it: a resumed run carries them on exactly),
    written to ``wall_windows.json`` in the run directory (``p_min_Pa``, ``p_max_Pa`` per bin
    in the order of ``wall_pressure.csv``'s rows of a stage, ``windows``) every 30 s of wall
    time and when the run ends."""

    def __init__(self, path: Path):
        self.path = path
        self.sim = None

    def attach(self, sim) -> None:
        self.sim = sim
        sim.add_wall_time_callback(lambda sim_, state: self.write(), 30.0)

    def write(self) -> None:
        from fipy_hopper.io import write_json

        if self.sim is None:
            return
        extremes = self.sim.window_extremes
        low, high = (None, None) if extremes is None else (a.tolist() for a in extremes)
        write_json(self.path, {"p_min_Pa": low, "p_max_Pa": high,
                               "windows": self.sim.record.envelope_windows})


def run_case(case: dict, root, force: bool = False, threads: int | None = 1) -> dict:
    """Run (or read) one case into ``root/cases/<name>``; returns its row.

    Never raises for a failed run: the row carries ``error`` and whatever the run measured.
    ``threads``: numba threads of the run (1 on a cluster's workers, one per core, so that
    two runs never compete for a core; ``None``: all cores, for a serial sweep).
    """
    from fipy_hopper.api import run
    from fipy_hopper.config import ResolutionWarning

    path = Path(root) / CASES / case["name"]
    status = "new" if force else case_status(case, root)
    row = {"case": case["name"], **case["params"]}
    if status == "done":
        return {**row, **_finished_row(path), "reused": True, "error": ""}
    if status == "conflict":
        return {**row, "reused": False, "run_dir": str(path),
                "error": f"{path} holds a different configuration"}
    resume = status == "resume"
    tracker = _AlphaBounds(path / ALPHA_BOUNDS, resume) if case.get("track_alpha") else None
    windows = _WallWindows(path / WALL_WINDOWS) if case.get("track_wall_windows") else None
    setups = [t.attach for t in (tracker, windows) if t is not None]

    def setup(sim):
        for attach in setups:
            attach(sim)
    started, cpu = time.perf_counter(), time.process_time()
    error = ""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResolutionWarning)
        try:
            run(case["config"], path, force=not resume, resume=resume, quiet=True,
                plots=case.get("plots", True), setup=setup if setups else None,
                command="studies: " + " ".join(sys.argv), threads=threads)
        except Exception as exc:  # the run wrote what it measured; keep the sweep going
            error = f"{type(exc).__name__}: {exc}"
    if tracker is not None:
        tracker.write()
    if windows is not None:
        windows.write()
    out = {**row, **_finished_row(path), "reused": False, "error": error}
    out["case_wall_time_s"] = time.perf_counter() - started
    out["case_cpu_time_s"] = time.process_time() - cpu    # this process (one worker thread)
    return out


def _finished_row(path: Path) -> dict:
    summary = _read_json(path / "summary.json") or {}
    row = {k: (math.nan if v is None else v) for k, v in summary.items()}
    bounds = _read_json(path / ALPHA_BOUNDS)
    if bounds:
        row.update(alpha_min=bounds["alpha_min"], alpha_max=bounds["alpha_max"])
    manifest = _read_json(path / "manifest.json") or {}
    row["code_commit"] = manifest.get("code_commit", "")
    row["run_dir"] = str(path)
    return row


# ---------------------------------------------------------------- running a list of cases
def study_options(args, names) -> dict:
    """The study options given on the command line: ``args.<name>`` for each of ``names`` that
    is not ``None``, and ``case_plots`` with ``--case-plots`` or ``--no-case-plots``."""
    options = {name: getattr(args, name) for name in names if getattr(args, name) is not None}
    if args.case_plots is not None:
        options["case_plots"] = args.case_plots
    return options


def resolve_options(defaults: dict, options: dict, quick_options: dict | None = None) -> dict:
    """A study's options: ``defaults``, then ``quick_options`` (the quick setting, if given),
    then ``options``; an option the study does not have raises ``TypeError``."""
    unknown = set(options) - set(defaults)
    if unknown:
        raise TypeError(f"unknown options {sorted(unknown)}; known: {sorted(defaults)}")
    return {**defaults, **(quick_options or {}), **options}


def run_study(name: str, study: dict, args) -> list:
    """Create ``args.out`` and run the study's cases there (:func:`sweep`); returns the rows."""
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{name}: {len(study['cases'])} case(s) into {args.out}")
    return sweep(study["cases"], args)


def rounded(x, digits: int):
    """``round(x, digits)``, or ``None`` for a missing or non-finite number (for JSON)."""
    return round(x, digits) if finite(x) else None


def add_arguments(parser: argparse.ArgumentParser, study: str) -> None:
    """The options every study shares."""
    parser.add_argument("--out", type=Path, default=DEFAULT_ROOT / study,
                        help=f"output folder (default: studies/output/{study})")
    parser.add_argument("--quick", action="store_true",
                        help="the tiny, fast setting used by the tests")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--serial", action="store_true",
                       help="run the cases one after the other in this process (no Dask)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use an existing Dask scheduler instead of a local cluster")
    parser.add_argument("--workers", type=int, default=None,
                        help="worker processes of the local cluster (default: the cores)")
    parser.add_argument("--force", action="store_true",
                        help="recompute every case, even finished ones")
    parser.add_argument("--case-plots", dest="case_plots", default=None,
                        action=argparse.BooleanOptionalAction,
                        help="draw (or not) each run's own pictures; the study's own are always "
                             "drawn (default: the study's setting); `fipy-hopper plot RUN_DIR` "
                             "draws them later")


def run_cases(cases: list, root, serial: bool = False, scheduler: str | None = None,
              workers: int | None = None, force: bool = False, log=print) -> list:
    """Run ``cases`` into ``root/cases/``; returns their rows in the order of ``cases``.

    Finished cases are read without starting a cluster; the others run longest first.
    """
    root = Path(root).resolve()
    (root / CASES).mkdir(parents=True, exist_ok=True)
    names = [c["name"] for c in cases]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"two cases share a name: {twice}")
    statuses = {c["name"]: ("new" if force else case_status(c, root)) for c in cases}
    conflicts = [n for n, s in statuses.items() if s == "conflict"]
    if conflicts:
        raise SystemExit(
            f"{len(conflicts)} finished case(s) in {root / CASES} were run with a different "
            f"configuration ({', '.join(conflicts[:3])}{', ...' if len(conflicts) > 3 else ''});"
            " use another --out, or --force to recompute them")
    rows = {}
    todo = []
    for c in cases:
        if statuses[c["name"]] == "done":
            rows[c["name"]] = run_case(c, root)
        else:
            todo.append(c)
    if rows:
        log(f"{len(rows)} of {len(cases)} case(s) already finished in {root / CASES}: not rerun")
    todo.sort(key=lambda c: -estimated_cost(c["config"]))
    started = time.perf_counter()

    def report(done, row):
        per_metre = "steady_discharge_rate_kg_s_m" in row          # a wedge
        rate = row.get("steady_discharge_rate_kg_s_m" if per_metre
                       else "steady_discharge_rate_kg_s", math.nan)
        summary = (f"{row.get('flow_mode', '?')} flow, W = {rate:.3g} kg/s"
                   + ("/m" if per_metre else ""))
        if row.get("error"):
            summary = "ERROR " + row["error"]
        log(f"[{done}/{len(todo)}] {row['case']}: {summary} "
            f"({row.get('case_wall_time_s', math.nan):.0f} s, "
            f"cpu {row.get('case_cpu_time_s', math.nan):.0f} s; "
            f"{time.perf_counter() - started:.0f} s elapsed)")

    if todo and serial:
        for k, c in enumerate(todo, 1):
            row = run_case(c, root, force=force, threads=None)    # one run: every core
            rows[c["name"]] = row
            report(k, row)
    elif todo:
        with _client(scheduler, workers, len(todo), log) as client:
            from dask.distributed import as_completed

            futures = client.map(run_case, todo, root=str(root), force=force, pure=False)
            case_of = dict(zip(futures, todo))
            for k, fut in enumerate(as_completed(futures), 1):
                try:
                    row = fut.result()
                except Exception as exc:   # the worker died (memory, killed): keep going
                    c = case_of[fut]
                    row = {"case": c["name"], **c["params"], "reused": False,
                           "run_dir": str(root / CASES / c["name"]),
                           "error": f"worker lost: {type(exc).__name__}: {exc}"}
                rows[row["case"]] = row
                report(k, row)
    return [rows[n] for n in names]


@contextlib.contextmanager
def _client(scheduler, workers, n_cases, log):
    try:
        import cloudpickle
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise SystemExit(f"the Dask sweep needs dask.distributed ({exc}); install it with "
                         "pip install 'dask[distributed]', or run with --serial") from None
    # this module is sent to the workers by value: they need fipy_hopper, not studies/
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    if scheduler:
        log(f"connecting to the Dask scheduler at {scheduler}")
        with Client(scheduler) as client:
            yield client
        return
    n = workers or os.cpu_count() or 1
    n = max(1, min(n, n_cases))
    log(f"starting a local Dask cluster: {n} worker process(es), 1 thread each")
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        yield client


def sweep(cases: list, args, log=print) -> list:
    """:func:`run_cases` with the options of :func:`add_arguments`."""
    return run_cases(cases, args.out, serial=args.serial, scheduler=args.scheduler,
                     workers=args.workers, force=args.force, log=log)


# ---------------------------------------------------------------- study outputs
def write_rows_csv(path, rows: list, first: tuple = ()) -> None:
    """A CSV of the rows (the union of their keys, ``first`` columns first)."""
    import csv

    keys = list(first)
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: _csv_value(r.get(k, "")) for k in keys})


def _csv_value(v):
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(float(v))
    if isinstance(v, (list, tuple)):
        return " ".join(str(x) for x in v)
    return v


def write_study_json(out, study: str, title: str, setting: str, settings: dict,
                     numbers: dict, findings: list, figures: list, tables: list = (),
                     rows: list = (), argv=None, headline: str = "") -> Path:
    """``study.json``: what ``make_report.py`` reads (settings, headline numbers, findings as
    sentences, figures with captions, tables as ``{"title", "columns", "rows"}``, and a
    one-line ``headline``, by default the first finding)."""
    from fipy_hopper.io import write_json
    import datetime
    import fipy_hopper

    wall = [r.get("wall_time_s") for r in rows if isinstance(r.get("wall_time_s"), (int, float))]
    data = {"study": study, "title": title, "setting": setting,
            "created": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "fipy_hopper_version": fipy_hopper.__version__, "commit": _git_commit(),
            "command": " ".join(["python", f"studies/{study}.py",
                                 *(sys.argv[1:] if argv is None else argv)]),
            "cases": len(rows), "run_commits": run_commits(rows),
            "cases_failed": sum(1 for r in rows if r.get("error")),
            "case_wall_time_total_s": float(sum(w for w in wall if math.isfinite(w))),
            "headline": headline or (findings[0] if findings else ""),
            "settings": settings, "numbers": numbers, "findings": list(findings),
            "figures": list(figures), "tables": list(tables)}
    path = Path(out) / "study.json"
    write_json(path, data)
    return path


def _git_commit() -> str:
    """The commit of the code that wrote the study (short hash, and whether the package, the
    studies' scripts or their configurations had uncommitted changes), or "" outside a git
    checkout (:func:`fipy_hopper.io.code_commit`)."""
    from fipy_hopper.io import code_commit

    # the studies' scripts and configurations (not their outputs, REPORT.md and its
    # figures, which the report itself rewrites), relative to the package's folder
    return code_commit(also=("../studies/*.py", "../studies/configs"))


def run_commits(rows) -> dict:
    """How many of ``rows`` were run by each commit of the code (their manifests'
    ``code_commit``; "not recorded" for runs from before the manifests carried it)."""
    counts = {}
    for r in rows:
        key = r.get("code_commit") or "not recorded"
        counts[key] = counts.get(key, 0) + 1
    return counts


def setting_label(quick: bool, options: dict, cosmetic=("case_plots", "thumbnails")) -> str:
    """``"quick"``, ``"default"`` or ``"custom"`` (options that change no number ignored)."""
    changed = [k for k in options if k not in cosmetic]
    if changed:
        return "custom"
    return "quick" if quick else "default"


def figure(width, height):
    """A matplotlib Figure on the Agg canvas (no pyplot, no display)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save(fig, path, dpi=110) -> Path:
    from fipy_hopper.io import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


def pct(a, b) -> float:
    """Percent difference of ``a`` from ``b``: ``100 (a - b) / b``."""
    try:
        return 100.0 * (float(a) - float(b)) / float(b)
    except (TypeError, ValueError, ZeroDivisionError):
        return math.nan


def finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)
