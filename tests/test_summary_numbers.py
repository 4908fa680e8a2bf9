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


def test_a_flat_floor_stops_when_its_flow_has_stopped_and_reports_its_heel(tmp_path):
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
