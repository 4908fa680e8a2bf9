"""The reference hopper in 3D from filling to empty, run as users run it: ``fipy-hopper run``.

``pytest tests/benchmarks/test_bench_emptying_3d.py --benchmark-only`` runs ``fipy-hopper run``
once, in this process, on ``studies/configs/reference.toml`` with what 3D needs changed and
nothing else: ``[hopper] dimensions = 3``, 1 cm cubes (``numerics.cell_size = 0.01``: the 3
cells across the outlet's radius the configuration asks), the outlet centred and the default
mirror planes (a quarter of the silo computed, results for the whole), no markers (3D has
none); filled to rest and emptied with everything a run does: the 3D field snapshots
(hexahedral VTU of the whole silo every ``field_interval``, 0.25 s), the time series, the wall
loads in 12 sectors, checkpoints and the pictures (``flow_plane.png``,
``wall_circumference.png``, ``wall_unrolled.png``, ``discharge.png``).  ``extra_info`` records
what the 2D benchmark (``test_bench_emptying.py``) records: the simulation's own wall time
(``summary.json``), the rest (pictures and the writing at the end), the steps, the cells (the
computed part's), the threads, the peak resident memory of the process and the headline
results; and the 3D run's ``dimensions``, ``mirror_factor``, the loaded cells of the fill
(:func:`fipy_hopper.space.estimate.loaded_cells`) and the snapshots written.
``python studies/performance.py --only emptying_3d`` runs it and writes what it measured to
``docs/performance.md`` (record ``reference_3d_1cm``), beside the 2D demo with their ratio.

Under the default ``--benchmark-disable`` a tiny 3D silo on 2 cm cubes is emptied instead,
as a plain test.
"""

import json
import pathlib
import re
import resource
import time
import warnings

import numba
import pytest

from fipy_hopper.cli import main

REFERENCE = pathlib.Path(__file__).resolve().parents[2] / "studies" / "configs" / "reference.toml"

TINY = """
[hopper]
bin_diameter = 0.2
outlet_diameter = 0.12
bin_height = 0.06
fill_height = 0.04
half_angle_deg = 30.0
dimensions = 3
[numerics]
cell_size = 0.02
gravity_ramp_time = 0.05
[run]
field_interval = 0.1
"""

PICTURES = ("flow_plane.png", "wall_circumference.png", "wall_unrolled.png", "discharge.png")


def reference_3d(text: str, cell_size: float = 0.01) -> str:
    """``reference.toml``'s text in 3D: ``dimensions = 3`` added to ``[hopper]``, the cell
    size and no markers; every other key as it is."""
    out = text.replace("[hopper]\n", "[hopper]\ndimensions = 3\n", 1)
    out = out.replace("cell_size = 0.005", f"cell_size = {cell_size}", 1)
    out = re.sub(r"^markers_per_side = \d+", "markers_per_side = 0", out, count=1, flags=re.M)
    for key in ("dimensions = 3", f"cell_size = {cell_size}", "markers_per_side = 0"):
        assert key in out, key
    return out


def test_the_reference_in_3d_changes_only_what_3d_needs():
    """The benchmark's configuration is the reference's but for the three keys."""
    import tomllib

    from fipy_hopper.config import HopperConfig

    ref = tomllib.loads(REFERENCE.read_text())
    three = tomllib.loads(reference_3d(REFERENCE.read_text()))
    assert three["hopper"] == {**ref["hopper"], "dimensions": 3}
    assert three["numerics"] == {**ref["numerics"], "cell_size": 0.01}
    assert three["run"] == {**ref["run"], "markers_per_side": 0}
    assert three["material"] == ref["material"] and three["wall"] == ref["wall"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # 3 cells across the outlet's radius
        cfg = HopperConfig.from_dict(three)
    assert cfg.hopper.outlet_offset == 0.0 and cfg.numerics.mirror_planes == "auto"


def test_bench_reference_3d_run(benchmark, tmp_path):
    config = tmp_path / "hopper.toml"
    config.write_text(TINY if benchmark.disabled else reference_3d(REFERENCE.read_text()))
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
    assert summary["dimensions"] == 3 and summary["mirror_factor"] == 4.0
    assert summary["stop_reason"] == "empty"
    assert summary["mass_balance_error"] < 1e-9
    for picture in PICTURES:
        assert (out / picture).is_file(), picture
    from fipy_hopper import load_config
    from fipy_hopper.space.config import SpaceConfig
    from fipy_hopper.space.estimate import loaded_cells

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loaded = loaded_cells(SpaceConfig.from_config(load_config(config)))
    snapshots = len(list((out / "fields").glob("fields_*.vtu")))
    benchmark.extra_info.update({
        "total_s": timing["total"],
        "simulation_s": summary["wall_time_s"],
        "pictures_and_writing_s": timing["total"] - summary["wall_time_s"],
        "threads": numba.get_num_threads(),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "loaded_cells": loaded, "snapshots": snapshots,
        **{k: summary[k] for k in ("steps", "cells", "dimensions", "mirror_factor",
                                   "discharge_time_s", "steady_discharge_rate_kg_s",
                                   "flow_mode", "mass_balance_error")}})
