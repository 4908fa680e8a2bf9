"""The wall traction recovered from the wall's reaction (:mod:`fipy_hopper.wall_traction`):
exact stretch by stretch, positive (Coulomb holds wherever it holds at the nodes), and where
the wall cuts the cells smooth, converging bin by bin under refinement, at rest and in
discharge; the plain binning of the reaction, node by node, is not."""

import math
import warnings

import numpy as np
import pytest

from fipy_hopper import geometry, theory
from fipy_hopper.config import HopperConfig
from fipy_hopper.diagnostics import bin_scatter, relative_l2, smooth_fit_rms
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation
from fipy_hopper.boundary import Segment
from fipy_hopper.wall_traction import StretchRecovery

CONE = Segment((0.03, 0.0), (0.15, 0.33), s_start=0.0, index=1, axisymmetric=True)
PLATE = Segment((0.03, 0.0), (0.15, 0.33), s_start=0.0, index=1, axisymmetric=False)


def scattered_forces(stretch, n=400, seed=1):
    """Entries at random points of the stretch with random forces (normal >= 0, Coulomb
    with mu = 0.3)."""
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(stretch.s_start, stretch.s_end, n))
    normal = rng.uniform(0.0, 2.0, n)
    shear = rng.uniform(-0.3, 0.3, n) * normal
    return s, np.stack([normal, shear], axis=1)


@pytest.mark.parametrize("stretch", [CONE, PLATE], ids=["axisymmetric", "plane"])
def test_the_recovered_traction_carries_each_stretch_force_exactly(stretch):
    """Bin means times bin areas, and the spline's coefficients times their basis areas, add
    up to the entries' summed force, normal and shear, to round-off; so do the raw bins."""
    s, force = scattered_forces(stretch)
    rec = StretchRecovery.build(stretch, np.arange(len(s)), s, 0.015, 0.02)
    total = force.sum(axis=0)
    np.testing.assert_allclose(rec.bin_area @ rec.traction(force), total, rtol=1e-12)
    np.testing.assert_allclose(rec.basis_area @ rec.coefficients(force), total, rtol=1e-12)
    np.testing.assert_allclose(rec.bin_area @ rec.raw_traction(force), total, rtol=1e-12)
    assert rec.bin_area.sum() == pytest.approx(float(stretch.area(stretch.s_start,
                                                                  stretch.s_end)), rel=1e-12)


def test_the_recovered_traction_obeys_coulomb_wherever_the_nodes_do():
    """Positive weights: p_n >= 0 and |tau| <= mu p_n in every bin and at every point when
    every entry's force obeys them (mu = 0.3)."""
    s, force = scattered_forces(CONE, seed=2)
    rec = StretchRecovery.build(CONE, np.arange(len(s)), s, 0.015, 0.02)
    for p in (rec.traction(force), rec.evaluate(force, np.linspace(0, CONE.s_end, 777))):
        assert np.all(p[:, 0] >= 0)
        assert np.all(np.abs(p[:, 1]) <= 0.3 * p[:, 0] * (1 + 1e-12))


@pytest.mark.parametrize("stretch", [CONE, PLATE], ids=["axisymmetric", "plane"])
def test_a_smooth_traction_is_recovered_to_its_bin_means(stretch):
    """Entries every millimetre along a stretch carrying p(s) = 1000 (1 + 2 s) Pa (doubling
    over half a metre) times their share of the wall (midpoints to their neighbours): away
    from the stretch's ends (more than two knot spans) the bin means are the exact ones
    within 0.2 % (1e-4 on a plane wall: the spline's average reproduces a linear
    traction); at the ends, within 1 %: there a clamped basis function averages the last
    quarter of a knot span, a bias of about a third of a span times the gradient."""
    def exact(a, b):
        s = np.linspace(a, b, 2001)
        c = stretch.weight(s)
        return np.trapezoid(1000 * (1 + 2 * s) * c, s) / np.trapezoid(c, s)
    s = np.arange(0.0005, stretch.s_end, 0.001)
    mids = np.concatenate([[0.0], 0.5 * (s[1:] + s[:-1]), [stretch.s_end]])
    f = np.array([exact(a, b) * float(stretch.area(a, b)) for a, b in zip(mids[:-1], mids[1:])])
    rec = StretchRecovery.build(stretch, np.arange(len(s)), s, 0.015, 0.02)
    p = rec.traction(f)
    want = np.array([exact(a, b) for a, b in zip(rec.edges[:-1], rec.edges[1:])])
    error = np.abs(p - want) / want
    inner = (rec.centres > 0.04) & (rec.centres < stretch.s_end - 0.04)
    assert error[inner].max() < (2e-3 if stretch.axisymmetric else 1e-4)
    assert error.max() < 0.01


def test_the_smoothness_measures_on_known_profiles():
    """The measures the tests below and the wall-pressure study read: a cubic profile
    deviates from its cubic fit by round-off, whatever lies outside the fitted span; a
    +-5 % alternation about a constant by 4.97 % RMS; the bin-to-bin scatter of
    900, 1100, 900, 1100, 900 is (2 x 200/1100 + 200/900)/3, of a straight line 0, and a
    bin without a value drops only the terms it is in."""
    s = np.arange(30) * 0.015 + 0.0075
    cubic = 1000 + 500 * s - 300 * s ** 2 + 900 * s ** 3
    spoiled = np.where((s < 0.05) | (s > 0.4), 1e6, cubic)
    assert smooth_fit_rms(s, spoiled, 0.05, 0.4) < 1e-12
    alternating = 1000 * (1 + 0.05 * (-1) ** np.arange(30))
    assert smooth_fit_rms(s, alternating, 0.0, 1.0) == pytest.approx(0.04972, abs=1e-5)
    zigzag = np.array([900, 1100, 900, 1100, 900.0])
    assert bin_scatter(zigzag) == pytest.approx((2 * 200 / 1100 + 200 / 900) / 3, rel=1e-12)
    assert bin_scatter(cubic[:2].tolist() + [np.nan] + [1.0, 2.0, 3.0]) == 0.0
    assert bin_scatter(1000 + 200 * s) < 1e-15


# ---------------------------------------------------------------- at rest on cut walls
def reference(cell_size=0.005, half_angle=20.0, shape="conical", **run):
    raw = HopperConfig().to_dict()
    raw["hopper"]["half_angle_deg"] = half_angle
    raw["numerics"]["cell_size"] = cell_size
    raw["run"].update({"end_time": 0, "markers_per_side": 0, **run})
    if shape == "wedge":
        raw["hopper"].update(shape="wedge", bin_width=raw["hopper"].pop("bin_diameter"),
                             outlet_width=raw["hopper"].pop("outlet_diameter"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict(raw)


def run(cfg):
    sim = Simulation(HopperModel(cfg), progress=False)
    sim.run()
    return sim


def hopper_bins(sim):
    """The bins of the hopper's stretch (the cone), 2 cm left out at each end."""
    geom = sim.model.cfg.hopper
    s = sim.record.wall["filling"][1]
    s_t = float(geometry.transition_arc_length(geom))
    return s, 0.02, s_t - 0.02


CASES = [(10.0, "conical"), (20.0, "conical"), (35.0, "conical"), (60.0, "conical"),
         (20.0, "wedge")]


@pytest.fixture(scope="module", params=CASES, ids=[f"{a:g}-{k}" for a, k in CASES])
def at_rest(request):
    half_angle, shape = request.param
    return run(reference(half_angle=half_angle, shape=shape))


def test_the_pressure_on_a_cut_wall_at_rest_is_smooth(at_rest):
    """At rest, 5 mm cells, 15 mm bins: the hopper wall's p_n deviates from a smooth cubic
    over its bins (2 cm left out at each end) by at most 3 % RMS, for cones of 10 to 60 deg
    and a wedge, the wall crossing the cells at every slope; the reaction binned node by node
    does not (over 3 %: the test tells the two apart)."""
    s, lo, hi = hopper_bins(at_rest)
    p = at_rest.record.wall["filling"][4]
    raw = at_rest.record.wall_raw["filling"][0]
    assert at_rest.model.cfg.wall_bin_width_m == pytest.approx(0.015)
    assert smooth_fit_rms(s, p, lo, hi) <= 0.03
    assert smooth_fit_rms(s, raw, lo, hi) > 0.03


def test_the_recovered_traction_carries_the_reaction_and_the_weight(at_rest):
    """Each stretch's recovered traction times its wall area is its entries' summed reaction
    (1e-9), and the wall's vertical traction plus the outlet plate's reaction balances the
    weight within 0.5 %."""
    sim = at_rest
    loads, rec = sim.wall_loads, sim.record
    _, _, _, _, p_n, tau = rec.wall["filling"]
    area, bins = loads.bin_area, loads.bins
    up = area * (-p_n * bins.normal[:, 1] + tau * bins.tangent[:, 1])
    section = sim.model.section_factor
    assert section * up.sum() == pytest.approx(rec.rest_balance["wall"], rel=1e-9)
    weight = rec.rest_balance["weight"]
    assert abs(section * up.sum() + rec.rest_balance["outlet"] - weight) < 0.005 * weight


WALL_CELLS = (0.0075, 0.005, 0.00375, 0.0025)
WALL_BIN = 0.015            # m: every grid's wall bins ("auto" at 5 mm and finer)


@pytest.fixture(scope="module")
def refined():
    """The reference hopper at rest at 7.5, 5, 3.75 and 2.5 mm on the same 15 mm wall bins
    (fill-only runs; one fixture for every test of the profile at rest under refinement)."""
    return {h: run(reference(cell_size=h, wall_bin_width=WALL_BIN)) for h in WALL_CELLS}


@pytest.fixture(scope="module")
def discharged():
    """The reference hopper at 5 mm, filled and 1.6 s into the discharge."""
    return run(reference(end_time=1.6))


def corner_bin(sim):
    """The index of the bin wall's first bin above the transition."""
    s = sim.record.wall["filling"][1]
    return int(np.flatnonzero(s > float(geometry.transition_arc_length(
        sim.model.cfg.hopper)))[0])


def test_the_profile_at_rest_converges_bin_by_bin(refined):
    """The reference hopper at rest at 5, 3.75 and 2.5 mm, on the same 15 mm bins: between
    3.75 and 2.5 mm no bin of the loaded wall differs by 5 % or more, but for the two bins at
    the outlet lip (a re-entrant corner: singular stress) and the top bin under the free
    surface (75 Pa, 2 % of the peak, set by how the surface is smeared over a cell: 4.9 %
    with the corner's load on the cone, 5.4 % with it shared), the bin wall's first bin above
    the transition among them (the corner's node shares its load with the bin wall: within
    1 % here, 8.8 % when the cone took it all); and the L2 differences decrease."""
    runs = refined
    s = runs[0.005].record.wall["filling"][1]
    p = {h: sim.record.wall["filling"][4] for h, sim in runs.items()}
    for h in p:
        np.testing.assert_array_equal(runs[h].record.wall["filling"][1], s)
    geom = runs[0.005].model.cfg.hopper
    s_top = float(geometry.arc_length(geom.fill_level, geom))
    corner = corner_bin(runs[0.005])
    width = runs[0.005].model.cfg.wall_bin_width_m
    loaded = (np.arange(len(s)) >= 2) & (s < s_top - width)
    diff = np.abs(p[0.00375] - p[0.0025]) / p[0.0025]
    assert diff[loaded].max() < 0.05
    assert diff[corner] < 0.05
    l2 = [np.linalg.norm(p[a] - p[b]) / np.linalg.norm(p[b])
          for a, b in ((0.005, 0.00375), (0.00375, 0.0025))]
    assert l2[0] > l2[1]


def coulomb_ratio(sim, stage):
    """``|tau| / (tan phi_w p_n)`` in every loaded bin of the walls' stretches (the cone and
    the bin wall) of a stage, and where each bin is (True on the cone)."""
    _, s, _, _, p, tau = sim.record.wall[stage]
    mu = math.tan(math.radians(sim.model.cfg.wall.friction_angle_deg))
    loaded = p > 0
    s_t = float(geometry.transition_arc_length(sim.model.cfg.hopper))
    return np.abs(tau[loaded]) / (mu * p[loaded]), s[loaded] < s_t


def test_coulomb_holds_in_every_bin_at_rest_beside_the_corner(refined):
    """At rest at 5, 3.75 and 2.5 mm: |tau| <= tan phi_w p_n in every bin of the cone and of
    the bin wall (the corner's node shares its impulse inside both walls' friction cones),
    and the bin wall's first bin above the transition is within 5 % of the next (it carries
    its share of the corner: 20 % short at 5 mm when the cone took it all)."""
    for h, sim in refined.items():
        if h > 0.005:
            continue
        ratio, on_cone = coulomb_ratio(sim, "filling")
        assert on_cone.any() and (~on_cone).any()
        assert ratio.max() <= 1.0 + 1e-9, h
        p = sim.record.wall["filling"][4]
        k = corner_bin(sim)
        assert abs(p[k] / p[k + 1] - 1) < 0.05, h


def test_filled_cone_pressure_against_walker(refined):
    """The cone's filled pressure against Walker's slice method (headline ``cone_walker``).

    Held on every grid from 7.5 to 2.5 mm: the mean wall pressure over the cone within 5 % of
    Walker's filling solution started from Janssen's vertical stress at the transition
    (K = 1 - sin phi).  Why 5 %: the slice method takes the vertical stress uniform across each
    slice; taking the oedometric K = nu / (1 - nu) = 0.43 of the elastic fill (the measured wall
    K is 0.41) in place of 0.5 moves Walker's mean by 2 %."""
    for cell, sim in refined.items():
        cfg = sim.model.cfg
        _, s, r, z, p, _ = sim.record.wall["filling"]
        geom, rho = cfg.hopper, cfg.material.density
        phi, phi_w = cfg.material.friction_angle_deg, cfg.wall.friction_angle_deg
        cone = z < geom.cone_height
        mu = math.tan(math.radians(phi_w))
        sigma_vt = float(theory.janssen_vertical_stress(geom.fill_height, rho, geom.bin_diameter,
                                                        float(theory.k_jaky(phi)), mu))
        h = geom.bin_radius / math.tan(geom.half_angle)
        x = np.clip(z[cone] + geom.outlet_radius / math.tan(geom.half_angle), 0.0, h)
        walker = theory.walker_hopper_wall_pressure(x, h, geom.half_angle_deg, rho, phi, phi_w,
                                                    sigma_vt, mode="filling")
        assert np.mean(p[cone]) == pytest.approx(np.mean(walker), rel=0.05), cell


def test_filled_wall_pressure_converges_with_the_cell_size(refined):
    """The filled wall profile converges with the cell size (headline ``wall_convergence``;
    over the whole wall, the outlet lip included, bin by bin on the 15 mm bins that every
    grid shares).

    Held: the successive relative L2 changes decrease and the last is below 5 % (the
    wall-load convergence criterion of the wall-pressure study).  The bins are the same on
    every grid, so the comparison has no merging or interpolation error of its own."""
    s = refined[WALL_CELLS[0]].record.wall["filling"][1]
    profiles = []
    for cell in WALL_CELLS:
        np.testing.assert_array_equal(refined[cell].record.wall["filling"][1], s)
        profiles.append(refined[cell].record.wall["filling"][4])
    changes = [relative_l2(a, b) for a, b in zip(profiles, profiles[1:])]
    assert all(later < earlier for earlier, later in zip(changes, changes[1:])), changes
    assert changes[-1] < 0.05, changes


def test_coulomb_holds_in_every_bin_of_every_stage(discharged):
    """Filled and 1.6 s into the discharge (5 mm): |tau| <= tan phi_w p_n in every bin of the
    cone and of the bin wall at rest and in the early discharge (the envelope has no shear)."""
    stages = [k for k in discharged.record.wall if k != "discharge_envelope"]
    assert stages == ["filling", "early_discharge"]
    for stage in stages:
        ratio, on_cone = coulomb_ratio(discharged, stage)
        assert on_cone.any() and (~on_cone).any()
        assert ratio.max() <= 1.0 + 1e-9, stage


def test_the_pressure_on_the_cone_in_discharge_is_smooth(discharged):
    """The reference hopper at 5 mm, the 0.1 s window from the moment 90 % of the mass is
    left: the cone's bin-to-bin scatter of p_n is at most 4 %; the plain binning's is more."""
    sim = discharged
    _, s, _, _, p, _ = sim.record.wall["early_discharge"]
    raw = sim.record.wall_raw["early_discharge"][0]
    s_t = float(geometry.transition_arc_length(sim.model.cfg.hopper))
    cone = s < s_t
    assert bin_scatter(p[cone]) <= 0.04
    assert bin_scatter(raw[cone]) > 0.04
