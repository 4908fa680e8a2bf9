"""Benchmark of the whole flow-mode map at its default resolution (target: the map of
at least 30 cases in under 30 minutes on 2 cores).

``pytest tests/benchmarks/test_bench_flow_mode_map.py --benchmark-enable`` runs
``studies/flow_mode_map.py`` with its defaults (30 cases, 5 mm cells, 0.8 s of discharge) on a
Dask ``LocalCluster`` with one worker per core, once (``pedantic``, one round); what it
measured, with the date, the machine and the commit, is in ``docs/performance.md`` (written by
``python studies/performance.py``, which runs this benchmark).  Under the default
``--benchmark-disable`` the same code runs a 2-case map on the quick setting, serially, as a
plain test.  ``FLOW_MODE_MAP_OUT=DIR`` keeps
the measured map's outputs in ``DIR`` (a fresh folder: finished cases there are not rerun),
e.g. ``studies/output/flow_mode_map`` for the report.
"""

import csv
import importlib.util
import os
import pathlib

import pytest

STUDY = pathlib.Path(__file__).resolve().parents[2] / "studies" / "flow_mode_map.py"


def load_study():
    spec = importlib.util.spec_from_file_location("flow_mode_map_bench", STUDY)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_flow_mode_map(benchmark, tmp_path):
    study = load_study()
    out = tmp_path / "flow_mode_map"
    if benchmark.enabled and os.environ.get("FLOW_MODE_MAP_OUT"):
        out = pathlib.Path(os.environ["FLOW_MODE_MAP_OUT"])
    if benchmark.disabled:
        argv = ["--quick", "--serial", "--out", str(out)]
    else:
        pytest.importorskip("dask.distributed")
        argv = ["--out", str(out)]
    benchmark.pedantic(study.main, args=(argv,), rounds=1, iterations=1)
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    expected = 2 if benchmark.disabled else len(study.setup()["cases"])
    assert len(rows) == expected and expected >= (2 if benchmark.disabled else 30)
    assert all(r["flow_mode"] in ("mass", "funnel") and not r["error"] for r in rows)
    benchmark.extra_info["cases"] = len(rows)
    benchmark.extra_info["cores"] = os.cpu_count()
    benchmark.extra_info["case_wall_time_total_s"] = sum(float(r["wall_time_s"]) for r in rows)
