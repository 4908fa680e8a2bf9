"""Simulation: owns a run of a hopper model — filling, discharge, stop rules, schedules.

One loop for every model: the Eulerian section :class:`HopperModel`, the updated-Lagrangian
section :class:`~fipy_hopper.lagrangian.LagrangianModel` or the 3D circular silo
:class:`~fipy_hopper.space.model.SpaceModel`, and the simulation uses only what
:class:`~fipy_hopper.protocol.HopperModelProtocol` declares (the wall loads are the model's,
:meth:`~fipy_hopper.protocol.HopperModelProtocol.wall_measures`; in 3D a wall "bin" of the
record is a patch, a height bin times a sector around the circumference).  The model steps;
the simulation decides when to stop, measures on a schedule and calls the writers and
diagnostics attached to it (callbacks that read the state and never change it).
Every measurement reads the state between the run's own steps: nothing steps the model but
the run.

Stages:

- **filling**: the outlet plate is closed, gravity rises linearly over the model's ramp
  (``HopperModel.ramp_time``: a number of periods of the column's lowest elastic mode, so
  that the fill is quasi-static whatever the stiffness and the size) and a mass-proportional
  damping removes the elastic waves.  The fill is *at rest* when, after the ramp, the kinetic
  energy is below ``settle_kinetic_energy * M g L`` (``M`` the mass, ``L`` the fill depth from
  outlet to surface) and the damping carries less than ``settle_damping_fraction`` of the
  weight over the last check interval (the walls and the plate hold the rest).  Filling gives
  up at ``max_fill_time`` and says so (``RunRecord.fill_at_rest`` false,
  :func:`not_at_rest_message`).  ``end_time = 0`` stops there: ``"filled"``, or
  ``"fill_not_at_rest"`` when the fill gave up before it came to rest (its wall loads are
  those of a moving fill).
- **discharge**: the plate is removed; the run stops at ``end_time`` or, for ``"empty"``, when
  less than ``empty_fraction`` of the initial mass is left in the hopper (``"empty"``), or when
  the flow has stopped (``"at_rest"``, :data:`AT_REST_AFTER`: a heel on a shallow cone, an
  arch, a rathole; the summary names which, :class:`~fipy_hopper.diagnostics.OutcomeRule`, and
  when it stopped), or at ``max_time`` (``"max_time"``); any run stops at ``wall_time_limit``.
  These are :class:`StopRule` objects in ``Simulation.stop_rules`` (checked in order every
  check interval, the first that applies names the reason); a study adds its own there.

What runs, and when: objects the simulation holds and calls, each reading the state —
``schedules`` (:class:`Schedule`, simulated time, at the checks: the
:class:`StabilityCheck` first, then field writers and other callbacks), ``stage_marks``
(:class:`StageMark`: when the wall loads of a discharge stage are measured),
``stop_rules`` (:class:`StopRule`) and ``wall_schedules`` (:class:`WallTimeSchedule`, wall
time: checkpoints); the model's ``after_transport`` hooks run after each transport.  A
study adds or replaces entries of these lists.

What is measured, and when:

- the time series (``timeseries.csv``) every ``output_interval`` of discharge, at the first
  step at or after each sample time (evenly spaced to within one step), and once more when
  the run stops;
- the vertical momentum balance of the grid (``loads.csv``, :meth:`WallLoads.balance`) over
  each ``output_interval``, filling and discharge;
- the wall loads from the wall's reaction (:class:`~fipy_hopper.diagnostics.WallLoads`) over
  windows: at rest (``filling``: the last check interval of the fill), from the moment 90 % and
  50 % of the mass is left (``early_discharge``, ``mid_discharge``: ``load_window`` s), and over
  consecutive windows of ``load_window`` s through the whole discharge, whose largest ``p_n``
  per bin is the envelope (``discharge_envelope``); beside each, the stress-sampled profile
  (:class:`~fipy_hopper.diagnostics.WallSampler`, averaged over the checks of the window).
"""

from __future__ import annotations

import hashlib
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
from .protocol import halt_reason

#: The flow has stopped (stop reason ``"at_rest"``) when, later than ``AT_REST_AFTER`` s after
#: the outlet is fully open (``run.opening_time`` after the opening began), every sample of
#: the last ``AT_REST_WINDOW`` s had a discharge rate below ``AT_REST_RATE`` of the initial
#: mass per second (an arch over the outlet, a rathole: little ever moves out), or below
#: ``AT_REST_SHARE`` of the steady discharge rate so far (:func:`~fipy_hopper.diagnostics.
#: steady_rate`) with the material at rest, its rms speed
#: (:func:`~fipy_hopper.diagnostics.material_speed`) below ``AT_REST_SPEED`` of the outlet's
#: free-fall speed ``sqrt(g B_0)`` (``B_0`` the outlet's width or diameter): the heel of a flat
#: floor or a shallow cone, whose dead zones creep on and would never drain below
#: ``empty_fraction`` (measured on a flat-bottomed slot silo at 1 cm: the heel drains at a
#: rate falling as about 1/t, 5 % of the steady rate 6 s after the opening, its material's
#: rms speed then 1.6 mm/s against 7.7 mm/s for 1 % of sqrt(g B_0)).  The summary names
#: which (:class:`fipy_hopper.diagnostics.OutcomeRule`) and what is left
#: (``remaining_mass_kg``, ``heap_angle_deg``).
AT_REST_AFTER, AT_REST_WINDOW, AT_REST_RATE = 0.5, 0.25, 1e-3
AT_REST_SHARE, AT_REST_SPEED = 0.05, 0.01
#: Stages whose wall loads are measured from the moment this fraction of the mass is left
#: (the default :class:`StageMark` s).
STAGE_MARKS = {"early_discharge": 0.9, "mid_discharge": 0.5}
#: Wall-load stages in the order they are written.
WALL_STAGES = ("filling", "early_discharge", "mid_discharge", "discharge_envelope")


class NotAtRestWarning(RuntimeWarning):
    """The fill gave up at ``numerics.max_fill_time`` and the discharge started from it."""


def not_at_rest_message(cfg) -> str:
    """What to say of a fill that did not come to rest by ``numerics.max_fill_time``."""
    return (f"the fill did not come to rest within numerics.max_fill_time = "
            f"{cfg.numerics.max_fill_time:g} s: its wall loads (and a discharge started from "
            "it) are those of a moving fill; raise numerics.max_fill_time (or relax "
            "numerics.settle_kinetic_energy, numerics.settle_damping_fraction)")


@dataclass
class Schedule:
    """Call ``fn(sim, state)`` every ``interval`` seconds of simulated time in ``stages``."""

    fn: Callable
    interval: float
    stages: tuple = ("filling", "discharge")
    next_time: float = 0.0


@dataclass
class StageMark:
    """A discharge stage whose wall loads are measured over one ``load_window`` from the first
    check at which at most ``mass_fraction`` of the initial mass is left in the hopper (the
    stage ``name`` in ``wall_pressure.csv``)."""

    name: str
    mass_fraction: float


def default_stage_marks() -> list:
    """:data:`STAGE_MARKS` as :class:`StageMark` s: 90 % and 50 % of the mass left."""
    return [StageMark(name, fraction) for name, fraction in STAGE_MARKS.items()]


@dataclass
class WallTimeSchedule:
    """Call ``fn(sim, state)`` every ``interval`` seconds of wall time (``last``: the wall
    clock, ``time.perf_counter``, of the last call)."""

    fn: Callable
    interval: float
    last: float


class StabilityCheck:
    """The scheduled stability check (first of ``Simulation.schedules``, at every check of
    both stages): :class:`~fipy_hopper.model.InstabilityError` on a state the model finds
    unstable (:meth:`~fipy_hopper.protocol.HopperModelProtocol.check_stable`) or on mass that
    the books do not account for (the mass in the domain plus the mass lost through its bottom
    against the first check's, to 1e-6)."""

    def __init__(self):
        self.books = None           # kg, 3D: in the domain and lost, at the first check

    def __call__(self, sim, state):
        m = sim.model
        m.check_stable(state)
        total = m.total_mass(state) + state.lost
        if self.books is None:
            self.books = total
        if not abs(total - self.books) <= 1e-6 * self.books:
            raise InstabilityError(
                f"mass not accounted for at step {state.step}, t = {state.t:.6g} s: "
                f"{total:.9g} kg in the grid and lost, {self.books:.9g} kg at the start")


@dataclass
class StopRule:
    """A rule that ends the discharge: ``applies(sim, t_discharge, mass)`` (the simulation, the
    time since the outlet opened in s, the mass left in the hopper in kg) is checked every
    check interval, after the measurements of that check; the first rule of
    ``Simulation.stop_rules`` that applies names the stop reason: ``name``, or the string it
    returns if it returns one.  Rules read the state; they never change it."""

    name: str
    applies: Callable


def _halt_rule(sim, t_dis, mass):
    return halt_reason(sim.state)


def _end_time_rule(sim, t_dis, mass):
    return sim.end_time != "empty" and t_dis >= float(sim.end_time) - 1e-12


def _empty_rule(sim, t_dis, mass):
    return sim.end_time == "empty" and mass < sim.model.cfg.run.empty_fraction * \
        sim.record.initial_mass


def _at_rest_rule(sim, t_dis, mass):
    return sim.end_time == "empty" and sim._rest_samples > 0


def _max_time_rule(sim, t_dis, mass):
    return t_dis >= sim.model.cfg.run.max_time


def _wall_time_rule(sim, t_dis, mass):
    return sim._out_of_wall_time()


def default_stop_rules() -> list:
    """The discharge's stop rules, in order: ``halt`` (the model cannot go on, e.g. a
    Lagrangian mesh too distorted: the reason is the state's ``halt``), ``end_time`` (a
    discharge of ``end_time`` s),
    ``empty`` and ``at_rest`` (for ``end_time = "empty"``: less than ``empty_fraction`` of the
    initial mass left; the flow has stopped, :data:`AT_REST_AFTER`), ``max_time`` and
    ``wall_time_limit``."""
    return [StopRule("halt", _halt_rule),
            StopRule("end_time", _end_time_rule), StopRule("empty", _empty_rule),
            StopRule("at_rest", _at_rest_rule), StopRule("max_time", _max_time_rule),
            StopRule("wall_time_limit", _wall_time_rule)]


@dataclass
class RunRecord:
    """What a run measured (all SI; masses are 3D, kg; forces 3D, N)."""

    t: list = field(default_factory=list)               # s since the outlet opened
    mass_in_hopper: list = field(default_factory=list)
    discharged: list = field(default_factory=list)
    rate: list = field(default_factory=list)             # kg/s over the last interval
    mass_flow_index: list = field(default_factory=list)
    stagnant_fraction: list = field(default_factory=list)
    wall_slip_ratio: list = field(default_factory=list)      # -, FlowModeRule, per sample
    wall_slip_fraction: list = field(default_factory=list)   # -, share of the hopper wall
    # per sample, the wall slip ratio of each stretch of hopper wall (diagnostics.hopper_rows)
    wall_slip_stretches: list = field(default_factory=list)
    # per sample, the wall slip fraction of each stretch of hopper wall
    wall_slip_stretch_fractions: list = field(default_factory=list)
    # rows (s, r, z, slip / axis speed) of the loaded hopper-wall contacts at the last sample
    # of the flow-mode window (wall_slip.csv, the flow-pattern picture)
    wall_slip_profile: list = field(default_factory=list)
    # 3D, per sample: the wall slip ratio of each hopper stretch in each sector (a section's
    # samples: empty lists)
    wall_slip_sectors: list = field(default_factory=list)
    bin_lateral_stress_ratio: list = field(default_factory=list)   # -, in the bin's full cells
    # stage -> (t since the outlet opened, s, r, z, p_n, tau): the traction recovered from the
    # wall's reaction, its mean per bin (diagnostics.WallLoads.profile); in 3D per patch, and
    # the hoop shear tau_theta after tau (space.wall.PatchLoads.profile)
    wall: dict = field(default_factory=dict)
    # stage -> (p_n, tau) of the plain binning of the reaction (WallLoads.raw_profile)
    wall_raw: dict = field(default_factory=dict)
    # the wall (chain) of each bin: "wall", "left_wall", "insert_1", ...
    wall_names: list = field(default_factory=list)
    # 3D: each bin's (patch's) angle around the circumference (deg, its sector's centre) and
    # its profile segment; empty for a section
    wall_theta: list = field(default_factory=list)
    wall_segment: list = field(default_factory=list)
    # stage -> {wall or insert: [F_x, F_z]} (N, 3D) over the stage's window
    chain_forces: dict = field(default_factory=dict)
    # insert -> the largest downward load of the material on it over the discharge's windows
    # (N, 3D)
    insert_force_max: dict = field(default_factory=dict)
    # stage -> the forces at the walls' corners (diagnostics.WallLoads.corner_forces)
    corner_forces: dict = field(default_factory=dict)
    # stage -> (p_n, tau) stress-sampled on the same bins (NaN where a bin held no material)
    wall_stress: dict = field(default_factory=dict)
    wall_window: dict = field(default_factory=dict)      # stage -> window duration (s)
    # stage -> (hoop, meridional per bin, [hopper tension, bin wall compression] at the
    # transition), N/m (diagnostics.WallLoads.membrane_forces)
    wall_forces: dict = field(default_factory=dict)
    loads: list = field(default_factory=list)            # rows of loads.csv (dicts)
    rest_balance: dict = field(default_factory=dict)     # the balance over the rest window
    envelope_windows: int = 0
    # the flow channel per window of the discharge (the envelope's windows), measured on the
    # window's mean fields (HopperModelProtocol.channel_measures): one dict per window and
    # height, with the window's start and end (s since the outlet opened); none for a section
    channel_windows: list = field(default_factory=list)
    wall_k: float = math.nan                             # p_n / (-sigma_zz) at the bin wall, at rest
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
                 progress: Optional[bool] = None, flow_rule=diagnostics.FlowModeRule(),
                 outcome_rule=diagnostics.OutcomeRule()):
        run = model.cfg.run
        self.model = model
        self.state = state if state is not None else model.initial_state()
        self.end_time = run.end_time if end_time is None else end_time
        self.wall_time_limit = run.wall_time_limit if wall_time_limit is None else wall_time_limit
        self.progress = sys.stderr.isatty() if progress is None else progress
        self.flow_rule = flow_rule
        self.outcome_rule = outcome_rule
        self._rest_samples = 0           # samples that the last check found at rest (0: flowing)
        self._rest_rate = math.nan       # kg/s: the rate below which it found them at rest
        self.record = RunRecord()
        #: what runs at the checks (simulated-time schedules, in order): the stability check
        #: first, then the callbacks (field writers, studies' probes: :meth:`add_callback`)
        self.stability = StabilityCheck()
        self.schedules: list[Schedule] = [Schedule(self.stability, 0.0, ("filling", "discharge"),
                                                   self.state.t)]
        #: the discharge stages whose wall loads are measured (:class:`StageMark`)
        self.stage_marks: list[StageMark] = default_stage_marks()
        #: the model's stress-sampled wall profile and wall loads from the wall's reaction
        self.wall_sampler, self.wall_loads = model.wall_measures()
        self.record.wall_names = [str(name) for name in self.wall_sampler.bins.wall]
        if self.wall_sampler.theta is not None:            # 3D: the patches' angles
            self.record.wall_theta = [float(t) for t in self.wall_sampler.theta]
            self.record.wall_segment = [int(k) for k in self.wall_sampler.segment]
        self._insert_names = [c.name for c in model.cfg.boundary.inserts]
        self.load_window = run.load_window_s
        self._started = None
        self._last_progress = 0.0
        self._eta_mark = None            # (wall time, discharge time) when the ETA clock started
        self.t_open = math.nan
        self.next_sample = math.nan      # next time-series sample (s, run time)
        self.next_load_sample = math.nan  # next loads.csv row (s, run time)
        self.next_envelope = math.nan    # end of the current envelope window (s, run time)
        self._readings: dict = {}        # window name -> WallLoads.reading at its start
        self._stress_sums: dict = {}     # stage -> [sum p_n, sum tau, count] of the window
        self.envelope = None             # largest windowed p_n per bin in discharge
        self.envelope_raw = None         # the same of the plain binning (for checking)
        #: the smallest and the largest windowed p_n of every wall bin in discharge, a bin's
        #: unmeasured windows (NaN) left out: ``(low, high)`` arrays, None before a window
        self.window_extremes = None
        #: the sums over the current discharge window's checks of the model's channel fields
        #: (``HopperModelProtocol.channel_fields``) and how many checks they hold
        self._channel_sums = None
        self._channel_count = 0
        self.wall_schedules: list[WallTimeSchedule] = []   # e.g. checkpoints
        #: the discharge's stop rules, in order (:class:`StopRule`; a custom rule, e.g. a
        #: discharged mass, is inserted or appended here)
        self.stop_rules: list[StopRule] = default_stop_rules()

    def add_wall_time_callback(self, fn: Callable, interval: float):
        """Call ``fn(sim, state)`` every ``interval`` seconds of wall time (e.g. checkpoints).

        They are called last in a check, after the samples and the stop rules, when the run goes
        on, and once more when it stops for its wall-time limit: a checkpoint written there
        holds the state at the top of the loop, where :meth:`restore` continues, so a resumed
        run repeats the uninterrupted one step for step (a checkpoint written from a
        simulated-time callback would skip the rest of its check on resume).
        """
        self.wall_schedules.append(WallTimeSchedule(fn, interval, time.perf_counter()))

    def _call_wall_schedules(self, force=False):
        now = time.perf_counter()
        for entry in self.wall_schedules:
            if force or now - entry.last >= entry.interval:
                entry.fn(self, self.state)
                entry.last = time.perf_counter()

    # -------------------------------------------------------------- callbacks
    def add_callback(self, fn: Callable, interval: float, stages=("filling", "discharge")):
        self.schedules.append(Schedule(fn, interval, tuple(stages), self.state.t))

    def _call_schedules(self):
        for s in self.schedules:
            if self.state.stage in s.stages and self.state.t >= s.next_time - 1e-12:
                s.fn(self, self.state)
                s.next_time = self.state.t + s.interval

    # -------------------------------------------------------------- stages
    def _out_of_wall_time(self) -> bool:
        return self.wall_time_limit > 0 and time.perf_counter() - self._started > \
            self.wall_time_limit

    def _steps_until(self, t_target: float) -> int:
        """Steps until the state's time first reaches ``t_target`` (at least 1)."""
        ahead = (t_target - self.state.t) / self.model.dt
        return max(1, int(math.ceil(ahead - 1e-9)))

    def fill(self) -> bool:
        """Bring the filled hopper to rest with the outlet closed; True when at rest."""
        m, st = self.model, self.state
        num, run = m.cfg.numerics, m.cfg.run
        if self._started is None:
            self._started = time.perf_counter()
        mass = m.total_mass(st)
        depth = m.cfg.hopper.fill_level
        threshold = num.settle_kinetic_energy * mass * GRAVITY * depth
        settle = num.settle_damping_fraction
        check_every = max(1, int(0.005 / m.dt))
        loads = self.wall_loads
        if "check" not in self._readings:
            self._readings["check"] = self._readings["sample"] = loads.reading(m, st)
            self.next_load_sample = st.t + run.output_interval
        window = None
        while st.stage == "filling":
            m.advance(st, min(check_every - st.step % check_every,
                              self._steps_until(self.next_load_sample)))
            if st.t >= self.next_load_sample - 1e-12:
                self._load_sample("filling")
                self.next_load_sample += run.output_interval
            if halt_reason(st):                 # the model cannot go on: the fill ends here
                self.record.stop_reason = halt_reason(st)
                self.record.fill_time = st.t
                return False
            if st.step % check_every:
                continue
            self._call_schedules()              # the stability check first
            previous, current = self._readings["check"], loads.reading(m, st)
            self._readings["check"] = current
            balance = loads.balance(previous, current)
            ke = m.kinetic_energy(st)
            if (st.t >= m.ramp_time and ke < threshold
                    and abs(balance["damping"]) <= settle * balance["weight"]):
                self.record.fill_at_rest = True
                window = (previous, current)
                break
            if st.t >= num.max_fill_time:
                window = (previous, current)
                break
            if self._out_of_wall_time():
                self.record.stop_reason = "wall_time_limit"
                self._call_wall_schedules(force=True)
                return False
            # last: a checkpoint here resumes exactly (see add_wall_time_callback)
            self._call_wall_schedules()
            self._progress(f"filling t={st.t:.3f} s  KE/MgL={ke / (mass * GRAVITY * depth):.2e}"
                           f"  damping/weight={balance['damping'] / balance['weight']:.1e}")
        m.transport_step(st)
        self.record.fill_time = st.t
        self.record.rest_balance = loads.balance(*window)
        self._wall_stage("filling", *window)
        self.record.wall_k = loads.wall_k(self.record.wall["filling"][4], st)
        return self.record.fill_at_rest

    def discharge(self) -> str:
        """Open the outlet and run until a stop rule fires; returns the stop reason."""
        m, st, rec = self.model, self.state, self.record
        run = m.cfg.run
        loads = self.wall_loads
        if self._started is None:
            self._started = time.perf_counter()
        if st.stage == "filling":
            m.open_outlet(st)
            self.t_open = st.t
            rec.initial_mass = m.mass_in_hopper(st)
            self._log_sample(force=True)
            self.next_sample = st.t + run.output_interval
            self.next_load_sample = st.t + run.output_interval
            self._readings["sample"] = self._readings["envelope"] = loads.reading(m, st)
            self.next_envelope = st.t + self.load_window
        m0 = rec.initial_mass
        check_every = max(1, int(0.002 / m.dt))
        reason = ""
        while not reason:
            m.advance(st, min(check_every - st.step % check_every,
                              self._steps_until(self.next_sample)))
            if st.t >= self.next_sample - 1e-12:
                self._log_sample()
                self.next_sample += run.output_interval
                self._load_sample("discharge")
            if st.step % check_every and not halt_reason(st):
                continue
            self._call_schedules()              # the stability check first
            t_dis = st.t - self.t_open
            mass = m.mass_in_hopper(st)
            self._discharge_windows(mass, m0)
            self._rest_rate = (self._at_rest() if t_dis > AT_REST_AFTER + run.opening_time
                               else math.nan)
            self._rest_samples = len(rec.rate) if math.isfinite(self._rest_rate) else 0
            reason = ""
            for rule in self.stop_rules:
                applies = rule.applies(self, t_dis, mass)
                if applies:
                    reason = applies if isinstance(applies, str) else rule.name
                    break
            reason = reason or halt_reason(st)      # a model that cannot go on stops the run
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
        self._finish_discharge_stages()
        rec.stop_reason = reason
        return reason

    def run(self) -> RunRecord:
        """Fill, then discharge (unless ``end_time`` is 0); returns the :class:`RunRecord`."""
        self._started = time.perf_counter()
        self.record.stop_reason = ""
        try:
            if self.state.stage == "filling":
                self.fill()
            if self.record.stop_reason == "wall_time_limit" or halt_reason(self.state):
                pass
            elif self.end_time != "empty" and float(self.end_time) == 0.0:
                self.record.stop_reason = ("filled" if self.record.fill_at_rest
                                           else "fill_not_at_rest")
            else:
                self.discharge()
        finally:
            self.record.wall_time = time.perf_counter() - self._started
            self.record.steps = self.state.step
            if self.progress:
                sys.stderr.write("\n")
        return self.record

    @property
    def fill_gave_up(self) -> bool:
        """True once the fill has stopped at ``max_fill_time`` without coming to rest."""
        return bool(self.record.rest_balance) and not self.record.fill_at_rest

    # -------------------------------------------------------------- measuring
    def _at_rest(self) -> float:
        """The rate (kg/s) below which every sample of the last :data:`AT_REST_WINDOW` s
        lies, if the flow has stopped by either rule of :data:`AT_REST_AFTER` (little moves
        out; or the discharge has dwindled to a creep with the material at rest), else NaN."""
        rec, m = self.record, self.model
        n = max(1, int(round(AT_REST_WINDOW / m.cfg.run.output_interval)))
        if len(rec.rate) < n:
            return math.nan
        recent = np.abs(np.asarray(rec.rate[-n:]))
        little = AT_REST_RATE * max(rec.initial_mass, 1e-9)
        if np.all(recent < little):
            return little
        if not recent.max() < AT_REST_SHARE * np.nanmax(rec.rate):   # the steady rate's bound
            return math.nan
        dwindled = AT_REST_SHARE * diagnostics.steady_rate(rec.t, rec.mass_in_hopper,
                                                           rec.rate)[0]
        if not np.all(recent < dwindled):
            return math.nan
        x0, x1 = m.cfg.boundary.outlet
        width = (x1 - x0) * (2.0 if m.cfg.boundary.section.half else 1.0)
        speed = m.material_speed(self.state)
        return dwindled if speed < AT_REST_SPEED * math.sqrt(GRAVITY * width) else math.nan

    def flow_stopped_time(self) -> float:
        """When the flow stopped (s after the opening), NaN if it had not by the end of the
        run: if the last check of the discharge found the flow at rest (:meth:`_at_rest`,
        :data:`AT_REST_AFTER`; evaluated whatever ``end_time``), the end of the last sample
        interval before that check with a rate of at least the rate it found the flow below,
        or 0 if there was none (the outlet opened on an arch).  The sample taken when the run
        stops is left out: its interval can be a few steps, over which the elastic sway of an
        arch moves more than the rule's rate."""
        rec, n = self.record, self._rest_samples
        if not n:
            return math.nan
        fast = np.flatnonzero(np.abs(np.asarray(rec.rate[:n])) >= self._rest_rate)
        return float(rec.t[fast[-1]]) if len(fast) else 0.0

    def _eta(self, t_dis: float, mass: float) -> str:
        """`` ETA ...`` of the progress line: the wall time to the end, from the discharge's
        progress since the ETA clock started (its first call)."""
        now = time.perf_counter()
        if self._eta_mark is None:
            self._eta_mark = (now, t_dis, mass)
            return ""
        wall0, t0, mass0 = self._eta_mark
        elapsed, simulated = now - wall0, t_dis - t0
        if elapsed < 2.0 or simulated <= 0:
            return ""
        if self.end_time == "empty":
            rate = (mass0 - mass) / simulated
            target = self.model.cfg.run.empty_fraction * self.record.initial_mass
            remaining = (mass - target) / rate if rate > 0 else math.inf
            remaining = min(remaining, self.model.cfg.run.max_time - t_dis)
        else:
            remaining = float(self.end_time) - t_dis
        seconds = elapsed / simulated * max(remaining, 0.0)
        if not math.isfinite(seconds):
            return ""
        return f"  ETA {seconds:.0f} s"

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
            # the mass is booked at the transports, every few steps: over an interval much
            # shorter than output_interval (the sample taken when the run stops) a rate
            # would be a lump's, not the flow's; it is not given
            span = t - rec.t[-1]
            rate = ((st.discharged - rec.discharged[-1]) / span
                    if span >= 0.5 * m.cfg.run.output_interval else math.nan)
        rec.t.append(t)
        rec.mass_in_hopper.append(mass)
        rec.discharged.append(st.discharged)
        rec.rate.append(rate)
        index, stagnant = m.flow_mode_measures(st, self.flow_rule)
        rec.mass_flow_index.append(index)
        rec.stagnant_fraction.append(stagnant)
        previous = self._readings.get("sample")     # the wall's impulse at the last sample
        slip, share, ratios, shares, profile, sectors = m.wall_slip_measures(
            st, previous["wall"] if previous is not None else None, self.flow_rule)
        rec.wall_slip_ratio.append(slip)
        rec.wall_slip_stretches.append([float(r) for r in ratios])
        rec.wall_slip_stretch_fractions.append([float(f) for f in shares])
        rec.wall_slip_fraction.append(share)
        rec.wall_slip_sectors.append([] if sectors is None else np.asarray(sectors).tolist())
        if len(rec.t) > 1 and _before_flow_window_end(t, mass, rec.initial_mass) \
                and len(profile):
            rec.wall_slip_profile = profile.tolist()
        rec.bin_lateral_stress_ratio.append(m.bin_lateral_stress_ratio(st))

    def _load_sample(self, stage: str):
        """A row of ``loads.csv``: the vertical balance since the previous row."""
        current = self.wall_loads.reading(self.model, self.state)
        previous = self._readings.get("sample")
        self._readings["sample"] = current
        if previous is None or not current["t"] > previous["t"]:
            return
        row = {"stage": stage, "t_s": current["t"]}
        row.update(self.wall_loads.balance(previous, current))
        self.record.loads.append(row)

    def _stress_profile(self):
        return self.wall_sampler.profile_all(self.state)[3:]

    def _discharge_windows(self, mass: float, m0: float):
        """At a check of the discharge: start and finish the stage windows, close envelope
        windows, and add the stress-sampled profile to the open stage windows."""
        m, st, loads = self.model, self.state, self.wall_loads
        for mark in self.stage_marks:
            stage = mark.name
            if stage not in self._readings and stage not in self.record.wall \
                    and mass <= mark.mass_fraction * m0:
                self._readings[stage] = loads.reading(m, st)
                self._stress_sums[stage] = None
        for stage in [mark.name for mark in self.stage_marks]:
            if stage in self._readings:
                self._add_stress(stage)
                if st.t - self._readings[stage]["t"] >= self.load_window - 1e-12:
                    self._wall_stage(stage, self._readings.pop(stage),
                                     loads.reading(m, st))
        self._add_channel_fields()
        if st.t >= self.next_envelope - 1e-12:
            current = loads.reading(m, st)
            p_n = loads.profile(self._readings["envelope"], current)[3]
            raw = loads.raw_profile(self._readings["envelope"], current)[3]
            forces = loads.chain_forces(self._readings["envelope"], current)
            for name in self._insert_names:
                load = forces[name][1]     # its push up on the material: the load on it
                self.record.insert_force_max[name] = max(
                    self.record.insert_force_max.get(name, -math.inf), load)
            self.envelope = p_n if self.envelope is None else np.maximum(self.envelope, p_n)
            low, high = self.window_extremes or (p_n, p_n)
            self.window_extremes = (np.fmin(low, p_n), np.fmax(high, p_n))
            self.envelope_raw = (raw if self.envelope_raw is None
                                 else np.maximum(self.envelope_raw, raw))
            self.record.envelope_windows += 1
            self._measure_channel(self._readings["envelope"]["t"], current["t"])
            self._readings["envelope"] = current
            self.next_envelope = st.t + self.load_window

    def _add_channel_fields(self):
        """Add the model's channel fields now to the current window's sums."""
        fields = self.model.channel_fields(self.state)
        if not len(fields):
            return
        if self._channel_sums is None:
            self._channel_sums = [np.array(f, float) for f in fields]
        else:
            for total, f in zip(self._channel_sums, fields):
                total += f
        self._channel_count += 1

    def _measure_channel(self, t_start: float, t_end: float):
        """The channel of the window ``t_start``-``t_end`` (s, run time) on its mean fields,
        into ``record.channel_windows``; the sums start again."""
        if self._channel_sums is not None and self._channel_count > 0:
            means = tuple(total / self._channel_count for total in self._channel_sums)
            window = {"window": self.record.envelope_windows,
                      "t_start_s": t_start - self.t_open, "t_end_s": t_end - self.t_open,
                      "checks": self._channel_count}
            self.record.channel_windows.extend(
                {**window, **row} for row in self.model.channel_measures(means))
        self._channel_sums, self._channel_count = None, 0

    def _add_stress(self, stage: str):
        p, tau = self._stress_profile()
        sums = self._stress_sums.get(stage)
        ok = np.isfinite(p)
        if sums is None:
            sums = [np.zeros_like(p), np.zeros_like(p), np.zeros_like(p)]
        sums[0] += np.where(ok, p, 0.0)
        sums[1] += np.where(ok, tau, 0.0)
        sums[2] += ok
        self._stress_sums[stage] = sums

    def _wall_stage(self, stage: str, start: dict, end: dict):
        """Record the wall loads of ``stage`` over the window ``start``-``end``: the traction
        recovered from the reaction, its plain binning, and the stress-sampled profile
        (averaged over the window's checks, or at its end when it had none)."""
        values = self.wall_loads.profile(start, end)     # 3D: tau_theta after tau
        s, r, z, p_n, tau = values[:5]
        self.record.wall_raw[stage] = self.wall_loads.raw_profile(start, end)[3:]
        sums = self._stress_sums.pop(stage, None)
        if sums is None or not np.any(sums[2]):
            p_s, tau_s = self._stress_profile()
        else:
            count = np.maximum(sums[2], 1)
            p_s = np.where(sums[2] > 0, sums[0] / count, np.nan)
            tau_s = np.where(sums[2] > 0, sums[1] / count, np.nan)
        t_open = self.t_open if np.isfinite(self.t_open) else end["t"]
        self.record.wall[stage] = (end["t"] - t_open,) + tuple(values)
        hoop, meridional, at_transition = self.wall_loads.membrane_forces(start, end, p_n,
                                                                          tau)
        self.record.chain_forces[stage] = {k: list(v) for k, v in
                                           self.wall_loads.chain_forces(start, end).items()}
        self.record.corner_forces[stage] = self.wall_loads.corner_forces(p_n, tau)
        self.record.wall_forces[stage] = (hoop, meridional, np.asarray(at_transition))
        self.record.wall_stress[stage] = (p_s, tau_s)
        self.record.wall_window[stage] = end["t"] - start["t"]

    def _finish_discharge_stages(self):
        """At the end of the discharge: the envelope as a stage (its ``tau`` is not an
        envelope: NaN) and stage windows that the end cut short, over what they had."""
        m, st = self.model, self.state
        for stage in [mark.name for mark in self.stage_marks]:
            if stage in self._readings:
                start = self._readings.pop(stage)
                if st.t > start["t"]:
                    self._wall_stage(stage, start, self.wall_loads.reading(m, st))
        if self.envelope is not None:
            sampler = self.wall_sampler
            nan = np.full_like(self.envelope, np.nan)
            self.record.wall["discharge_envelope"] = (
                st.t - self.t_open, sampler.centres, sampler.r, sampler.z, self.envelope, nan)
            self.record.wall_raw["discharge_envelope"] = (self.envelope_raw, nan)
            self.record.wall_stress["discharge_envelope"] = (nan, nan)
            self.record.wall_forces["discharge_envelope"] = (     # no one state: no meridional
                self.wall_loads.hoop_force(self.envelope), nan, np.full(2, np.nan))
            self.record.wall_window["discharge_envelope"] = self.load_window

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
        wall, wall_stress = rec.pop("wall"), rec.pop("wall_stress")
        wall_forces, wall_raw = rec.pop("wall_forces"), rec.pop("wall_raw")
        for stage, values in wall.items():
            for k, arr in enumerate(values[1:]):
                arrays[f"wall__{stage}__{k}"] = np.asarray(arr)
            for k, arr in enumerate(wall_raw.get(stage, ())):
                arrays[f"wallraw__{stage}__{k}"] = np.asarray(arr)
            for k, arr in enumerate(wall_stress.get(stage, ())):
                arrays[f"wallstress__{stage}__{k}"] = np.asarray(arr)
            for k, arr in enumerate(wall_forces.get(stage, ())):
                arrays[f"wallforces__{stage}__{k}"] = np.asarray(arr)
        readings = {}
        for name, reading in self._readings.items():
            readings[name] = {k: v for k, v in reading.items() if not isinstance(v, np.ndarray)}
            for k, v in reading.items():
                if isinstance(v, np.ndarray):
                    arrays[f"reading__{name}__{k}"] = v
        for stage, sums in self._stress_sums.items():
            if sums is not None:
                for k, v in enumerate(sums):
                    arrays[f"stresssum__{stage}__{k}"] = v
        if self.envelope is not None:
            arrays["envelope"] = self.envelope
        if self.envelope_raw is not None:
            arrays["envelope_raw"] = self.envelope_raw
        if self.window_extremes is not None:
            arrays["window_low"], arrays["window_high"] = self.window_extremes
        for k, total in enumerate(self._channel_sums or ()):
            arrays[f"channelsum__{k}"] = total
        meta = {"fingerprint": self.fingerprint(), "state": scalars, "record": rec,
                "wall_times": {stage: values[0] for stage, values in wall.items()},
                "t_open": self.t_open, "next_sample": self.next_sample,
                "next_load_sample": self.next_load_sample,
                "next_envelope": self.next_envelope, "readings": readings,
                "stress_sums": {k: v is not None for k, v in self._stress_sums.items()},
                "channel_count": self._channel_count,
                "mass_books": self.stability.books,
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

    def fingerprint(self) -> str:
        """What the run is, as a hash: its resolved configuration (the canonical TOML) and its
        material law (class and parameters).  A checkpoint holds it; :meth:`restore` refuses
        another run's."""
        law = self.model.material
        text = (self.model.cfg.to_toml() + f"\n# law {type(law).__module__}."
                f"{type(law).__qualname__} {sorted(law.parameters().items())!r}\n")
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def restore(self, path) -> None:
        """Continue from a checkpoint written by :meth:`checkpoint` (same configuration).

        The file is checked before anything changes (:func:`fipy_hopper.io.read_checkpoint`:
        its size, the names, types and shapes of its arrays against this run's state, no
        pickle, the state's time and step within this run's; then :meth:`_check_checkpoint`:
        the fingerprint of this run, the record's and the measurements' types, names and
        shapes): a damaged or foreign checkpoint raises
        :class:`~fipy_hopper.io.CheckpointError` naming the file and what is wrong."""
        from . import io as fio

        arrays, meta = fio.read_checkpoint(path, self.state, self.model.cfg, self.model.dt)
        self._check_checkpoint(arrays, meta, f"checkpoint {path}")
        wall, wall_stress, wall_forces, wall_raw = {}, {}, {}, {}
        for stage, t_stage in meta["wall_times"].items():
            wall[stage] = (t_stage,) + tuple(arrays.pop(f"wall__{stage}__{k}") for k in range(
                6 if f"wall__{stage}__5" in arrays else 5))      # 3D: tau_theta too
            wall_raw[stage] = tuple(arrays.pop(f"wallraw__{stage}__{k}") for k in range(2))
            wall_stress[stage] = tuple(arrays.pop(f"wallstress__{stage}__{k}") for k in range(2))
            wall_forces[stage] = tuple(arrays.pop(f"wallforces__{stage}__{k}") for k in range(3))
        self._readings = {}
        for name, scalars in meta.get("readings", {}).items():
            reading = dict(scalars)
            for key in ("wall", "plate", "budget"):
                reading[key] = arrays.pop(f"reading__{name}__{key}")
            self._readings[name] = reading
        self._stress_sums = {}
        for stage, present in meta.get("stress_sums", {}).items():
            self._stress_sums[stage] = ([arrays.pop(f"stresssum__{stage}__{k}")
                                         for k in range(3)] if present else None)
        self.envelope = arrays.pop("envelope", None)
        self.envelope_raw = arrays.pop("envelope_raw", None)
        low, high = arrays.pop("window_low", None), arrays.pop("window_high", None)
        self.window_extremes = None if low is None or high is None else (low, high)
        n_fields = len([k for k in arrays if k.startswith("channelsum__")])
        self._channel_sums = ([arrays.pop(f"channelsum__{k}") for k in range(n_fields)]
                              if n_fields else None)
        self._channel_count = int(meta.get("channel_count", 0))
        self.state = type(self.state)(**meta["state"], **arrays)
        self.record = RunRecord(**meta["record"], wall=wall, wall_stress=wall_stress,
                                wall_forces=wall_forces, wall_raw=wall_raw)
        n = len(self.record.wall_slip_stretches[-1]) if self.record.wall_slip_stretches else 0
        for name, unknown in (("wall_slip_stretch_fractions", [math.nan] * n),
                              ("wall_slip_sectors", [])):  # per-sample measures this version
            values = getattr(self.record, name)          # adds: not measured before it
            values[:0] = [unknown] * (len(self.record.t) - len(values))
        self.t_open = meta["t_open"]
        self.next_sample = meta["next_sample"]
        self.next_load_sample = meta.get("next_load_sample", math.nan)
        self.next_envelope = meta.get("next_envelope", math.nan)
        if meta.get("mass_books") is not None:
            self.stability.books = meta["mass_books"]
        for s, t_next in zip(self.schedules, meta["schedules"]):
            s.next_time = t_next
        self.model.reset_caches()

    def _check_checkpoint(self, arrays: dict, meta: dict, where: str) -> None:
        """Raise :class:`~fipy_hopper.io.CheckpointError` unless the metadata and the
        measurement arrays of a checkpoint are this run's, as :meth:`checkpoint` writes them:
        the fingerprint; the record's fields with the types of :class:`RunRecord`'s (lists of
        numbers of one length); the stages, readings and sums with the shapes of this run's
        wall bins and contacts; the schedules' times numbers."""
        from .io import CheckpointError, is_number, same_kind

        def fail(message):
            raise CheckpointError(f"{where}: {message}")

        if meta.get("fingerprint") != self.fingerprint():
            fail("it belongs to another run (its configuration or material law differs from "
                 "this run's)" if isinstance(meta.get("fingerprint"), str) else
                 "it holds no fingerprint of its run (written by an older version); start the "
                 "run again")
        known = {"fingerprint", "state", "record", "wall_times", "t_open", "next_sample",
                 "next_load_sample", "next_envelope", "readings", "stress_sums", "mass_books",
                 "schedules", "channel_count"}
        for key in meta:
            if key not in known:
                fail(f"its metadata holds an unknown entry {str(key)[:40]!r}")
        for key in ("t_open", "next_sample", "next_load_sample", "next_envelope",
                    "mass_books"):
            if not same_kind(meta.get(key), 0.0):
                fail(f"its metadata's {key} = {str(meta[key])[:40]} is not a number")
        record, template = meta["record"], vars(RunRecord())
        series = ("t", "mass_in_hopper", "discharged", "rate", "mass_flow_index",
                  "stagnant_fraction", "bin_lateral_stress_ratio")
        for key, value in record.items():
            like = template.get(key)
            if key in ("wall", "wall_stress", "wall_forces", "wall_raw") or key not in template:
                fail(f"its record holds an unknown field {str(key)[:40]!r}")
            if isinstance(like, list) and key in series:
                ok = isinstance(value, list) and all(is_number(v) for v in value)
            elif key in ("loads", "wall_names", "channel_windows"):
                ok = isinstance(value, list) and all(
                    isinstance(row, str) if key == "wall_names" else isinstance(row, dict)
                    and all(isinstance(v, str) or is_number(v) for v in row.values())
                    for row in value)
            elif key == "chain_forces":
                ok = isinstance(value, dict) and all(
                    isinstance(f, dict) and all(isinstance(v, list) and len(v) == 2
                                                and all(is_number(x) for x in v)
                                                for v in f.values()) for f in value.values())
            elif key == "corner_forces":
                ok = isinstance(value, dict) and all(
                    isinstance(c, list) and all(isinstance(row, dict) and all(
                        isinstance(v, str) or is_number(v) for v in row.values())
                        for row in c) for c in value.values())
            elif isinstance(like, dict):
                ok = isinstance(value, dict) and all(is_number(v) for v in value.values())
            else:
                ok = same_kind(value, like) and not (isinstance(like, int) and value < 0)
            if not ok:
                fail(f"its record's {key} is not {type(like).__name__} of the run's kind")
        if len({len(record.get(k, [])) for k in series}) > 1:
            fail("its record's time series have different lengths")
        n_bins = len(self.wall_sampler.centres)
        stages = set(WALL_STAGES) | {mark.name for mark in self.stage_marks}
        shapes = {}
        for stage, t_stage in meta["wall_times"].items():
            if stage not in stages or not is_number(t_stage):
                fail(f"its wall samples name an unknown stage {str(stage)[:40]!r}")
            for name, count in (("wall", 5), ("wallraw", 2), ("wallstress", 2),
                                ("wallforces", 3)):
                for k in range(count):
                    if f"{name}__{stage}__{k}" not in arrays:
                        fail(f"array '{name}__{stage}__{k}' is missing")
            shapes.update({f"wall__{stage}__{k}": (n_bins,) for k in range(6)})
            shapes.update({f"wallstress__{stage}__{k}": (n_bins,) for k in range(2)})
            shapes.update({f"wallraw__{stage}__{k}": (n_bins,) for k in range(2)})
            shapes.update({f"wallforces__{stage}__{k}": (n_bins,) for k in range(2)})
            shapes[f"wallforces__{stage}__2"] = (2,)
        readings = meta.get("readings", {})
        if not isinstance(readings, dict):
            fail("its readings are not a table")
        for name, scalars in readings.items():
            if name not in stages | {"check", "sample", "envelope"} or not (
                    isinstance(scalars, dict) and all(is_number(v) for v in scalars.values())
                    and is_number(scalars.get("t"))):
                fail(f"its reading {str(name)[:40]!r} is not one of this run's")
            for key, like in (("wall", self.state.wall_impulse),
                              ("plate", self.state.plate_impulse),
                              ("budget", self.state.momentum_budget)):
                if f"reading__{name}__{key}" not in arrays:
                    fail(f"array 'reading__{name}__{key}' is missing")
                shapes[f"reading__{name}__{key}"] = np.shape(like)
        sums = meta.get("stress_sums", {})
        if not isinstance(sums, dict) or not all(
                k in stages and isinstance(v, bool) for k, v in sums.items()):
            fail("its stress sums name unknown stages")
        shapes.update({f"stresssum__{stage}__{k}": (n_bins,) for stage, present in sums.items()
                       if present for k in range(3)})
        shapes["envelope"] = shapes["envelope_raw"] = (n_bins,)
        shapes["window_low"] = shapes["window_high"] = (n_bins,)
        fields = self.model.channel_fields(self.state)
        shapes.update({f"channelsum__{k}": np.shape(f) for k, f in enumerate(fields)})
        count = meta.get("channel_count", 0)
        if not (isinstance(count, int) and not isinstance(count, bool) and count >= 0):
            fail(f"its metadata's channel_count = {str(count)[:40]} is not a count")
        present = sum(1 for k in arrays if k.startswith("channelsum__"))
        if present not in (0, len(fields)) or (count > 0) != (present > 0):
            fail(f"its channel sums ({present} arrays, {count} checks) are not this run's "
                 f"({len(fields)} fields)")
        state_arrays = set(vars(self.state))
        for key, value in vars(self.state).items():
            if isinstance(value, np.ndarray) and key not in arrays:
                fail(f"array {key!r} of the state is missing")
        for key, array in arrays.items():
            if key in state_arrays:
                continue
            if key not in shapes:
                fail(f"array {key[:60]!r} belongs to no stage, reading or sum of the metadata")
            if array.shape != shapes[key]:
                fail(f"array {key[:60]!r} has shape {array.shape}, expected {shapes[key]}")
        if not all(is_number(t) for t in meta["schedules"]):
            fail("its schedule times are not numbers")
        for s, t_next in zip(self.schedules, meta["schedules"]):     # when each runs next
            high = meta["state"]["t"] + s.interval + 2.0 * self.model.dt + 1e-9
            if not (math.isfinite(t_next) and 0.0 <= t_next <= high):
                fail(f"its schedule time {t_next!r} is not a time of this run (allowed "
                     f"range [0, {high:.6g}] s)")

    # -------------------------------------------------------------- results
    def summary(self) -> dict:
        """The run's headline numbers (the ``summary.json`` contract)."""
        m, st, rec = self.model, self.state, self.record
        rate, spread, n = diagnostics.steady_rate(rec.t, rec.mass_in_hopper, rec.rate)
        t = np.asarray(rec.t)
        masses = np.asarray(rec.mass_in_hopper)
        m0 = rec.initial_mass
        window, window_name = flow_mode_window(t, masses, m0)
        index, stagnant = (_window_median(getattr(rec, name), window)
                           for name in ("mass_flow_index", "stagnant_fraction"))
        stretches = diagnostics.stretch_calls(
            m.cfg, [r for r, w in zip(rec.wall_slip_stretches, window) if w],
            [f for f, w in zip(rec.wall_slip_stretch_fractions, window) if w], self.flow_rule)
        calls = diagnostics.flow_call(stretches)
        slip, share = calls["wall_slip_ratio"], calls["wall_slip_fraction"]
        remaining = m.mass_in_hopper(st)
        if np.isfinite(m0) and m0 > 0:
            balance = abs(remaining + st.discharged - m0) / m0
            left = remaining / m0
        else:
            balance = left = math.nan
        mode = calls["flow_mode"] if len(t) else "none"
        stopped = self.flow_stopped_time()
        channel, height = math.nan, math.nan
        if math.isfinite(stopped):
            channel, height = m.empty_channel(st, self.outcome_rule)
            mode = diagnostics.classify_outcome(mode, True, left, channel, height,
                                                self.outcome_rule)
        out = {
            "steady_discharge_rate_kg_s": rate,
            "steady_rate_spread": spread,
            "flow_mode": mode,
            "wall_slip_ratio": slip,
            "wall_slip_fraction": share,
            "flow_mode_window": window_name,
            "flow_mode_samples": int(np.sum(window)),
            "mass_flow_index": index,
            "stagnant_fraction": stagnant,
            "initial_mass_kg": m0 if np.isfinite(m0) else m.mass_in_hopper(st),
            "remaining_mass_kg": remaining,
            "remaining_mass_fraction": left,
            "flow_stopped_time_s": stopped,
            "rathole_diameter_m": channel if mode == "rathole" else math.nan,
            "heap_angle_deg": m.heap_angle(st) if math.isfinite(stopped) else math.nan,
            "discharged_kg": st.discharged,
            "mass_balance_error": balance,
            "discharge_time_s": float(t[-1]) if len(t) else 0.0,
            "fill_time_s": rec.fill_time,
            "fill_at_rest": rec.fill_at_rest,
            "gravity_ramp_time_s": m.ramp_time,
            "stop_reason": rec.stop_reason,
            "cells": m.n_cells,
            "steps": st.step,
            "dt_s": m.dt,
            "wall_time_s": rec.wall_time,
            "youngs_modulus_used": m.cfg.material.youngs_modulus,
            "cell_size_m": m.cell_size,
            "hourglass_coefficient": m.cfg.numerics.hourglass_coefficient,
            "grid_viscosity": m.cfg.numerics.grid_viscosity,
            "bulk_viscosity": m.cfg.bulk_viscosity,
            "rate_dependence": m.cfg.material.rate_dependence,
            "grain_diameter_m": m.cfg.material.grain_diameter,
        }
        out["hopper_stretches"] = stretches
        out.update(self.wall_loads.summary(self))
        out.update(m.summary_extras(st))
        return out


def flow_mode_window(t, mass, m0) -> tuple:
    """``(window, name)``: which time-series samples the flow-mode numbers are medians over
    (a boolean per sample) and what they are.  ``"mass_left"``: the samples at least 0.1 s
    after the opening with 90 % to 40 % of the initial mass ``m0`` left; where none is (a
    short run), ``"short_run"``: every sample at least 0.1 s after the opening (the opening's
    transient left out); ``"none"`` when there is none of those either (the flow-mode numbers
    are then NaN and the calls ``"unknown"``)."""
    t, mass = np.asarray(t, float), np.asarray(mass, float)
    window = (mass <= 0.9 * m0) & _before_flow_window_end(t, mass, m0)
    if window.any():
        return window, "mass_left"
    window = t > 0.1
    return window, ("short_run" if window.any() else "none")


def _window_median(values, window) -> float:
    """The median of a per-sample measure over the samples of ``window``, NaN samples left
    out; NaN when none is finite."""
    chosen = np.asarray(values, float)[window]
    return float(np.nanmedian(chosen)) if np.isfinite(chosen).any() else math.nan


def _before_flow_window_end(t, mass, m0):
    """Whether samples lie at or before the end of the flow-mode window: at least 0.1 s after
    the opening with at least 40 % of the initial mass ``m0`` left (the window also needs at
    most 90 % left, :meth:`Simulation.summary`)."""
    return (np.asarray(t) > 0.1) & (np.asarray(mass) >= 0.4 * m0)
