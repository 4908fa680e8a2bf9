"""The Python API, mirroring the command line: load a configuration, run it, read the results.

::

    import fipy_hopper as fh
    cfg = fh.load_config("studies/configs/reference.toml")
    summary = fh.run(cfg, "hopper_run")            # like: fipy-hopper run ... --out hopper_run
    res = fh.read_results("hopper_run")
    res.summary["steady_discharge_rate_kg_s"], res.timeseries["discharge_rate_kg_s"]

:func:`run` writes the run directory described in :mod:`fipy_hopper.io` and the pictures of
:mod:`fipy_hopper.plotting`.  The solver modules are imported when a run starts, so importing
this module is cheap.
"""

from __future__ import annotations

import math
import os
import sys
import time
import traceback
import warnings
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Callable, Optional, Union

import numpy as np

from .config import ConfigError, HopperConfig
from . import io as fio
from . import resources
from .summary_text import write_summary_text

__all__ = ["load_config", "run", "read_results", "Results", "expected_quantities",
           "make_model", "UnfinishedRunWarning", "ResultsError"]


def load_config(path: Union[str, os.PathLike]) -> HopperConfig:
    """Read and validate a TOML configuration (raises :class:`ConfigError` naming the key)."""
    if Path(path).is_dir():
        raise ConfigError(f"{path} is a directory, not a configuration file")
    try:
        return HopperConfig.from_toml(path)
    except UnicodeDecodeError as exc:     # a binary file: from_toml decodes before parsing
        raise ConfigError(f"{path} is not valid TOML: not UTF-8 text (byte {exc.start})") \
            from None


def _resolve(config_or_path) -> tuple:
    if isinstance(config_or_path, HopperConfig):
        return config_or_path, "<HopperConfig>"
    if isinstance(config_or_path, dict):
        return HopperConfig.from_dict(config_or_path), "<dict>"
    if isinstance(config_or_path, (str, os.PathLike)):
        return load_config(config_or_path), str(Path(config_or_path).resolve())
    raise ConfigError(f"expected a HopperConfig, a dict or a path to a TOML file, "
                      f"got {type(config_or_path).__name__}")


def expected_quantities(cfg: HopperConfig) -> dict:
    """What theory and the numerics say about a configuration before it runs.

    Every silo: ``fill_mass_kg`` (the density times the filled volume, 3D),
    ``p_wave_speed_m_s``, ``transition_height_m`` (of the wall's transition,
    :meth:`~fipy_hopper.boundary.Boundary.transition_height`), ``beverloo_flat_rate_kg_s``
    (Beverloo's rate through the outlet in a flat floor, C = 0.58, k = 1.5 with the
    material's grain diameter d; for a plane silo the slot rate, C' = 1.03, per metre),
    ``outlet_grains`` (the outlet's diameter, or a slot's width, in grain diameters), ``expected_discharge_time_s`` (the fill mass
    at the rate below, else at that one: an order of magnitude), and ``jenike_flow_mode``,
    the overall call of Jenike's calls per stretch of hopper wall
    (:func:`~fipy_hopper.diagnostics.stretch_calls`, by the rule of
    :func:`~fipy_hopper.diagnostics.overall_call`; ``"unknown"`` for a friction angle below
    the range of Jenike's fit).  For a wedge the masses and rates are per metre of length
    (the keys keep their names here; :func:`per_metre` renames them for the files).

    Only for the silos the closed forms describe (:attr:`HopperGeometry.classic`: a cone, a
    wedge or a flat floor under a bin, no insert in the material): ``cone_height_m``,
    ``rose_tanaka_factor`` (1 for a wedge: no plane hopper factor from a readable source),
    ``beverloo_rate_kg_s`` (Beverloo's rate times the Rose-Tanaka hopper factor), and
    ``jenike_critical_half_angle_deg`` (conical, or the plane-flow angle: the conical one plus
    10 deg, :func:`theory.jenike_critical_half_angle_plane`), with the internal friction
    angle as the effective angle of internal friction.  Other silos have a rate and a
    critical angle per stretch only where a stretch allows (the run's ``hopper_stretches``).

    With a cohesion ``c > 0`` also Jenike's design numbers (``docs/correlations.md`` section g):
    ``unconfined_yield_strength_Pa`` ``sigma_c = 2 c cos(phi)/(1 - sin(phi))``;
    ``critical_outlet_simplified_m`` ``2 sigma_c/(rho g)``; ``jenike_rathole_diameter_m``
    ``G(phi) sigma_c/(rho g)`` (NaN for phi outside the 30-70 deg of the fit of G); and for a
    classic silo ``jenike_critical_outlet_m`` ``H(theta) sigma_c/(rho g)`` (NaN for a flat
    bottom, outside the fit of H).  An outlet smaller than the critical outlet may arch.
    """
    from . import theory
    from .diagnostics import flow_call, stretch_calls

    geom, mat, wall = cfg.hopper, cfg.material, cfg.wall
    bnd = cfg.boundary
    classic = bnd.hopper_shape if geom.classic else None
    out = {"fill_mass_kg": mat.density * geom.fill_volume(),
           "p_wave_speed_m_s": mat.p_wave_speed,
           "transition_height_m": bnd.transition_height("wall")}
    grains = mat.grain_diameter
    out["outlet_grains"] = geom.outlet_diameter / grains if grains > 0 else math.inf
    if geom.rectangular and not geom.outlet_size[2]:   # a rectangular outlet
        flat = float(theory.beverloo_rectangular_rate(mat.density, *geom.outlet_size[:2],
                                                      d=grains))
        critical = theory.jenike_critical_half_angle
    elif geom.axisymmetric:
        flat = float(theory.beverloo_rate(mat.density, geom.outlet_diameter, d=grains))
        critical = theory.jenike_critical_half_angle
    else:     # per metre of slot; no plane hopper factor from a readable source
        flat = float(theory.beverloo_slot_rate(mat.density, geom.outlet_diameter, d=grains))
        critical = theory.jenike_critical_half_angle_plane
    out["beverloo_flat_rate_kg_s"] = flat
    rate = flat
    if classic is not None:
        factor = (float(theory.rose_tanaka_factor(classic.half_angle_deg))
                  if geom.axisymmetric else 1.0)
        rate = flat * factor
        out.update(cone_height_m=classic.transition_height, rose_tanaka_factor=factor,
                   beverloo_rate_kg_s=rate)
        try:
            out["jenike_critical_half_angle_deg"] = float(critical(
                mat.friction_angle_deg, wall.friction_angle_deg))
        except ValueError:   # friction angle below the range of Jenike's fit
            out["jenike_critical_half_angle_deg"] = math.nan
    out["jenike_flow_mode"] = flow_call(stretch_calls(cfg, []))["jenike_flow_mode"]
    out["expected_discharge_time_s"] = out["fill_mass_kg"] / rate
    if mat.cohesion > 0:
        sigma_c = float(theory.unconfined_yield_strength(mat.cohesion, mat.friction_angle_deg))
        out["unconfined_yield_strength_Pa"] = sigma_c
        out["critical_outlet_simplified_m"] = float(theory.critical_outlet_simplified(
            sigma_c, mat.density))
        formulas = [("jenike_rathole_diameter_m", lambda: theory.jenike_rathole_diameter(
            sigma_c, mat.density, mat.friction_angle_deg))]
        if classic is not None:
            formulas.append(("jenike_critical_outlet_m", lambda: theory.jenike_critical_outlet(
                sigma_c, mat.density, classic.half_angle_deg)))
        for key, formula in formulas:
            try:
                out[key] = float(formula())
            except ValueError:   # outside the range of Jenike's fit
                out[key] = math.nan
    return out


def run(config_or_path, out, force: bool = False, resume: bool = False, quiet: bool = True,
        checkpoint_interval: float = 60.0, plots: bool = True,
        setup: Optional[Callable] = None, command: Optional[str] = None,
        config_source: Optional[str] = None, threads: Optional[int] = None,
        profile: bool = False) -> dict:
    """Run a hopper into the directory ``out`` and return its summary (``summary.json``).

    Parameters
    ----------
    config_or_path : a :class:`HopperConfig`, a dict of sections or a path to a TOML file.
    out : the run directory; refused if it exists and is not empty, unless ``force``, and
        if it holds the configuration file being run (a run writes its ``config.toml``).
    force : overwrite the outputs of a previous run in ``out``.
    resume : continue the interrupted run in ``out`` from its checkpoint; the configuration
        must equal the one the run started with.  The outputs equal an uninterrupted run's.
    quiet : no progress line (it is only ever shown on a terminal).
    checkpoint_interval : wall-clock seconds between checkpoints (0: none).
    plots : draw the pictures when the run ends.
    setup : optional ``setup(sim)`` called with the :class:`~fipy_hopper.simulation.Simulation`
        before it runs, to attach more callbacks (``sim.add_callback``).
    command, config_source : recorded in the manifest (the command line and the configuration
        file, when called from the command line).
    threads : numba threads of the compiled steps, at most the cores this process may use
        (:func:`~fipy_hopper.resources.check_threads`).  Default: the cores that other
        processes leave free, measured at the start and every few seconds of the run
        (:class:`~fipy_hopper.resources.ThreadGovernor`).  The results do not depend on it.
    profile : time the phases of the run (:mod:`fipy_hopper.profiling`) and write them to
        ``profile.json``; the results do not depend on it.  A resumed run's profile covers
        the session since the resumption.

    Raises :class:`ConfigError` or :class:`~fipy_hopper.io.RunDirectoryError` before anything
    runs, and before the run directory is made or changed (a run that needs more memory than
    is available, :func:`~fipy_hopper.resources.check_memory`; a checkpoint that is not this
    run's); :class:`~fipy_hopper.model.InstabilityError` (and any other error) after writing
    everything measured so far with ``stop_reason`` ``"unstable: ..."`` (``"failed: ..."``);
    ``KeyboardInterrupt`` after writing the outputs so far with ``stop_reason``
    ``"interrupted"`` (continue with ``resume=True``), or :class:`PicturesInterrupted` (a
    ``KeyboardInterrupt``) when only the pictures of a finished run were being drawn.  A run
    stopped by ``run.wall_time_limit`` returns normally with ``stop_reason``
    ``"wall_time_limit"``; its last checkpoint is kept, so ``resume=True`` continues it.  A fill that does not come to
    rest by ``numerics.max_fill_time`` ends a fill-only run (``end_time = 0``) with
    ``stop_reason`` ``"fill_not_at_rest"``; a discharge started from it warns
    (:class:`~fipy_hopper.simulation.NotAtRestWarning`).
    """
    _check_arguments(out, force=force, resume=resume, quiet=quiet, plots=plots,
                     profile=profile, checkpoint_interval=checkpoint_interval, setup=setup)
    cfg, source = _resolve(config_or_path)
    source = config_source or source
    command = command or "fipy_hopper.run (Python API)"
    lagrangian = cfg.numerics.formulation == "lagrangian"
    if lagrangian and resume:
        raise ConfigError('resume: a numerics.formulation = "lagrangian" run is not '
                          'checkpointed (it stops when its mesh distorts, within seconds of '
                          'discharge); run it again')
    if lagrangian and profile:
        raise ConfigError('profile: the phases are those of the Eulerian model\'s compiled '
                          'step; numerics.formulation = "lagrangian" has none to time')
    if lagrangian:
        checkpoint_interval = 0
    # every refusal before anything is built or written
    if threads is not None:
        resources.check_threads(threads)
    resources.check_memory(cfg)
    _refuse_replacing_the_input(source, out, resume)
    fio.RunDirectory.check(out, force=force, resume=resume)
    if resume:
        _refuse_another_configuration(cfg, out)
    governor = resources.ThreadGovernor() if threads is None and not lagrangian else None

    from .model import InstabilityError
    from .simulation import NotAtRestWarning, Simulation, not_at_rest_message

    from .profiling import PhaseProfile
    from .profiling import timed as profiling_timed

    phases = PhaseProfile() if profile else None
    timed = partial(profiling_timed, phases)

    with timed("set-up"):
        model = make_model(cfg, threads=threads)
    model.profile = phases
    sim = Simulation(model, progress=(not quiet) and sys.stderr.isatty())
    if governor is not None:
        model.threads = governor.update()
        sim.add_wall_time_callback(governor, governor.interval)
    # Ctrl-C while the directory is opened and the run is set up takes effect once that is
    # done (never half-way through removing an earlier run's files), with the manifest
    # saying "interrupted"
    with _interrupts_deferred() as early:
        rundir = fio.RunDirectory(out, force=force, resume=resume)
    manifest = None
    try:
        with _interrupts_deferred() as setting_up:
            fields = _field_writer(rundir, model, cfg)

            def snapshot(sim_, state):
                with timed("snapshots and checkpoints"):
                    fields(sim_, state)
                    _write_tables(rundir, sim_.record, cfg.hopper.axisymmetric)

            interval = cfg.run.field_interval
            sim.add_callback(snapshot, interval, stages=("filling",))
            sim.add_callback(snapshot, interval, stages=("discharge",))
            if checkpoint_interval and checkpoint_interval > 0:
                def checkpoint(sim_, state):
                    with timed("snapshots and checkpoints"):
                        sim_.checkpoint(rundir.checkpoint)
                        manifest.checkpoint_written(state.t, state.step)
                sim.add_wall_time_callback(checkpoint, checkpoint_interval)
            if setup is not None:
                setup(sim)
            if resume:   # the checkpoint is checked before anything in the directory changes
                sim.restore(rundir.checkpoint)
                manifest = (fio.Manifest.load(rundir / rundir.MANIFEST)
                            if (rundir / rundir.MANIFEST).is_file()
                            else fio.Manifest.new(rundir / rundir.MANIFEST, source, command))
                rundir.remove_profile()
                fields.resume(sim.state.step)
                manifest.begin_session(command, sim.state.step, sim.state.t)
            else:    # the manifest first: a directory with a run's files is a run's (--force)
                manifest = fio.Manifest.new(rundir / rundir.MANIFEST, source, command)
                manifest.begin_session(command)
                fio.atomic_write_text(rundir / rundir.CONFIG, cfg.to_toml())
        if early.caught or setting_up.caught:
            raise KeyboardInterrupt
    except BaseException as exc:
        if manifest is not None and isinstance(exc, KeyboardInterrupt):
            with _interrupts_deferred():
                manifest.end_session("interrupted", "interrupted", 0.0)
        rundir.close()
        raise

    started = time.perf_counter()
    status, reason, error = "finished", "", None
    try:
        sim.run()
        reason = sim.record.stop_reason
        if reason == "wall_time_limit":      # not the end of the run: it can be resumed
            status = "stopped"
        elif sim.fill_gave_up and reason != "fill_not_at_rest":
            warnings.warn(not_at_rest_message(cfg), NotAtRestWarning)
    except InstabilityError as exc:
        status, reason, error = "failed", f"unstable: {exc}", exc
    except KeyboardInterrupt as exc:
        status, reason, error = "interrupted", "interrupted", exc
    except Exception as exc:
        interrupt = _interrupt_behind(exc)
        if interrupt is not None:   # Ctrl-C inside a writer whose clean-up then failed
            status, reason, error = "interrupted", "interrupted", interrupt
        else:                       # keep what was measured, then report
            status, reason, error = "failed", f"failed: {type(exc).__name__}: {exc}", exc
            fio.atomic_write_text(rundir / rundir.ERROR_LOG, traceback.format_exc())
    wall = time.perf_counter() - started

    # Ctrl-C from here on is taken once the results and the manifest are written: they are
    # always whole, and the manifest always ends in a finished state
    try:
        with _interrupts_deferred() as finishing:
            status, reason, error, summary = _finish(rundir, sim, cfg, fields, manifest,
                                                     status, reason, error, wall, out)
        pictures_interrupted = finishing.caught and status != "interrupted"
        if plots and status != "interrupted" and not pictures_interrupted:
            try:
                from . import plotting
                with timed("pictures"):
                    plotting.plot_run(rundir.path)
            except KeyboardInterrupt:        # the results are complete: only pictures lack
                pictures_interrupted = True
            except Exception as exc:  # pictures are a convenience; the data are written
                warnings.warn(f"the pictures could not be drawn: {exc}", RuntimeWarning)
        with _interrupts_deferred() as closing:
            if phases is not None:
                fio.write_json(rundir / rundir.PROFILE, phases.report())
        pictures_interrupted |= closing.caught and status != "interrupted"
    finally:
        rundir.close()                       # release the run directory's lock
    if error is not None:
        raise error
    if pictures_interrupted:
        raise PicturesInterrupted(rundir.path)
    return fio._jsonable(summary)


def _finish(rundir, sim, cfg, fields, manifest, status, reason, error, wall, out) -> tuple:
    """Write what a run measured (the last snapshot, the tables, ``summary.json`` and beside it
    ``summary.txt``, the terminal's summary naming the run directory as ``out``) and end the
    manifest's session: ``(status, reason, error, summary)``.  An error in the tables or the
    summary of a run that had not failed fails it (``stop_reason`` ``"failed: ..."``, the
    traceback in ``error.log``, :class:`ResultsError` raised by :func:`run`): a summary is
    whole or the run says it failed."""
    # after an interrupt the state may be half a step old, so no snapshot of it is taken
    # (the resumed run continues from the last checkpoint), and a sample may be half taken
    if status == "interrupted":
        _drop_half_sample(sim.record)
    if status != "interrupted" and fields.last_step != sim.state.step:
        try:
            fields.write(sim.state, sim.t_open)
        except Exception:  # pragma: no cover - never hide the run's own error
            pass
    try:
        _write_tables(rundir, sim.record, cfg.hopper.axisymmetric)
        summary = _summary(sim, cfg, reason, whole=status in ("finished", "stopped"))
    except Exception as exc:
        if error is None:
            what = f"{type(exc).__name__}: {exc}"
            status, reason = "failed", f"failed: the results could not be computed: {what}"
            error = ResultsError(f"the results could not be computed: {what}")
            error.__cause__ = exc
            fio.atomic_write_text(rundir / rundir.ERROR_LOG, traceback.format_exc())
        summary = _partial_summary(sim, cfg, reason)
    manifest.end_session(status, reason, wall)
    summary["wall_time_s"] = manifest.total_wall_time()
    fio.write_json(rundir / rundir.SUMMARY, summary)
    write_summary_text(rundir / rundir.SUMMARY_TEXT, summary, out)
    if status == "finished":
        rundir.checkpoint.unlink(missing_ok=True)
    return status, reason, error, summary


#: the time series of :class:`~fipy_hopper.simulation.RunRecord`, one value a sample
SAMPLE_SERIES = ("t", "mass_in_hopper", "discharged", "rate", "mass_flow_index",
                 "stagnant_fraction", "wall_slip_ratio", "wall_slip_stretches",
                 "wall_slip_fraction", "wall_slip_sectors", "bin_lateral_stress_ratio")


def _drop_half_sample(record) -> None:
    """A sample that Ctrl-C cut short (some of its series appended, not all) is dropped: the
    time series keep the samples they all have."""
    series = [getattr(record, name) for name in SAMPLE_SERIES if hasattr(record, name)]
    common = min((len(values) for values in series), default=0)
    for values in series:
        del values[common:]


class ResultsError(RuntimeError):
    """The run's tables or its summary could not be computed (the run is marked failed and
    the traceback is in ``error.log``): never a summary with parts silently missing."""


def _interrupt_behind(exc: BaseException):
    """The ``KeyboardInterrupt`` an exception was raised while handling (a writer whose
    clean-up failed after Ctrl-C), or None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


class _interrupts_deferred:
    """Hold Ctrl-C (SIGINT) and SIGTERM while a block writes what must be whole: a signal
    that comes is noted (``caught``) and acted on by the caller after the block.  In the main
    thread only (elsewhere signals are not delivered to Python); the handlers are restored."""

    SIGNALS = ("SIGINT", "SIGTERM")

    def __enter__(self):
        import signal
        import threading

        self.caught, self.previous = False, {}
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                number = getattr(signal, name, None)
                if number is not None:
                    self.previous[number] = signal.signal(number, self._note)
        return self

    def _note(self, signum, frame):
        self.caught = True

    def __exit__(self, *exc):
        import signal

        for number, handler in self.previous.items():
            signal.signal(number, handler)
        return False


def _check_arguments(out, checkpoint_interval, setup, **flags) -> None:
    """:func:`run`'s arguments, before anything is made: :class:`ConfigError` naming the
    argument, its value and what it may be."""
    if isinstance(out, bool) or not isinstance(out, (str, os.PathLike)):
        raise ConfigError(f"out = {_show(out)}: expected a directory name (a str or a path)")
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise ConfigError(f"{name} = {_show(value)}: expected True or False")
    if isinstance(checkpoint_interval, (bool, np.bool_)) or \
            not isinstance(checkpoint_interval, (int, float, np.integer, np.floating)) or \
            not (math.isfinite(checkpoint_interval) and checkpoint_interval >= 0):
        raise ConfigError(f"checkpoint_interval = {_show(checkpoint_interval)}: expected a "
                          "finite number of seconds >= 0 (0: no checkpoints)")
    if setup is not None and not callable(setup):
        raise ConfigError(f"setup = {_show(setup)}: expected None or a function setup(sim)")


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class PicturesInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) while the pictures of a run were drawn: the run's results are
    complete in the directory ``args[0]``; ``fipy-hopper plot DIR`` draws the pictures."""


def _refuse_replacing_the_input(source: str, out, resume: bool) -> None:
    """A new run writes its resolved configuration to ``out/config.toml``: refuse when that
    is the configuration file being run (``--out`` the folder holding it)."""
    if resume or not source or source.startswith("<"):
        return
    target = Path(out) / fio.RunDirectory.CONFIG
    try:
        same = Path(source).is_file() and target.is_file() and target.samefile(source)
    except OSError:
        return
    if same:
        raise fio.RunDirectoryError(
            f"{target} is the configuration being run, and a run writes its resolved "
            f"configuration there: choose another run directory than {out} (or move the "
            f"configuration out of it)")


def _refuse_another_configuration(cfg: HopperConfig, out) -> None:
    """``resume``: the configuration must be the one the run in ``out`` started with."""
    saved_path = Path(out) / fio.RunDirectory.CONFIG
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        saved = load_config(saved_path)
    if saved != cfg:
        raise ConfigError(f"the configuration differs from the one the run in {out} started "
                          f"with ({saved_path}); resume with that one")


def make_model(cfg: HopperConfig, threads: Optional[int] = None):
    """The model of ``cfg``: for ``hopper.dimensions = 3`` the 3D circular silo
    :class:`~fipy_hopper.space.model.SpaceModel`; for a section that of
    ``cfg.numerics.formulation``, the Eulerian :class:`~fipy_hopper.model.HopperModel` or the
    updated-Lagrangian :class:`~fipy_hopper.lagrangian.LagrangianModel` (``threads``: numba
    threads of the Eulerian models' compiled steps)."""
    if cfg.hopper.dimensions == 3:
        from .space.model import SpaceModel
        return SpaceModel(cfg, threads=threads)
    if cfg.numerics.formulation == "lagrangian":
        from .lagrangian import LagrangianModel
        return LagrangianModel(cfg)
    from .model import HopperModel
    return HopperModel(cfg, threads=threads)


def _field_writer(rundir, model, cfg):
    """The field snapshots' writer of the model: the grid's quads of a section, the moving
    mesh of a Lagrangian run, the hexahedra of the whole 3D silo."""
    if model.dimensions == 3:
        from .space.output import SpaceFieldWriter
        return SpaceFieldWriter(rundir.fields, model)
    strength = (cfg.material.cohesion, cfg.material.friction_angle_deg)
    if cfg.numerics.formulation == "lagrangian":
        return fio.MeshFieldWriter(rundir.fields, model, *strength)
    return fio.FieldWriter(rundir.fields, model.grid, *strength)


def _write_tables(rundir, record, axisymmetric: bool = True) -> None:
    from .diagnostics import FlowModeRule

    fio.write_timeseries(rundir / rundir.TIMESERIES, record, axisymmetric)
    fio.write_wall_pressure(rundir / rundir.WALL_PRESSURE, record)
    if record.wall_theta:                        # 3D: the extremes around the circumference
        fio.write_wall_extremes(rundir / rundir.WALL_EXTREMES, record)
    if record.channel_windows:                   # 3D, a circular plan: the channel per window
        fio.write_channel_windows(rundir / rundir.CHANNEL_WINDOWS, record)
    fio.write_loads(rundir / rundir.LOADS, record, axisymmetric)
    fio.write_wall_slip(rundir / rundir.WALL_SLIP, record, FlowModeRule().slip_ratio)


def _summary(sim, cfg, reason: str, whole: bool = True) -> dict:
    """The run's ``summary.json``: :meth:`Simulation.summary` with the theory's numbers.  An
    error in it is raised when the run ended as it should (``whole``); a run that failed or
    was interrupted, which may not have measured what the summary needs, gets
    :func:`_partial_summary` (its stop reason says it did not finish)."""
    try:
        summary = dict(sim.summary())
    except Exception:
        if whole:
            raise
        return _partial_summary(sim, cfg, reason)
    summary["stop_reason"] = reason
    expected = expected_quantities(cfg)
    summary["outlet_grains"] = expected["outlet_grains"]
    for key in ("beverloo_rate_kg_s", "jenike_critical_half_angle_deg", "jenike_flow_mode",
                "unconfined_yield_strength_Pa", "jenike_critical_outlet_m",
                "critical_outlet_simplified_m", "jenike_rathole_diameter_m"):
        if key in expected:          # the closed forms only for the silos they describe
            summary[key] = expected[key]
    return summary if cfg.hopper.axisymmetric else per_metre(summary)


def _partial_summary(sim, cfg, reason: str) -> dict:
    """The summary of a run that did not finish (failed or interrupted) and whose full
    summary could not be computed: what is known without measurements, the rest NaN
    (``null``), ``flow_mode`` ``"unknown"``; its ``stop_reason`` says why."""
    rec = sim.record
    summary = {"steady_discharge_rate_kg_s": math.nan, "flow_mode": "unknown",
               "mass_flow_index": math.nan, "wall_slip_ratio": math.nan,
               "wall_slip_fraction": math.nan, "initial_mass_kg": rec.initial_mass,
               "remaining_mass_kg": math.nan, "mass_balance_error": math.nan,
               "discharge_time_s": rec.t[-1] if rec.t else 0.0,
               "cells": sim.model.n_cells, "steps": sim.state.step,
               "wall_time_s": math.nan, "stop_reason": reason,
               "youngs_modulus_used": cfg.material.youngs_modulus}
    return summary if cfg.hopper.axisymmetric else per_metre(summary)


#: the per-metre names of a wedge's results (defined with the output files)
PER_METRE, per_metre, result_key = fio.PER_METRE, fio.per_metre, fio.result_key


# ---------------------------------------------------------------- reading results
@dataclass
class Results:
    """The results in a run directory (read by :func:`read_results`).

    ``summary`` and ``manifest`` are the JSON dictionaries; ``timeseries`` maps each column of
    ``timeseries.csv`` to an array; ``wall_pressure`` each column of ``wall_pressure.csv`` to an
    array (``stage`` as strings); ``snapshots`` lists the field snapshots (``file``, ``step``,
    ``t_s``, ``discharge_time_s``, ``stage``); :meth:`field` reads one with meshio.
    """

    path: Path
    summary: dict
    manifest: dict
    config: HopperConfig
    timeseries: dict
    wall_pressure: dict
    snapshots: list = field(default_factory=list)

    def field(self, index: int = -1):
        """The ``meshio.Mesh`` of snapshot ``index`` (cell data ``alpha``, ``layer``, ...)."""
        return fio.read_vtu(self.path / fio.RunDirectory.FIELDS / self.snapshots[index]["file"])

    @property
    def finished(self) -> bool:
        """True when the run finished (its manifest says so)."""
        return self.manifest.get("status") == "finished"

    def wall_stage(self, stage: str) -> dict:
        """The wall pressure rows of one stage (``filling``, ``early_discharge``, ...)."""
        sel = self.wall_pressure["stage"] == stage
        return {k: v[sel] for k, v in self.wall_pressure.items()}


class UnfinishedRunWarning(RuntimeWarning):
    """:func:`read_results` of a run that did not finish (running, interrupted, stopped or
    failed, by its manifest, or one without a manifest): its files hold what was measured so
    far, which is no run's final result."""


def read_results(out) -> Results:
    """Read a run directory written by :func:`run` or ``fipy-hopper run``.

    A run that did not finish (``manifest.json``'s status ``"running"``, ``"interrupted"``,
    ``"stopped"`` or ``"failed"``, or no manifest) is read all the same, with an
    :class:`UnfinishedRunWarning` saying so: its files are whole (every file is written
    atomically) and what it measured is what one looks at to see why it stopped, but its
    summary is not a finished run's (``Results.finished`` is False)."""
    import json

    path = Path(out)
    names = fio.RunDirectory
    missing = [n for n in (names.SUMMARY, names.TIMESERIES, names.CONFIG)
               if not (path / n).is_file()]
    if missing:
        raise FileNotFoundError(f"{path} is not a finished run directory (no {', '.join(missing)})")
    with open(path / names.SUMMARY, encoding="utf-8") as fh:
        summary = json.load(fh)
    manifest = {}
    if (path / names.MANIFEST).is_file():
        with open(path / names.MANIFEST, encoding="utf-8") as fh:
            manifest = json.load(fh)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = load_config(path / names.CONFIG)
    wall = (fio.read_csv(path / names.WALL_PRESSURE) if (path / names.WALL_PRESSURE).is_file()
            else {c: np.array([]) for c in fio.WALL_PRESSURE_COLUMNS})
    if "stage" in wall:
        wall["stage"] = np.asarray(wall["stage"], dtype=str)
    snapshots = []
    if (path / names.FIELDS / fio.FieldWriter.INDEX).is_file():
        snapshots = fio.read_snapshot_index(path / names.FIELDS)
    _warn_unfinished(path, manifest, summary)
    return Results(path=path, summary=summary, manifest=manifest, config=cfg,
                   timeseries=fio.read_csv(path / names.TIMESERIES), wall_pressure=wall,
                   snapshots=snapshots)


def _warn_unfinished(path: Path, manifest: dict, summary: dict) -> None:
    """:class:`UnfinishedRunWarning` for a run directory whose run did not finish."""
    status = manifest.get("status")
    reason = manifest.get("stop_reason") or summary.get("stop_reason") or ""
    why = f" ({reason})" if reason and reason != status else ""
    if not manifest:
        what = "has no manifest.json, so whether its run finished is unknown"
    elif status == "finished":
        return
    elif status == "running":
        what = ("holds a run that has not finished (manifest status 'running': a run is "
                "writing it now, or it was killed)")
    elif status in ("interrupted", "stopped"):
        what = (f"holds a run that was {status}{why}; continue it with --resume "
                "(resume=True)")
    else:
        what = f"holds a run that did not finish: {status}{why}"
    warnings.warn(f"{path} {what}: its files hold what was measured until then, not a "
                  "finished run's results", UnfinishedRunWarning, stacklevel=3)
