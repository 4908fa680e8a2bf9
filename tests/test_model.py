"""HopperModel: compiled kernels equal the numpy reference; conservation through a transport."""

import warnings

import numpy as np
import pytest

from fipy_hopper import momentum
from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel


@pytest.fixture(scope="module")
def small_cfg():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.25,
                       "fill_height": 0.15},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.02}})


def test_compiled_step_equals_numpy_reference(small_cfg):
    """600 steps (filling, then 200 of discharge, with transports) agree to round-off."""
    fast, ref = HopperModel(small_cfg, backend="numba"), HopperModel(small_cfg, backend="numpy")
    a, b = fast.initial_state(), ref.initial_state()
    for k in range(600):
        if k == 400:
            fast.open_outlet(a)
            ref.open_outlet(b)
        fast.step(a)
        ref.step(b)
    assert np.max(np.abs(a.v - b.v)) <= 1e-9 * np.max(np.abs(b.v))
    assert np.max(np.abs(a.sigma - b.sigma)) <= 1e-9 * np.max(np.abs(b.sigma))
    assert np.max(np.abs(a.alpha - b.alpha)) <= 1e-12
    assert a.discharged == pytest.approx(b.discharged, rel=1e-9, abs=1e-15)


@pytest.mark.parametrize("plate_closed", [True, False])
def test_compiled_contact_equals_numpy(small_cfg, plate_closed):
    """Random velocities at every node in contact (corners and the lip included): the
    compiled contact and its numpy reference give the same velocities and impulses, to the
    bit."""
    from fipy_hopper import stepping
    model = HopperModel(small_cfg)
    rng = np.random.default_rng(0)
    g = model.grid
    v = rng.normal(size=(2, g.nz + 1, g.nr + 1))
    mass = rng.uniform(0.5, 2.0, size=(g.nz + 1, g.nr + 1))
    row_nodes, node_j, node_i, node_ptr, normal, mu, kind, entry = model.contact_groups
    wall = np.zeros((len(model.contact_list[0]), 2))
    plate = np.zeros((len(model.plate_list[0]), 2))
    ref_v, ref_wall, ref_plate = v.copy(), wall.copy(), plate.copy()
    momentum.contact_nodes(ref_v, mass, model.contact_groups, plate_closed, ref_wall, ref_plate)
    for q in range(len(node_j)):
        stepping._contact_node(v, node_j[q], node_i[q], mass, node_ptr[q], node_ptr[q + 1],
                               normal, mu, kind, entry, plate_closed, wall, plate)
    assert np.array_equal(v, ref_v)
    assert np.array_equal(wall, ref_wall)
    assert np.array_equal(plate, ref_plate)
    # nothing presses into a wall afterwards
    for q in range(len(node_j)):
        for k in range(node_ptr[q], node_ptr[q + 1]):
            if kind[k] == 0 or plate_closed:
                assert v[:, node_j[q], node_i[q]] @ normal[k, :2] <= 1e-12


def test_a_corner_pressed_from_both_sides_stops(small_cfg):
    """At the outlet lip with the plate closed, weight pressing down on the plate and into the
    cone gives rest, not an inward slide (what contacts applied one after the other gave)."""
    from fipy_hopper import stepping
    model = HopperModel(small_cfg)
    row_nodes, node_j, node_i, node_ptr, normal, mu, kind, entry = model.contact_groups
    g, geom = model.grid, small_cfg.hopper
    lip = [q for q in range(len(node_j)) if abs(g.z_nodes[node_j[q]]) < 1e-12
           and abs(g.r_nodes[node_i[q]] - geom.outlet_radius) < 1e-12]
    assert len(lip) == 1
    q = lip[0]
    v = np.zeros((2, g.nz + 1, g.nr + 1))
    v[:, node_j[q], node_i[q]] = (0.01, -0.02)            # outward and down
    mass = np.ones((g.nz + 1, g.nr + 1))
    wall = np.zeros((len(model.contact_list[0]), 2))
    plate = np.zeros((len(model.plate_list[0]), 2))
    stepping._contact_node(v, node_j[q], node_i[q], mass, node_ptr[q], node_ptr[q + 1], normal,
                           mu, kind, entry, True, wall, plate)
    assert np.all(v[:, node_j[q], node_i[q]] == 0.0)
    assert wall.sum(axis=0) + plate.sum(axis=0) == pytest.approx([-0.01, 0.02])
    assert plate[:, 1].sum() > 0.0                         # the plate holds it up


def test_mass_is_conserved_to_round_off_through_discharge(small_cfg):
    model = HopperModel(small_cfg)
    st = model.initial_state()
    for _ in range(300):
        model.step(st)
    model.transport_step(st)
    model.open_outlet(st)
    m0 = model.mass_in_hopper(st)
    total0 = model.total_mass(st)
    for _ in range(1500):
        model.step(st)
    model.transport_step(st)
    assert st.discharged > 0.01 * m0
    assert abs(model.mass_in_hopper(st) + st.discharged - m0) < 1e-12 * m0
    assert abs(model.total_mass(st) + st.lost - total0) < 1e-12 * total0
    assert st.alpha.min() >= -1e-12 and st.alpha.max() <= 1 + 1e-12


def test_after_transport_hooks_see_every_transport_and_change_nothing(small_cfg):
    """A hook runs once after every transport step, sees the carried alpha, and a run with
    hooks is the run without them bit for bit (measurements read the state)."""
    plain, hooked = HopperModel(small_cfg), HopperModel(small_cfg)
    seen = []
    hooked.after_transport.append(lambda state: seen.append((state.step, state.alpha.sum())))
    a, b = plain.initial_state(), hooked.initial_state()
    done = 0
    while done < 300:
        done += plain.advance(a, 300 - done)
    done = 0
    while done < 300:
        done += hooked.advance(b, 300 - done)
    assert len(seen) > 3
    assert [s for s, _ in seen] == sorted({s for s, _ in seen})       # once per transport
    assert seen[-1][1] == b.alpha.sum()
    assert np.array_equal(a.v, b.v) and np.array_equal(a.sigma, b.sigma)
    assert np.array_equal(a.alpha, b.alpha)
