"""The 3D keys of a run configuration: ``[hopper] dimensions``, ``outlet_offset``,
``[numerics] mirror_planes``, ``[run] wall_sectors``; each bad value refused in one line naming
the key, its value and what is allowed; the resolved configuration round-trips; a section's
configuration file is the one it was before the 3D keys existed."""

import copy
import warnings

import pytest

from fipy_hopper.config import ConfigError, HopperConfig

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

#: the small conical silo of the 3D tests (fipy_hopper.space.config.small_silo) at 2 cm
SMALL = {"hopper": {"bin_diameter": 0.28, "half_angle_deg": 30.0, "outlet_diameter": 0.12,
                    "bin_height": 0.16, "fill_height": 0.1, "dimensions": 3},
         "numerics": {"cell_size": 0.02}}


def config(**sections):
    data = copy.deepcopy(SMALL)
    for name, keys in sections.items():
        data.setdefault(name, {}).update(keys)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict(data)


def refusal(**sections) -> str:
    with pytest.raises(ConfigError) as info:
        config(**sections)
    message = str(info.value)
    assert "\n" not in message and len(message) < 400
    return message


def test_a_3d_configuration_round_trips_and_maps_to_the_3d_settings():
    from fipy_hopper.space.config import SpaceConfig
    cfg = config(hopper={"outlet_offset": 0.04}, numerics={"mirror_planes": "none"},
                 run={"wall_sectors": 24, "end_time": 0.2})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = HopperConfig.from_dict(tomllib.loads(cfg.to_toml()))
    assert again == cfg
    assert cfg.run.markers_per_side == 0             # the default 2 resolves to none in 3D
    space = SpaceConfig.from_config(cfg)
    assert (space.outlet_offset, space.mirror_planes, space.wall_sectors) == (0.04, "none", 24)
    assert space.to_config() is cfg and space.to_toml() == cfg.to_toml()
    assert cfg.grid_shape() == (18, 18, 22) and cfg.n_cells == 18 * 18 * 22   # the whole


def test_a_section_file_has_no_3d_keys():
    """A section's resolved configuration is written as before (so its run's fingerprint,
    and a checkpoint's, are unchanged)."""
    text = HopperConfig().to_toml()
    for key in ("dimensions", "outlet_offset", "mirror_planes", "wall_sectors"):
        assert key not in text
    assert HopperConfig.from_dict(tomllib.loads(text)) == HopperConfig()


@pytest.mark.parametrize("sections, words", [
    ({"hopper": {"dimensions": 4}}, "hopper.dimensions = 4: expected 2"),
    ({"hopper": {"dimensions": "3"}}, "hopper.dimensions = '3': expected 2"),
    ({"hopper": {"outlet_offset": 0.08}}, "hopper.outlet_offset = 0.08 m puts the outlet"),
    ({"hopper": {"outlet_offset": -0.01}}, "hopper.outlet_offset = -0.01 m: allowed range"),
    ({"hopper": {"outlet_offset": 0.04, "dimensions": 2}},
     "hopper.outlet_offset = 0.04 m is for hopper.dimensions = 3"),
    ({"numerics": {"formulation": "lagrangian"}}, 'numerics.formulation = "lagrangian" is for'),
    ({"run": {"opening_time": 0.1}}, "run.opening_time = 0.1 s: the 3D model"),
    ({"run": {"markers_per_side": 3}}, "run.markers_per_side = 3: the 3D model"),
    ({"numerics": {"mirror_planes": "quarter"}, "hopper": {"outlet_offset": 0.04}},
     'numerics.mirror_planes = "quarter" needs a centred outlet'),
    ({"numerics": {"mirror_planes": "eighth"}}, "numerics.mirror_planes = 'eighth': expected"),
    ({"run": {"wall_sectors": 0}}, "run.wall_sectors = 0: expected an integer in [1, 360]"),
    ({"hopper": {"dimensions": 2}, "run": {"wall_sectors": 24}},
     "run.wall_sectors = 24 is for hopper.dimensions = 3"),
    ({"hopper": {"dimensions": 2}, "numerics": {"mirror_planes": "none"}},
     'numerics.mirror_planes = "none" is for hopper.dimensions = 3'),
    ({"numerics": {"cell_size": 0.0004}}, "makes a 3D grid (its computed part) of"),
])
def test_bad_3d_input_is_refused_in_one_line(sections, words):
    assert words in refusal(**sections)


def test_shapes_3d_does_not_compute_are_refused():
    wedge = {"shape": "wedge", "bin_width": 0.28, "outlet_width": 0.12, "bin_height": 0.16,
             "fill_height": 0.1, "half_angle_deg": 30.0, "dimensions": 3}
    data = {"hopper": wedge, "numerics": {"cell_size": 0.02}}
    with pytest.raises(ConfigError, match="computes a circular silo .* not a wedge"):
        HopperConfig.from_dict(data)
    plane = {"shape": "profile", "symmetry": "plane", "wall": [[0.06, 0.0], [0.14, 0.14],
                                                                [0.14, 0.3]],
             "fill_level": 0.2, "dimensions": 3}
    with pytest.raises(ConfigError, match="not a plane profile"):
        HopperConfig.from_dict({"hopper": plane, "numerics": {"cell_size": 0.02}})
    insert = dict(SMALL["hopper"], inserts=[{"outline": [[0.0, 0.15], [0.05, 0.15],
                                                         [0.0, 0.2]]}])
    assert HopperConfig.from_dict({"hopper": insert, "numerics": {"cell_size": 0.02}}
                                  ).hopper.inserts                  # centred: a 3D insert
    off_centre = dict(insert, outlet_offset=0.03)
    with pytest.raises(ConfigError, match="hopper.inserts: 1 insert given with "
                       "hopper.outlet_offset = 0.03 m; inserts in 3D .* need a centred"):
        HopperConfig.from_dict({"hopper": off_centre, "numerics": {"cell_size": 0.02}})
