"""A minimal run of the 3D model: fill to rest, open the outlet, discharge for a time or to
empty.  It stands in for :class:`fipy_hopper.simulation.Simulation` until that loop drives
the 3D model, and it follows that loop's rules, with its constants imported, not copied:

* **filling** (:meth:`Simulation.fill`): checks every :data:`FILL_CHECK` s of simulated time;
  at rest when, after the gravity ramp, the kinetic energy is below
  ``numerics.settle_kinetic_energy * M g L`` (``M`` the mass, ``L`` the fill level) and the
  damping carried at most ``numerics.settle_damping_fraction`` of the weight over the last
  check interval; gives up at ``numerics.max_fill_time``.  The rest window (the last check
  interval) gives the filled loads; a transport closes the fill;
* **discharge** (:meth:`Simulation.discharge`): the plate goes; a sample every
  ``run.output_interval`` (mass in the hopper, discharged mass, rate), checks every
  :data:`DISCHARGE_CHECK` s; stops at ``end_time``, or for ``"empty"`` below
  ``run.empty_fraction`` of the initial mass or when the flow has stopped
  (:data:`fipy_hopper.simulation.AT_REST_AFTER`, ``AT_REST_WINDOW``, ``AT_REST_RATE``), or at
  ``run.max_time``; the wall loads over ``run.load_window`` from the moment 90 % and 50 % of
  the mass is left (:data:`fipy_hopper.simulation.STAGE_MARKS`) and the envelope of
  consecutive windows (the largest pressure per patch).

Callbacks ``fn(model, state, record)`` run every ``interval`` s (field snapshots); they read
the state and never change it.  Not here: checkpoints, the time series' files, the opening
iris, markers (the shared loop's).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..simulation import AT_REST_AFTER, AT_REST_RATE, AT_REST_WINDOW, STAGE_MARKS
from .model import GRAVITY
from .wall import SpaceWallLoads

#: the loop's check intervals (s of simulated time): filling, discharge
FILL_CHECK, DISCHARGE_CHECK = 0.005, 0.002


@dataclass
class SpaceRecord:
    """What a run measured (SI, whole silo): the fill (``fill_time``, ``fill_at_rest``, the
    ``rest`` window's two readings), the discharge's samples (``t`` since the opening,
    ``mass_in_hopper``, ``discharged``, ``rate``), the load ``windows`` (stage -> (start,
    end) readings; ``"filling"`` the rest window), the stress-sampled maps at each window's
    end (``stress``: stage -> ``(p_n, tau, tau_theta)``), the discharge ``envelope`` of the
    patches' recovered pressure (n_bins, n_sectors),
    the flow-mode samples (``wall_slip``: per sample the slip ratio per sector), the vertical
    balance over every check interval of the fill and every sample interval of the discharge
    (``loads``: rows of :meth:`SpaceWallLoads.balance` with ``stage`` and ``t_s``), the
    ``stop_reason``, the steps and the wall time."""

    fill_time: float = math.nan
    fill_at_rest: bool = False
    rest: tuple = ()
    initial_mass: float = math.nan
    t: list = field(default_factory=list)
    mass_in_hopper: list = field(default_factory=list)
    discharged: list = field(default_factory=list)
    rate: list = field(default_factory=list)
    windows: dict = field(default_factory=dict)
    stress: dict = field(default_factory=dict)
    envelope: np.ndarray = None
    envelope_windows: int = 0
    wall_slip: list = field(default_factory=list)
    loads: list = field(default_factory=list)
    stop_reason: str = ""
    steps: int = 0
    wall_time: float = 0.0


class SpaceRun:
    """Fill a :class:`~fipy_hopper.space.model.SpaceModel` to rest and discharge it (module
    docstring).  ``end_time``: seconds of discharge, ``"empty"``, or 0 (fill only); default
    ``cfg.run.end_time``."""

    def __init__(self, model, state=None, end_time=None, flow_samples: bool = True):
        self.model = model
        self.state = state if state is not None else model.initial_state()
        self.end_time = model.cfg.run.end_time if end_time is None else end_time
        self.loads = SpaceWallLoads(model)
        self.record = SpaceRecord()
        self.callbacks = []              # [interval (s), next time, fn]
        self.flow_samples = flow_samples
        self.t_open = math.nan

    def add_callback(self, fn, interval: float):
        self.callbacks.append([float(interval), self.state.t, fn])

    def _callbacks(self, force=False):
        for entry in self.callbacks:
            if force or self.state.t >= entry[1] - 1e-12:
                entry[2](self.model, self.state, self.record)
                entry[1] = self.state.t + entry[0]

    def _advance_to(self, t_target: float, every: int) -> None:
        m, st = self.model, self.state
        ahead = max(1, int(math.ceil((t_target - st.t) / m.dt - 1e-9)))
        m.advance(st, min(every - st.step % every, ahead))

    # ------------------------------------------------------------------ stages
    def fill(self) -> bool:
        """Bring the fill to rest (module docstring); True when at rest."""
        m, st, rec = self.model, self.state, self.record
        num = m.cfg.numerics
        every = max(1, int(FILL_CHECK / m.dt))
        threshold = num.settle_kinetic_energy * m.total_mass(st) * GRAVITY * \
            m.cfg.hopper.fill_level
        previous = self.loads.reading(m, st)
        self._callbacks(force=True)
        while True:
            m.advance(st, every - st.step % every)
            if st.step % every:
                continue
            m.check_stable(st)
            self._callbacks()
            current = self.loads.reading(m, st)
            balance = self.loads.balance(previous, current)
            rec.loads.append({"stage": "filling", "t_s": current["t"], **balance})
            window = (previous, current)
            previous = current
            if (st.t >= m.ramp_time and m.kinetic_energy(st) < threshold
                    and abs(balance["damping"]) <= num.settle_damping_fraction
                    * balance["weight"]):
                rec.fill_at_rest = True
                break
            if st.t >= num.max_fill_time:
                break
        m.transport_step(st)
        rec.fill_time, rec.rest = st.t, window
        rec.windows["filling"] = window
        rec.stress["filling"] = self.loads.stress_maps(st)
        return rec.fill_at_rest

    def discharge(self) -> str:
        """Open the outlet and discharge until a stop rule applies; the stop reason."""
        m, st, rec = self.model, self.state, self.record
        run = m.cfg.run
        window = run.load_window_s
        m.open_outlet(st)
        self.t_open = st.t
        rec.initial_mass = m0 = m.mass_in_hopper(st)
        self._sample()
        next_sample = st.t + run.output_interval
        envelope_start = self.loads.reading(m, st)
        slip_start = sample_start = envelope_start
        open_windows = {}
        every = max(1, int(DISCHARGE_CHECK / m.dt))
        n_rest = max(1, int(round(AT_REST_WINDOW / run.output_interval)))
        while True:
            self._advance_to(next_sample, every)
            if st.t >= next_sample - 1e-12:
                self._sample()
                current = self.loads.reading(m, st)
                rec.loads.append({"stage": "discharge", "t_s": current["t"],
                                  **self.loads.balance(sample_start, current)})
                sample_start = current
                if self.flow_samples:
                    from .flow import wall_slip_by_sector
                    rec.wall_slip.append(wall_slip_by_sector(self, slip_start))
                    slip_start = self.loads.reading(m, st)
                next_sample += run.output_interval
            if st.step % every:
                continue
            m.check_stable(st)
            self._callbacks()
            t_dis, mass = st.t - self.t_open, m.mass_in_hopper(st)
            for stage, fraction in STAGE_MARKS.items():
                if stage not in open_windows and stage not in rec.windows \
                        and mass <= fraction * m0:
                    open_windows[stage] = self.loads.reading(m, st)
            for stage in list(open_windows):
                if st.t - open_windows[stage]["t"] >= window - 1e-12:
                    rec.windows[stage] = (open_windows.pop(stage), self.loads.reading(m, st))
                    rec.stress[stage] = self.loads.stress_maps(st)
            if st.t - envelope_start["t"] >= window - 1e-12:
                current = self.loads.reading(m, st)
                p_n = self.loads.maps(envelope_start, current)[0]
                rec.envelope = p_n if rec.envelope is None else np.fmax(rec.envelope, p_n)
                rec.envelope_windows += 1
                envelope_start = current
            reason = ""
            rates = rec.rate[-n_rest:]
            if self.end_time != "empty" and t_dis >= float(self.end_time) - 1e-12:
                reason = "end_time"
            elif self.end_time == "empty" and mass < run.empty_fraction * m0:
                reason = "empty"
            elif (self.end_time == "empty" and t_dis > AT_REST_AFTER and len(rates) == n_rest
                  and np.all(np.abs(rates) < AT_REST_RATE * m0)):
                reason = "at_rest"
            elif t_dis >= run.max_time:
                reason = "max_time"
            if reason:
                break
        m.transport_step(st)
        self._sample()
        for stage, start in open_windows.items():      # cut short by the end
            if st.t > start["t"]:
                rec.windows[stage] = (start, self.loads.reading(m, st))
                rec.stress[stage] = self.loads.stress_maps(st)
        rec.stop_reason = reason
        self._callbacks(force=True)
        return reason

    def run(self) -> SpaceRecord:
        """Fill, then discharge unless ``end_time`` is 0."""
        started = time.perf_counter()
        try:
            if self.state.stage == "filling":
                self.fill()
            if self.end_time == "empty" or float(self.end_time) > 0.0:
                self.discharge()
            else:
                self.record.stop_reason = "filled" if self.record.fill_at_rest \
                    else "fill_not_at_rest"
        finally:
            self.record.steps = self.state.step
            self.record.wall_time = time.perf_counter() - started
        return self.record

    def _sample(self):
        m, st, rec = self.model, self.state, self.record
        t = st.t - self.t_open
        if rec.t and t <= rec.t[-1] + 1e-12:
            return
        rate = (st.discharged - rec.discharged[-1]) / (t - rec.t[-1]) if rec.t else 0.0
        rec.t.append(t)
        rec.mass_in_hopper.append(m.mass_in_hopper(st))
        rec.discharged.append(st.discharged)
        rec.rate.append(rate)
