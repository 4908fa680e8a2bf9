"""The reference hopper from filling to empty, run as users run it: ``fipy-hopper run``.

``pytest tests/benchmarks/test_bench_emptying.py --benchmark-only`` runs
``fipy-hopper run studies/configs/reference.toml --out DIR --quiet`` once per cell size (5 mm
as configured, and 2.5 mm), in this process, with everything a run does: markers, field
snapshots, time series, checkpoints and the pictures.  ``extra_info`` records the simulation's
own wall time (``summary.json``), the rest (pictures and the writing at the end), the steps,
the cells, the threads, the peak resident memory of the process and the headline results.
``python studies/performance.py`` runs it and writes what it measured to ``docs/performance.md``
(the README quotes its time and memory from there).  Under the default ``--benchmark-disable``
a small hopper on a 1 cm grid runs instead, as a plain test.
"""

import json
import pathlib
import resource
import time
import warnings

import numba
import pytest

from fipy_hopper.cli import main

REFERENCE = pathlib.Path(__file__).resolve().parents[2] / "studies" / "configs" / "reference.toml"

SMALL = """
[hopper]
bin_diameter = 0.2
outlet_diameter = 0.06
bin_height = 0.06
fill_height = 0.04
[numerics]
cell_size = 0.01
gravity_ramp_time = 0.05
[run]
field_interval = 0.1
"""


@pytest.mark.parametrize("cell_size", [0.005, 0.0025])
def test_bench_reference_hopper_run(benchmark, cell_size, tmp_path):
    if benchmark.disabled and cell_size != 0.005:
        pytest.skip("one size when benchmarks are disabled")
    config = tmp_path / "hopper.toml"
    if benchmark.disabled:
        config.write_text(SMALL)
    else:
        text = REFERENCE.read_text()
        config.write_text(text.replace("cell_size = 0.005", f"cell_size = {cell_size}"))
        assert f"cell_size = {cell_size}" in config.read_text()
    out = tmp_path / "run"
    timing = {}

    def run():
        started = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            code = main(["run", str(config), "--out", str(out), "--quiet", "--force"])
        timing["total"] = time.perf_counter() - started
        return code

    code = benchmark.pedantic(run, rounds=1, iterations=1)
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "empty"
    assert summary["mass_balance_error"] < 1e-9
    for picture in ("flow_pattern.png", "discharge.png", "wall_pressure.png"):
        assert (out / picture).is_file()
    benchmark.extra_info.update({
        "total_s": timing["total"],
        "simulation_s": summary["wall_time_s"],
        "pictures_and_writing_s": timing["total"] - summary["wall_time_s"],
        "threads": numba.get_num_threads(),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        **{k: summary[k] for k in ("steps", "cells", "discharge_time_s",
                                   "steady_discharge_rate_kg_s", "flow_mode",
                                   "mass_balance_error")}})
