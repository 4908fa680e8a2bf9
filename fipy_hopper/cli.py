"""The ``fipy-hopper`` command line.

::

    fipy-hopper run CONFIG.toml --out DIR [--force] [--resume] [--quiet] [--checkpoint-interval S]
                    [--threads N] [--profile]
    fipy-hopper demo [--out DIR] [--force] [--resume] [--quiet] [--checkpoint-interval S]
                     [--threads N] [--profile]
    fipy-hopper plot DIR
    fipy-hopper validate CONFIG.toml [--picture PATH.png]

Exit codes: 0 success; 2 bad input (a configuration error, a missing or non-TOML file, an
output directory that would be overwritten or that another run is using, a path the system
refuses, a directory that ``plot`` cannot read), reported in one line on stderr; 1 a run that
failed (unstable, or an internal error), with the reason, after writing everything measured so
far, and a fill-only run (``end_time = 0``) whose fill did not come to rest by
``numerics.max_fill_time`` (``stop_reason`` ``"fill_not_at_rest"``: its outputs are written,
but its loads are those of a moving fill; a discharge started from such a fill is a warning);
130 a run interrupted with Ctrl-C or SIGTERM, at any moment: its outputs written whole, its
manifest ``"interrupted"`` (``"finished"`` when only the pictures or the printing were cut
short), and one line of advice (continue it with ``--resume`` once a checkpoint has been
written).  ``validate`` writes nothing unless ``--picture`` asks for a drawing; ``--force``
replaces only an earlier run's files in a directory it wrote (its ``manifest.json``), never
through a symbolic link (:class:`fipy_hopper.io.RunDirectory`).
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import signal
import sys
import threading
import warnings
from pathlib import Path

from . import __version__
from .config import ConfigError, HopperConfig, ResolutionWarning, SamplingWarning
from .config import short_text as _short
from .summary_text import PROG

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in the same one-line style (exit code 2)."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{PROG}: error: {message}\n")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description=(
        "Eulerian Mohr-Coulomb simulation of the filling and discharge of silos and hoppers "
        "on FiPy: a conical or wedge-shaped hopper under a bin, or any wall drawn as straight "
        "segments with inserts, in an axisymmetric or a plane section, or a circular silo "
        "whole in 3D with its outlet on or off the axis; the discharge rate, the flow mode "
        "per stretch of hopper wall and the wall loads, compared with Beverloo, Jenike, "
        "Janssen, Walker and EN 1991-4 where they describe the silo."),
        epilog="Exit codes: 0 success, 1 the run failed (or a fill-only run's fill did not "
        "come to rest), 2 bad input, 130 interrupted.")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    def run_options(q, out_required):
        q.add_argument("--out", metavar="DIR", required=out_required,
                       default=None if out_required else "hopper_run",
                       help="run directory" + ("" if out_required else " (default: hopper_run)"))
        q.add_argument("--force", action="store_true",
                       help="replace the files of an earlier run in DIR (a run directory of "
                       "fipy-hopper only; files of your own there are kept)")
        q.add_argument("--resume", action="store_true",
                       help="continue the interrupted run in DIR from its checkpoint")
        q.add_argument("--quiet", action="store_true",
                       help="no progress line and no summary (errors are still reported)")
        q.add_argument("--checkpoint-interval", metavar="SECONDS", type=float, default=60.0,
                       help="wall-clock seconds between checkpoints (default 60; 0: none)")
        q.add_argument("--threads", metavar="N", type=int, default=None,
                       help="threads of the compiled steps, at most one per core this process "
                       "may use (default: the cores other processes leave free, measured "
                       "every few seconds; the results do not depend on it)")
        q.add_argument("--profile", action="store_true",
                       help="time the phases of the run (compiled step, transport, output, "
                       "pictures) into DIR/profile.json and print them; the results do not "
                       "depend on it")

    q = sub.add_parser("run", help="run a hopper described by a TOML configuration",
                       description="Run the hopper of CONFIG.toml: fill, discharge, and write "
                       "results, fields for ParaView and pictures into --out DIR.")
    q.add_argument("config", metavar="CONFIG.toml", help="configuration file (TOML)")
    run_options(q, out_required=True)

    q = sub.add_parser("demo", help="run the reference hopper from filling to empty",
                       description="Run the reference hopper (D = 0.3 m, 20 deg cone, "
                       "D0 = 0.06 m, 0.3 m of dry sand; the defaults of HopperConfig) from "
                       "filling to empty: one and a half to five minutes on two cores (91-287 s "
                       "measured, 7-20 s of it for writing and the pictures).")
    run_options(q, out_required=False)

    from .plotting import PICTURES
    q = sub.add_parser("plot", help="draw the pictures of a run directory",
                       description="Draw the pictures of the run in DIR from its files (those "
                       "the run has the data of): " + "; ".join(
                           f"{p.name}, {p.shows}" for p in PICTURES) + ".")
    q.add_argument("dir", metavar="DIR", help="run directory")

    q = sub.add_parser("validate", help="check a configuration and print derived quantities",
                       description="Check CONFIG.toml and print the grid, the time step, the "
                       "wave speed, the fill mass, Beverloo's rate, Jenike's critical angle "
                       "and the boundary (walls, corners, outlet, fill); for a 3D silo the "
                       "grid's cells, memory and an estimate of the time, refusing a grid "
                       "that will not fit in memory; it writes nothing, unless --picture "
                       "names a PNG file to draw the boundary to.")
    q.add_argument("config", metavar="CONFIG.toml", help="configuration file (TOML)")
    q.add_argument("--picture", metavar="PATH.png", default=None,
                   help="draw the boundary to this PNG file (default: no file is written)")
    return p


def _error(message: str, code: int) -> int:
    text = " ".join(str(message).split())
    sys.stderr.write(f"{PROG}: error: {text}\n")
    return code


def _load(path: str) -> HopperConfig:
    from .api import load_config
    try:
        return load_config(path)
    except OSError as exc:         # e.g. a name too long for the file system
        raise ConfigError(f"cannot read configuration {_short(path)}: "
                          f"{exc.strerror or exc}") from None


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as one line on stderr, without the source line."""
    sys.stderr.write(f"{PROG}: warning: {message}\n")


def _validate(args) -> int:
    """Check a configuration and print what follows from it, without building the grid (the
    grid's size and the time step follow from the configuration by the model's own rules)."""
    from .api import expected_quantities
    from .resources import available_memory

    from .diagnostics import stretch_calls

    cfg = _load(args.config)
    e = expected_quantities(cfg)
    need, have = cfg.memory_estimate(), available_memory()
    memory = f"about {need / 1e9:.2g} GB" + (
        "" if have is None else f" ({have / 1e9:.2g} GB available)" if need <= have else
        f", more than the {have / 1e9:.2g} GB available: the run would be refused")
    geom, run = cfg.hopper, cfg.run
    nr, nz = cfg.grid_shape()[::2] if geom.dimensions == 3 else cfg.grid_shape()
    h = cfg.numerics.cell_size
    theta_c = e.get("jenike_critical_half_angle_deg", math.nan)
    if e["jenike_flow_mode"] == "unknown":
        theta_c_text = "n/a (friction angle below the 19.5 deg range of the fit)"
    elif theta_c != theta_c:
        theta_c_text = "none: the wall is as rough as the material (phi_w >= phi)"
    else:
        theta_c_text = f"{theta_c:.1f} deg"
    end = run.end_time if isinstance(run.end_time, str) else f"{run.end_time:g} s"
    hopper, per = ("cone", "") if geom.axisymmetric else ("wedge", "/m (per metre of length)")
    lines = [
        f"{args.config}: valid",
        f"  grid               {nr} x {nz} = {nr * nz} cells of {h:g} m "
        f"({geom.outlet_radius / h:.1f} across the outlet "
        f"{'radius' if geom.axisymmetric else 'half-width'}), {memory}",
        f"  P-wave speed c_p   {e['p_wave_speed_m_s']:.4g} m/s",
        f"  time step          {cfg.time_step:.4g} s (at most {cfg.step_estimate():.3g} steps)",
        f"  transition height  {e['transition_height_m']:.4g} m (the bin wall's foot"
        + ("" if cfg.boundary.transition("wall") else "; none: the wall's top") + ")",
        f"  fill mass          {e['fill_mass_kg']:.4g} kg{per}",
        _grain_line(cfg.material, e),
        (f"  Beverloo rate      {e['beverloo_rate_kg_s']:.4g} kg/s = "
         f"{e['beverloo_flat_rate_kg_s']:.4g} kg/s (flat bottom, C = 0.58, k = 1.5) x "
         f"{e['rose_tanaka_factor']:.3f} (Rose-Tanaka, {geom.half_angle_deg:g} deg cone)"
         if geom.axisymmetric else
         f"  Beverloo rate      {e['beverloo_rate_kg_s']:.4g} kg/s per m of slot "
         f"(plane flow, W' = C' rho sqrt(g) (B - k d)^1.5, C' = 1.03, k = 1.5, no hopper "
         f"factor)")
        if "beverloo_rate_kg_s" in e else
        (f"  Beverloo rate      n/a: no closed form for this silo (the outlet's flat-bottom "
         f"rate is {e['beverloo_flat_rate_kg_s']:.4g} kg/s{per})"),
        f"  discharge time     about {e['expected_discharge_time_s']:.3g} s at "
        + ("that rate" if "beverloo_rate_kg_s" in e else "the flat-bottom rate"),
        (f"  Jenike theta_c     {theta_c_text} (phi = {cfg.material.friction_angle_deg:g} deg, "
         f"phi_w = {cfg.wall.friction_angle_deg:g} deg"
         + ("" if geom.axisymmetric else "; plane flow: the conical angle + 10 deg") + ")")
        if "jenike_critical_half_angle_deg" in e else
        "  Jenike theta_c     per stretch of hopper wall (below)",
        (f"  expected flow      {e['jenike_flow_mode']} flow ({geom.half_angle_deg:g} deg "
         f"{hopper})" if geom.classic else
         f"  expected flow      {e['jenike_flow_mode']} flow by Jenike over the stretches of "
         "hopper wall: " + "; ".join(
             f"{st['wall']} segment {st['segment']}, {st['half_angle_deg']:.1f} deg: "
             f"{st['jenike_call']}" + ("" if st["counted"] else " (not counted)")
             for st in stretch_calls(cfg, []))),
        f"  run                until {end}, samples every {run.output_interval:g} s, "
        f"fields every {run.field_interval:g} s",
    ]
    if "unconfined_yield_strength_Pa" in e:
        lines[-1:-1] = _cohesion_lines(cfg, e)
    if cfg.numerics.formulation == "lagrangian":
        lines[1], lines[3] = _lagrangian_lines(cfg)
    if geom.dimensions == 3:
        from .resources import check_memory
        check_memory(cfg)                   # a grid that will not fit: refused, exit 2
        grid, lines[3] = _three_d_lines(cfg, e, memory)
        lines[1:2] = grid
    if args.picture is not None:      # nothing is written unless asked
        from .io import atomic_path
        picture = Path(args.picture)
        if picture.suffix.lower() != ".png":
            return _error(f"--picture = {_short(args.picture)}: expected the name of a PNG "
                          "file (ending in .png)", EXIT_BAD_INPUT)
        try:
            with atomic_path(picture) as tmp:
                cfg.boundary.draw(tmp)
        except OSError as exc:
            return _error(f"cannot write {_short(picture)}: {exc.strerror or exc}",
                          EXIT_BAD_INPUT)
        lines.append(f"  boundary           drawn to {_short(picture)}")
    else:
        lines.append("  boundary" + (
            "           the rectangular silo's faces" if geom.rectangular else
            "           the section below, revolved about the axis (the outlet off it as "
            "above)" if geom.dimensions == 3 else ""))
    if geom.rectangular:
        from .space.boundary import silo_boundary
        described = silo_boundary(cfg.space_config()).describe(cfg.material.density)
    else:
        described = cfg.boundary.describe(cfg.material.density)
    lines += ["    " + line for line in described.split("\n")]
    print("\n".join(lines))
    return EXIT_OK


def _three_d_lines(cfg, e: dict, memory: str) -> tuple:
    """The grid and time-step lines of ``validate`` for a 3D run (``hopper.dimensions = 3``):
    the computed part's grid and its loaded cells, the memory, the outlet's offset, and the
    steps and the wall time of the fill and the discharge on one thread
    (:func:`fipy_hopper.space.estimate.time_estimate`: an indication)."""
    from .space.estimate import loaded_cells, time_estimate
    from .space.grid import computed_part

    space = cfg.space_config()
    nx, ny, nz = cfg.grid_shape()
    h, geom, run = cfg.numerics.cell_size, cfg.hopper, cfg.run
    part = {(True, True): "a quarter", (False, True): "the half y >= 0",
            (True, False): "the half x >= 0",
            (False, False): "the whole silo"}[computed_part(space.mirror_planes,
                                                            space.outlet_offset)]
    radius = max(r for r, _ in geom.wall_points)
    across = "half-size" if geom.rectangular and not geom.outlet_size[2] else "radius"
    grid = [f"  grid (3D)          {nx} x {ny} x {nz} = {nx * ny * nz:,} cubes of {h:g} m "
            f"({part}, numerics.mirror_planes = \"{cfg.numerics.mirror_planes}\"; "
            f"{loaded_cells(space):,} loaded; {geom.outlet_radius / h:.1f} across the outlet "
            f"{across}), {memory}"]
    if geom.rectangular:
        ex, ey = geom.offset_xy
        ox, oy, round_outlet = geom.outlet_size
        outlet = f"{ox:g} m round" if round_outlet else f"{ox:g} m x {oy:g} m"
        grid += [f"  plan               rectangular, bin {geom.bin_width:g} m (x) x "
                 f"{geom.bin_length:g} m (y), "
                 + (f"a hopper of plane faces {geom.cone_height:.4g} m high"
                    if geom.cone_height > 0 else "a flat floor")
                 + f", outlet {outlet} at [{ex:g}, {ey:g}] m; wall loads per face in "
                 f"{run.wall_sectors} sectors across its width"]
    else:
        grid += [f"  outlet offset      {geom.outlet_offset:g} m from the axis along +x "
                 f"(e/R = {geom.outlet_offset / radius:.3g}); wall loads in "
                 f"{run.wall_sectors} sectors around the circumference"]
    discharge = (float(run.end_time) if run.end_time != "empty"
                 else min(e["expected_discharge_time_s"], run.max_time))
    t = time_estimate(space, discharge, emptied=run.end_time == "empty")
    steps = (f"  time step          {cfg.time_step:.4g} s (at most {cfg.step_estimate():.3g} "
             f"steps); estimated {t['fill_steps']:.3g} steps filling + "
             f"{t['discharge_steps']:.3g} discharging ({discharge:.3g} s), about "
             f"{_duration(t['seconds'])} on one thread (an indication)")
    return grid, steps


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _lagrangian_lines(cfg) -> tuple:
    """The mesh and time-step lines of ``validate`` for a Lagrangian run: the mesh's size, its
    worst element and its first time step (the smallest element length over c_p)."""
    from .lagrangian import LagrangianModel

    model = LagrangianModel(cfg)
    mesh = model.mesh
    return (f"  mesh (Lagrangian)  {mesh.n_elements} elements in {mesh.n_cols} columns, moving "
            f"with the material (worst aspect {model.initial_quality['max_aspect']:.2f}); the "
            f"run stops when an element distorts",
            f"  time step          {model.dt0:.4g} s at the start (it shrinks as the mesh "
            f"distorts)")


def _plot(args) -> int:
    from . import plotting
    from .io import RunDirectoryError, check_run_files

    run = Path(args.dir)
    try:
        check_run_files(run)
    except RunDirectoryError as exc:
        return _error(exc, EXIT_BAD_INPUT)
    try:
        paths = plotting.plot_run(run)
    except RunDirectoryError as exc:      # a snapshot that cannot be read
        return _error(exc, EXIT_BAD_INPUT)
    except Exception as exc:  # a file that passed the checks but cannot be drawn
        return _error(f"cannot draw the pictures of {_short(run)}: {type(exc).__name__}: "
                      f"{_short(exc, 300)}", EXIT_FAILED)
    for path in paths:
        print(path)
    return EXIT_OK


def _run(args, config, source=None) -> int:
    from . import api
    from .io import RunDirectory, RunDirectoryError

    if not (math.isfinite(args.checkpoint_interval) and args.checkpoint_interval >= 0):
        return _error(f"--checkpoint-interval = {args.checkpoint_interval:g}: expected "
                      "a finite number of seconds >= 0 (0: no checkpoints)", EXIT_BAD_INPUT)
    if not args.out.strip():
        return _error(f"--out = {args.out!r}: expected a directory name", EXIT_BAD_INPUT)
    if args.threads is not None:
        from .resources import check_threads
        check_threads(args.threads, "--threads")
    command = " ".join(shlex.quote(a) for a in [PROG] + list(args.argv))
    start = ("fipy-hopper demo" if args.command == "demo" else
             f"fipy-hopper run {shlex.quote(args.config)}") + f" --out {shlex.quote(args.out)}"
    again = start + " --resume"
    try:
        with _sigterm_as_interrupt():
            summary = api.run(config, args.out, force=args.force, resume=args.resume,
                              quiet=args.quiet, checkpoint_interval=args.checkpoint_interval,
                              command=command, config_source=source, threads=args.threads,
                              profile=args.profile)
    except (ConfigError, RunDirectoryError) as exc:
        return _error(exc, EXIT_BAD_INPUT)
    except api.PicturesInterrupted:
        return _error(f"interrupted after the run finished; its results are complete in "
                      f"{args.out}; draw its pictures with: {PROG} plot "
                      f"{shlex.quote(args.out)}", EXIT_INTERRUPTED)
    except KeyboardInterrupt:
        return _error(_interrupted_message(args.out, start, again), EXIT_INTERRUPTED)
    except Exception as exc:
        from .model import InstabilityError
        kind = "the run went unstable" if isinstance(exc, InstabilityError) else "the run failed"
        log = Path(args.out) / RunDirectory.ERROR_LOG
        where = f"; the traceback is in {log}" if log.is_file() else ""
        return _error(f"{kind}: {exc} (everything measured so far is in {args.out}{where})",
                      EXIT_FAILED)
    try:
        return _after_the_run(args, config, summary, again)
    except KeyboardInterrupt:       # while printing: the run and its files are complete
        if summary.get("stop_reason") == "wall_time_limit":
            return _error(f"interrupted; the run had stopped at run.wall_time_limit with its "
                          f"outputs in {args.out}; continue with: {again}", EXIT_INTERRUPTED)
        return _error(f"interrupted after the run finished; its results are complete in "
                      f"{args.out} (summary.json); draw its pictures again with: {PROG} plot "
                      f"{shlex.quote(args.out)}", EXIT_INTERRUPTED)


def _after_the_run(args, config, summary: dict, again: str) -> int:
    """What ``run`` prints once a run has returned, and its exit code."""
    from .io import RunDirectory

    if args.profile and not args.quiet:
        from .profiling import format_report
        report = json.loads((Path(args.out) / RunDirectory.PROFILE).read_text())
        print(f"where the time went ({Path(args.out) / RunDirectory.PROFILE}):")
        print(format_report(report))
    if not args.quiet:
        _print_summary(summary, args.out)
    if summary.get("stop_reason") == "fill_not_at_rest":
        from .simulation import not_at_rest_message
        return _error(f"{not_at_rest_message(config)} (the outputs are in {args.out})",
                      EXIT_FAILED)
    if not args.quiet:
        if summary.get("stop_reason") == "wall_time_limit":
            if (Path(args.out) / RunDirectory.CHECKPOINT).is_file():
                print(f"  stopped at run.wall_time_limit; continue with: {again}")
            else:
                print("  stopped at run.wall_time_limit without a checkpoint "
                      "(--checkpoint-interval 0): it cannot be continued")
    return EXIT_OK


def _interrupted_message(out: str, start: str, again: str) -> str:
    """What to do after Ctrl-C: ``--resume`` only if a checkpoint exists to resume from."""
    from .io import RunDirectory

    folder = Path(out)
    try:
        if (folder / RunDirectory.CHECKPOINT).is_file():
            return (f"interrupted; the outputs so far are in {out}; continue from the last "
                    f"checkpoint with: {again}")
        written = folder.is_dir() and any(p.name != RunDirectory.LOCK for p in folder.iterdir())
    except OSError:
        written = False
    if written:
        return (f"interrupted before the first checkpoint, so it cannot be resumed; the "
                f"outputs so far are in {out}; start again with: {start} --force")
    return f"interrupted before the run started; start it with: {start}"


class _sigterm_as_interrupt:
    """SIGTERM (a batch scheduler's notice) stops a run like Ctrl-C: outputs written, resumable."""

    def __enter__(self):
        self.previous = None
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGTERM, self._raise)
        return self

    @staticmethod
    def _raise(signum, frame):
        raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self.previous is not None:
            signal.signal(signal.SIGTERM, self.previous)
        return False


def _grain_line(mat, e: dict) -> str:
    """The grains and the law's rate dependence, for ``validate``."""
    law = ("mu(I) above the Mohr-Coulomb limit (delta_mu = "
           f"{mat.friction_rise:g}, I_0 = {mat.inertial_number_i0:g}, rho_s = "
           f"{mat.grain_density:g} kg/m3)" if mat.rate_dependence == "mu_I"
           else "none (the plain rate-independent law)")
    across = (f", the outlet {e['outlet_grains']:.3g} grains across"
              if mat.grain_diameter > 0 else "")
    return (f"  grains             d = {mat.grain_diameter:g} m{across}; rate dependence "
            f"{law}")


def _cohesion_lines(cfg, e: dict) -> list:
    """The lines of ``validate`` for a cohesive material: Jenike's design numbers."""
    mat, geom = cfg.material, cfg.hopper
    d0 = geom.outlet_diameter

    def length(value, why):
        return f"{value:.4g} m" if value == value else f"n/a ({why})"

    jenike, simple = e.get("jenike_critical_outlet_m", math.nan), e["critical_outlet_simplified_m"]
    critical = jenike if jenike == jenike else simple
    why = ("flat bottom, outside the fit of H" if "jenike_critical_outlet_m" in e
           else "no one hopper angle: not a cone under a bin")

    def verdict(value):
        if value != critical:
            return ""
        return (f"; the outlet, {d0:g} m, is {'below' if d0 < value else 'above'} it: "
                f"{'it may arch' if d0 < value else 'no stable arch expected'}")

    return [
        f"  cohesion           c = {mat.cohesion:g} Pa: unconfined yield strength "
        f"sigma_c = {e['unconfined_yield_strength_Pa']:.4g} Pa",
        f"  critical outlet    Jenike H(theta) sigma_c/(rho g) = "
        f"{length(jenike, why)}{verdict(jenike)}",
        f"                     simplified 2 sigma_c/(rho g) = {simple:.4g} m{verdict(simple)}",
        f"  critical rathole   Jenike G(phi) sigma_c/(rho g) = "
        f"{length(e['jenike_rathole_diameter_m'], 'phi outside the 30-70 deg of the fit')}",
    ]


def _print_summary(s: dict, out) -> None:
    """Print the summary of a run (:func:`fipy_hopper.summary_text.summary_lines`: what the
    run wrote to ``summary.txt``)."""
    from .summary_text import summary_lines

    print("\n".join(summary_lines(s, out)))


def main(argv=None) -> int:
    """Entry point of ``fipy-hopper``; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:      # --help, --version, usage errors: argparse has spoken
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    args.argv = argv
    if args.command is None:
        parser.print_usage(sys.stderr)
        return _error("no command given; choose one of run, demo, plot, validate "
                      f"({PROG} --help, or {PROG} COMMAND --help)", EXIT_BAD_INPUT)
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        warnings.filterwarnings("default", category=ResolutionWarning)
        warnings.filterwarnings("default", category=SamplingWarning)
        return _dispatch(args)


def _dispatch(args) -> int:
    try:
        if args.command == "validate":
            return _validate(args)
        if args.command == "plot":
            return _plot(args)
        if args.command == "demo":
            return _run(args, HopperConfig(), "the reference hopper (HopperConfig() defaults)")
        return _run(args, _load(args.config), str(Path(args.config).resolve()))
    except ConfigError as exc:
        return _error(exc, EXIT_BAD_INPUT)
    except OSError as exc:        # a path the system refuses (too long, no permission, ...)
        name = f"{_short(exc.filename)}: " if exc.filename else ""
        return _error(f"{name}{exc.strerror or exc}", EXIT_BAD_INPUT)
    except KeyboardInterrupt:
        return _error("interrupted", EXIT_INTERRUPTED)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
