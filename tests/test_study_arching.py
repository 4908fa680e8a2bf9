"""The arching study (``studies/arching.py``) on its quick setting, serially: every bisection
ends with a bracket no wider than 10 % whose ratio to Jenike is finite, the figures and tables
are written, and a second run reads the finished runs instead of recomputing them.

The quick setting: a 0.3 m bin, 20 deg cone, 1 cm cells, two cohesions, the E check at
20 MPa, and the rathole pair (measured: about 20 s for the first run, 2 s for the rerun).
"""

import csv
import json
import math
import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from study_files import PNG, load  # noqa: E402


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("arching")
    assert load("arching").main(["--quick", "--serial", "--out", str(out)]) == 0
    return out


def read_json(path):
    with open(path) as fh:
        return json.load(fh)


def test_every_bisection_ends_with_a_narrow_bracket(quick):
    with open(quick / "brackets.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3                  # two cohesions, and the E check at 20 MPa
    for r in rows:
        assert r["status"] == "bracketed", r
        lo, hi = float(r["d_arch_m"]), float(r["d_flow_m"])
        assert 0 < lo < hi <= 1.1 * lo + 1e-12
        ratio = float(r["ratio"])
        assert math.isfinite(ratio) and ratio > 0
        assert float(r["ratio_low"]) <= ratio <= float(r["ratio_high"])
    with open(quick / "results.csv", newline="") as fh:
        runs = list(csv.DictReader(fh))
    # the bracket's ends are runs with those outcomes
    for r in rows:
        mine = {float(x["outlet_diameter_m"]): x["outcome"] for x in runs
                if x["task"] == r["task"]}
        assert mine[float(r["d_arch_m"])] == "arches"
        assert mine[float(r["d_flow_m"])] == "flows"


def test_study_json_figures_and_numbers(quick):
    data = read_json(quick / "study.json")
    assert data["study"] == "arching" and data["setting"] == "quick"
    numbers = data["numbers"]
    assert numbers["bracketed"] == numbers["cases"] == 2
    assert numbers["largest_bracket_width"] <= 0.1 + 1e-9
    assert math.isfinite(numbers["ratio_mean"]) and numbers["ratio_spread_max_over_min"] >= 1
    assert math.isfinite(numbers["exponent_n_theta20"])
    assert set(numbers["e_check"]) == {"E5MPa", "E20MPa"}
    rat = numbers["rathole"]
    assert rat["jenike_rathole_diameter_m"] > 0
    for tag in ("cohesive", "cohesionless"):
        assert 0 <= rat[tag]["remaining_mass_fraction"] <= 1
    assert any("exponent" in f or "^n" in f for f in data["findings"])
    assert any(f.startswith("E check") for f in data["findings"])
    assert any(f.startswith("Rathole case") for f in data["findings"])
    for fig in data["figures"]:
        assert (quick / fig["file"]).read_bytes()[:8] == PNG
    assert "critical_outlet.png" in [f["file"] for f in data["figures"]]


def test_a_rerun_reads_the_finished_runs(quick):
    assert load("arching").main(["--quick", "--serial", "--out", str(quick)]) == 0
    numbers = read_json(quick / "study.json")["numbers"]
    assert numbers["runs"] > 0 and numbers["runs_new"] == 0
