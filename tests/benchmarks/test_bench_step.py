"""Benchmarks of one explicit step of the reference hopper (issue 3).

``pytest tests/benchmarks --benchmark-only`` measures at 5 mm and 2.5 mm cells (the state is a
hopper part-way through its fill, so plastic and elastic cells are mixed).  Under the default
``--benchmark-disable`` the same code runs once on a 1 cm grid as a plain test.
"""

import warnings

import numpy as np
import pytest

from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel


def prepared_model(cell_size, steps=300):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict({"numerics": {"cell_size": cell_size,
                                                   "gravity_ramp_time": 0.01}})
    model = HopperModel(cfg)
    state = model.initial_state()
    for _ in range(steps):
        model.step(state)
    return model, state


@pytest.mark.parametrize("cell_size", [0.005, 0.0025])
def test_bench_reference_hopper_step(benchmark, cell_size):
    if benchmark.disabled:
        cell_size = 0.01
    model, state = prepared_model(cell_size, steps=300 if not benchmark.disabled else 20)
    t0 = state.t
    benchmark(model.step, state)
    assert state.t > t0 and np.all(np.isfinite(state.sigma))
    benchmark.extra_info["cells"] = model.grid.n_cells
    benchmark.extra_info["dt_s"] = model.dt
