"""Where a run's wall-clock time goes: ``fipy-hopper run --profile`` (``profile.json``).

A :class:`PhaseProfile` attached to a model (``model.profile``) collects, while the run goes
on and without changing any number of it:

* the phases of the compiled material steps (:data:`fipy_hopper.stepping.PHASES`: the step
  set-up of each call, forces, nodes, stress update, faces; the 3D model's
  :func:`fipy_hopper.space.stepping.material_steps` under the same names, its set-up the lists
  made in Python before each call), counted in processor cycles inside the compiled loop (:func:`fipy_hopper.stepping.read_cycles`, about 10 ns a reading) and
  converted to seconds with the counter's rate measured against ``time.perf_counter`` over the
  run;
* the parts of each transport (advection of the cell fields, redistribution, fields and
  momentum, markers), the field snapshots and checkpoints, and the pictures, by
  ``time.perf_counter``;
* "other": the wall time not in any of them (the Python loop, the time-series samples, the
  stress and wall-load measurements and, in the first run after an installation, numba's
  compilation of the kernels).

``compiled_calls_s`` is the time of the compiled calls by ``time.perf_counter`` around them:
the compiled phases add up to it, less the cost of calling.

On a processor without a cycle counter that user code may read (not x86) the compiled phases
are reported together, as the time spent in the compiled calls.
"""

from __future__ import annotations

import time
from contextlib import contextmanager, nullcontext

import numpy as np

from . import stepping

#: the parts timed by ``time.perf_counter`` (seconds), in the order of the report
TIMED_PARTS = ("set-up", "transport: advection", "transport: redistribution",
               "transport: fields and momentum", "transport: markers", "snapshots and checkpoints",
               "pictures")


class PhaseProfile:
    """Accumulated time of each phase of a run (see the module's text)."""

    def __init__(self):
        #: cycles of each phase of :func:`fipy_hopper.stepping.material_steps`, added to by it
        self.cycles = np.zeros(len(stepping.PHASES), dtype=np.int64)
        self.seconds = dict.fromkeys(TIMED_PARTS, 0.0)
        #: the compiled calls by ``time.perf_counter`` around them (s)
        self.compiled_seconds = 0.0
        self.steps = 0
        #: the loaded cells (alpha >= alpha_min) summed over the steps
        self.loaded_cell_steps = 0
        self.transports = 0
        self._start = (time.perf_counter(), int(stepping.read_cycles()))

    @contextmanager
    def timed(self, part: str):
        """Add the wall time of the ``with`` block to ``part`` (one of :data:`TIMED_PARTS`)."""
        started = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[part] += time.perf_counter() - started

    def cycle_rate(self) -> float:
        """The cycle counter's rate (1/s) from the run so far; NaN without a counter."""
        now, count = time.perf_counter(), int(stepping.read_cycles())
        elapsed, counted = now - self._start[0], count - self._start[1]
        if not stepping.HAS_CYCLE_COUNTER or elapsed <= 0.0 or counted <= 0:
            return float("nan")
        return counted / elapsed

    def report(self, wall_time: float | None = None) -> dict:
        """The phases in seconds and as fractions of ``wall_time`` (s; default: the time since
        the profile was made), the counts and the time per step (µs), as written to
        ``profile.json``."""
        if wall_time is None:
            wall_time = time.perf_counter() - self._start[0]
        rate = self.cycle_rate()
        phases = {}
        if rate == rate:
            for name, cycles in zip(stepping.PHASES, self.cycles):
                phases[f"step: {name}"] = float(cycles) / rate
        else:
            phases["step: compiled phases (no cycle counter)"] = self.compiled_seconds
        phases.update(self.seconds)
        phases["other"] = max(wall_time - sum(phases.values()), 0.0)
        steps = max(self.steps, 1)
        return {
            "wall_time_s": wall_time,
            "steps": self.steps,
            "mean_loaded_cells": self.loaded_cell_steps / steps,
            "transports": self.transports,
            "cycle_rate_hz": rate,
            "compiled_calls_s": self.compiled_seconds,
            "phases_s": phases,
            "fractions": {k: (v / wall_time if wall_time > 0 else float("nan"))
                          for k, v in phases.items()},
            "us_per_step": {k: 1e6 * v / steps for k, v in phases.items()},
        }


def timed(profile: PhaseProfile | None, part: str):
    """A context that adds its wall time to ``part`` of ``profile``; nothing without one."""
    return nullcontext() if profile is None else profile.timed(part)


def format_report(report: dict) -> str:
    """The report of :meth:`PhaseProfile.report` as a table of lines."""
    lines = [f"  {'phase':34s} {'s':>8s} {'share':>7s} {'us/step':>9s}"]
    for name, seconds in report["phases_s"].items():
        lines.append(f"  {name:34s} {seconds:8.2f} {100 * report['fractions'][name]:6.1f}% "
                     f"{report['us_per_step'][name]:9.1f}")
    lines.append(f"  {'wall time':34s} {report['wall_time_s']:8.2f}  ({report['steps']} steps, "
                 f"{report['transports']} transports, {report['mean_loaded_cells']:.0f} loaded "
                 "cells on average)")
    return "\n".join(lines)
