"""The mass/funnel call from the slip of the material along the hopper wall (FlowModeRule).

The rule's measure on constructed velocity fields (Eulerian contact entries and Lagrangian
wall stations), and its calls on coarse discharges (1 cm cells, 0.8 s): a steep smooth cone
(mass), the same cone with phi_w = phi (funnel: the wall cannot slide), a shallow rough wedge
(funnel).
"""

import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from fipy_hopper import diagnostics
from fipy_hopper.config import HopperConfig
from fipy_hopper.diagnostics import FlowModeRule, wall_slip, wall_slip_measures
from fipy_hopper.lagrangian import LagrangianModel
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_discharge import discharge  # noqa: E402
from test_wedge import wedge  # noqa: E402


def cone(half_angle=20.0, cell=0.01, formulation="eulerian"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06,
                       "half_angle_deg": half_angle, "bin_height": 0.17, "fill_height": 0.15},
            "wall": {"friction_angle_deg": 20.0},
            "numerics": {"cell_size": cell, "formulation": formulation}})


def test_wall_slip_weighs_each_contact_by_its_load_and_its_length():
    """Three loaded contacts of one stretch at s = 0, 1, 3 (lengths 0.5, 1.5, 1 between the
    midpoints), a fourth unloaded, a fifth on another stretch: S = sum N u/U / sum N."""
    load = np.array([1.0, 3.0, 2.0, 0.0, 5.0])
    slip = np.array([0.5, 0.1, 1.0, 9.0, 0.0])
    axis = np.array([1.0, 1.0, 2.0, 1.0, 1.0])
    s = np.array([0.0, 1.0, 3.0, 2.0, 9.0])
    stretch = np.array([0, 0, 0, 0, 1])
    ratio, fraction = wall_slip(load, slip, axis, s, stretch, FlowModeRule(slip_ratio=0.2))
    assert ratio[0] == pytest.approx((1.0 * 0.5 + 3.0 * 0.1 + 2.0 * 0.5) / 6.0, rel=1e-12)
    assert fraction[0] == pytest.approx((0.5 + 1.0) / 3.0, rel=1e-12)
    assert ratio[1] == 0.0 and fraction[1] == 0.0


def test_hopper_stretches_are_the_sloping_wall_segments():
    """A stretch of hopper wall is a wall segment that is not vertical (a slope or a floor),
    one label each in the table's order; the bin wall, the tubes, inserts and convex corners
    (-1) belong to none."""
    cfg = HopperConfig.from_dict({"hopper": {
        "shape": "profile", "wall": [[0.03, 0.0], [0.06, 0.1], [0.15, 0.2], [0.15, 0.5]],
        "fill_level": 0.4, "inserts": [{"outline": [[0.0, 0.3], [0.05, 0.25], [0.0, 0.2]]}]},
        "numerics": {"cell_size": 0.01}})
    rows = diagnostics.hopper_rows(cfg.boundary)
    assert rows.tolist() == [1, 2]                     # tube 0, two slopes, then the bin wall
    segment = np.array([1, 1, 3, 2, -1, 0, 4])
    assert diagnostics.hopper_stretches(segment, rows).tolist() == [0, 0, -1, 1, -1, -1, -1]


def _loaded_eulerian(half_angle=20.0):
    """A filled coarse cone whose hopper contacts all press on the wall (unit impulse along
    the normal) and whose nodes all move straight down at 1 m/s."""
    model = HopperModel(cone(half_angle))
    state = model.initial_state()
    state.v[1] = -1.0
    s, normals, segment = model.wall_entries()
    state.wall_impulse[:] = -np.where((segment == 1)[:, None], normals, 0.0)
    return model, state, s, segment


def test_measure_on_a_vertical_plug_flow_is_the_cos_of_the_half_angle():
    """Everything falling at U: the slip down the cone wall is U cos(theta) at every contact,
    so S = cos(theta) and the whole wall slides (theta = 20 deg: mass)."""
    model, state, _, _ = _loaded_eulerian(20.0)
    before = state.copy()
    ratio, fraction, per_stretch, profile = wall_slip_measures(model, state)
    assert ratio == pytest.approx(math.cos(math.radians(20.0)), rel=1e-12)
    assert fraction == 1.0 and len(per_stretch) == 1
    assert np.allclose(profile[:, 3], math.cos(math.radians(20.0)), rtol=1e-12)
    assert np.all(np.diff(profile[:, 0]) >= 0) and np.all(profile[:, 2] >= 0.0)
    assert diagnostics.classify_flow_mode(ratio) == "mass"
    for key, value in before.__dict__.items():      # the measurement read the state only
        assert np.array_equal(getattr(state, key), value), key


def test_measure_of_a_wall_that_sticks_on_its_upper_half():
    """The hopper contacts above mid-height of the cone held at rest: the wall slides on its
    lower half only (by length) and S is the lower half's share of the load times cos."""
    model, state, s, segment = _loaded_eulerian(20.0)
    j, i, _, _ = model.contact_list
    z = model.grid.z_nodes[j]
    upper = (segment == 1) & (z > 0.5 * model.cfg.hopper.cone_height)
    state.v[:, j[upper], i[upper]] = 0.0
    state.v[1, :, 0] = -1.0                          # the axis still moves
    ratio, fraction, _, _ = wall_slip_measures(model, state)
    hopper = segment == 1
    lower = hopper & ~upper
    assert ratio == pytest.approx(lower.sum() / hopper.sum()
                                  * math.cos(math.radians(20.0)), rel=1e-12)
    x = np.sort(s[hopper])
    edges = np.concatenate([x[:1], 0.5 * (x[1:] + x[:-1]), x[-1:]])
    sliding = np.isin(x, s[lower])
    assert fraction == pytest.approx(np.diff(edges)[sliding].sum() / (x[-1] - x[0]), rel=1e-12)
    assert 0.35 < fraction < 0.65
    # a wall held everywhere: funnel
    state.v[:, j[hopper], i[hopper]] = 0.0
    assert wall_slip_measures(model, state)[0] == 0.0
    assert diagnostics.classify_flow_mode(0.0) == "funnel"


def test_lagrangian_stations_measure_the_same_plug_flow():
    """On the Lagrangian mesh the cone's wall stations see the nodes on the wall: falling at
    U they slip at U cos(theta) against an axis falling at U (stations of half an element
    that hold no node have no slip, NaN, and are left out)."""
    model = LagrangianModel(cone(20.0, formulation="lagrangian"))
    state = model.initial_state()
    state.v[:, 1] = -1.0
    s, normals, segment = model.wall_entries()
    state.wall_impulse[:] = -np.where((segment == 1)[:, None], normals, 0.0)
    slip, axis = model.contact_slip(state)
    cone_stations = segment == 1
    assert np.isfinite(slip[cone_stations]).mean() > 0.5
    ratio, fraction, _, _ = wall_slip_measures(model, state)
    assert ratio == pytest.approx(math.cos(math.radians(20.0)), rel=1e-9)
    assert fraction == 1.0
    assert np.allclose(axis[cone_stations], 1.0)


@pytest.fixture(scope="module")
def steep_cones():
    """A 15 deg cone discharged with a smooth wall (phi_w = 5 deg) and with phi_w = phi."""
    return {wall: discharge(15.0, wall)[2] for wall in (5.0, 30.0)}


def test_steep_smooth_cone_slides_along_its_whole_wall(steep_cones):
    s = steep_cones[5.0]
    assert s["flow_mode"] == "mass"
    assert s["wall_slip_fraction"] == 1.0 and s["wall_slip_ratio"] > 0.6


def test_steep_cone_with_phi_w_equal_to_phi_is_funnel_flow(steep_cones):
    """At phi_w = phi the material yields inside before the wall slides: only the lightly
    loaded contacts in front of the wall's staircase slip, S stays far below the threshold
    (the old near-wall index, which reads the first cells' shear, said 0.64: mass)."""
    s = steep_cones[30.0]
    assert s["flow_mode"] == "funnel"
    assert s["wall_slip_ratio"] < 0.5 * FlowModeRule().slip_ratio
    assert s["wall_slip_fraction"] < 0.6


def test_shallow_rough_wedge_is_funnel_flow():
    sim = Simulation(HopperModel(wedge(wall_deg=25.0, half_angle_deg=60.0,
                                       run={"end_time": 0.8})), progress=False)
    sim.run()
    s = sim.summary()
    assert s["flow_mode"] == "funnel"
    assert s["wall_slip_ratio"] < 0.05 and s["wall_slip_fraction"] < 0.1
    assert s["stagnant_fraction"] > 0.2


def test_the_slip_measurement_does_not_change_the_run(monkeypatch):
    """A short coarse discharge with the wall-slip measurement at every sample and one without
    it (the measurement replaced by NaNs) end in the same state, to the bit."""
    def run():
        sim = Simulation(HopperModel(cone(30.0)), end_time=0.1, progress=False)
        sim.run()
        return sim

    measured = run()
    assert np.isfinite(measured.record.wall_slip_ratio[1:]).all()
    monkeypatch.setattr(diagnostics, "wall_slip_measures",
                        lambda *a, **k: (math.nan, math.nan, np.zeros(0), np.zeros((0, 4))))
    plain = run()
    assert np.isnan(plain.record.wall_slip_ratio).all()
    for key, value in measured.state.__dict__.items():
        assert np.array_equal(getattr(plain.state, key), value), key
