"""Configuration validation, the wall geometry and the grid's cut cells."""

import math

import numpy as np
import pytest

from fipy_hopper import geometry
from fipy_hopper.config import ConfigError, HopperConfig, HopperGeometry, ResolutionWarning
from fipy_hopper.mesh import build_grid


def test_reference_defaults():
    cfg = HopperConfig()
    assert cfg.hopper.bin_diameter == 0.3 and cfg.hopper.half_angle_deg == 20.0
    assert cfg.hopper.outlet_diameter == 0.06 and cfg.hopper.fill_height == 0.3
    assert cfg.material.density == 1500 and cfg.material.youngs_modulus == 5e6
    assert cfg.wall.friction_angle_deg == 15.0
    assert cfg.hopper.cone_height == pytest.approx(0.12 / math.tan(math.radians(20)))


@pytest.mark.parametrize("section, key, value, words", [
    ("hopper", "outlet_diameter", 0.4, ["hopper.outlet_diameter", "bin"]),
    ("hopper", "fill_height", 0.5, ["hopper.fill_height", "top of the bin"]),
    ("hopper", "half_angle_deg", 95, ["hopper.half_angle_deg", "(0, 90]"]),
    ("hopper", "bin_diameter", -1, ["hopper.bin_diameter", "allowed range"]),
    ("material", "poisson_ratio", 0.5, ["material.poisson_ratio", "(-1, 0.5)"]),
    ("material", "dilation_angle_deg", 40, ["material.dilation_angle_deg", "[0, 30]"]),
    ("material", "density", "heavy", ["material.density", "expected a number"]),
    ("wall", "friction_angle_deg", -3, ["wall.friction_angle_deg"]),
    ("numerics", "cell_size", 0.02, ["numerics.cell_size", "cells across the outlet radius"]),
    ("run", "end_time", "forever", ["run.end_time", '"empty"']),
])
def test_bad_values_name_the_key(section, key, value, words):
    with pytest.raises(ConfigError) as err:
        HopperConfig.from_dict({section: {key: value}})
    for w in words:
        assert w in str(err.value)


def test_unknown_key_did_you_mean():
    with pytest.raises(ConfigError, match="did you mean 'hopper.outlet_diameter'"):
        HopperConfig.from_dict({"hopper": {"outlet_diamter": 0.05}})
    with pytest.raises(ConfigError, match="did you mean 'material'"):
        HopperConfig.from_dict({"materail": {}})


def test_few_cells_across_outlet_warns():
    with pytest.warns(ResolutionWarning):
        HopperConfig.from_dict({"numerics": {"cell_size": 0.0075}})


def test_toml_round_trip(tmp_path):
    cfg = HopperConfig.from_dict({"hopper": {"half_angle_deg": 30.0}, "run": {"end_time": 1.5}})
    path = tmp_path / "c.toml"
    path.write_text(cfg.to_toml())
    assert HopperConfig.from_toml(path) == cfg
    path.write_text("this is [not toml")
    with pytest.raises(ConfigError, match="not valid TOML"):
        HopperConfig.from_toml(path)


def test_signed_distance_is_exact_distance():
    geom = HopperGeometry()
    th = geom.half_angle
    # a point at distance d inside the cone wall, measured along its normal
    s = 0.1
    rw, zw, nr, nz = geometry.wall_point(s, geom)
    for d in (0.01, -0.005):
        r, z = rw - d * nr, zw - d * nz
        assert geometry.signed_distance(r, z, geom) == pytest.approx(d, abs=1e-12)
        n = geometry.wall_normal(r, z, geom)
        assert n[0] == pytest.approx(math.cos(th)) and n[1] == pytest.approx(-math.sin(th))
    # bin wall and axis
    assert geometry.signed_distance(0.0, 0.5, geom) == pytest.approx(0.15)
    assert geometry.signed_distance(0.16, 0.5, geom) == pytest.approx(-0.01)
    # below the outlet: the free-fall tube of the outlet's radius
    assert geometry.signed_distance(0.02, -0.02, geom) == pytest.approx(0.01)
    assert geometry.signed_distance(0.04, -0.02, geom) == pytest.approx(-0.01)
    assert geometry.arc_length(geom.cone_height, geom) == pytest.approx(
        geometry.transition_arc_length(geom))


def test_grid_open_volume_matches_hopper_volume():
    cfg = HopperConfig.from_dict({"numerics": {"cell_size": 0.005, "min_open_fraction": 0.0}})
    g = build_grid(cfg)
    assert g.n_cells == g.mesh.numberOfCells
    above = g.z_cells[:, None] > 0
    inside = (g.z_cells[:, None] < cfg.hopper.fill_level - 1e-9)
    # open volume of full rows below the fill level vs the exact frustum + cylinder volume
    rows = above & inside
    vol = 2 * math.pi * np.sum((g.kappa * g.cell_volume)[rows[:, 0]])
    z_top = g.z_nodes[1:][rows[:, 0]].max()
    geom = cfg.hopper
    exact = geom.fill_volume() - math.pi * geom.bin_radius ** 2 * (geom.fill_level - z_top)
    assert vol == pytest.approx(exact, rel=2e-3)
    # the outlet plane is a grid line and its open faces span the outlet area
    assert g.z_nodes[g.j_outlet] == 0.0
    area = 2 * math.pi * np.sum((np.asarray(g.mesh._faceAreas) * g.face_aperture)[g.outlet_faces])
    assert area == pytest.approx(math.pi * geom.outlet_radius ** 2, rel=2e-3)
