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
    ratio, fraction, per_stretch, _, profile = wall_slip_measures(model, state)
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
    ratio, fraction, _, _, _ = wall_slip_measures(model, state)
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
    ratio, fraction, _, _, _ = wall_slip_measures(model, state)
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
                        lambda *a, **k: (math.nan, math.nan, np.zeros(0), np.zeros(0),
                                         np.zeros((0, 4))))
    plain = run()
    assert np.isnan(plain.record.wall_slip_ratio).all()
    for key, value in measured.state.__dict__.items():
        assert np.array_equal(getattr(plain.state, key), value), key


# ---------------------------------------------------------------- the overall call
TWO_SLOPES = {"hopper": {"shape": "profile", "fill_level": 0.4,
                         "wall": [[0.03, 0.0], [0.06, 0.1], [0.15, 0.2], [0.15, 0.5]]},
              "numerics": {"cell_size": 0.01}}


def _calls(samples, fractions=None, data=TWO_SLOPES):
    cfg = HopperConfig.from_dict(data)
    samples = [list(map(float, row)) for row in samples]
    fractions = samples if fractions is None else fractions
    stretches = diagnostics.stretch_calls(cfg, samples, fractions)
    return stretches, diagnostics.flow_call(stretches)


def test_the_overall_call_is_the_rule_applied_to_the_stretches_calls():
    """Mass flow when every hopper stretch's S (its median over the window) reaches 0.2.
    Constructed series where the two orders differ: each stretch slides in two samples of
    three but not in the same ones, so the median of the per-sample minimum is 0.1 (funnel)
    while every stretch's median is 0.5 (mass): the call is mass, as every stretch says, and
    the headline ratio is the smallest stretch median."""
    samples = [[0.5, 0.1], [0.1, 0.5], [0.5, 0.5]]
    stretches, call = _calls(samples)
    assert float(np.median(np.min(samples, axis=1))) == 0.1       # min, then median
    assert [st["slip_ratio"] for st in stretches] == [0.5, 0.5]   # median, then min
    assert [st["call"] for st in stretches] == ["mass", "mass"]
    assert call["flow_mode"] == "mass" and call["wall_slip_ratio"] == 0.5
    # one stretch resting against its wall: funnel, its S the headline's
    stretches, call = _calls([[0.5, 0.1], [0.6, 0.15], [0.7, 0.12]],
                             [[1.0, 0.1], [1.0, 0.3], [1.0, 0.2]])
    assert [st["call"] for st in stretches] == ["mass", "funnel"]
    assert call["flow_mode"] == "funnel"
    assert call["wall_slip_ratio"] == 0.12 and call["wall_slip_fraction"] == 0.2


def test_a_stretch_without_samples_is_unknown_and_never_contradicts():
    """A stretch not measured in any sample of the window says ``"unknown"`` with no slip
    ratio and does not enter the overall call; with no stretch measured (no sample in the
    window: a run too short) everything is unknown."""
    nan = math.nan
    stretches, call = _calls([[0.5, nan], [0.6, nan]])
    assert [st["call"] for st in stretches] == ["mass", "unknown"]
    assert math.isnan(stretches[1]["slip_ratio"]) and stretches[1]["samples"] == 0
    assert call["flow_mode"] == "mass" and call["wall_slip_ratio"] == 0.55
    stretches, call = _calls([])
    assert [st["call"] for st in stretches] == ["unknown", "unknown"]
    assert call["flow_mode"] == "unknown" and math.isnan(call["wall_slip_ratio"])


def test_a_sliver_shorter_than_a_cell_enters_no_overall_call():
    """A 1.4 mm first segment at the lip (45 deg under a 31 deg cone; shorter ones are
    refused): listed with its own calls but not counted, so neither the simulated call nor
    Jenike's overall call is its."""
    data = {"hopper": {"shape": "profile", "fill_level": 0.4, "wall": [
        [0.03, 0.0], [0.031, 0.001], [0.15, 0.2], [0.15, 0.5]]},
        "wall": {"friction_angle_deg": 15.0}, "material": {"friction_angle_deg": 40.0},
        "numerics": {"cell_size": 0.01}}
    stretches, call = _calls([[0.05, 0.5], [0.05, 0.6]], data=data)
    assert [st["counted"] for st in stretches] == [False, True]
    assert stretches[0]["call"] == "funnel" and stretches[0]["jenike_call"] == "funnel"
    assert stretches[1]["jenike_call"] == "mass"
    assert call["flow_mode"] == "mass" and call["jenike_flow_mode"] == "mass"


def test_the_flow_mode_window_falls_back_on_a_short_run_and_says_so():
    """The samples with 90 % to 40 % left after 0.1 s; on a run that never gets there, the
    samples after 0.1 s (``"short_run"``); on one that never gets past 0.1 s, none."""
    from fipy_hopper.simulation import flow_mode_window

    t = np.array([0.0, 0.05, 0.1, 0.15, 0.2, 0.25])
    window, name = flow_mode_window(t, [10.0, 9.9, 9.5, 8.5, 6.0, 3.0], 10.0)
    assert name == "mass_left" and window.tolist() == [False] * 3 + [True, True, False]
    window, name = flow_mode_window(t, np.full(6, 9.95), 10.0)
    assert name == "short_run" and window.tolist() == [False] * 3 + [True] * 3
    window, name = flow_mode_window(t[:3], np.full(3, 9.95), 10.0)
    assert name == "none" and not window.any()


# ---------------------------------------------------------------- an insert on the axis
INSERT = {"hopper": {"shape": "profile", "fill_level": 0.3,
                     "wall": [[0.03, 0.0], [0.15, 0.2], [0.15, 0.4]],
                     "inserts": [{"outline": [[0.0, 0.05], [0.04, 0.05], [0.04, 0.25],
                                              [0.0, 0.25]]}]},
          "numerics": {"cell_size": 0.01}}


def test_an_insert_on_the_axis_keeps_its_walls_contacts():
    """A plug flow at 1 m/s down (the nodes in the insert at rest): beside the insert the
    axis speed is read from the material's nearest column, so every loaded contact of the
    cone keeps its slip ratio, cos(theta) (the axis node inside the insert, at rest, dropped
    the contacts at its heights)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HopperModel(HopperConfig.from_dict(INSERT))
    g, bnd = model.grid, model.cfg.boundary
    state = model.initial_state()
    X, Z = np.meshgrid(g.r_nodes, g.z_nodes)
    in_insert = (X <= 0.04) & (Z >= 0.05) & (Z <= 0.25)      # in it or on it
    state.v[1] = np.where(in_insert, 0.0, -1.0)
    s, normals, segment = model.wall_entries()
    cone = segment == diagnostics.hopper_rows(bnd)[0]
    state.wall_impulse[:] = -np.where(cone[:, None], normals, 0.0)
    j, _, _, _ = model.contact_list
    beside = cone & (g.z_nodes[j] > 0.05) & (g.z_nodes[j] < 0.25)
    assert beside.sum() >= 10
    assert np.all(state.v[1, j[beside], model.centre_column] == 0.0)   # the insert's nodes
    _, axis = model.contact_slip(state)
    assert np.all(axis[cone] == 1.0)
    ratio, fraction, _, _, profile = wall_slip_measures(model, state)
    assert len(profile) == cone.sum()
    theta = math.atan2(0.12, 0.2)
    assert ratio == pytest.approx(math.cos(theta), rel=1e-12) and fraction == 1.0


def test_material_stopped_beside_an_insert_is_no_rathole():
    """Material at rest everywhere above the insert's foot, the gap between the outlet and
    the insert empty: the first column (in the insert, closed) is no empty channel, the
    material beside the insert closes it."""
    from fipy_hopper.diagnostics import OutcomeRule, empty_channel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HopperModel(HopperConfig.from_dict(INSERT))
    g = model.grid
    state = model.initial_state()
    Zc = np.broadcast_to(g.z_cells[:, None], state.alpha.shape)
    state.alpha = np.where((g.kappa > 0) & (Zc > 0.05) & (Zc < 0.2), 1.0, 0.0)
    assert math.isnan(empty_channel(model, state, OutcomeRule())[0])
    # with the material beside the insert gone too, the channel is there (radius 0.06 m)
    Rc = np.broadcast_to(g.r_cells[None, :], state.alpha.shape)
    state.alpha = np.where(Rc < 0.06, 0.0, state.alpha)
    diameter, height = empty_channel(model, state, OutcomeRule())
    assert diameter == pytest.approx(0.12, abs=0.011) and height == pytest.approx(0.2)
