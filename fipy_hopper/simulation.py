"""Simulation: owns a run of a :class:`HopperModel` — filling, discharge, stop rules, schedules.

The model steps; the simulation decides when to stop, measures on a schedule and calls the
writers and diagnostics attached to it (callbacks that read the state and never change it).

Stages:

- **filling**: the outlet plate is closed, gravity is ramped up over ``gravity_ramp_time`` and a
  mass-proportional damping (critical for the column's lowest elastic mode) removes the elastic
  waves.  The fill is *at rest* when, after the ramp, the kinetic energy is below
  ``settle_kinetic_energy * M g L`` (``M`` the mass, ``L`` the fill depth from outlet to
  surface).  Filling gives up at ``max_fill_time`` and says so.
- **discharge**: the plate is removed; the run stops at ``end_time`` or, for ``"empty"``, when
  less than ``empty_fraction`` of the initial mass is left in the hopper (``"empty"``), or when
  nothing has left for 0.25 s and the kinetic energy is tiny (``"at_rest"``: a heel on a
  shallow cone), or at ``max_time`` (``"max_time"``); any run stops at ``wall_time_limit``.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from . import diagnostics
from .model import GRAVITY, HopperModel, InstabilityError, State


def _nanmean(samples) -> np.ndarray:
    """Mean over axis 0 ignoring NaN; NaN where every sample is NaN."""
    arr = np.asarray(samples, dtype=float)
    count = np.isfinite(arr).sum(axis=0)
    total = np.where(np.isfinite(arr), arr, 0.0).sum(axis=0)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


@dataclass
class Schedule:
    """Call ``fn(sim, state)`` every ``interval`` seconds of simulated time in ``stages``."""

    fn: Callable
    interval: float
    stages: tuple = ("filling", "discharge")
    next_time: float = 0.0


@dataclass
class RunRecord:
    """What a run measured (all SI; masses are 3D, kg)."""

    t: list = field(default_factory=list)               # s since the outlet opened
    mass_in_hopper: list = field(default_factory=list)
    discharged: list = field(default_factory=list)
    rate: list = field(default_factory=list)             # kg/s over the last interval
    mass_flow_index: list = field(default_factory=list)
    stagnant_fraction: list = field(default_factory=list)
    wall: dict = field(default_factory=dict)             # stage -> (t, s, r, z, p_n, tau)
    fill_time: float = math.nan
    fill_at_rest: bool = False
    initial_mass: float = math.nan
    stop_reason: str = ""
    wall_time: float = 0.0
    steps: int = 0


class Simulation:
    """Run a hopper from filling to the end of discharge."""

    def __init__(self, model: HopperModel, state: Optional[State] = None,
                 end_time=None, wall_time_limit: Optional[float] = None,
                 progress: Optional[bool] = None, flow_rule=diagnostics.FlowModeRule()):
        run = model.cfg.run
        self.model = model
        self.state = state if state is not None else model.initial_state()
        self.end_time = run.end_time if end_time is None else end_time
        self.wall_time_limit = run.wall_time_limit if wall_time_limit is None else wall_time_limit
        self.progress = sys.stderr.isatty() if progress is None else progress
        self.flow_rule = flow_rule
        self.record = RunRecord()
        self.schedules: list[Schedule] = []
        self.wall_sampler = diagnostics.WallSampler(model)
        self._wall_avg: dict = {}
        self._started = None
        self._last_progress = 0.0
        self._eta_mark = None            # (wall time, discharge time) when the ETA clock started
        self.t_open = math.nan
        self.next_sample = math.nan
        self.wall_schedules: list = []   # [fn, wall-time interval, last call]

    def add_wall_time_callback(self, fn: Callable, interval: float):
        """Call ``fn(sim, state)`` every ``interval`` seconds of wall time (e.g. checkpoints).

        They are called last in a check, after the samples and the stop rules, when the run goes
        on, and once more when it stops for its wall-time limit: a checkpoint written there
        holds the state at the top of the loop, where :meth:`restore` continues, so a resumed
        run repeats the uninterrupted one step for step (a checkpoint written from a
        simulated-time callback would skip the rest of its check on resume).
        """
        self.wall_schedules.append([fn, interval, time.perf_counter()])

    def _call_wall_schedules(self, force=False):
        now = time.perf_counter()
        for entry in self.wall_schedules:
            fn, interval, last = entry
            if force or now - last >= interval:
                fn(self, self.state)
                entry[2] = time.perf_counter()

    # -------------------------------------------------------------- callbacks
    def add_callback(self, fn: Callable, interval: float, stages=("filling", "discharge")):
        self.schedules.append(Schedule(fn, interval, tuple(stages), self.state.t))

    def _call_schedules(self):
        for s in self.schedules:
            if self.state.stage in s.stages and self.state.t >= s.next_time - 1e-12:
                s.fn(self, self.state)
                s.next_time = self.state.t + s.interval

    # -------------------------------------------------------------- stages
    def _check_stable(self):
        st = self.state
        v = st.v
        speed = np.hypot(v[0], v[1])
        limit = 50.0 * math.sqrt(GRAVITY * max(self.model.cfg.hopper.top, 0.1))
        bad = ~np.isfinite(speed) | (speed > limit)
        if bad.any():
            j, i = np.argwhere(bad)[0]
            g = self.model.grid
            raise InstabilityError(
                f"runaway velocity at step {st.step}, t = {st.t:.6g} s, node r = "
                f"{g.r_nodes[i]:.4g} m, z = {g.z_nodes[j]:.4g} m (|v| = {speed[j, i]:.3g} m/s, "
                f"limit {limit:.3g} m/s)")

    def _out_of_wall_time(self) -> bool:
        return self.wall_time_limit > 0 and time.perf_counter() - self._started > \
            self.wall_time_limit

    def fill(self) -> bool:
        """Bring the filled hopper to rest with the outlet closed; True when at rest."""
        m, st = self.model, self.state
        num = m.cfg.numerics
        if self._started is None:
            self._started = time.perf_counter()
        mass = m.total_mass(st)
        depth = m.cfg.hopper.fill_level
        threshold = num.settle_kinetic_energy * mass * GRAVITY * depth
        check_every = max(1, int(0.005 / m.dt))
        while st.stage == "filling":
            m.advance(st, check_every - st.step % check_every)
            if st.step % check_every == 0:
                self._check_stable()
                self._call_schedules()
                if st.t >= num.gravity_ramp_time and m.kinetic_energy(st) < threshold:
                    self.record.fill_at_rest = True
                    break
                if st.t >= num.max_fill_time:
                    break
                if self._out_of_wall_time():
                    self.record.stop_reason = "wall_time_limit"
                    self._call_wall_schedules(force=True)
                    return False
                # last: a checkpoint here resumes exactly (see add_wall_time_callback)
                self._call_wall_schedules()
                self._progress(f"filling t={st.t:.3f} s  KE/MgL={m.kinetic_energy(st) / (mass * GRAVITY * depth):.2e}")
        m.transport_step(st)
        self.record.fill_time = st.t
        self._sample_wall("filling", average_over=0.0)
        return self.record.fill_at_rest

    def discharge(self) -> str:
        """Open the outlet and run until a stop rule fires; returns the stop reason."""
        m, st, rec = self.model, self.state, self.record
        run = m.cfg.run
        if self._started is None:
            self._started = time.perf_counter()
        if st.stage == "filling":
            m.open_outlet(st)
            self.t_open = st.t
            rec.initial_mass = m.mass_in_hopper(st)
            self._log_sample(force=True)
            self.next_sample = st.t + run.output_interval
        m0 = rec.initial_mass
        check_every = max(1, int(0.002 / m.dt))
        stage_marks = {"early_discharge": 0.9, "mid_discharge": 0.5}
        reason = ""
        while not reason:
            m.advance(st, check_every - st.step % check_every)
            if st.step % check_every:
                continue
            self._check_stable()
            self._call_schedules()
            if st.t >= self.next_sample - 1e-12:
                self._log_sample()
                self.next_sample += run.output_interval
            t_dis = st.t - self.t_open
            mass = m.mass_in_hopper(st)
            for name, frac in stage_marks.items():
                if name not in rec.wall and mass <= frac * m0:
                    self._sample_wall(name, average_over=0.1)
            if self.end_time != "empty" and t_dis >= float(self.end_time):
                reason = "end_time"
            elif self.end_time == "empty" and mass < run.empty_fraction * m0:
                reason = "empty"
            elif self.end_time == "empty" and t_dis > 0.5 and self._at_rest():
                reason = "at_rest"
            elif t_dis >= run.max_time:
                reason = "max_time"
            elif self._out_of_wall_time():
                reason = "wall_time_limit"
            # last: a checkpoint here resumes exactly (see add_wall_time_callback)
            if not reason:
                self._call_wall_schedules()
            elif reason == "wall_time_limit":
                self._call_wall_schedules(force=True)
            if self.progress:
                self._progress(f"discharge t={t_dis:.3f} s  step {st.step}  "
                               f"left {mass:.3g} kg  W={rec.rate[-1] if rec.rate else 0:.3g} kg/s"
                               + self._eta(t_dis, mass))
        self._log_sample(force=True)
        rec.stop_reason = reason
        return reason

    def run(self) -> RunRecord:
        """Fill, then discharge; returns the :class:`RunRecord`."""
        self._started = time.perf_counter()
        self.record.stop_reason = ""
        try:
            if self.state.stage == "filling":
                self.fill()
            if self.record.stop_reason != "wall_time_limit":
                self.discharge()
        finally:
            self.record.wall_time = time.perf_counter() - self._started
            self.record.steps = self.state.step
            if self.progress:
                sys.stderr.write("\n")
        return self.record

    # -------------------------------------------------------------- measuring
    def _at_rest(self) -> bool:
        rec = self.record
        n = max(1, int(round(0.25 / self.model.cfg.run.output_interval)))
        if len(rec.rate) < n:
            return False
        recent = np.asarray(rec.rate[-n:])
        return bool(np.all(np.abs(recent) < 1e-3 * max(rec.initial_mass, 1e-9)))

    def _log_sample(self, force=False):
        m, st, rec = self.model, self.state, self.record
        t = st.t - self.t_open
        if rec.t and not force and t <= rec.t[-1]:
            return
        if rec.t and t <= rec.t[-1] + 1e-12:
            return
        mass = m.mass_in_hopper(st)
        rate = 0.0
        if rec.t:
            rate = (st.discharged - rec.discharged[-1]) / (t - rec.t[-1])
        rec.t.append(t)
        rec.mass_in_hopper.append(mass)
        rec.discharged.append(st.discharged)
        rec.rate.append(rate)
        index, stagnant = diagnostics.flow_mode_measures(m, st, self.flow_rule)
        rec.mass_flow_index.append(index)
        rec.stagnant_fraction.append(stagnant)

    def _sample_wall(self, stage: str, average_over: float = 0.0):
        """Wall pressure profile; in discharge the mean over ``average_over`` s of steps.

        Samples are taken every 20 steps; a bin's mean is over the samples in which it held
        material (the free surface moves down during the average).
        """
        st = self.state
        s, r, z, p, tau = self.wall_sampler.profile_all(st)
        samples_p, samples_t = [p], [tau]
        for _ in range(int(average_over / self.model.dt / 20)):
            for _ in range(20):
                self.model.step(st)
            _, _, _, p2, t2 = self.wall_sampler.profile_all(st)
            samples_p.append(p2)
            samples_t.append(t2)
        p, tau = _nanmean(samples_p), _nanmean(samples_t)
        ok = np.isfinite(p)
        t_stage = st.t - (self.t_open if np.isfinite(self.t_open) else st.t)
        self.record.wall[stage] = (t_stage, s[ok], r[ok], z[ok], p[ok], tau[ok])

    def _progress(self, text: str):
        if not self.progress:
            return
        now = time.perf_counter()
        if now - self._last_progress < 0.5:
            return
        self._last_progress = now
        sys.stderr.write(f"\r{text}  wall {now - self._started:.0f} s   ")
        sys.stderr.flush()

    # -------------------------------------------------------------- checkpoints
    def checkpoint(self, path) -> None:
        """Write everything needed to resume to ``path`` (``.npz``), atomically.

        The file is written to a temporary name in the same directory and renamed over
        ``path``, so a run killed at any moment leaves either the old or the new checkpoint.
        """
        st = self.state
        arrays = {k: v for k, v in st.__dict__.items() if isinstance(v, np.ndarray)}
        scalars = {k: v for k, v in st.__dict__.items() if not isinstance(v, np.ndarray)}
        rec = dict(self.record.__dict__)
        wall = rec.pop("wall")
        for stage, values in wall.items():
            for k, arr in enumerate(values[1:]):
                arrays[f"wall__{stage}__{k}"] = np.asarray(arr)
        meta = {"state": scalars, "record": rec,
                "wall_times": {stage: values[0] for stage, values in wall.items()},
                "t_open": self.t_open, "next_sample": self.next_sample,
                "schedules": [s.next_time for s in self.schedules]}
        path = os.fspath(path)
        folder = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(prefix=".checkpoint-", suffix=".npz", dir=folder)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    def restore(self, path) -> None:
        """Continue from a checkpoint written by :meth:`checkpoint` (same configuration)."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["__meta__"]))
            arrays = {k: data[k].copy() for k in data.files if k != "__meta__"}
        wall = {}
        for stage, t_stage in meta["wall_times"].items():
            wall[stage] = (t_stage,) + tuple(arrays.pop(f"wall__{stage}__{k}") for k in range(5))
        self.state = State(**meta["state"], **{k: v for k, v in arrays.items()
                                                if not k.startswith("wall__")})
        self.record = RunRecord(**meta["record"], wall=wall)
        self.t_open = meta["t_open"]
        self.next_sample = meta["next_sample"]
        for s, t_next in zip(self.schedules, meta["schedules"]):
            s.next_time = t_next
        self.model._mass = None

    # -------------------------------------------------------------- results
    def summary(self) -> dict:
        """The run's headline numbers (the ``summary.json`` contract)."""
        m, st, rec = self.model, self.state, self.record
        rate, spread, n = diagnostics.steady_rate(rec.t, rec.mass_in_hopper, rec.rate)
        t = np.asarray(rec.t)
        masses = np.asarray(rec.mass_in_hopper)
        m0 = rec.initial_mass
        window = (masses <= 0.9 * m0) & (masses >= 0.4 * m0) & (t > 0.1)
        idx = np.asarray(rec.mass_flow_index)[window] if window.any() else np.asarray(
            rec.mass_flow_index[1:])
        stag = np.asarray(rec.stagnant_fraction)[window] if window.any() else np.asarray(
            rec.stagnant_fraction[1:])
        index = float(np.nanmedian(idx)) if np.isfinite(idx).any() else math.nan
        stagnant = float(np.nanmedian(stag)) if np.isfinite(stag).any() else math.nan
        remaining = m.mass_in_hopper(st)
        balance = abs(remaining + st.discharged - m0) / m0 if m0 > 0 else math.nan
        return {
            "steady_discharge_rate_kg_s": rate,
            "steady_rate_spread": spread,
            "flow_mode": diagnostics.classify_flow_mode(index, stagnant, self.flow_rule),
            "mass_flow_index": index,
            "stagnant_fraction": stagnant,
            "initial_mass_kg": m0,
            "remaining_mass_kg": remaining,
            "discharged_kg": st.discharged,
            "mass_balance_error": balance,
            "discharge_time_s": float(t[-1]) if len(t) else 0.0,
            "fill_time_s": rec.fill_time,
            "fill_at_rest": rec.fill_at_rest,
            "stop_reason": rec.stop_reason,
            "cells": m.grid.n_cells,
            "steps": st.step,
            "dt_s": m.dt,
            "wall_time_s": rec.wall_time,
            "youngs_modulus_used": m.cfg.material.youngs_modulus,
            "cell_size_m": m.grid.h,
            "hourglass_coefficient": m.cfg.numerics.hourglass_coefficient,
        }
