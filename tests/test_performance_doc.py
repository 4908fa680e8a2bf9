"""``docs/performance.md`` is written by the benchmarks' own output, never by hand.

``studies/performance.py`` turns pytest-benchmark's JSON into figures with their date, machine
(CPU model, cores) and commit, merges them into ``docs/performance.json`` and writes from it the
page and the README's timing sentence.  Here the writer runs on fake measurements (no
benchmark is run: the lead measures, alone on the machine), and the committed page and
sentence are held to the committed store.
"""

import importlib.util
import json
import pathlib
import shutil
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"
if str(STUDIES) not in sys.path:
    sys.path.insert(0, str(STUDIES))
_spec = importlib.util.spec_from_file_location("performance_under_test",
                                               STUDIES / "performance.py")
performance = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(performance)

CPU = "Fake(R) Processor 9000"


def fake_benchmark_json(total=123.4, rss=456.7, when="2031-05-06T07:08:09.123+00:00"):
    """What ``pytest --benchmark-json`` writes, with invented numbers."""
    def run(cell, total_s, rss_mb, steps, cells):
        return {"fullname": f"tests/benchmarks/test_bench_emptying.py::"
                            f"test_bench_reference_hopper_run[{cell}]",
                "params": {"cell_size": cell}, "stats": {"median": total_s, "max": total_s},
                "extra_info": {"total_s": total_s, "simulation_s": total_s - 10.0,
                               "pictures_and_writing_s": 10.0, "threads": 1,
                               "peak_rss_mb": rss_mb, "steps": steps, "cells": cells,
                               "flow_mode": "mass"}}

    def phase(cell, name, median, **extra):
        return {"fullname": f"tests/benchmarks/test_bench_step.py::test_bench_discharge_step"
                            f"[{name}-{cell}]", "params": {"cell_size": cell, "phase": name},
                "stats": {"median": median}, "extra_info": {"cells": 4768, "threads": 1,
                                                            **extra}}
    return {"datetime": when,
            "machine_info": {"cpu": {"brand_raw": CPU, "count": 64}},
            "commit_info": {"id": "0123456789abcdef0123456789abcdef01234567", "dirty": True},
            "benchmarks": [run(0.005, total, rss, 500_000, 4768),
                           run(0.0025, 987.6, 1234.5, 1_000_000, 18414),
                           phase(0.005, "step", 0.02, steps_per_round=200),
                           phase(0.005, "stress_update", 6.7e-5, loaded_cells=1958),
                           {"fullname": "tests/benchmarks/test_bench_flow_mode_map.py::"
                                        "test_bench_flow_mode_map",
                            "params": None, "stats": {"max": 77.7, "median": 77.7},
                            "extra_info": {"cases": 30, "cores": 64,
                                           "case_wall_time_total_s": 140.0}}]}


def test_figures_carry_date_machine_commit_and_values():
    records = {r["key"]: r for r in performance.records(fake_benchmark_json())}
    assert set(records) == {"demo", "fine_2p5mm", "step_5mm", "flow_mode_map"}
    demo = records["demo"]
    assert demo["measured"] == "2031-05-06 07:08"
    assert demo["machine"] == f"{CPU}, 64 cores"
    assert demo["commit"] == "0123456+dirty"
    assert demo["values"]["total_s"] == 123.4 and demo["values"]["peak_rss_mb"] == 456.7
    assert records["step_5mm"]["values"]["step"] == pytest.approx(100.0)    # 0.02 s / 200
    assert records["step_5mm"]["values"]["stress_update"] == pytest.approx(67.0)
    page = performance.page(performance.merge({"figures": []}, list(records.values())))
    for text in ("2031-05-06 07:08", f"{CPU}, 64 cores", "git 0123456+dirty", "123 s",
                 "457 MB", "988 s", "1.2 GB", "500 000", "77.7 s", "| stress update | 67 |",
                 "test_bench_reference_hopper_run[0.005]"):
        assert text in page, text
    sentence = performance.timing_sentence(performance.merge({"figures": []},
                                                             list(records.values())))
    assert "The demo takes 123 s and 457 MB" in sentence
    assert "the 2.5 mm run takes 988 s and 1.2 GB" in sentence and CPU in sentence


def test_a_new_measurement_replaces_only_its_own_figures(tmp_path):
    store = performance.load()
    quoted = {r["key"] for r in store["figures"]}
    merged = performance.merge(store, performance.records(fake_benchmark_json()))
    keys = [r["key"] for r in merged["figures"]]
    assert len(keys) == len(set(keys))
    by_key = {r["key"]: r for r in merged["figures"]}
    assert by_key["demo"]["machine"] == f"{CPU}, 64 cores"
    for key in quoted - {"demo", "fine_2p5mm", "flow_mode_map"}:
        assert by_key[key] == {r["key"]: r for r in store["figures"]}[key]
    dropped = performance.merge(merged, [], drop={"test_suite"})
    assert "test_suite" not in {r["key"] for r in dropped["figures"]}


def copy_tree(tmp_path):
    (tmp_path / "docs").mkdir()
    for name in ("README.md", "docs/performance.json", "docs/performance.md"):
        shutil.copyfile(ROOT / name, tmp_path / name)
    return tmp_path


def test_writer_rewrites_page_store_and_readme_together(tmp_path):
    root = copy_tree(tmp_path)
    store = performance.merge(performance.load(root),
                              performance.records(fake_benchmark_json(total=55.5)))
    changed = performance.write(performance.outputs(store, root))
    assert sorted(p.name for p in changed) == ["README.md", "performance.json",
                                               "performance.md"]
    assert "The demo takes 55.5 s" in (root / "README.md").read_text(encoding="utf-8")
    assert "55.5 s" in (root / "docs" / "performance.md").read_text(encoding="utf-8")
    assert json.loads((root / "docs" / "performance.json").read_text())["figures"][0][
        "values"]["total_s"] == 55.5
    assert performance.write(performance.outputs(store, root)) == []     # nothing left to do
    assert not list(root.rglob(".*.tmp*"))                               # no temporary left


def test_nothing_is_written_when_the_readme_has_no_timing_region(tmp_path):
    root = copy_tree(tmp_path)
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}
    readme = root / "README.md"
    readme.write_text(readme.read_text(encoding="utf-8").replace("<!-- timings:end -->", ""),
                      encoding="utf-8")
    store = performance.merge(performance.load(root),
                              performance.records(fake_benchmark_json()))
    with pytest.raises(performance._docs.RegionError, match="timings"):
        performance.write(performance.outputs(store, root))
    for path, data in before.items():
        if path != readme:
            assert path.read_bytes() == data, path


def test_committed_page_and_readme_sentence_are_the_stores():
    files = performance.outputs(performance.load())
    stale = [str(p.relative_to(ROOT)) for p, text in files.items()
             if p.read_text(encoding="utf-8") != text]
    assert not stale, f"not as generated from docs/performance.json: {stale}; run " \
                      f"'python studies/performance.py --render'"
    store = performance.load()
    for record in store["figures"]:
        assert record["measured"] and record["machine"] and record["commit"], record["key"]


def test_the_3d_reference_is_written_beside_the_demo_with_their_ratio():
    """A 3D reference run (``test_bench_emptying_3d.py``) becomes the record
    ``reference_3d_1cm`` with the 2D run's values and its loaded cells, mirror factor and
    snapshots; the page sets it beside the demo, with the ratio of their times and memory
    (a range when the demo's figure is a range), and says when the two were not measured side
    by side.  Without it the page has no such section."""
    bench = fake_benchmark_json(total=100.0, rss=400.0)
    bench["benchmarks"].append({
        "fullname": "tests/benchmarks/test_bench_emptying_3d.py::test_bench_reference_3d_run",
        "params": None, "stats": {"median": 950.0, "max": 950.0},
        "extra_info": {"total_s": 950.0, "simulation_s": 900.0,
                       "pictures_and_writing_s": 50.0, "threads": 1, "peak_rss_mb": 800.0,
                       "steps": 270_000, "cells": 21675, "loaded_cells": 8198,
                       "mirror_factor": 4.0, "snapshots": 60, "dimensions": 3}})
    records = {r["key"]: r for r in performance.records(bench)}
    three = records["reference_3d_1cm"]
    assert three["values"]["total_s"] == 950.0 and three["values"]["loaded_cells"] == 8198
    assert "dimensions" not in three["values"]
    store = performance.merge({"figures": []}, list(records.values()))
    assert [r["key"] for r in store["figures"]][:3] == ["demo", "fine_2p5mm",
                                                        "reference_3d_1cm"]
    page = performance.page(store)
    section = page.split("## The reference in 3D beside the demo", 1)[1].split("\n## ", 1)[0]
    words = " ".join(section.split())                 # the sentences, unwrapped
    for text in ("| The demo: the reference hopper", "| The reference hopper in 3D, 1 cm cubes",
                 "21 675", "950 s", "8 198 loaded cells", "total 9.5 times the demo's",
                 "simulation 10 times the demo's", "peak memory 2 times the demo's"):
        assert text in words, text
    assert "not side by side" not in words
    stored = performance.load()              # the committed store, its demo made a range
    quoted = {"figures": [dict(r, values=dict(r["values"], total_s=[120.0, 150.0]))
                          if r["key"] == "demo" else r for r in stored["figures"]
                          if r["key"] != "reference_3d_1cm"]}
    later = performance.merge(quoted, [dict(three, measured="2031-06-01 10:00")])
    words = " ".join(performance.page(later).split("## The reference in 3D beside the demo")[1]
                     .split())
    assert f"total {950.0 / 150.0:.3g}–{950.0 / 120.0:.3g} times the demo's" in words
    assert "not side by side" in words
    assert "## The reference in 3D" not in performance.page(quoted)
