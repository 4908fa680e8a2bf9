"""Benchmark of the reference hopper's complete emptying at 5 mm cells (issue 4).

``pytest tests/benchmarks/test_bench_emptying.py --benchmark-only`` runs the whole reference
case once (fill, then discharge until empty) and records steps, cells and the summary in
``extra_info``.  Under ``--benchmark-disable`` a small hopper on a 1 cm grid empties instead.
"""

import warnings

from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation


def empty_hopper(cfg):
    sim = Simulation(HopperModel(cfg), progress=False)
    sim.run()
    return sim.summary()


def test_bench_reference_hopper_empties(benchmark):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if benchmark.disabled:
            cfg = HopperConfig.from_dict({
                "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.06,
                           "fill_height": 0.04},
                "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05}})
        else:
            cfg = HopperConfig()
    summary = benchmark.pedantic(empty_hopper, args=(cfg,), rounds=1, iterations=1)
    benchmark.extra_info.update({k: summary[k] for k in (
        "steps", "cells", "discharge_time_s", "steady_discharge_rate_kg_s", "stop_reason",
        "mass_balance_error", "wall_time_s")})
    assert summary["stop_reason"] == "empty"
    assert summary["mass_balance_error"] < 1e-9
