"""The summary's and the pictures' numbers say what is true of the run they describe: no rate
over a sliver of an interval, a flat floor's heel stops the run when the flow has stopped and
is reported, a fill-only run is described by its loads at rest (coarse, short runs)."""

import math
import warnings

import numpy as np
import pytest

import fipy_hopper as fh
from fipy_hopper import diagnostics
from fipy_hopper.config import HopperConfig

SMALL = {"hopper": {"bin_diameter": 0.2, "bin_height": 0.2, "fill_height": 0.1},
         "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05},
         "run": {"output_interval": 0.02, "field_interval": 0.1, "markers_per_side": 0}}


def config(data, **run) -> HopperConfig:
    data = {k: dict(v) for k, v in data.items()}
    data["run"].update(run)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict(data)


def test_no_rate_over_a_sliver_of_an_interval(tmp_path):
    """A run that stops 1 ms after a sample (end_time 0.201 s, samples every 0.02 s): the
    last sample's interval is a few steps, over which the mass booked at a transport would
    read as a spike; its rate is not given (NaN), every other rate covers a whole interval,
    and the steady rate and the pictures leave it out."""
    summary = fh.run(config(SMALL, end_time=0.201), tmp_path / "run", threads=1)
    ts = fh.read_results(tmp_path / "run").timeseries
    t, rate = ts["t_s"], ts["discharge_rate_kg_s"]
    span = np.diff(t)
    assert span[-1] < 0.01 and math.isnan(rate[-1])
    assert np.all(span[:-1] >= 0.01) and np.all(np.isfinite(rate[:-1]))
    assert math.isfinite(summary["steady_discharge_rate_kg_s"])
    assert (tmp_path / "run" / "discharge.png").is_file()


def test_steady_rate_leaves_out_the_samples_without_a_rate():
    """The median and spread of the plateau over the finite rates only."""
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.401])
    mass = np.array([10.0, 8.5, 7.0, 5.5, 4.0, 3.99])
    rate = np.array([0.0, 15.0, 15.0, 16.0, 14.0, math.nan])
    value, spread, n = diagnostics.steady_rate(t, mass, rate)
    assert (value, n) == (15.0, 4)


def test_a_flat_floor_stops_when_its_flow_has_stopped_and_reports_its_heel(tmp_path, capsys):
    """A flat-bottomed plane silo (a slot in a flat floor) with end_time = "empty": its dead
    zones never drain, so the run ends "at_rest" (the rate below 1 % of the steady rate, the
    material at rest) long before max_time, with the heel it leaves: its mass (more than
    empty_fraction), and its surface's angle, at most the friction angle."""
    data = {"hopper": {"shape": "wedge", "bin_width": 0.3, "outlet_width": 0.06,
                       "half_angle_deg": 90.0, "bin_height": 0.2, "fill_height": 0.12},
            "numerics": {"cell_size": 0.01},
            "run": {"output_interval": 0.02, "field_interval": 1.0, "markers_per_side": 0}}
    cfg = config(data, end_time="empty", max_time=30.0)
    summary = fh.run(cfg, tmp_path / "run", threads=1, plots=False)
    assert summary["stop_reason"] == "at_rest"
    assert summary["flow_stopped_time_s"] < summary["discharge_time_s"] < 30.0
    left = summary["remaining_mass_fraction"]
    assert cfg.run.empty_fraction < left < 0.5
    assert summary["remaining_mass_kg_m"] == pytest.approx(
        left * summary["initial_mass_kg_m"], rel=1e-12)
    assert summary["flow_mode"] == "funnel"
    assert 0.0 < summary["heap_angle_deg"] <= cfg.material.friction_angle_deg
    from fipy_hopper.cli import _print_summary
    _print_summary(summary, tmp_path / "run")
    text = capsys.readouterr().out
    assert f"its surface at {summary['heap_angle_deg']:.1f} deg" in text
    assert (tmp_path / "run" / "summary.txt").read_text(encoding="utf-8") == text   # the API's


def test_the_summary_text_says_n_a_for_what_a_summary_lacks():
    """The summary's lines (``summary.txt``, the terminal's) of a summary with keys missing,
    NaN or null, and of a 3D rectangular plan's with a corner's pressure NaN: every line is
    written, what is not known reads ``n/a``."""
    from fipy_hopper.summary_text import summary_lines

    lines = summary_lines({}, "run")
    assert lines[0] == "fipy-hopper: n/a after n/a s of discharge (n/a steps, n/a s wall time)"
    assert lines[2].startswith("  flow mode              n/a (wall slip ratio n/a")
    assert lines[-1] == "  results in             run/"
    three_d = {"stop_reason": "end_time", "steady_discharge_rate_kg_s": math.nan,
               "dimensions": 3, "plan": "rectangular", "outlet_offset_m": [0.01, None],
               "filling_wall_pressure_max_over_min_largest": 1.25,
               "filling_corner_pressure_Pa": {"x_plus_y_plus": [2.0, math.nan, 5.0],
                                              "x_minus_y_plus": [None, 3.0],
                                              "x_minus_y_minus": [math.nan]},
               "discharge_envelope_corner_pressure_Pa": {"x_plus_y_plus": [None]},
               "flow_mode_by_sector": ["mass", "funnel", "none", "mass"],
               "flow_stopped_time_s": 1.5, "remaining_mass_fraction": None}
    text = "\n".join(summary_lines(three_d, "run"))
    assert "steady discharge rate  n/a kg/s" in text
    assert "up to 1.25 at rest, n/a from 90 % left" in text and "offset [0.01, n/a] m" in text
    assert "filling: the largest pressure 3 to 5 Pa over the four corners" in text
    assert "discharge envelope: the largest pressure n/a to n/a Pa" in text
    assert "flow mode by sector    mass in 2 of 3 measured sectors" in text
    assert "the flow stopped 1.5 s after the opening with n/a % of the mass left" in text


def _labels(fig) -> list:
    return [line.get_label() for ax in fig.axes for line in ax.get_lines()]


@pytest.fixture(scope="module")
def fill_only(tmp_path_factory):
    """A small cone filled and brought to rest, no discharge (end_time = 0)."""
    data = {"hopper": {"bin_diameter": 0.2, "bin_height": 0.2, "fill_height": 0.15},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05},
            "run": {"field_interval": 0.1, "markers_per_side": 0}}
    out = tmp_path_factory.mktemp("fill") / "run"
    return fh.run(config(data, end_time=0.0), out, threads=1), out


def test_a_fill_only_run_is_described_by_its_loads_at_rest(fill_only, capsys):
    """Its wall pressure is drawn against the theories at rest only (no discharge curve, no
    C_h), its stress picture's title is whole, and the terminal summary gives the loads at
    rest (the weight and what carries it, the transition's forces) rather than n/a."""
    from fipy_hopper import plotting
    from fipy_hopper.cli import _print_summary

    summary, out = fill_only
    assert summary["stop_reason"] == "filled" and summary["flow_mode"] == "none"
    labels = _labels(plotting.wall_pressure(out))
    assert any(label.startswith("Walker, cone, filling") for label in labels)
    assert not any("discharge" in label for label in labels), labels
    title = plotting.stress_pattern(out)._suptitle.get_text()
    assert "\n" in title and "mobilised friction" in title
    _print_summary(summary, out)
    text = capsys.readouterr().out
    assert (out / "summary.txt").read_text(encoding="utf-8") == text    # written by fh.run
    weight = summary["fill_weight_N"]
    assert f"{weight:.4g} N: the walls carry" in text and "weight at rest" in text
    assert f"{summary['hopper_meridional_tension_N_m']:.4g} N/m" in text
    assert "steady discharge rate" not in text


def test_the_stress_picture_tells_stress_free_material_from_empty(fill_only):
    """Material present but stress-free is drawn grey, not white: a grey layer covers exactly
    the cells holding material (alpha > 1/2) under the mobilised friction, which is masked
    where it is undefined (stress-free), so those cells show the grey; empty cells stay white;
    the legend says which is which."""
    import numpy as np
    from fipy_hopper import plotting

    _, out = fill_only
    fig = plotting.stress_pattern(out)
    ax = fig.axes[0]
    grey = [m for m in ax.collections if getattr(m.get_cmap(), "N", 0) == 1]
    assert len(grey) == 1
    snap = plotting.load_snapshot(out, plotting.snapshots(out)[-1])
    drawn = ~np.ma.getmaskarray(grey[0].get_array()).reshape(snap["alpha"].shape)
    assert np.array_equal(drawn, snap["alpha"] > 0.5)
    assert {t.get_text() for t in ax.get_legend().get_texts()} == {"material, stress-free",
                                                                  "empty"}


def test_one_K_for_both_of_janssens_curves_and_it_is_named(fill_only):
    """wall_forces.png sets the hoop force and the meridional force against Janssen with the
    same K (the one measured at the bin wall), named in both labels."""
    from fipy_hopper import plotting

    summary, out = fill_only
    labels = [label for label in _labels(plotting.wall_forces(out))
              if label.startswith("Janssen")]
    K = summary["wall_k_bin"]
    assert len(labels) == 2 and all(f"K = {K:.2f} measured at the bin wall" in label
                                    for label in labels), labels


def test_an_inserts_pressure_is_drawn_along_the_insert_on_its_own_axis(tmp_path):
    """A hopper with an insert on the axis, filled: the insert's pressure is on a panel of
    its own, against the arc length along the insert (to its length), not on the wall's."""
    from fipy_hopper import plotting

    data = {"hopper": {"shape": "profile", "fill_level": 0.3,
                       "wall": [[0.03, 0.0], [0.15, 0.2], [0.15, 0.4]],
                       "inserts": [{"outline": [[0.0, 0.1], [0.05, 0.15], [0.0, 0.2]]}]},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05},
            "run": {"field_interval": 0.1, "markers_per_side": 0}}
    cfg = config(data, end_time=0.0)
    fh.run(cfg, tmp_path / "run", threads=1)
    fig = plotting.wall_pressure(tmp_path / "run")
    panels = {ax.get_title(): ax for ax in fig.axes}
    inserts = panels["Inserts (no closed form)"]
    assert [line.get_label() for line in inserts.get_lines()] == ["insert_1, at rest"]
    s = inserts.get_lines()[0].get_xdata()
    assert 0.0 < s.max() <= cfg.boundary.chain("insert_1").length
    wall = next(ax for title, ax in panels.items() if title.startswith("Wall pressure"))
    assert not any("insert" in line.get_label() for line in wall.get_lines())
