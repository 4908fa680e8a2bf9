"""The validation studies run on their quick settings and their outputs hold.

Every study runs serially (no Dask) on tiny hoppers with 1 cm cells; one test runs two tiny
cases on a one-worker Dask ``LocalCluster`` when dask.distributed is installed.  The report
is generated from the outputs of all of them.
"""

import argparse
import csv
import json
import math
import os
import pathlib
import shutil
import sys

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from study_files import STUDIES, assert_png, load, rows_of, study_json  # noqa: E402


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("study_outputs")


def run_quick(root, name, *extra):
    out = root / name
    assert load(name).main(["--quick", "--serial", "--out", str(out), *extra]) == 0
    return out


@pytest.fixture(scope="module")
def flow_map(root):
    return run_quick(root, "flow_mode_map")


@pytest.fixture(scope="module")
def discharge(root):
    return run_quick(root, "discharge_rate")


@pytest.fixture(scope="module")
def wall(root):
    return run_quick(root, "wall_pressure")


@pytest.fixture(scope="module")
def convergence(root):
    return run_quick(root, "convergence")


@pytest.fixture(scope="module")
def robustness(root):
    return run_quick(root, "robustness")


# ---------------------------------------------------------------- plane flow
def test_plane_flow_study_runs_wedges_against_the_plane_theories(root):
    """The quick plane-flow study: two wedges on either side of Jenike's plane-flow boundary
    are classified as it says, the slot runs conserve mass and are fitted, and everything
    is per metre; the map draws the plane boundary with the conical one beside it."""
    out = run_quick(root, "plane_flow")
    data = study_json(out)
    numbers = data["numbers"]
    assert data["setting"] == "quick"
    assert numbers["map_classified"] == 2 and numbers["map_agreement_fraction"] == 1.0
    rows = {r["case"]: r for r in rows_of(out / "results.csv")}
    assert rows["theta20_wall12"]["flow_mode"] == "mass"
    assert rows["theta60_wall25"]["flow_mode"] == "funnel"
    # the plane boundary: the conical one + 10 deg (theory.jenike_critical_half_angle_plane)
    theta_c = float(rows["theta20_wall12"]["theta_c_deg"])
    from fipy_hopper import theory
    assert theta_c == pytest.approx(float(theory.jenike_critical_half_angle(30.0, 12.0)) + 10.0)
    slots = rows_of(out / "slots.csv")
    assert len(slots) == 2 and all(float(r["mass_balance_error"]) < 1e-9 for r in slots)
    assert all(float(r["window_rate_kg_s_m"]) > 0 for r in slots)
    assert math.isfinite(numbers["slot_exponent_flat"])
    for name in ("slot_exponent.png", "plane_flow_map.png"):
        assert_png(out / name)
    assert (out / "cases" / "slot60_theta90" / "summary.json").is_file()


# ---------------------------------------------------------------- flow-mode map
def test_flow_mode_map_classifies_the_two_clear_cases(flow_map):
    rows = {(float(r["half_angle_deg"]), float(r["wall_friction_deg"])): r
            for r in rows_of(flow_map / "results.csv")}
    assert rows[(15.0, 12.0)]["flow_mode"] == "mass"
    assert rows[(15.0, 12.0)]["jenike_mode"] == "mass"
    assert rows[(60.0, 25.0)]["flow_mode"] == "funnel"
    assert rows[(60.0, 25.0)]["jenike_mode"] == "funnel"
    data = study_json(flow_map)
    assert data["setting"] == "quick"
    assert data["numbers"]["agreement_fraction"] == 1.0
    assert data["numbers"]["classified"] == 2
    for name in ("flow_mode_map.png", "wall_slip.png", "thumbnails.png"):
        assert_png(flow_map / name)
    for case in ("theta15_wall12", "theta60_wall25"):     # ordinary run directories
        assert (flow_map / "cases" / case / "summary.json").is_file()
        assert (flow_map / "cases" / case / "config.toml").is_file()


def test_flow_mode_map_grid_check_reruns_the_cases_near_the_boundary():
    """The cases within 6 deg of Jenike's boundary (and no others) get a rerun on 2.5 mm
    cells; the analysis sets each against its map case and counts the cases beyond 4 deg."""
    study = load("flow_mode_map")
    setup = study.setup(pairs=((40.0, 10.0), (20.0, 10.0), (30.0, 30.0)))
    names = [c["name"] for c in setup["cases"]]
    assert names == ["theta40_wall10", "theta40_wall10_fine", "theta20_wall10",
                     "theta30_wall30"]
    fine = setup["cases"][1]
    assert fine["config"]["numerics"]["cell_size"] == 0.0025 and fine["params"]["grid_check"]
    rows = [{"case": c["name"], **c["params"], "flow_mode": mode, "wall_slip_ratio": x}
            for c, mode, x in zip(setup["cases"], ("mass", "funnel", "mass", "funnel"),
                                  (0.25, 0.15, 0.6, 0.05))]
    numbers = study.analyse(rows, setup["options"])
    assert numbers["classified"] == 3 and numbers["agreeing"] == 3
    assert numbers["cases_beyond_4deg"] == 3 and numbers["funnel_at_rough_walls"]
    assert numbers["grid_checked"] == 1 and numbers["grid_same_call"] == 0
    assert numbers["grid_changed"] == ["theta40_wall10_fine"]
    assert "mass / funnel" in study.grid_check_finding(rows, numbers, setup["options"])


def test_case_pictures_are_the_study_setting_unless_asked_for():
    sweep = load("_sweep")
    parser = argparse.ArgumentParser()
    sweep.add_arguments(parser, "flow_mode_map")
    assert "case_plots" not in sweep.study_options(parser.parse_args([]), [])
    assert sweep.study_options(parser.parse_args(["--case-plots"]), [])["case_plots"] is True
    assert sweep.study_options(parser.parse_args(["--no-case-plots"]), [])["case_plots"] is False
    assert load("flow_mode_map").DEFAULTS["case_plots"] is False     # 30 runs: off


@pytest.mark.parametrize("name", ["flow_mode_map", "plane_flow", "discharge_rate",
                                  "wall_pressure", "stiffness_spread", "convergence",
                                  "robustness", "funnel_channel", "lagrangian_vs_eulerian",
                                  "arching", "three_d", "wall_zone", "eccentric"])
def test_a_study_refuses_an_option_it_does_not_have(name):
    with pytest.raises(TypeError, match=r"unknown options \['bogus'\]; known: "):
        load(name).setup(bogus=1)


def test_restarted_sweep_does_not_recompute_finished_cases(flow_map, capsys):
    summaries = sorted((flow_map / "cases").glob("*/summary.json"))
    stamps = {p: p.stat().st_mtime_ns for p in summaries}
    load("flow_mode_map").main(["--quick", "--serial", "--out", str(flow_map)])
    assert "2 of 2 case(s) already finished" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in summaries} == stamps
    assert all(r["reused"] == "True" for r in rows_of(flow_map / "results.csv"))


def test_a_finished_case_with_another_configuration_is_refused(flow_map):
    with pytest.raises(SystemExit, match="different configuration"):
        load("flow_mode_map").main(["--quick", "--serial", "--out", str(flow_map),
                                    "--end-time", "0.5"])


def test_case_status_reads_finished_resumable_and_new_cases(flow_map, tmp_path):
    import _sweep   # on sys.path once a study is loaded

    study = load("flow_mode_map").setup(quick=True)
    case = study["cases"][0]
    assert _sweep.case_status(case, flow_map) == "done"
    root = tmp_path / "copy"
    shutil.copytree(flow_map / "cases" / case["name"], root / "cases" / case["name"])
    summary_path = root / "cases" / case["name"] / "summary.json"
    summary = json.loads(summary_path.read_text())
    summary["stop_reason"] = "interrupted"
    summary_path.write_text(json.dumps(summary))
    assert _sweep.case_status(case, root) == "new"       # no checkpoint: run again
    (root / "cases" / case["name"] / "checkpoint.npz").write_bytes(b"")
    assert _sweep.case_status(case, root) == "resume"
    assert _sweep.case_status(study["cases"][1], root) == "new"


def test_a_study_names_the_code_that_made_its_runs(flow_map, tmp_path):
    """Each case's row carries its run's ``code_commit`` (the manifest's), ``study.json``
    counts them, and the report names them when they are not the study's own commit."""
    import _sweep

    from fipy_hopper import io

    data = json.loads((flow_map / "study.json").read_text())
    assert data["run_commits"] == {io.code_commit() or "not recorded": data["cases"]}
    rows = [_sweep._finished_row(p.parent) for p in (flow_map / "cases").glob("*/summary.json")]
    assert len(rows) == 2 and {r["code_commit"] for r in rows} == {io.code_commit()}
    assert _sweep.run_commits([{"code_commit": "abc1234"}, {"code_commit": ""},
                               {"code_commit": "abc1234"}]) == {"abc1234": 2,
                                                                "not recorded": 1}
    make_report = load("make_report")
    same = {"commit": "abc1234", "run_commits": {"abc1234": 3}}
    assert make_report._runs_made_by(same) == ""
    older = {"commit": "abc1234", "run_commits": {"abc1234": 1, "0ld0001": 2,
                                                  "not recorded": 1}}
    assert make_report._runs_made_by(older) == (
        " Its runs were made by git abc1234 (1 case), git 0ld0001 (2 cases), code not "
        "recorded (1 case).")


# ---------------------------------------------------------------- discharge rate
def test_discharge_rate_exponent_and_beverloo_constant(discharge):
    fits = rows_of(discharge / "fits.csv")
    assert len(fits) == 1 and int(fits[0]["outlets"]) >= 4
    n = float(fits[0]["exponent_n"])
    assert 2.0 <= n <= 3.0, n                           # 5/2, wide band on a 1 cm grid
    assert 0.4 <= float(fits[0]["C_beverloo_via_rose_tanaka"]) <= 0.8
    rows = rows_of(discharge / "results.csv")
    assert {float(r["half_angle_deg"]) for r in rows} == {45.0, 90.0}
    for r in rows:
        assert float(r["steady_discharge_rate_kg_s"]) > 0
        assert math.isfinite(float(r["diff_beverloo_pct"]))
        assert math.isfinite(float(r["diff_brown_pct"]))
    for name in ("rate_vs_outlet.png", "rate_vs_half_angle.png"):
        assert_png(discharge / name)
    assert "exponent_n_theta45" in study_json(discharge)["numbers"]


# ---------------------------------------------------------------- wall pressure
def test_wall_pressure_profiles_theories_and_switch(wall):
    comparison = rows_of(wall / "comparison.csv")
    seen = {(r["stage"], r["region"], r["theory"].split(" (")[0].split(",")[0])
            for r in comparison}
    assert ("filling", "bin", "Janssen") in seen
    assert ("filling", "cone", "Walker slice") in seen
    assert any(s[0] == "early_discharge" and s[2].startswith("EN 1991-4") for s in seen)
    for r in comparison:
        assert float(r["mean_sim_Pa"]) > 0 and float(r["mean_theory_Pa"]) > 0
    switch = rows_of(wall / "switch.csv")
    assert switch and float(switch[0]["peak_sim_Pa"]) > 0
    assert float(switch[0]["walker_ratio_Fe_over_K"]) > 1
    pictures = sorted(wall.glob("wall_pressure_theta30_wall15_*.png"))
    assert len(pictures) == 4                       # two cell sizes, two more moduli
    for picture in pictures:
        assert_png(picture)
    profiles = rows_of(wall / "profiles.csv")
    assert {r["stage"] for r in profiles} >= {"filling", "early_discharge"}
    assert all(float(r["p_n_raw_Pa"]) > 0 for r in profiles if r["stage"] == "filling")
    series = rows_of(wall / "convergence.csv")
    assert {r["series"] for r in series} == {"grid", "stiffness"}
    assert all(math.isfinite(float(r["l2_change_pct"])) for r in series)
    # bin by bin on the shared 2 cm bins: 10 and 7.5 mm cells have the same bins
    for r in series:
        for region in ("cone_max_diff_pct", "bin_wall_max_diff_pct"):
            assert 0.0 <= float(r[region]) <= float(r["max_diff_pct"])
        assert r["where"].split(",")[0] in ("cone", "bin wall")
    numbers = study_json(wall)["numbers"]
    assert "E_spread_pct[filling]" in numbers and "l2_change_pct[filling|10->7.5 mm]" in numbers
    assert "max_diff_pct[filling|10->7.5 mm]" in numbers
    assert numbers["fill_equilibrium_residual_max_pct"] < 0.5
    # the spread below and above the transition: a pair's whole-wall L2 is a weighted mean of
    # its two parts', so the largest over the pairs lies within the parts' largest
    for key in [k for k in numbers if k.startswith("E_spread_pct[") and "|" not in k]:
        cone, above = numbers[key[:-1] + "|cone]"], numbers[key[:-1] + "|bin]"]
        assert 0.0 < numbers[key] <= max(cone, above) * (1 + 1e-12)
    assert_png(wall / "convergence.png")
    # the bin's K read from each stiffness case's time series (NaN where the quick setting's
    # small bin has no band of full cells, or the discharge is shorter than the window)
    moduli = [k for k in numbers if k.startswith("bin_k_rest[")]
    assert len(moduli) == 3
    for key in moduli + [k.replace("rest", "discharge") for k in moduli]:
        assert numbers[key] is None or 0.0 < numbers[key] < 3.0, key


def test_wall_pressure_smoothness_of_the_three_estimates(wall):
    """``smoothness.csv``: per case and stage, the hopper wall's RMS deviation of p_n from a
    cubic over its bins (2 cm left out at each end) and its bin-to-bin scatter, for the
    recovered traction, the reaction binned node by node (raw) and the stress-sampled
    estimate.  On the quick 15 deg cone at rest (1 cm cells, 2 cm bins) they measured 0.8,
    21.8 and 10.0 % RMS; in every case and stage the recovered traction is smoother than the
    raw binning by both measures.  The cones and the wedge at rest have their picture."""
    rows = rows_of(wall / "smoothness.csv")
    of = {(r["case"], r["stage"]): r for r in rows}
    assert {("theta15_wall15_h10_E5_rest", "filling"), ("wedge15_wall15_h10_E5_rest", "filling"),
            ("theta30_wall15_h10_E5", "filling"),
            ("theta30_wall15_h10_E5", "early_discharge")} <= set(of)
    cone = of[("theta15_wall15_h10_E5_rest", "filling")]
    assert float(cone["rms_recovered_pct"]) < 1.5
    assert float(cone["rms_raw_pct"]) > 15.0 and float(cone["rms_stress_pct"]) > 5.0
    for r in rows:
        for kind in ("rms", "scatter"):
            assert float(r[f"{kind}_recovered_pct"]) < float(r[f"{kind}_raw_pct"]), \
                (r["case"], r["stage"], kind)
    data = study_json(wall)
    assert data["numbers"]["rest_rms_max_pct[recovered]"] < 1.5
    assert any(t["title"].startswith("Smoothness of p_n") for t in data["tables"])
    assert_png(wall / "rest_profiles.png")


def test_wall_pressure_stiffness_series_from_the_command_line(wall, tmp_path):
    """``--youngs-moduli`` sets the stiffness series; the finished cases are reused and only
    the new modulus runs."""
    out = tmp_path / "wall_pressure"
    shutil.copytree(wall, out)
    before = {p.name for p in (out / "cases").iterdir()}
    assert load("wall_pressure").main(["--quick", "--serial", "--out", str(out),
                                       "--youngs-moduli", "2e6", "20e6", "80e6"]) == 0
    added = {p.name for p in (out / "cases").iterdir()} - before
    assert added == {"theta30_wall15_h10_E80"}
    numbers = study_json(out)["numbers"]
    assert sorted(k for k in numbers if k.startswith("bin_k_rest[")) == [
        "bin_k_rest[2 MPa]", "bin_k_rest[20 MPa]", "bin_k_rest[5 MPa]", "bin_k_rest[80 MPa]"]
    pairs = {r["pair"] for r in rows_of(out / "convergence.csv") if r["series"] == "stiffness"}
    assert "E 20 / 80 MPa" in pairs


# ---------------------------------------------------------------- convergence
def test_convergence_three_cell_sizes_and_three_moduli(convergence):
    rows = rows_of(convergence / "results.csv")
    assert len({r["cell_size_mm"] for r in rows}) >= 3
    assert len({r["youngs_modulus_MPa"] for r in rows}) >= 3
    numbers = study_json(convergence)["numbers"]
    assert numbers["rate_spread_over_E_pct"] < 10.0
    assert len(numbers["rates_by_cell_kg_s"]) == 3
    diffs = rows_of(convergence / "profiles.csv")
    assert {r["series"] for r in diffs} == {"cell size", "stiffness"}
    assert_png(convergence / "convergence.png")


# ---------------------------------------------------------------- funnel channel
def test_funnel_channel_edge_on_a_constructed_speed_profile():
    """Speed falling linearly from the axis, 1 - r/R: half the axis cell's speed is reached
    at r = (R + r_0)/2 exactly (linear between cell centres); loose cells (alpha <= 1/2) count
    as at rest, and a row whose axis cell is empty has no edge."""
    study = load("funnel_channel")
    R = 0.1
    r = (np.arange(20) + 0.5) * 0.005
    speed = np.tile(1.0 - r / R, (3, 1))
    alpha = np.ones_like(speed)
    alpha[1, 6:] = 0.3
    alpha[2, 0] = 0.3
    half = study.edge_radius(r, speed, alpha, 0.5)
    assert half[0] == pytest.approx(0.5 * (R + r[0]), rel=1e-12)
    assert half[1] == pytest.approx(r[5] + (0.5 * speed[1, 0] - speed[1, 5]) / (0 - speed[1, 5])
                                    * (r[6] - r[5]), rel=1e-12)
    assert np.isnan(half[2])
    t = np.array([0.0, 1.0, 2.0, 3.0])
    assert study.mean_rate(t, 2.0 * t, 0.5, 2.5) == pytest.approx(2.0)


def test_funnel_channel_study_writes_its_outputs(root):
    out = run_quick(root, "funnel_channel")
    numbers = study_json(out)["numbers"]["funnel_default"]
    assert numbers["cell_sizes_mm"] == [10.0, 7.5]
    assert all(math.isfinite(x) for x in numbers["early_rate_kg_s"])
    assert all(x is not None for x in numbers["edge_angle_deg"])
    assert all(x is not None and x > 0 for x in numbers["edge_width_grains"])
    assert_png(out / "funnel_channel.png")
    assert len(rows_of(out / "channel.csv")) > 10


# ---------------------------------------------------------------- grain size
def test_grain_size_offset_fit_on_constructed_rates():
    """Rates made exactly as W = A (D0 - k d)^n give back k and n (the fit the study makes
    of its runs: never a value set in a test of the model)."""
    study = load("grain_size")
    d0 = np.repeat([0.04, 0.06, 0.08], 4)
    d = np.tile([0.0005, 0.001, 0.002, 0.003], 3)
    for k, n in ((1.4, 2.5), (0.6, 2.62)):
        w = 3.0 * (d0 - k * d) ** n
        a, k_fit, n_fit = study.fit_offset(d0, d, w)
        assert k_fit == pytest.approx(k, abs=1e-3) and n_fit == pytest.approx(n, rel=1e-4)
        a, k_held, _ = study.fit_offset(d0, d, w, n=n)
        assert k_held == pytest.approx(k, abs=1e-3)


def test_grain_size_study_writes_its_outputs(root):
    out = run_quick(root, "grain_size")
    data = study_json(out)
    rows = rows_of(out / "results.csv")
    laws = {r["law"] for r in rows}
    assert laws == {"plain", "mu_I"}
    assert all(not r["error"] for r in rows)
    # the grain size slows the flow: every mu(I) case below the plain law at its outlet
    assert all(float(r["ratio_to_plain"]) < 1.0 for r in rows if r["law"] == "mu_I")
    assert "k_free" in data["numbers"]
    assert_png(out / "rate_vs_grain.png")


def test_shear_band_study_measures_the_band_in_grains(root):
    """The quick layers: the band is the grain size's (the same at both cells within 15 %,
    wider in mm for the coarser grains), and the plain law's is one cell."""
    out = root / "shear_band"
    assert load("shear_band").main(["--quick", "--out", str(out)]) == 0
    numbers = study_json(out)["numbers"]
    for d in (1, 3):
        assert numbers[f"band_change_pct_v0.5_d{d}mm"] < 15.0
    assert numbers["band_mm_v0.5_d3mm"][-1] > numbers["band_mm_v0.5_d1mm"][-1]
    assert all(c <= 1.01 for c in numbers["plain_band_cells_v0.5"])
    assert_png(out / "shear_band.png")


# ---------------------------------------------------------------- shear zone at the bin wall
def test_wall_zone_on_constructed_speed_rows():
    """A plug at 1 m/s with a linear fall over the last 12 mm to 0.4 at the wall: the zone
    (speed below 95 % of the plug) is 12 mm x 0.05 / 0.6 = 1 mm short of the fall's start,
    found between cell centres; a plug that slides whole has no zone and slip 1; a row
    at rest has no plug."""
    study = load("wall_zone")
    R, h = 0.15, 0.0025
    r = (np.arange(60) + 0.5) * h
    fall = 0.012
    speed = np.where(r < R - fall, 1.0, 1.0 - 0.6 * (r - (R - fall)) / fall)
    plug, width, slip = study.wall_zone(r, speed, R)
    assert plug == pytest.approx(1.0)
    assert width == pytest.approx(fall - 0.05 / 0.6 * fall, rel=1e-9)
    assert slip == pytest.approx(speed[-1])
    assert study.wall_zone(r, np.full_like(r, 0.3), R) == (pytest.approx(0.3), 0.0, 1.0)
    assert all(math.isnan(x) for x in study.wall_zone(r, np.zeros_like(r), R))


def test_wall_zone_study_writes_its_outputs(root):
    out = run_quick(root, "wall_zone")
    numbers = study_json(out)["numbers"]
    assert set(numbers) == {"d1mm", "plain"}
    assert numbers["d1mm"]["cell_sizes_mm"] == [10.0, 7.5]
    # the rough wall holds the material back: a zone, and the wall's cell below the plug
    assert all(w is not None and w > 0 for w in numbers["d1mm"]["zone_width_mm"])
    assert all(s is not None and s < 0.9 for s in numbers["d1mm"]["wall_slip"])
    assert len(rows_of(out / "profiles.csv")) > 10
    assert_png(out / "wall_zone.png")


# ---------------------------------------------------------------- robustness
def test_robustness_bands_are_evaluated_for_both_hoppers(robustness):
    bands = rows_of(robustness / "bands.csv")
    assert {(b["hopper"], b["band"]) for b in bands} == {
        (h, b) for h in ("mass", "funnel")
        for b in ("stiffness", "cell_size", "hourglass", "alpha_bounds", "mass_balance")}
    status = {(b["hopper"], b["band"]): b["status"] for b in bands}
    assert status[("mass", "alpha_bounds")] == "PASS"
    assert status[("funnel", "alpha_bounds")] == "PASS"
    assert status[("mass", "mass_balance")] == "n/a"       # quick: no complete emptying asked
    assert all(b["status"] in ("PASS", "FAIL", "n/a") for b in bands)
    rows = rows_of(robustness / "results.csv")
    assert len(rows) == 14
    assert {r["flow_mode"] for r in rows if r["hopper"] == "mass"} == {"mass"}
    assert {r["flow_mode"] for r in rows if r["hopper"] == "funnel"} == {"funnel"}
    for r in rows:
        assert float(r["mass_balance_error"]) < 1e-9
        assert -1e-12 <= float(r["alpha_min"]) and float(r["alpha_max"]) <= 1 + 1e-3
    assert_png(robustness / "robustness.png")
    assert_png(robustness / "robustness_discharge.png")


def test_robustness_bands_on_known_numbers():
    study = load("robustness")
    opts = study.setup()["options"]

    def row(hopper, h, e, f, w, err=1e-12, stop="empty", lo=0.0, hi=1.0):
        return {"hopper": hopper, "cell_size_mm": h, "youngs_modulus_MPa": e,
                "hourglass_factor": f, "steady_discharge_rate_kg_s": w,
                "mass_balance_error": err, "stop_reason": stop, "alpha_min": lo,
                "alpha_max": hi}

    good = [row("mass", 5.0, 2.0, 1.0, 3.30), row("mass", 5.0, 5.0, 1.0, 3.32),
            row("mass", 5.0, 20.0, 1.0, 3.40), row("mass", 7.5, 5.0, 1.0, 3.10),
            row("mass", 3.75, 5.0, 1.0, 3.35), row("mass", 5.0, 5.0, 0.5, 3.35),
            row("mass", 5.0, 5.0, 2.0, 3.28)]
    bands = {b["band"]: b for b in study.evaluate_bands(good, opts)}
    assert all(b["passed"] is True for b in bands.values()), bands
    assert bands["stiffness"]["value"] == pytest.approx(0.10 / 3.32)
    assert bands["cell_size"]["value"] == pytest.approx(0.03 / 3.35)

    bad = [dict(r) for r in good]
    bad[2]["steady_discharge_rate_kg_s"] = 3.60          # E = 20 MPa: 9 % off
    bad[4]["steady_discharge_rate_kg_s"] = 3.70          # 5 -> 3.75 mm: larger change
    bad[6]["steady_discharge_rate_kg_s"] = 3.00          # doubled hourglass: -10 %
    bad[0]["alpha_max"] = 1.01
    bad[1]["stop_reason"] = "at_rest"
    bands = {b["band"]: b for b in study.evaluate_bands(bad, opts)}
    assert all(b["passed"] is False for b in bands.values()), bands


# ---------------------------------------------------------------- Dask
def test_local_dask_cluster_runs_two_tiny_cases(tmp_path):
    pytest.importorskip("dask.distributed")
    load("flow_mode_map")
    import _sweep

    base = {"hopper": {"bin_diameter": 0.16, "half_angle_deg": 45.0, "outlet_diameter": 0.06,
                       "fill_height": 0.04, "bin_height": 0.06},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05},
            "run": {"end_time": 0.1, "output_interval": 0.02}}
    cases = [_sweep.make_case(_sweep.case_name(("wall", w)), {"wall_friction_deg": w},
                              _sweep.merge(base, wall={"friction_angle_deg": w}), plots=False)
             for w in (10.0, 20.0)]
    rows = _sweep.run_cases(cases, tmp_path, workers=1, log=lambda *a: None)
    assert [r["case"] for r in rows] == ["wall10", "wall20"]
    for r in rows:
        assert r["error"] == "" and r["reused"] is False
        assert r["stop_reason"] == "end_time"
        assert (tmp_path / "cases" / r["case"] / "summary.json").is_file()
        assert r["run_dir"] == os.fspath(tmp_path.resolve() / "cases" / r["case"])


# ---------------------------------------------------------------- discharge dynamics
def test_discharge_dynamics_reads_the_bin_plug_without_changing_the_run(root):
    """The study's sampler reads the state after every transport and never changes the run:
    a discharge with it attached ends in exactly the state of one without.  Its quick outputs
    hold one row per modulus, a plug stress of the order of the filled column's weight, and
    an even, sub-millisecond sampling."""
    dynamics = load("discharge_dynamics")
    out = run_quick(root, "discharge_dynamics")
    rows = rows_of(out / "results.csv")
    assert [float(r["youngs_modulus_MPa"]) for r in rows] == [2.0, 5.0, 20.0]
    # the plug sits 0.13-0.26 m below the surface of a 0.3 m bin: between the Janssen
    # asymptote's share and the full hydrostatic head (rho g z = 1.9-3.8 kPa)
    for r in rows:
        assert 300.0 < float(r["plug_stress_mean_Pa"]) < 3800.0, r
    data = study_json(out)
    assert data["setting"] == "quick" and data["tables"][0]["rows"]
    assert_png(out / "discharge_dynamics.png")

    import numpy as np
    from fipy_hopper.config import HopperConfig
    from fipy_hopper.model import HopperModel
    from fipy_hopper.simulation import Simulation

    def final_state(with_sampler):
        cfg = HopperConfig.from_dict({"numerics": {"cell_size": 0.01},
                                      "run": {"end_time": 0.1, "markers_per_side": 0}})
        model = HopperModel(cfg, threads=1)
        plug = dynamics.plug_cells(model)
        seen = []
        if with_sampler:
            model.after_transport.append(
                lambda st: seen.append(float(np.mean(st.sigma[..., 1][plug]))))
        sim = Simulation(model, progress=False)
        sim.run()
        return sim.state, seen

    plain, _ = final_state(False)
    sampled, seen = final_state(True)
    assert len(seen) > 50
    for name in ("v", "alpha", "sigma", "eps_p", "loose"):
        assert np.array_equal(getattr(plain, name), getattr(sampled, name)), name


# ---------------------------------------------------------------- any silo
def test_geometries_study_measures_each_silo(root):
    """The quick geometries study (10 mm cells, 1.5 s): each silo's numbers are there, and
    one physical fact per silo holds: the expanded-flow hopper's steep lower stretch slides
    more than its shallow upper one (Jenike: mass below, funnel above); the insert carries a
    positive load less than the fill's weight, at rest and in discharge; the slot's near and far
    walls carry the same pressure at rest (the closed slot's silo is mirror-symmetric but
    for the floor's friction) and not in discharge; the ledge slides less than the hopper
    below it; the walls' vertical reactions add up to the summary's."""
    out = run_quick(root, "geometries")
    data = study_json(out)
    assert data["setting"] == "quick" and data["cases_failed"] == 0
    numbers = data["numbers"]
    assert set(numbers) == {"expanded", "funnel", "insert", "slot", "ledge"}
    for n in numbers.values():
        assert n["mass_balance_error"] < 1e-9 and n["fill_equilibrium_residual"] < 0.005
    lower, upper = numbers["expanded"]["stretches"]
    assert (lower["jenike_call"], upper["jenike_call"]) == ("mass", "funnel")
    assert lower["slip_ratio"] > upper["slip_ratio"]
    ins = numbers["insert"]
    assert 0.0 < ins["force_rest_N"] < ins["fill_weight_N"]
    assert 0.0 < ins["force_discharge_max_N"] < ins["fill_weight_N"]
    for where in ("top", "widest"):
        assert all(math.isfinite(ins[where][k]) for k in (
            "ratio_rest_theory", "ratio_rest_simulated", "ratio_discharge_simulated"))
    pressure = numbers["slot"]["pressure"]
    assert pressure["filling"]["near_over_far"] == pytest.approx([1.0] * 4, abs=0.05)
    assert max(abs(r - 1.0) for r in pressure["early_discharge"]["near_over_far"]) > 0.1
    assert numbers["slot"]["walls_sum_minus_summary_N_m"] == pytest.approx(
        0.0, abs=1e-6 * numbers["slot"]["fill_weight_N_m"])
    hopper, ledge = numbers["ledge"]["stretches"]
    assert ledge["half_angle_deg"] == 90.0 and ledge["slip_ratio"] < hopper["slip_ratio"]
    for name in ("geometries.png", "slot_walls.png", "flow_pattern_slot.png",
                 "wall_pressure_insert.png"):
        assert_png(out / name)


# ---------------------------------------------------------------- three dimensions
@pytest.fixture(scope="module")
def three_d(root):
    return run_quick(root, "three_d")


def test_three_d_study_sets_3d_against_the_section_and_off_centre_outlets(three_d):
    """The quick 3D study (2 cm cubes, the small conical silo as the reference, 0.3 s of
    discharge; a flat-bottomed silo and an eccentric cone, 0.32 m, with the outlet at e/R = 0
    and 0.5, 0.4 s):
    its files and pictures; the reference in 3D against its section: the fill within 1 %,
    the rate within 5 % (measured +0.02 % and -4.1 %), the wall pressure at rest above the
    lip's bin within 5 % RMS (measured 4.4 %) and round (largest over smallest 1.007); the
    centred silos round at rest (the largest over the smallest pressure around the
    circumference below 1.05 on the flat silo's bin wall and the cone, measured at most 1.011;
    the cone's one bin-wall bin below 1.1), and so the flat silo's bin wall with its outlet
    off the axis (measured 1.011); off centre the discharge is unsymmetric: the flat silo's
    bin wall at 90 % left above 1.2 (measured 1.47), the cone's wall slides on the outlet's
    side and not on the far side; the mass balance to 1e-9 (the offsets whole cells)."""
    data = study_json(three_d)
    assert data["setting"] == "quick" and data["cases"] == 6 and data["cases_failed"] == 0
    numbers = data["numbers"]
    for name in ("reference.png", "flat_summary.png", "flat_channels.png", "cone_summary.png",
                 "cone_channels.png", "flow_plane_reference_3d.png",
                 "wall_unrolled_flat_e0p5.png", "wall_circumference_cone_e0p5.png"):
        assert_png(three_d / name)
    for name in ("results.csv", "reference_bins.csv", "reference_profiles.csv",
                 "circumference.csv", "channel.csv"):
        assert rows_of(three_d / name), name
    assert len(data["findings"]) == 9 and all(data["findings"])
    ref = numbers["reference"]
    assert abs(ref["fill_mass_diff_pct"]) < 1.0 and abs(ref["rate_diff_pct"]) < 5.0
    assert ref["loads"]["filling"]["rms_above_lip_pct"] < 5.0
    assert ref["loads"]["filling"]["max_over_min_largest"] < 1.05
    assert ref["three_d"]["flow_mode_by_sector"] == ["mass"] * 12
    assert len(ref["plane"]["heights"]) == 4
    for r in rows_of(three_d / "results.csv"):
        assert float(r["mass_balance_error"]) < 1e-9, r["case"]
    circ = rows_of(three_d / "circumference.csv")
    for case, part in (("flat_e0", "bin wall"), ("cone_e0", "hopper"),
                       ("flat_e0p5", "bin wall")):
        rest = [float(r["max_over_min"]) for r in circ if r["case"] == case and
                r["stage"] == "filling" and r["loaded"] == "True" and r["part"] == part]
        assert len(rest) >= 3 and max(rest) < 1.05, (case, rest)
    # the centred cone's one bin-wall bin, just above the transition, carries 9 % of the
    # stage's largest pressure (164 Pa) and is round within 9 % (measured 1.086)
    rest = [float(r["max_over_min"]) for r in circ if r["case"] == "cone_e0" and
            r["stage"] == "filling" and r["part"] == "bin wall"]
    assert len(rest) == 1 and rest[0] < 1.1
    ecc = numbers["eccentric"]
    assert ecc["flat_e0"]["circumference"]["early_discharge"]["bin_wall"]["largest"] < 1.05
    assert ecc["flat_e0p5"]["circumference"]["early_discharge"]["bin_wall"]["largest"] > 1.2
    calls = ecc["cone_e0p5"]["flow_mode_by_sector"]
    assert calls[0] == "mass" and calls[6] == "funnel"       # 0 deg: the outlet's side


def test_three_d_study_measures_the_channel(three_d):
    """The flow channel per window of the discharge of each 3D case (``channel.csv``, from
    the runs' ``channel_windows.csv``): off centre (the flat silo, e/R = 0.5) it touches the
    wall on the outlet's side at every plane of every window's band (contact angle 0) with its
    centre on that side (measured theta_c 49.5 deg, e_c/R 0.53 over 3 windows); centred it does not lean (e_c/R below 0.1, contact at no more than a plane);
    the centred cone flows at the whole wall (mass flow, theta_c 180)."""
    rows = rows_of(three_d / "channel.csv")
    assert {r["case"] for r in rows} == {"flat_e0", "flat_e0p5", "cone_e0", "cone_e0p5"}
    ecc = study_json(three_d)["numbers"]["eccentric"]
    off = ecc["flat_e0p5"]["channel"]
    assert off["heights"] >= 4 and off["touching"] == off["heights"]
    assert 10.0 < off["theta_c_deg"] < 180.0 and off["e_c_over_R"] > 0.2
    band = [r for r in rows if r["case"] == "flat_e0p5" and r["in_band"] == "True"]
    assert off["source"] == "windows" and off["windows"] >= 3
    assert {r["source"] for r in rows} == {"windows"}
    assert len(band) == off["heights"]            # every window's band, pooled
    assert all(abs(float(r["contact_angle_deg"])) < 1e-6 for r in band)
    assert all(float(r["centroid_x_m"]) > 0.0 for r in band)
    centred = ecc["flat_e0"]["channel"]
    assert centred["e_c_over_R"] < 0.1 and centred["touching"] <= 1
    assert ecc["cone_e0"]["channel"]["theta_c_deg"] == 180.0
    assert ecc["cone_e0"]["channel"]["whole_wall"] == ecc["cone_e0"]["channel"]["heights"]


def test_three_d_reference_compares_the_loaded_bins_only(tmp_path):
    """The reference's wall pressure, 3D against the section, over the bins that carry at
    least ``loaded_fraction`` of the stage's largest section pressure: constructed tables of
    four bins, the 3D mean 2 % above the section's in the three loaded ones and 1,000 times
    it in a bin at the surface that carries 1 Pa of 1,000 (what the 50 % stage of the default
    run showed: 172,642 %); the RMS above the lip's bin 2 %, the largest ratio around that of
    the loaded bins, and the surface bin still in the rows (flagged)."""
    study = load("three_d")
    s = np.array([0.0, 0.1, 0.2, 0.3])
    sec = np.array([800.0, 1000.0, 600.0, 1.0])
    theta = np.arange(12) * 30.0

    def table(path, rows, columns):
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(columns)
            w.writerows(rows)

    d3, d2 = tmp_path / "three_d", tmp_path / "section"
    d3.mkdir(), d2.mkdir()
    rows = []
    for k in range(4):
        mean = sec[k] * (1000.0 if k == 3 else 1.02)
        for t in theta:
            wobble = 1.0 + (0.5 if k == 3 else 0.01) * math.cos(math.radians(t))
            rows.append(["filling", "wall", s[k], 0.5, s[k] + 0.05, t, 1, mean * wobble])
    table(d3 / "wall_pressure.csv", rows,
          ["stage", "wall", "s_m", "r_m", "z_m", "theta_deg", "segment", "p_n_Pa"])
    table(d2 / "wall_pressure.csv", [["filling", "wall", s[k], s[k] + 0.05, sec[k]]
                                     for k in range(4)],
          ["stage", "wall", "s_m", "z_m", "p_n_Pa"])
    rows, numbers = study.reference_bins({"run_dir": str(d3)}, {"run_dir": str(d2)}, 0.05)
    n = numbers["filling"]
    assert n["loaded_bins"] == 3
    assert n["rms_above_lip_pct"] == pytest.approx(2.0, abs=1e-6)
    assert n["max_over_min_largest"] == pytest.approx(1.01 / 0.99, abs=1e-4)
    assert [r["loaded"] for r in rows] == [True, True, True, False]
    assert rows[3]["diff_pct"] == pytest.approx(99900.0)


def test_three_d_study_reads_window_tables_of_every_version(tmp_path):
    """``three_d.window_channels`` reads a run's ``channel_windows.csv`` per window (the rows
    of each window together, its start and end); a table written before the outline's
    extent was measured (without ``x_min_m`` ... ``y_max_m``) reads with NaN there."""
    from fipy_hopper import io as fio

    study = load("three_d")
    old = [c for c in fio.CHANNEL_WINDOWS_COLUMNS if not c.endswith(("_min_m", "_max_m"))]
    assert len(old) == len(fio.CHANNEL_WINDOWS_COLUMNS) - 4
    rows = [[w, 0.1 * (w - 1), 0.1 * w, 50] + [z] + [1.0] * (len(old) - 5)
            for w in (1, 2) for z in (0.1, 0.2, 0.3)]
    with open(tmp_path / "channel_windows.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(old)
        writer.writerows(rows)
    windows = study.window_channels(tmp_path)
    assert [(t0, t1) for t0, t1, _ in windows] == [(0.0, 0.1), (0.1, 0.2)]
    for _, _, prof in windows:
        np.testing.assert_array_equal(prof.z, [0.1, 0.2, 0.3])
        assert np.all(prof.theta_c == 1.0) and np.all(np.isnan(prof.x_min))
    assert study.window_channels(tmp_path / "nowhere") == []


def test_three_d_study_reads_the_channel_of_a_snapshot_as_the_model_does(tmp_path):
    """The study reads a written 3D snapshot (``space.output.SpaceFieldWriter``: the whole
    silo, mirror images included) back to the nodes' downward speed and material and finds
    the channel :func:`fipy_hopper.space.channel.model_channel` finds on the state it was
    written from, to round-off: the flat-bottomed silo's grid (the half y >= 0, 2 cm), every
    open cell full to 0.26 m, the nodes moving down in EN 1991-4's G = 0.6 channel."""
    from types import SimpleNamespace

    from fipy_hopper import theory
    from fipy_hopper.space import channel as ch
    from fipy_hopper.space.boundary import SiloBoundary
    from fipy_hopper.space.grid import build_grid
    from fipy_hopper.space.output import SpaceFieldWriter

    study = load("three_d")
    b = SiloBoundary.from_profile(((0.06, 0.0), (0.14, 0.0), (0.14, 0.4)), 0.26, 0.04, 20.0)
    g = build_grid(b, 0.02, 1.0, 0.0, "auto")
    R = b.radius
    en = theory.en1991_eccentric_channel(R, 0.6, math.tan(math.radians(15.0)), 30.0)
    Z, Y, X = np.meshgrid(g.z_nodes, g.y_nodes, g.x_nodes, indexing="ij")
    v = np.zeros((3,) + Z.shape)
    v[2] = -np.where(np.hypot(X - en.e_c, Y) < 0.6 * R, 1.0, -0.01) * (1.0 + Z)
    alpha = np.where(g.kappa > 0, 1.0, 0.0)
    alpha[g.centres(2) > 0.26] = 0.0
    state = SimpleNamespace(v=v, alpha=alpha, sigma=np.zeros(alpha.shape + (6,)),
                            eps_p=np.zeros_like(alpha), loose=np.zeros_like(alpha),
                            t=0.5, step=10, stage="discharge")
    model = SimpleNamespace(grid=g, boundary=b)
    path = SpaceFieldWriter(tmp_path, model).write(state, t_open=0.0)
    read = study.snapshot_channel(path, R, 0.0)
    direct = ch.model_channel(model, state)
    assert len(read.z) >= 12
    np.testing.assert_allclose(read.z, direct.z, atol=1e-12)
    for name in ("area", "theta_c", "contact_angle", "r_c", "e_c"):
        np.testing.assert_allclose(getattr(read, name), getattr(direct, name), rtol=1e-9,
                                   atol=1e-12, err_msg=name)
    assert np.all(np.abs(read.r_c - 0.6 * R) < g.h)


def test_three_d_study_estimates_its_default_from_the_settings():
    """The default setting's cases and their cost by ``space.estimate`` (nothing run): the
    reference in 3D (1 cm, a quarter) and its section, each family at e/R = 0, 0.25, 0.5,
    0.75 (2 cm, a quarter centred, else a half, H/D = 2; the offsets whole cells); a few hours
    on two cores at most (estimated 17,100 s on one thread)."""
    study = load("three_d")
    setup = study.setup()
    names = [c["name"] for c in setup["cases"]]
    assert names == ["reference_3d", "reference_section", "flat_e0", "flat_e0p25",
                     "flat_e0p5", "flat_e0p75", "cone_e0", "cone_e0p25", "cone_e0p5",
                     "cone_e0p75"]
    rows = {r["case"]: r for r in study.estimate(setup)}
    assert rows["reference_3d"]["grid"] == "17x17x75"
    assert rows["reference_section"]["dimensions"] == 2
    assert rows["flat_e0p75"]["cells"] == 2 * rows["flat_e0"]["cells"]
    total = sum(r.get("seconds", 0.0) for r in rows.values())
    assert 2 * 3600 < total < 6 * 3600          # about 3.3 h on one thread
    assert max(r.get("memory_GB", 0.0) for r in rows.values()) < 1.0
    config = setup["cases"][5]["config"]["hopper"]
    assert config["outlet_offset"] == pytest.approx(0.24)    # e/R = 0.75 of a 0.32 m radius
    # every offset a whole number of cells (the outlet's edge faces: the module docstring)
    assert [c["params"]["outlet_offset_cells"] for c in setup["cases"][2:6]] == [0, 4, 8, 12]
    opts = setup["options"]
    assert 2.0 <= opts["fill_level"] / opts["bin_diameter"] <= 3.0


def test_envelope_estimates_its_default_from_the_settings(capsys):
    """``envelope.py --estimate`` (nothing run): a line per case of the default's twelve
    (three offsets, mu_w and phi each at both extremes) with its grid, memory and time, and the
    total (estimated 552 s on one thread); a centred case (a quarter) has half the cells of an
    off-centre one (a half)."""
    study = load("envelope")
    assert study.main(["--estimate"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 13 and lines[-1].startswith("all: about ")
    assert all(" cubes (" in line and " s on one thread" in line for line in lines[:-1])
    rows = load("three_d").estimate(study.setup())
    total = sum(r["seconds"] for r in rows)
    assert 60 < total < 3600
    assert rows[0]["cells"] * 2 == rows[-1]["cells"]


def test_envelope_runs_offsets_and_material_extremes(root):
    """``envelope.py --quick``: a flat-bottomed square bin (2 cm) with its outlet centred and
    half-way to its wall, each with mu_w and phi both at their lower and both at their upper
    characteristic values (four cases, a Dask sweep run serially): every case finished with
    its discharge window recorded; a row of ``envelope.csv`` per patch of the floor and the
    four faces (4 sectors), each largest at least the largest at rest and each smallest at
    most the smallest at rest over the cases, named by a case and a window; EN 1991-4's K
    range and the factors in ``study.json``; the picture."""
    out = run_quick(root, "envelope")
    data = study_json(out)
    assert data["setting"] == "quick" and data["cases"] == 4
    numbers = data["numbers"]
    assert numbers["cases_failed"] == 0
    assert numbers["K_lower_en1991"] < numbers["K_m_en1991"] < numbers["K_upper_en1991"]
    assert numbers["phi_lower_deg"] == pytest.approx(30.0 / 1.3, abs=1e-3)
    assert numbers["mu_w_upper"] == pytest.approx(1.4 * math.tan(math.radians(15.0)),
                                                  abs=1e-4)
    cases = rows_of(out / "results.csv")
    assert len(cases) == 4 and all(r["error"] == "" for r in cases)
    assert {r["offset_fraction"] for r in cases} == {"0.0", "0.5"}
    for r in cases:
        with open(pathlib.Path(r["run_dir"]) / "wall_windows.json") as fh:
            assert json.load(fh)["windows"] >= 1
    table = rows_of(out / "envelope.csv")
    walls = [r["wall"] for r in table]
    assert sorted(set(walls)) == ["floor", "x_minus", "x_plus", "y_minus", "y_plus"]
    assert all(walls.count(w) % 4 == 0 for w in set(walls))
    names = {r["case"] for r in cases}
    for r in table:
        if r["p_max_Pa"] == "":                 # a patch of the floor wholly over the outlet
            assert r["wall"] == "floor"
            continue
        assert float(r["p_max_Pa"]) >= float(r["p_filling_max_Pa"]) - 1e-9
        assert float(r["p_min_Pa"]) <= float(r["p_filling_min_Pa"]) + 1e-9
        assert r["p_max_case"] in names and r["p_max_window"] in ("filling", "discharge")
        assert r["cases"] == "4"
    assert any(r["p_max_window"] == "discharge" for r in table)
    assert_png(out / "envelope.png")


# ---------------------------------------------------------------- the report
def test_stiffness_spread_runs_both_hoppers_with_and_without_the_viscosities(root):
    out = run_quick(root, "stiffness_spread")
    data = study_json(out)
    assert data["setting"] == "quick"
    numbers = data["numbers"]
    for key in ("b=0,b1=0", "b=0.5,b1=0", "b=0,b1=0.1"):
        masses = numbers[f"funnel_mass_kg[{key}]"]
        assert len(masses) == 2 and all(m > 0 for m in masses.values())
        assert 0 <= numbers[f"funnel_mass_spread_pct[{key}]"] < 50
        for stage in ("filling", "early_discharge", "discharge_envelope"):
            assert math.isfinite(numbers[f"reference_wall_l2_pct[{key}|{stage}]"])
    rows = rows_of(out / "results.csv")
    assert {(r["grid_viscosity"], r["bulk_viscosity"]) for r in rows} == {
        ("0.0", "0.0"), ("0.5", "0.0"), ("0.0", "0.1")}
    assert all(r["error"] == "" for r in rows)
    assert_png(out / "stiffness_spread.png")


def test_report_is_generated_from_the_outputs(root, flow_map, discharge, wall, convergence,
                                              robustness, tmp_path):
    assert load("element_tests").main(["--out", str(root / "element_tests"),
                                       "--n-steps", "20"]) == 0
    make_report = load("make_report")
    report = tmp_path / "REPORT.md"
    assert make_report.main(["--root", str(root), "--out", str(report)]) == 0
    text = report.read_text()
    # every study run here is reported; only the Lagrangian comparison (exercised in
    # tests/test_lagrangian.py) may be listed as missing
    if "## Missing studies" in text:
        missing = text.split("## Missing studies", 1)[1]
        for name in ("flow_mode_map", "discharge_rate", "wall_pressure", "convergence",
                     "robustness", "element_tests"):
            assert f"- `{name}`:" not in missing, name
    for title in ("Jenike", "outlet diameter", "Wall pressure", "Convergence", "Robustness",
                  "element tests"):
        assert title in text, title
    assert "agreement fraction 1.00" in text
    assert "Quick setting" in text
    links = [line.split("](")[1].rstrip(")") for line in text.splitlines()
             if line.startswith("![")]
    assert len(links) >= 10
    for link in links:
        assert_png(report.parent / link)

    partial = tmp_path / "partial"
    shutil.copytree(flow_map, partial / "flow_mode_map",
                    ignore=shutil.ignore_patterns("cases"))
    result = make_report.build(partial, tmp_path / "partial.md", copy=False)
    assert result["present"] == ["flow_mode_map"]
    assert set(result["missing"]) == {"plane_flow", "discharge_rate", "wall_pressure",
                                      "convergence",
                                      "discharge_dynamics", "stiffness_spread",
                                      "robustness", "funnel_channel", "grain_size",
                                      "shear_band", "wall_zone",
                                      "element_tests",
                                      "lagrangian_vs_eulerian", "arching", "geometries",
                                      "three_d", "envelope", "eccentric"}
    assert "python studies/robustness.py" in (tmp_path / "partial.md").read_text()


def test_report_rewrites_one_study_and_keeps_the_others(wall, tmp_path):
    """``--only wall_pressure``: the committed report's wall-pressure section and overview row
    are rewritten from the outputs (here the quick study's), every other study's are kept
    as they were, character for character; a study without outputs is refused before
    anything is written."""
    make_report = load("make_report")
    committed = (STUDIES / "REPORT.md").read_text()
    root = tmp_path / "root"
    root.mkdir()
    (root / "wall_pressure").symlink_to(wall)
    report = tmp_path / "REPORT.md"
    report.write_text(committed)
    with pytest.raises(FileNotFoundError, match="arching"):
        make_report.build(root, report, copy=False, only=["wall_pressure", "arching"])
    assert report.read_text() == committed
    assert make_report.main(["--root", str(root), "--out", str(report), "--no-copy",
                             "--only", "wall_pressure"]) == 0
    before = make_report.report_parts(committed)
    after = make_report.report_parts(report.read_text())
    missing = (committed.split("## Missing studies", 1)[1].split("\n## ", 1)[0].count("\n- `")
               if "## Missing studies" in committed else 0)
    assert set(after) == set(before)
    assert len(before) == len(make_report.STUDIES) + 1 - missing    # element tests beside
    for name in before:
        assert (after[name] == before[name]) == (name != "wall_pressure"), name
    assert "Smoothness of p_n" in "\n".join(after["wall_pressure"][1])
    assert "setting **quick**" in "\n".join(after["wall_pressure"][1])


def test_the_report_says_what_moved_and_why(tmp_path):
    """Against a previous headline in which one claim had another number and one was
    explained: the moved claim with its explanation, an unexplained one flagged, one whose
    study has the previous commit marked not rerun, the others unchanged (the committed
    report's own claims)."""
    make_report = load("make_report")
    report = (STUDIES / "REPORT.md").read_text(encoding="utf-8")
    current = json.loads((STUDIES / "headline.json").read_text(encoding="utf-8"))
    previous = json.loads(json.dumps(current))
    for claim in previous["claims"][:-1]:
        claim["study_commit"] = "0000000"       # rerun since; the last one was not
    a, b = previous["claims"][0], previous["claims"][1]
    a["values"] = {"changed": True}
    a["result"] = "an older result"
    b["values"] = {"changed": True}
    (tmp_path / "prev.json").write_text(json.dumps(previous))
    (tmp_path / "moved.json").write_text(json.dumps(
        {"change": "The default law changed.", "claims": {a["key"]: "because of the law"}}))
    lines = make_report.moved_section(report, tmp_path / "prev.json", tmp_path / "moved.json")
    text = "\n".join(lines)
    assert text.startswith(make_report.MOVED_TITLE) and "The default law changed." in text
    row_a = next(line for line in lines if line.startswith(f"| {a['claim']} |"))
    assert "an older result" in row_a and "because of the law" in row_a
    row_b = next(line for line in lines if line.startswith(f"| {b['claim']} |"))
    assert "moved, not yet explained" in row_b
    assert sum("| unchanged |" in line for line in lines) == len(current["claims"]) - 3
    last = previous["claims"][-1]
    row_last = next(line for line in lines if line.startswith(f"| {last['claim']} |"))
    assert row_last.endswith("| not rerun (the previous report's runs) |")
    assert make_report.moved_section(report, tmp_path / "absent.json") == []
