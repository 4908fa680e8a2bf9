"""The outlet opening over ``run.opening_time``: an iris that lets the plate's nodes go from the
axis outwards, the same in the compiled steps and the numpy reference."""

import math
import warnings

import numpy as np
import pytest

from fipy_hopper import stepping
from fipy_hopper.config import ConfigError, HopperConfig
from fipy_hopper.model import HopperModel

SMALL = {"hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.25,
                    "fill_height": 0.15},
         "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.02}}
FILL_STEPS = 400        # the fill of the small hopper, as in test_model.py


def small_config(**run) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({**SMALL, "run": {"end_time": 0.5, **run}})


def test_opening_time_is_checked():
    assert small_config().run.opening_time == 0.0
    with pytest.raises(ConfigError, match=r"run\.opening_time = -0\.1 s.*\[0, "):
        small_config(opening_time=-0.1)
    with pytest.raises(ConfigError, match=r"run\.opening_time = 0\.6 s is longer than the "
                                          r"discharge.*\[0, 0\.5\] s"):
        small_config(opening_time=0.6)
    with pytest.raises(ConfigError, match=r"run\.opening_time = 0\.1 s applies to "
                                          r'numerics\.formulation = "eulerian" only'):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            HopperConfig.from_dict({**SMALL, "run": {"end_time": 0.5, "opening_time": 0.1},
                                    "numerics": {**SMALL["numerics"],
                                                 "formulation": "lagrangian"}})


def test_opening_radius_grows_from_the_axis():
    opening = np.array([1.0, 0.2, 0.03])
    assert stepping.opening_radius(1.0, opening) == 0.0
    assert stepping.opening_radius(1.1, opening) == pytest.approx(0.015, rel=1e-12)
    assert stepping.opening_radius(1.2, opening) == math.inf
    assert stepping.opening_radius(5.0, np.array([-1.0, 0.2, 0.03])) == -1.0


def filled(cfg, backend="numba"):
    model = HopperModel(cfg, backend=backend)
    state = model.initial_state()
    for _ in range(FILL_STEPS):
        model.step(state)
    return model, state


def test_the_plate_lets_go_from_the_axis_outwards():
    """Half-way through the opening the plate holds only the nodes outside the opening
    radius, material leaves through the opened middle, and at the end the plate is gone."""
    probe = HopperModel(small_config())
    cfg = small_config(opening_time=200 * probe.dt)
    model, state = filled(cfg)
    m0 = model.mass_in_hopper(state)
    model.open_outlet(state)
    assert state.plate_closed and state.stage == "discharge"
    for _ in range(100):
        model.step(state)
    r_open = model.plate_opening_radius(state)
    assert r_open == pytest.approx(0.5 * cfg.hopper.outlet_radius, rel=1e-6)
    r_plate = model.grid.r_nodes[model.plate_list[1]]
    before = state.plate_impulse.copy()
    for _ in range(10):                   # the radius grows by 5 % of R_0 over these steps
        model.step(state)
    pushed = state.plate_impulse[:, 1] - before[:, 1]
    assert np.all(pushed[r_plate < r_open] == 0.0)
    outer = r_plate >= model.plate_opening_radius(state)
    assert np.all(pushed[outer] > 0.0)    # the rest of the plate still carries the material
    assert state.discharged > 0.0
    assert model.mass_in_hopper(state) < m0
    for _ in range(95):
        model.step(state)
    assert not state.plate_closed


def test_compiled_opening_equals_numpy_reference():
    """Fill, then 300 steps of which the first 100 open the outlet: the compiled steps and the
    numpy reference agree to round-off, as without the opening (test_model.py)."""
    probe = HopperModel(small_config())
    cfg = small_config(opening_time=100 * probe.dt)
    (fast, a), (ref, b) = filled(cfg, "numba"), filled(cfg, "numpy")
    fast.open_outlet(a)
    ref.open_outlet(b)
    for _ in range(300):
        fast.step(a)
        ref.step(b)
    assert not a.plate_closed and not b.plate_closed
    assert np.max(np.abs(a.v - b.v)) <= 1e-9 * np.max(np.abs(b.v))
    assert np.max(np.abs(a.sigma - b.sigma)) <= 1e-9 * np.max(np.abs(b.sigma))
    assert np.max(np.abs(a.alpha - b.alpha)) <= 1e-12
    assert np.max(np.abs(a.plate_impulse - b.plate_impulse)) <= 1e-9 * np.max(
        np.abs(b.plate_impulse))
    assert a.discharged == pytest.approx(b.discharged, rel=1e-9, abs=1e-15)
