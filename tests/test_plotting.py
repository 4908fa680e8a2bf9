"""The closed forms of the wall-pressure picture of a cone (the wedge's are in test_wedge.py),
and the forces picture of a run directory written before the wall's forces were."""

import math

import numpy as np
import pytest

from fipy_hopper import theory
from fipy_hopper.config import HopperConfig
from fipy_hopper.plotting import theory_wall_pressure

RHO = 1500.0


def cone(**hopper):
    return HopperConfig.from_dict({
        "hopper": {"bin_diameter": 0.3, "outlet_diameter": 0.06, "half_angle_deg": 20.0,
                   "bin_height": 0.35, "fill_height": 0.3, **hopper},
        "material": {"density": RHO, "friction_angle_deg": 30.0},
        "wall": {"friction_angle_deg": 15.0}})


def test_cone_picture_draws_en1991_hopper_loads():
    """A steep 20 deg cone: EN 1991-4's hopper loads sit on the EN vertical-wall filling stress
    at the transition (Janssen with K_m = 1.1 (1 - sin phi) = 0.55, C_b = 1): p_vft = 3335.4 Pa,
    F_f p_vft = 0.9152 x 3335.4 = 3052.5 Pa when filled and F_e p_vft = 1.3927 x 3335.4 =
    4645.2 Pa in discharge; below it the cone's slice (n = 2 (1 - b) mu cot beta) lies under
    a wedge's (S = 1) with the same top load."""
    cfg = cone()
    geom = cfg.hopper
    curves = theory_wall_pressure(cfg)
    assert set(curves) == {"Janssen, bin (K = 1 - sin phi)", "Walker, cone, filling",
                           "Walker, cone, discharge", "EN 1991-4, cone, filling",
                           "EN 1991-4, cone, discharge"}
    beta, phi = geom.half_angle_deg, cfg.material.friction_angle_deg
    mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
    gamma = RHO * theory.G
    K_m = float(theory.k_en1991(phi))
    p_vft = float(theory.en1991_filling_vertical_walls(geom.fill_height, gamma,
                                                       geom.bin_diameter, K_m, mu).p_v)
    assert p_vft == pytest.approx(3335.4, abs=0.1)
    assert theory.en1991_hopper_class(beta, K_m, mu) == "steep"
    F_f = float(theory.en1991_steep_filling_F(beta, mu))
    F_e = float(theory.en1991_steep_discharge_F(beta, mu, phi))
    s, p_fill = curves["EN 1991-4, cone, filling"]
    assert p_fill[-1] == pytest.approx(F_f * p_vft, rel=1e-9)
    assert p_fill[-1] == pytest.approx(3052.5, abs=0.1)
    p_dis = curves["EN 1991-4, cone, discharge"][1]
    assert p_dis[-1] == pytest.approx(F_e * p_vft, rel=1e-9)
    assert p_dis[-1] == pytest.approx(4645.2, abs=0.1)
    h = geom.bin_radius / math.tan(geom.half_angle)
    x = np.clip(s * math.cos(geom.half_angle) + geom.outlet_radius / math.tan(geom.half_angle),
                0.0, h)
    n_cone = float(theory.en1991_steep_filling_n(beta, mu, S=2))
    np.testing.assert_allclose(
        p_fill, F_f * np.asarray(theory.hopper_vertical_stress(x, h, gamma, n_cone, p_vft)),
        rtol=1e-9)
    wedge = theory.en1991_hopper_pressures(x, h, beta, gamma, K_m, mu, p_vft, S=1).p_n
    assert np.all(p_fill[:-1] < np.asarray(wedge)[:-1])


def test_cone_picture_en1991_shallow_and_flat():
    """A 45 deg cone is shallow for EN 1991-4 (tan beta = 1 > (1 - K_m) / (2 mu) = 0.84):
    its discharge loads equal its filling loads.  Beyond 85 deg (a flat bottom for the code)
    the EN curves are left out while Walker's are still drawn."""
    curves = theory_wall_pressure(cone(half_angle_deg=45.0))
    np.testing.assert_array_equal(curves["EN 1991-4, cone, filling"][1],
                                  curves["EN 1991-4, cone, discharge"][1])
    assert not np.allclose(curves["Walker, cone, filling"][1],
                           curves["Walker, cone, discharge"][1])
    flat = theory_wall_pressure(cone(half_angle_deg=88.0))
    assert "Walker, cone, filling" in flat
    assert not any(name.startswith("EN 1991-4") for name in flat)


def test_forces_picture_is_skipped_for_a_table_without_forces(tmp_path):
    """A run directory written before ``wall_pressure.csv`` had the wall's forces: no
    ``wall_forces.png`` (and no error); with the columns, a figure of two panels."""
    import csv

    from fipy_hopper import io
    from fipy_hopper.plotting import wall_forces

    cfg = cone()
    (tmp_path / "config.toml").write_text(cfg.to_toml())
    (tmp_path / "summary.json").write_text("{}")
    values = {"stage": "filling", "t_s": 0.0, "r_m": 0.05, "window_s": 0.01}
    old = [c for c in io.WALL_PRESSURE_COLUMNS if not c.endswith("_N_m")]
    for columns in (old, io.WALL_PRESSURE_COLUMNS):
        with open(tmp_path / "wall_pressure.csv", "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(columns)
            writer.writerows([values.get(c, 0.1 * k if c in ("s_m", "z_m") else 10.0 * k)
                              for c in columns] for k in range(1, 5))
        fig = wall_forces(tmp_path)
        assert (fig is None) == (columns is old)
    assert len(fig.axes) == 2


def test_flow_pattern_marks_where_the_hopper_wall_slides(tmp_path):
    """wall_slip.csv from a record: each loaded contact stands for the wall between the
    midpoints to its neighbours, green where its slip ratio reaches the rule's 0.2."""
    from types import SimpleNamespace

    from fipy_hopper import geometry
    from fipy_hopper.io import RunDirectory, write_wall_slip
    from fipy_hopper.plotting import wall_slip_segments

    cfg = cone()
    s = np.array([0.0, 0.02, 0.05])
    r, z, _, _ = geometry.wall_point(s, cfg.hopper)
    record = SimpleNamespace(wall_slip_profile=np.column_stack([s, r, z, [0.5, 0.1, 0.2]]))
    write_wall_slip(tmp_path / RunDirectory.WALL_SLIP, record, 0.2)
    segments = wall_slip_segments(tmp_path, cfg)
    assert [sliding for _, sliding in segments] == [True, False, True]
    ends = [(points[0], points[-1]) for points, _ in segments]
    middle = geometry.wall_point(np.array([0.01, 0.035]), cfg.hopper)
    np.testing.assert_allclose(ends[1][0], [middle[0][0], middle[1][0]], atol=1e-12)
    np.testing.assert_allclose(ends[1][1], [middle[0][1], middle[1][1]], atol=1e-12)
    assert wall_slip_segments(tmp_path / "none", cfg) == []


def test_walker_stretch_by_stretch_is_walker_on_a_single_cone():
    """The slices stacked stretch by stretch reduce to the classic Walker curve on a single
    cone under a bin (same sigma_vt at the transition), and on a two-slope hopper carry the
    vertical stress down: the lower stretch's curve starts from what the upper one leaves."""
    from fipy_hopper.plotting import _stacked_walker

    cfg = cone()
    classic = theory_wall_pressure(cfg, n=60)
    sigma_vt = 2000.0
    g, mat = cfg.hopper, cfg.material
    s = np.linspace(0.0, cfg.boundary.arc_at_height("wall", g.cone_height), 60)
    x = s * math.cos(g.half_angle) + g.outlet_radius / math.tan(g.half_angle)
    h = g.bin_radius / math.tan(g.half_angle)
    want = theory.walker_hopper_wall_pressure(np.clip(x, 0, h), h, g.half_angle_deg,
                                              mat.density, mat.friction_angle_deg,
                                              cfg.wall.friction_angle_deg, sigma_vt)
    got = _stacked_walker(cfg, sigma_vt, 2, "cone", n=60)["Walker, cone stretch 0, filling"]
    np.testing.assert_allclose(got[1], want, rtol=1e-9)
    assert "Walker, cone, filling" in classic
    two = HopperConfig.from_dict({"hopper": {
        "shape": "profile", "wall": [[0.03, 0.0], [0.06, 0.1], [0.15, 0.2], [0.15, 0.5]],
        "fill_level": 0.4}, "numerics": {"cell_size": 0.01}})
    curves = _stacked_walker(two, sigma_vt, 2, "cone", n=60)
    upper = curves["Walker, cone stretch 1, filling"]
    lower = curves["Walker, cone stretch 0, filling"]
    mu = math.tan(math.radians(two.wall.friction_angle_deg))
    beta_u = math.degrees(math.atan2(0.09, 0.1))
    beta_l = math.degrees(math.atan2(0.03, 0.1))
    carried = upper[1][0] / theory.en1991_steep_filling_F(beta_u, mu)
    assert lower[1][-1] == pytest.approx(theory.en1991_steep_filling_F(beta_l, mu) * carried,
                                         rel=1e-9)
