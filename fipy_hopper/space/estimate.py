"""What a 3D run will need, from its settings alone (nothing is built): its grid, its memory and,
as an indication, its time.  For ``validate`` to call before a run.

* :func:`grid_shape`: the computed part's cells ``(nx, ny, nz)`` by the grid's own rules
  (:func:`fipy_hopper.space.grid.build_grid`);
* :func:`memory_estimate`: ``{"cells", "bytes"}``: the peak bytes of building the model,
  filling and transporting, with its wall loads: :data:`MEMORY_BASE` (Python, FiPy, numba and
  the kernels: the sections' figure), :data:`MEMORY_TRANSIENT` and :data:`MEMORY_PER_CELL` a
  cell (measured with tracemalloc, below); :func:`check_memory` refuses, in one line, a grid
  that will not fit in the memory there is;
* :func:`time_estimate`: the steps of the fill and the discharge and the wall time they take
  at :data:`COST_PER_LOADED_CELL_STEP` (one thread): an indication only, measured on a
  machine shared with other work.
"""

from __future__ import annotations

import math

from ..config import MEMORY_BASE
from .grid import _axis_nodes, computed_part

#: bytes a cell at the peak of a run's start: the model, its state, its transport and its
#: wall loads (measured with tracemalloc: built, 120 steps with two transports, the wall
#: loads located: a peak of 3.30-3.34 kB a cell at 21,675 and 91,125 cells, of which 2.65-2.67
#: kB stay; the reference hopper at 1 and 0.6 cm, a quarter)
MEMORY_PER_CELL = 3.5e3
#: bytes on top on small grids (the cut cells' sub-samples, sampled in chunks of 1,024
#: cells, and the contact tables): measured 29 MB at 3,800 cells, 20 MB at 7,344
MEMORY_TRANSIENT = 5.0e7
#: seconds a loaded cell costs a step, transports included, one thread: an indication.  With
#: the block eigen-solve of the law's update the compiled steps of the reference hopper at 1 cm
#: (a quarter) took 0.57 us a loaded cell filling (8,200 loaded) and 0.56 us in discharge
#: (8,326), alone on an AMD EPYC, 2026-12-07; the whole run end to end (``fipy-hopper run``,
#: its outputs included, docs/performance.md) took 1,107 s, which this figure gives for it
#: (the loaded cells of :func:`time_estimate` fall steadily in discharge, the run's do not).
#: A busy machine adds up to half (point by point, the eigen-solve took 1.35-1.43 us busy,
#: 0.86-0.97 us quieter).
COST_PER_LOADED_CELL_STEP = 1.0e-6
#: the fill comes to rest by the loop's rule about this many gravity ramps after its start
#: (measured 1.08 on the small conical silo, 1.13 in a flat-bottomed bin)
FILL_RAMPS = 1.2


def grid_shape(cfg, cell_size: float | None = None) -> tuple:
    """``(nx, ny, nz)`` of the computed part's grid of a
    :class:`~fipy_hopper.space.config.SpaceConfig` (at ``cell_size``, default its own)."""
    h = cfg.numerics.cell_size if cell_size is None else float(cell_size)
    geom = cfg.hopper
    mirror_x, mirror_y = computed_part(cfg.mirror_planes, cfg.outlet_offset)
    radius = max(r for r, _ in geom.wall_points)
    half_x, half_y = ((0.5 * geom.bin_width, 0.5 * geom.bin_length) if geom.rectangular
                      else (radius, radius))
    nx = len(_axis_nodes(half_x, h, mirror_x)) - 1
    ny = len(_axis_nodes(half_y, h, mirror_y)) - 1
    outlet_radius = geom.wall_points[0][0]
    n_below = max(int(math.ceil(cfg.numerics.free_fall_depth * 2.0 * outlet_radius / h
                                - 1e-9)), 3)
    n_above = int(math.ceil(geom.wall_points[-1][1] / h - 1e-9)) + 1
    return nx, ny, n_below + n_above


def memory_estimate(cfg, cell_size: float | None = None) -> dict:
    """``{"cells": n, "bytes": b}``: the computed part's cells and the peak memory of its run
    (module docstring)."""
    nx, ny, nz = grid_shape(cfg, cell_size)
    cells = nx * ny * nz
    return {"cells": cells,
            "bytes": float(MEMORY_BASE + MEMORY_TRANSIENT + MEMORY_PER_CELL * cells)}


def check_memory(cfg, available: float | None = None) -> None:
    """Raise ``MemoryError`` with one line when the estimate exceeds ``available`` bytes
    (default: :func:`fipy_hopper.resources.available_memory`; nothing when unknown)."""
    if available is None:
        from ..resources import available_memory
        available = available_memory()
    if available is None:
        return
    need = memory_estimate(cfg)
    if need["bytes"] > available:
        raise MemoryError(
            f"numerics.cell_size = {cfg.numerics.cell_size:g} m makes a 3D grid of "
            f"{need['cells']:,} cells that needs about {need['bytes'] / 1e9:.3g} GB; "
            f"{available / 1e9:.3g} GB are available: a larger cell size or mirror planes")


def loaded_cells(cfg, cell_size: float | None = None) -> int:
    """The computed part's cells that the initial fill loads: the cells between the outlet
    plane and the fill level whose centre lies less than 0.45 cells outside the material
    region (a cut cell of less open volume is closed, ``min_open_fraction``), counted layer
    by layer from the silo's signed distance (against the model's count: 395 of 395, 782 of
    783, 1,580 of 1,580 and 8,198 of 8,200 cells, tests/test_space_estimate.py)."""
    import numpy as np

    from .boundary import silo_boundary
    h = cfg.numerics.cell_size if cell_size is None else float(cell_size)
    boundary = silo_boundary(cfg)
    mirror_x, mirror_y = computed_part(cfg.mirror_planes, cfg.outlet_offset)
    half_x, half_y = boundary.half_extent
    x = _axis_nodes(half_x, h, mirror_x)
    y = _axis_nodes(half_y, h, mirror_y)
    xc, yc = 0.5 * (x[1:] + x[:-1]), 0.5 * (y[1:] + y[:-1])
    Y, X = np.meshgrid(yc, xc, indexing="ij")
    total = 0
    level = cfg.hopper.fill_level
    for k in range(int(math.ceil(level / h - 1e-9))):
        z = np.full(X.shape, (k + 0.5) * h)
        d, _ = boundary.distance_normal(X, Y, z)
        total += int(np.count_nonzero(d > -0.45 * h))
    return total


def time_estimate(cfg, discharge_time: float, cell_size: float | None = None,
                  cost: float = COST_PER_LOADED_CELL_STEP, emptied: bool = True) -> dict:
    """The steps and the wall time (one thread, s) of a fill (:data:`FILL_RAMPS` gravity
    ramps) and a discharge of ``discharge_time`` s of simulated time, at ``cost`` a loaded
    cell and step: the fill's loaded cells throughout, the discharge's half of them on
    average when it empties the silo at a steady rate (``emptied``), else all of them."""
    h = cfg.numerics.cell_size if cell_size is None else float(cell_size)
    num = cfg.numerics
    c_p = cfg.material.p_wave_speed
    from ..config import damped_step_factor
    dt = num.dt_safety * h / c_p * damped_step_factor(cfg.bulk_viscosity)
    column = max(cfg.hopper.fill_level, h)
    ramp = (num.gravity_ramp_periods * 4.0 * column / c_p if num.gravity_ramp_time == "auto"
            else float(num.gravity_ramp_time))
    n = loaded_cells(cfg, h)
    fill_steps = FILL_RAMPS * ramp / dt
    discharge_steps = discharge_time / dt
    mean = 0.5 * n if emptied else n
    seconds = cost * (fill_steps * n + discharge_steps * mean)
    return {"dt_s": dt, "fill_steps": fill_steps, "discharge_steps": discharge_steps,
            "loaded_cells": n, "seconds": seconds}
