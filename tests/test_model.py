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
    fast, ref = HopperModel(small_cfg, kernels="numba"), HopperModel(small_cfg, kernels="numpy")
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


def test_contact_kernel_equals_numpy(small_cfg):
    model = HopperModel(small_cfg)
    rng = np.random.default_rng(0)
    v = rng.normal(size=(2, model.grid.nz + 1, model.grid.nr + 1))
    ref = v.copy()
    for mask, normal, mu in model.contact_passes:
        momentum.apply_wall_contact(ref, normal, mask, mu)
    momentum.contact_kernel(v, *model.contact_list)
    assert np.allclose(v, ref, rtol=1e-14, atol=1e-15)


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
