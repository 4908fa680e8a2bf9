"""Filling to rest: hydrostatic column, Janssen's bin, a conical hopper at rest (issue 3).

Coarse grids (1 cm cells); each case fills in a few seconds.  The fill is at rest by the
criterion of :mod:`fipy_hopper.simulation` (kinetic energy below 1e-6 M g L after the ramp).
"""

import math
import warnings

import numpy as np
import pytest

from fipy_hopper import theory
from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation

RHO, G = 1500.0, 9.81


def filled(hopper, wall_deg, cell=0.01, **numerics):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict({"hopper": hopper, "wall": {"friction_angle_deg": wall_deg},
                                      "numerics": {"cell_size": cell, **numerics}})
    model = HopperModel(cfg)
    sim = Simulation(model, progress=False)
    assert sim.fill(), "the fill did not come to rest"
    return model, sim


def row_mean(model, state, k):
    """alpha-weighted mean of stress component k over the full cells of each row."""
    w = state.alpha * model.open_volume * (state.alpha > 0.99)
    return (state.sigma[..., k] * w).sum(1) / np.maximum(w.sum(1), 1e-300)


def test_frictionless_bin_is_hydrostatic():
    H = 0.3
    model, sim = filled({"bin_diameter": 0.2, "outlet_diameter": 0.06, "half_angle_deg": 90,
                         "bin_height": H + 0.02, "fill_height": H}, wall_deg=0.0)
    g, st = model.grid, sim.state
    z = g.z_cells
    rows = (z > 0) & (z < H - 2 * g.h)          # away from the free surface
    szz = row_mean(model, st, 1)[rows]
    expected = -RHO * G * (H - z[rows])
    assert np.max(np.abs(szz / expected - 1)) < 0.02
    # oedometric: lateral ratio nu / (1 - nu) with frictionless walls
    k = row_mean(model, st, 0)[rows] / szz
    assert np.allclose(k, 0.3 / 0.7, rtol=0.02)


@pytest.fixture(scope="module")
def tall_janssen_bin():
    H = 0.9
    return H, *filled({"bin_diameter": 0.2, "outlet_diameter": 0.06, "half_angle_deg": 90,
                       "bin_height": H + 0.02, "fill_height": H}, wall_deg=20.0)


def test_bin_wall_pressure_follows_janssen(tall_janssen_bin):
    H, model, sim = tall_janssen_bin
    st, g = sim.state, model.grid
    mu = math.tan(math.radians(20.0))
    # K measured at the wall: sigma_rr / sigma_zz in the cell column next to the bin wall
    col = int(round(0.1 / g.h)) - 1
    rows = (g.z_cells > 0.1 * H) & (g.z_cells < 0.9 * H)
    K = float(np.median(st.sigma[rows, col, 0] / st.sigma[rows, col, 1]))
    assert 0.3 < K < 0.6
    _, s, r, z, p, tau = sim.record.wall["filling"]
    on_bin = (r > 0.099) & (z > 0.1 * H) & (z < 0.85 * H)
    janssen = theory.janssen_wall_pressure(H - z[on_bin], RHO, 0.2, K, mu)
    assert np.max(np.abs(p[on_bin] / janssen - 1)) < 0.10
    # friction is mobilised up the wall (material hangs on it) and bounded by Coulomb
    assert np.all(tau[on_bin] > 0) and np.all(tau[on_bin] <= mu * p[on_bin] * 1.05)


def test_tall_bin_approaches_janssen_asymptote(tall_janssen_bin):
    H, model, sim = tall_janssen_bin
    _, s, r, z, p, tau = sim.record.wall["filling"]
    asymptote = theory.janssen_asymptotic_wall_pressure(RHO, 0.2, math.tan(math.radians(20)))
    deep = (r > 0.099) & (z > 0.05) & (z < 0.15)      # 0.75-0.85 m below the surface
    assert np.all(p[deep] > 0.85 * asymptote) and np.all(p[deep] < 1.05 * asymptote)
    # and far below the hydrostatic wall pressure K rho g depth there
    assert np.all(p[deep] < 0.8 * 0.43 * RHO * G * (H - z[deep]))


def test_conical_hopper_comes_to_rest_with_walker_like_cone_pressure(tmp_path):
    model, sim = filled({"bin_diameter": 0.2, "outlet_diameter": 0.06, "half_angle_deg": 20,
                         "bin_height": 0.22, "fill_height": 0.2}, wall_deg=15.0)
    st = sim.state
    assert sim.record.fill_at_rest
    mass = model.total_mass(st)
    L = model.cfg.hopper.fill_level
    assert model.kinetic_energy(st) < 1e-6 * mass * G * L
    _, s, r, z, p, tau = sim.record.wall["filling"]
    assert np.all(np.isfinite(p)) and len(p) > 10
    hc = model.cfg.hopper.cone_height
    cone = (z > 0.2 * hc) & (z < 0.9 * hc)
    # pressures are compressive and of the order of the overburden (Walker's filling ratio)
    assert np.all(p[cone] > 0)
    assert np.all(p[cone] < RHO * G * (model.cfg.hopper.fill_level - z[cone]))
