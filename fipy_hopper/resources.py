"""What a run needs of the machine and what the machine has: memory and cores.

* :func:`memory_estimate`: the peak memory of a run, from the measured cost of its grid
  (:func:`fipy_hopper.config.grid_memory`), its markers and its wall loads (their own estimate,
  :meth:`fipy_hopper.diagnostics.WallLoads.estimated_bytes`); :func:`check_memory` refuses a
  run that needs more than :func:`available_memory`, before anything is written.
* :func:`available_cores`: the cores this process may run on (its CPU affinity and its
  cgroup's CPU quota); :func:`check_threads` refuses more threads than those.
* :class:`ThreadGovernor`: the default number of threads of a run.  The compiled step meets
  its threads at a barrier several times a step, so one thread on a core that another
  process also wants holds all the others up: on a busy machine one thread per core made a
  run about ten times slower than one thread.  The governor measures, from ``/proc/stat``,
  how much CPU time other processes take on this process's cores (its own taken out), and
  gives the run the cores they leave free (:func:`threads_for`), at the start of the run and
  every :attr:`ThreadGovernor.interval` seconds after; the results do not depend on it.
  OpenMP's wait policy is left as it is (libgomp spins briefly at a barrier, then sleeps):
  with no more threads than free cores the short spin is the fast choice.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Callable, Optional

from .config import ConfigError, _ceil_digits, grid_memory, grid_rows

#: A snapshot holds its markers several times over while it is written (the VTU's points,
#: cells and encoded text): measured peak 6.1 times the marker array (tracemalloc, 6 x 6
#: markers a cell, 4,768 cells: a transport, a snapshot and a checkpoint).
MARKER_PEAK_FACTOR = 6
#: Another process that takes more than this share of a core takes the core.
BUSY_CORE = 0.25


# ---------------------------------------------------------------- memory
def wall_bins(cfg, cell_size: float) -> int:
    """The bins of the wall-load profiles on a grid of ``cell_size`` (those of
    :func:`fipy_hopper.diagnostics.wall_bins`, from the configuration alone)."""
    from .diagnostics import wall_bins as bins

    return len(bins(cfg, cell_size).s)


def wall_entry_bound(cfg, cell_size: float) -> int:
    """At most how many wall contact entries the grid of ``cfg`` has: a node is in contact
    when it lies behind a wall or an insert or less than half a cell in front of it, so in
    each row of nodes only those beyond the (right) wall's narrowest ``x`` within half a cell
    of the row (and in a full section those short of the left wall's widest), less half a cell
    and one more for the sampling, can be, and those in each insert's outline grown by as
    much; and a row and a column of nodes more for the corners, whose nodes hold two walls
    (the boundary's :meth:`~fipy_hopper.boundary.Boundary.wall_x`)."""
    import numpy as np

    from .config import grid_columns

    bnd = cfg.boundary
    h, reach = cell_size, 0.5 * cell_size
    nr, n_below, n_above = grid_rows(cfg.hopper, cfg.numerics, h)
    x0, _ = grid_columns(cfg.hopper, h)
    x_nodes = x0 + h * np.arange(nr + 1)
    z_nodes = h * (np.arange(n_below + n_above + 1) - n_below)
    window = z_nodes[:, None] + reach * np.linspace(-1.0, 1.0, 9)[None, :]
    first = np.searchsorted(x_nodes, bnd.wall_x(window).min(axis=1) - reach - h)
    count = int(np.sum(nr + 1 - first))
    if not bnd.section.half:
        last = np.searchsorted(x_nodes, bnd.wall_x(window, "left_wall").max(axis=1)
                               + reach + h, side="right")
        count += int(np.sum(last))
    for insert in bnd.inserts:
        poly = np.asarray(insert.polygon, dtype=float)
        lo, hi = poly.min(axis=0) - reach - h, poly.max(axis=0) + reach + h
        count += int(np.sum((x_nodes >= lo[0]) & (x_nodes <= hi[0]))
                     * np.sum((z_nodes >= lo[1]) & (z_nodes <= hi[1])))
    return count + 2 * (nr + n_below + n_above + 2)


def memory_estimate(cfg, cell_size: Optional[float] = None) -> float:
    """Peak resident memory of a run of ``cfg`` (bytes; at another ``cell_size`` if given):
    the larger of building the grid and model (:func:`~fipy_hopper.config.grid_memory`) and
    what they keep plus the building of the wall loads
    (:meth:`~fipy_hopper.diagnostics.WallLoads.estimated_bytes` of :func:`wall_bins` and
    :func:`wall_entry_bound`), which comes after; and the markers (``markers_per_side``
    squared a cell, three floats each, :data:`MARKER_PEAK_FACTOR`).  A 3D run
    (``hopper.dimensions = 3``): :func:`fipy_hopper.space.estimate.memory_estimate`."""
    from .diagnostics import WallLoads

    h = cfg.numerics.cell_size if cell_size is None else cell_size
    if cfg.hopper.dimensions == 3:           # the 3D model's own measured estimate
        from .space.estimate import memory_estimate as space_memory
        return space_memory(cfg.space_config(), h)["bytes"]
    nr, n_below, n_above = grid_rows(cfg.hopper, cfg.numerics, h)
    cells = nr * (n_below + n_above)
    markers = cfg.run.markers_per_side ** 2 * cells * 3 * 8 * MARKER_PEAK_FACTOR
    wall = WallLoads.estimated_bytes(wall_bins(cfg, h), wall_entry_bound(cfg, h))
    return max(grid_memory(cells), grid_memory(cells, kept=True) + wall) + markers


def _cgroup_files(name: str, root: str = "/sys/fs/cgroup") -> list:
    """The cgroup v2 files ``name`` of this process's group and its parents (existing ones)."""
    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        return []
    path = next((line[3:] for line in lines if line.startswith("0::")), None)
    if path is None:
        return []
    group = Path(root) / path.lstrip("/")
    return [p / name for p in (group, *group.parents) if str(p).startswith(root)
            and (p / name).is_file()]


def available_memory() -> Optional[float]:
    """Bytes this process can still take: ``MemAvailable`` of ``/proc/meminfo``, less under a
    cgroup v2 memory limit (``memory.max`` - ``memory.current``); None where neither is
    known."""
    have = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                have = float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    for limit in _cgroup_files("memory.max"):
        try:
            text = limit.read_text().strip()
            if text != "max":
                used = float((limit.parent / "memory.current").read_text())
                room = max(float(text) - used, 0.0)
                have = room if have is None else min(have, room)
        except (OSError, ValueError):
            continue
    return have


def check_memory(cfg, available: Optional[float] = None) -> None:
    """Raise :class:`ConfigError` (one line: what the run needs, what is available, how to
    shrink it) if :func:`memory_estimate` exceeds the memory available (``available`` bytes,
    by default :func:`available_memory`; nothing is checked where that is unknown)."""
    have = available_memory() if available is None else available
    need = memory_estimate(cfg)
    if have is None or need <= have:
        return
    h = cfg.numerics.cell_size
    coarser = h * math.sqrt(need / have)
    for _ in range(60):                       # the estimate falls as the cells grow
        if memory_estimate(cfg, coarser) <= have:
            break
        coarser *= 1.1
    coarser = _ceil_digits(coarser)
    fits = coarser <= cfg.hopper.outlet_radius / 3 and memory_estimate(cfg, coarser) <= have
    how = (f"numerics.cell_size >= {coarser:.3g} m fits" if fits else
           "no grid with 3 cells across the outlet fits; free memory or run a smaller hopper")
    if cfg.run.markers_per_side > 2:
        how += f", and fewer markers take less (run.markers_per_side = " \
               f"{cfg.run.markers_per_side})"
    raise ConfigError(
        f"numerics.cell_size = {h:g} m: a run of {cfg.n_cells:,} cells needs about "
        f"{need / 1e9:.3g} GB, more than the {have / 1e9:.3g} GB of memory available; {how}")


# ---------------------------------------------------------------- cores
def available_cores() -> int:
    """The cores this process may run on: its CPU affinity (``os.sched_getaffinity``, else
    ``os.cpu_count()``), at most its cgroup's CPU quota (``cpu.max``) rounded up."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    for quota in _cgroup_files("cpu.max"):
        try:
            limit, period = quota.read_text().split()[:2]
            if limit != "max":
                cores = min(cores, max(1, math.ceil(float(limit) / float(period))))
        except (OSError, ValueError):
            continue
    return cores


def thread_limit() -> int:
    """The most threads a run can use: :func:`available_cores`, at most numba's
    ``NUMBA_NUM_THREADS``."""
    import numba

    return max(1, min(available_cores(), numba.config.NUMBA_NUM_THREADS))


def check_threads(threads, name: str = "threads") -> None:
    """Raise :class:`ConfigError` naming ``name`` unless ``threads`` is a whole number in
    ``[1, thread_limit()]``."""
    import numba

    cores, limit = available_cores(), thread_limit()
    if isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= limit:
        why = (f"NUMBA_NUM_THREADS = {numba.config.NUMBA_NUM_THREADS}" if limit < cores
               else f"the {cores} core{'s' * (cores > 1)} this process may use")
        raise ConfigError(f"{name} = {threads}: expected a number of threads in [1, {limit}] "
                          f"({why})")


# ---------------------------------------------------------------- the default threads
#: the fields of a ``cpuN`` line of ``/proc/stat`` that count as busy: user, nice, system,
#: irq, softirq, steal (not idle and iowait; guest time is inside user)
_BUSY_FIELDS = (0, 1, 2, 5, 6, 7)


def busy_seconds(stat: str, cores, tick: float) -> float:
    """The busy CPU time (s) of ``cores`` (CPU numbers) in the text of ``/proc/stat``, whose
    counts are in ticks of ``tick`` seconds."""
    total = 0
    for line in stat.splitlines():
        name, _, rest = line.partition(" ")
        if name.startswith("cpu") and name[3:].isdigit() and int(name[3:]) in cores:
            values = rest.split()
            total += sum(int(values[k]) for k in _BUSY_FIELDS if k < len(values))
    return total * tick


def threads_for(cores: int, others: float) -> int:
    """Threads for a run on ``cores`` cores while other processes take ``others`` cores'
    worth of CPU time: a core counts as taken once they take more than :data:`BUSY_CORE` of
    it; at least one thread."""
    taken = max(0, math.ceil(others - BUSY_CORE))
    return max(1, min(cores, cores - taken))


class CpuLoad:
    """The CPU time other processes take on this process's cores: ``/proc/stat``'s busy time
    of those cores less this process's own (``time.process_time``, all its threads), between
    one reading and the next (:meth:`others`)."""

    #: readings closer together than this (s) are too coarse (``/proc/stat`` counts in ticks
    #: of 10 ms): :meth:`others` waits for a longer window
    MIN_WINDOW = 0.2

    def __init__(self, cores=None, read_stat: Optional[Callable] = None,
                 clock: Callable = time.monotonic, own: Callable = time.process_time):
        if cores is None:
            try:
                cores = os.sched_getaffinity(0)
            except (AttributeError, OSError):
                cores = range(os.cpu_count() or 1)
        self.cores = set(cores)
        self.read_stat = read_stat or (lambda: Path("/proc/stat").read_text())
        self.clock, self.own = clock, own
        try:
            self.tick = 1.0 / os.sysconf("SC_CLK_TCK")
        except (AttributeError, ValueError, OSError):
            self.tick = 0.01
        self.last = self._reading()

    def _reading(self):
        try:
            return (self.clock(), busy_seconds(self.read_stat(), self.cores, self.tick),
                    self.own())
        except (OSError, ValueError, IndexError):
            return None

    def others(self) -> Optional[float]:
        """Cores' worth of CPU time that other processes took since the last window; None
        while the window is shorter than :data:`MIN_WINDOW` or where there is no
        ``/proc/stat``."""
        now = self._reading()
        if now is None or self.last is None:
            self.last = self.last or now
            return None
        wall = now[0] - self.last[0]
        if wall < self.MIN_WINDOW:
            return None
        busy = (now[1] - self.last[1]) - (now[2] - self.last[2])
        self.last = now
        return max(busy, 0.0) / wall


class ThreadGovernor:
    """The numba threads of a run that names none: :func:`threads_for` the cores of
    :func:`thread_limit` and the load of other processes (:class:`CpuLoad`), measured from its
    creation and then every :attr:`interval` seconds of wall time.  Call it as a wall-time
    callback (``sim.add_wall_time_callback(governor, governor.interval)``): it sets the
    model's ``threads``; the results do not depend on them."""

    interval = 2.0

    def __init__(self, limit: Optional[int] = None, load: Optional[CpuLoad] = None):
        self.limit = thread_limit() if limit is None else limit
        self.load = load if load is not None else CpuLoad()
        self.threads = self.limit

    def update(self) -> int:
        """The threads for the next interval (unchanged while the load is not known)."""
        others = self.load.others()
        if others is not None:
            self.threads = threads_for(self.limit, others)
        return self.threads

    def __call__(self, sim, state) -> None:
        sim.model.threads = self.update()
