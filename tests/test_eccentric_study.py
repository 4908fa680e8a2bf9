"""``studies/eccentric.py``: eccentric discharge in 3D against EN 1991-4 and AS 3774.

The quick study (``three_d.py``'s quick flat family at e/R = 0 and 0.5 and a small square
silo on a centred and an off-centre pyramid, 2 cm cubes, run serially) writes its outputs and
measures the factors; the factors of a constructed p(theta); the codes' curves on worked
values; the wall picture of a run draws the codes only for a circular silo with an
off-centre outlet.
"""

import csv
import json
import math
import pathlib
import sys

import numpy as np
import pytest

from fipy_hopper import plotting, theory
from fipy_hopper.space import pictures

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from study_files import PNG, load, rows_of  # noqa: E402


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("eccentric") / "eccentric"
    assert load("eccentric").main(["--quick", "--serial", "--out", str(out)]) == 0
    return out


# ---------------------------------------------------------------- the quick study
def test_quick_study_writes_its_outputs_and_measures_the_factors(quick):
    """Every case finished (mass balance 1e-9) with its discharge windows recorded; for
    every e/R case and stage (at rest, at 90 % left, over the windows) three heights of
    finite factors; off centre the largest pressure around the circumference over p_hf (the
    centred case's at rest) above 1 and the smallest below 1 at every height in discharge
    (measured 1.15, 1.10, 1.03 and 0.78, 0.88, 0.90 at 90 % left), EN's and AS's factors
    beside them and none for the centred case; the square silo's far over near face 1 when
    centred (the mirror images: to round-off) and not off centre (measured 0.51, 0.55 at 90 %
    left); the pictures."""
    data = json.loads((quick / "study.json").read_text())
    assert data["setting"] == "quick" and data["cases"] == 4 and data["cases_failed"] == 0
    assert data["findings"] and all(data["findings"])
    for r in rows_of(quick / "results.csv"):
        assert r["error"] == "" and abs(float(r["mass_balance_error"])) < 1e-9, r["case"]
    circ = data["numbers"]["circular"]
    assert sorted(circ) == ["flat_e0", "flat_e0p5"]
    # e/R = 0.5 is e_o = 0.25 d_c: at EN 1991-4's threshold, not above it
    assert [circ[c]["en1991_large_eccentricity"] for c in sorted(circ)] == [False, False]
    assert any("EN 1991-4 calls for its large-eccentricity case above e_o = 0.25 d_c (e/R = "
               "0.5; theory.en1991_large_eccentricity, as recalled [M]): at e/R = none of "
               "these offsets; at e/R = 0.5 its pattern is drawn for comparison only" in f
               for f in data["findings"])
    for case, n in circ.items():
        assert n["windows"] == "windows" and n["base"] == "centred"
        for stage in ("filling", "early_discharge", "discharge_windows"):
            entries = n["factors"][stage]
            assert [e["fraction"] for e in entries] == [0.25, 0.5, 0.75], (case, stage)
            for e in entries:
                for key in ("over", "under", "p_hf_Pa", "z_m"):
                    assert e[key] is not None and math.isfinite(e[key]), (case, stage, key)
                assert e["over"] >= e["under"]
            if n["e_over_R"] == 0.0:
                assert all("en" not in e for e in entries)
                continue
            for e in entries:
                assert sorted(e["en"]) == ["0.25", "0.4", "0.6"]
                assert e["en"]["0.4"][0] > 1.0 > e["en"]["0.4"][1]
                assert all(v is not None for v in e["as3774"]), (stage, e)
                if stage != "filling":
                    assert e["over"] > 1.0 > e["under"], (stage, e)
    # the channel per window of the discharge (each load window's mean field): centred no
    # contact and no offset; at e/R = 0.5 against the wall on the outlet's side (measured
    # theta_c 49.5 deg, e_c/R 0.53, contact at 0 deg, over 3 windows)
    for case, n in circ.items():
        ch = n["channel"]
        assert ch["source"] == "windows" and ch["windows"] >= 3, case
        assert ch["window_s"] == pytest.approx(0.1, abs=0.005)
        if n["e_over_R"] == 0.0:
            assert ch["theta_c_deg"] == 0.0 and abs(ch["e_c_over_R"]) < 1e-9
        else:
            assert 0.0 < ch["theta_c_deg"] < 180.0 and ch["e_c_over_R"] > 0.25
            assert abs(ch["contact_angle_deg"]) < 10.0
            assert ch["theta_c_deg_window_range"][1] - ch["theta_c_deg_window_range"][0] < 20.0
    chan = rows_of(quick / "channel.csv")
    assert {r["source"] for r in chan} == {"windows"}
    assert all(float(r["t_start_s"]) < float(r["t_s"]) for r in chan)
    rows = rows_of(quick / "circumference.csv")
    assert len(rows) == 2 * 3 * 3          # cases x stages x heights
    assert all(math.isfinite(float(r["over"])) for r in rows)
    theta = rows_of(quick / "pressure_theta.csv")
    assert len(theta) == 2 * 3 * 3 * 12     # ... x sectors
    sq = data["numbers"]["square"]
    centred, off = sq["square_e0"], sq["square_e40"]
    for stage in ("filling", "early_discharge"):
        for e in centred["stages"][stage]["heights"]:
            assert e["far_over_near"] == pytest.approx(1.0, abs=1e-6)
        for e in off["stages"][stage]["heights"]:
            assert math.isfinite(e["far_over_near"]) and abs(e["far_over_near"] - 1) > 0.05
            assert math.isfinite(e["corner_x_plus_y_plus_over_centred"])
    assert rows_of(quick / "square_faces.csv") and rows_of(quick / "square.csv")
    for name in ("circumference_e0p5.png", "factors.png", "square.png"):
        content = (quick / name).read_bytes()
        assert content[:8] == PNG and len(content) > 10_000, name


def test_quick_study_shares_three_d_s_cases():
    """The circular cases are ``three_d.py``'s flat family: the same names and the same
    configurations, default and quick (so ``--runs-from`` reads its finished runs); the
    default's cost by the estimate, a few hours on one thread."""
    eccentric, three_d = load("eccentric"), load("three_d")
    for quick in (False, True):
        mine = {c["name"]: c["config"] for c in eccentric.setup(quick=quick)["cases"]}
        theirs = {c["name"]: c["config"] for c in three_d.setup(quick=quick)["cases"]}
        flat = [n for n in mine if n.startswith("flat_")]
        assert flat == [n for n in theirs if n.startswith("flat_")]
        assert all(mine[n] == theirs[n] for n in flat)
    rows = three_d.estimate(eccentric.setup())
    total = sum(r["seconds"] for r in rows)
    assert 2 * 3600 < total < 5 * 3600             # estimated 11,300 s
    with pytest.raises(TypeError, match=r"unknown options \['bogus'\]"):
        eccentric.setup(bogus=1)


# ---------------------------------------------------------------- pure measures
def test_factors_of_a_constructed_pressure_around_the_wall():
    """max and min of p(theta) / p_ref and where, NaN sectors ignored; NaN without a
    positive reference or a finite sector; the bin nearest each fraction of the fill."""
    study = load("eccentric")
    theta = np.array([0.0, 90.0, 180.0, 270.0, 45.0])
    p = np.array([60.0, 80.0, 120.0, 100.0, np.nan])
    f = study.extreme_factors(p, 80.0, theta)
    assert f == {"over": 1.5, "under": 0.75, "theta_over": 180.0, "theta_under": 0.0}
    assert math.isnan(study.extreme_factors(p, 0.0)["over"])
    assert math.isnan(study.extreme_factors([np.nan, np.nan], 1.0)["under"])
    z = np.array([0.0, 0.1, 0.3, 0.5, 0.7, 0.9])
    wall = np.array([False, True, True, True, True, True])
    picks = study.height_bins(z, wall, 0.0, 1.0, (0.25, 0.5, 0.75))
    assert picks == [(0.25, 0.25, 2), (0.5, 0.5, 3), (0.75, 0.75, 4)]


def test_the_codes_curves_on_worked_values():
    """EN 1991-4's pattern as the code's own factors on the given p_hf: with EN's own filling
    pressure it is :func:`theory.en1991_eccentric_wall_pressure` (the worked values of
    docs/correlations.md: r = 2 m, G = 0.4, K = 0.5, 9 kN/m^3, z = 10 m: p_hce 5.59 kPa,
    p_hae 27.92 kPa), and twice the filling pressure doubles it; AS 3774's worked values
    (e_o = 1 m, d_c = 4 m, phi = 30 deg, p_nf = 10 kPa): +1500 Pa opposite the outlet,
    -2250 Pa on the near side; nothing for a centred outlet or without codes."""
    mu, phi = 0.491, 33.6
    codes = {"offset": 1.0, "radius": 2.0, "surface": 11.0, "K": 0.5, "mu": mu,
             "phi_deg": phi, "gamma": 9000.0, "G": 0.4}
    theta = np.array([0.0, 180.0])
    p_hf = float(theory.en1991_filling_vertical_walls(10.0, 9000.0, 4.0, 0.5, mu).p_h)
    assert p_hf == pytest.approx(16760, abs=10)
    ch = theory.en1991_eccentric_channel(2.0, 0.4, mu, phi)
    at = np.array([0.0, 1.5 * float(ch.theta_c), 180.0])
    curves = pictures.code_curves(at, 1.0, p_hf, 10_000.0, codes)
    en = curves["EN 1991-4, G = 0.4"]
    expected = theory.en1991_eccentric_wall_pressure(at, 10.0, 9000.0, 2.0, 0.4, 0.5, mu,
                                                     phi).p_h
    np.testing.assert_allclose(en, expected, rtol=1e-12)
    np.testing.assert_allclose(en, [5590, 27920, p_hf], atol=10)
    twice = pictures.code_curves(at, 1.0, 2 * p_hf, 10_000.0, codes)["EN 1991-4, G = 0.4"]
    np.testing.assert_allclose(twice, 2 * en, rtol=1e-12)
    as_codes = {**codes, "phi_deg": 30.0, "G": ()}
    h_D = 3.0 * math.tan(math.radians(30.0))           # (0.5 d_c + e_o) tan phi
    curves = pictures.code_curves(theta, h_D, p_hf, 10_000.0, as_codes)
    assert list(curves) == ["AS 3774"]
    np.testing.assert_allclose(curves["AS 3774"], [10_000 - 2250, 10_000 + 1500], rtol=1e-12)
    assert pictures.code_curves(theta, 1.0, p_hf, 1e4, {**codes, "offset": 0.0}) == {}
    assert pictures.code_curves(theta, 1.0, p_hf, 1e4, None) == {}


# ---------------------------------------------------------------- the run's wall picture
def _wall_csv(path):
    """A constructed ``wall_pressure.csv`` of a circular silo: three bins up a bin wall,
    12 sectors, at rest and in discharge."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["stage", "s_m", "z_m", "segment", "theta_deg", "p_n_Pa"])
        for stage, scale in (("filling", 1.0), ("early_discharge", 1.2)):
            for k, z in enumerate((0.05, 0.15, 0.25)):
                for t in range(0, 360, 30):
                    w.writerow([stage, z + 0.1, z, 1, float(t),
                                scale * (1000.0 - 3000.0 * z) * (1 + 0.1 * math.cos(
                                    math.radians(t)))])
    return path


def _labels(fig):
    return [t.get_text() for ax in fig.axes if ax.get_legend()
            for t in ax.get_legend().get_texts()]


def test_the_wall_picture_draws_the_codes_only_off_centre(tmp_path, quick):
    """:func:`pictures.circumference_figure`: with an off-centre circular silo's codes the
    discharge panel names EN 1991-4's pattern and AS 3774's rule in its legend and draws a
    curve of each per height on the bin wall (3 heights: 6 more lines), the panel at rest
    none; a centred outlet, or no codes, none. The run's own codes
    (:func:`plotting.eccentric_codes`): a dict for the quick study's off-centre circular run,
    None for its centred one and for the square silo (a rectangular plan)."""
    import matplotlib.pyplot as plt

    path = _wall_csv(tmp_path / "wall_pressure.csv")
    codes = {"offset": 0.08, "radius": 0.16, "surface": 0.3, "bin_foot": 0.0, "K": 0.5,
             "mu": math.tan(math.radians(15.0)), "phi_deg": 30.0, "gamma": 14715.0, "G": 0.4}
    figs = {name: pictures.circumference_figure(path, codes=c) for name, c in (
        ("off", codes), ("centred", {**codes, "offset": 0.0}), ("none", None))}
    try:
        labels = _labels(figs["off"])
        assert sum(x.startswith("EN 1991-4, G = 0.4") for x in labels) == 1
        assert sum(x.startswith("AS 3774") for x in labels) == 1
        rest, discharge = figs["off"].axes
        assert len(discharge.lines) == len(rest.lines) + 3 * 2 + 2   # curves + legend proxies
        for name in ("centred", "none"):
            assert not any(x.startswith(("EN", "AS")) for x in _labels(figs[name])), name
            assert len(figs[name].axes[1].lines) == 3
    finally:
        for fig in figs.values():
            plt.close(fig)
    cases = quick / "cases"
    found = plotting.eccentric_codes(cases / "flat_e0p5")
    assert found["offset"] == pytest.approx(0.08) and found["radius"] == pytest.approx(0.16)
    assert plotting.eccentric_codes(cases / "flat_e0") is None
    assert plotting.eccentric_codes(cases / "square_e40") is None
    png = plotting.wall_circumference(cases / "flat_e0p5", tmp_path / "circumference.png")
    assert png.read_bytes()[:8] == PNG
