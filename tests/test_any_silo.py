"""Any silo a designer draws: the boundary as data runs the same as the shorthands
it generalises, a full plane section mirrors the half one, an insert away from the material
changes nothing, and new shapes keep the mass and the vertical balance (coarse, short runs)."""

import filecmp
import math
import warnings

import numpy as np
import pytest

import fipy_hopper as fh
from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel

RUN = {"output_interval": 0.02, "field_interval": 0.1, "markers_per_side": 1}


def config(data) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict(data)


def shorthand(shape="conical", cell=0.01, end=0.3):
    data = HopperConfig().to_dict()
    data["numerics"]["cell_size"] = cell
    data["run"].update(end_time=end, **RUN)
    if shape == "wedge":
        data["hopper"].update(shape="wedge", bin_width=data["hopper"].pop("bin_diameter"),
                              outlet_width=data["hopper"].pop("outlet_diameter"))
    return data


def as_profile(data, **hopper):
    """The shorthand's silo written as a profile: the wall from the lip to the top."""
    g = config(data).hopper
    out = {k: dict(v) for k, v in data.items()}
    out["hopper"] = {"shape": "profile",
                     "symmetry": "axisymmetric" if g.axisymmetric else "plane",
                     "wall": [[g.outlet_radius, 0.0], [g.bin_radius, g.cone_height],
                              [g.bin_radius, g.top]],
                     "fill_level": g.fill_level, **hopper}
    return out


def same_summary(a: dict, b: dict, skip=("wall_time_s",)) -> list:
    """The keys of ``a`` whose values differ in ``b`` (NaN equals NaN)."""
    def equal(x, y):
        if isinstance(x, float) and isinstance(y, float):
            return x == y or (math.isnan(x) and math.isnan(y))
        return x == y
    return [k for k in a if k not in skip and not equal(a[k], b.get(k))]


@pytest.mark.parametrize("shape", ["conical", "wedge"])
def test_the_shorthand_written_as_a_profile_gives_the_same_results(shape, tmp_path):
    """The reference hopper (and the reference wedge, as a plane profile) written as
    ``shape = "profile"``: the summary equal but for the wall time, the CSVs byte for byte."""
    data = shorthand(shape)
    a = fh.run(config(data), tmp_path / "shorthand", threads=1)
    b = fh.run(config(as_profile(data)), tmp_path / "profile", threads=1)
    assert same_summary(a, b) == []
    for name in ("timeseries.csv", "wall_pressure.csv", "loads.csv", "wall_slip.csv"):
        assert filecmp.cmp(tmp_path / "shorthand" / name, tmp_path / "profile" / name,
                           shallow=False), name


def full_section(data):
    """The wedge's section drawn whole: its wall and the mirror image, a centred slot."""
    out = as_profile(data, section="full")
    out["hopper"]["left_wall"] = [[-x, z] for x, z in out["hopper"]["wall"]]
    return out


def test_a_full_section_with_a_centred_slot_is_the_wedge(tmp_path):
    """The reference wedge (the shorthand computes one half and reports both) against the
    same section drawn whole: the weight and the steady rate within 0.5 %, and the loads on
    the two walls mirror images of each other (within 2 % L2) at rest and in discharge."""
    data = shorthand("wedge", cell=0.0075, end=0.6)
    a = fh.run(config(data), tmp_path / "half", threads=1)
    b = fh.run(config(full_section(data)), tmp_path / "full", threads=1)
    assert b["fill_weight_N_m"] == pytest.approx(a["fill_weight_N_m"], rel=0.005)
    assert b["initial_mass_kg_m"] == pytest.approx(a["initial_mass_kg_m"], rel=0.005)
    assert b["steady_discharge_rate_kg_s_m"] == pytest.approx(
        a["steady_discharge_rate_kg_s_m"], rel=0.005)
    wall = fh.read_results(tmp_path / "full").wall_pressure
    for stage in ("filling", "early_discharge"):
        right = (wall["stage"] == stage) & (wall["wall"] == "wall")
        left = (wall["stage"] == stage) & (wall["wall"] == "left_wall")
        p_r, p_l = wall["p_n_Pa"][right], wall["p_n_Pa"][left]
        assert len(p_r) == len(p_l) > 10
        np.testing.assert_allclose(wall["s_m"][right], wall["s_m"][left])
        assert np.linalg.norm(p_r - p_l) / np.linalg.norm(p_r) < 0.02, stage


PLAIN = {"shape": "profile", "wall": [[0.03, 0.0], [0.15, 0.2], [0.15, 0.5]],
         "fill_level": 0.3}


NEAR_BASE = {"numerics": {"cell_size": 0.01}, "run": {"end_time": 0.3, **RUN}}
#: inserts the material never touches: an inverted cone well above the fill, and a box on
#: the axis 3.5 cells above it (the strip behind its top face runs down through the material:
#: the contact once held that whole column up, and the discharge stopped)
ABOVE = {"far": [[0.0, 0.48], [0.05, 0.44], [0.0, 0.40]],
         "box 3.5 cells above": [[0.0, 0.335], [0.05, 0.335], [0.05, 0.375], [0.0, 0.375]]}


@pytest.fixture(scope="module")
def plain_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plain") / "plain"
    return fh.run(config({"hopper": PLAIN, **NEAR_BASE}), folder, threads=1), folder


@pytest.mark.parametrize("outline", list(ABOVE.values()), ids=list(ABOVE))
def test_an_insert_above_the_fill_changes_nothing(outline, plain_run, tmp_path):
    """An insert above the material: the plain hopper's results to the bit (its time series
    and its wall's loads), the insert carrying nothing, and no contact of the insert at a
    node outside it further than half a cell from it."""
    plain, plain_dir = plain_run
    hopper = {**PLAIN, "inserts": [{"outline": outline}]}
    cfg = config({"hopper": hopper, **NEAR_BASE})
    model = HopperModel(cfg)
    j, i, _, _ = model.contact_list
    bnd, g = model.boundary, model.grid
    kinds = np.array([c.kind for c in bnd.chains])
    on_insert = kinds[bnd.table.chain[model.contact_owner]] == "insert"
    x, z = g.r_nodes[i[on_insert]], g.z_nodes[j[on_insert]]
    assert np.all(bnd.in_solid(x, z) | (np.abs(bnd.signed_distance(x, z)) < 0.5 * g.h))
    insert = fh.run(cfg, tmp_path / "insert", threads=1)
    assert same_summary(plain, insert) == []
    assert insert["insert_1_vertical_force_N"] == 0.0
    assert filecmp.cmp(plain_dir / "timeseries.csv",
                       tmp_path / "insert" / "timeseries.csv", shallow=False)
    a = fh.read_results(plain_dir).wall_pressure
    b = fh.read_results(tmp_path / "insert").wall_pressure
    on_wall = b["wall"] == "wall"
    for column in ("s_m", "p_n_Pa", "tau_Pa", "p_n_raw_Pa", "p_n_stress_Pa"):
        np.testing.assert_array_equal(a[column], b[column][on_wall], err_msg=column)
    assert np.all(b["p_n_Pa"][~on_wall] == 0.0)


SHAPES = {
    "two slopes": {"hopper": {"shape": "profile", "fill_level": 0.4, "wall": [
        [0.03, 0.0], [0.06, 0.1], [0.15, 0.2], [0.15, 0.5]]}, "numerics": {"cell_size": 0.01}},
    "insert": {"hopper": {"shape": "profile", "fill_level": 0.4,
                          "wall": [[0.03, 0.0], [0.15, 0.2], [0.15, 0.5]],
                          "inserts": [{"outline": [[0.0, 0.22], [0.06, 0.16], [0.0, 0.12]]}]},
               "numerics": {"cell_size": 0.01}},
    "off-centre slot": {"hopper": {"shape": "profile", "symmetry": "plane", "section": "full",
                                   "fill_level": 0.3,
                                   "wall": [[0.0, 0.0], [0.15, 0.0], [0.15, 0.5]],
                                   "left_wall": [[-0.04, 0.0], [-0.15, 0.0], [-0.15, 0.5]]},
                        "numerics": {"cell_size": 0.005}},
}


@pytest.fixture(scope="module", params=list(SHAPES), ids=list(SHAPES))
def shape_run(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp("shape")
    data = {**SHAPES[request.param], "run": {"end_time": 0.3, **RUN}}
    cfg = config(data)
    return request.param, cfg, fh.run(cfg, folder / "run", threads=1), folder / "run"


def test_new_shapes_keep_the_mass_and_the_vertical_balance(shape_run):
    """A two-slope hopper, a hopper with an inverted-cone insert and a flat-bottomed plane
    silo with an off-centre slot: mass balance to 1e-9, the vertical balance at rest within
    0.5 % of the weight (the walls, the insert and the plate carry it) and to round-off in
    every row of loads.csv; an insert's load at rest is in loads.csv's wall column and its
    own, and is the weight of some of the material above it, less than all of it."""
    name, cfg, summary, folder = shape_run
    weight = "fill_weight_N_m" if not cfg.hopper.axisymmetric else "fill_weight_N"
    assert summary["mass_balance_error"] < 1e-9
    assert summary["fill_equilibrium_residual"] < 0.005
    assert summary["load_balance_residual_max"] < 1e-9
    assert summary["stop_reason"] == "end_time"
    if name == "insert":
        load = summary["insert_1_vertical_force_N"]
        assert 0.0 < load < summary[weight]
        from fipy_hopper.io import read_csv
        loads = read_csv(folder / "loads.csv")
        assert "insert_1_vertical_N" in loads
        rest = loads["stage"] == "filling"
        assert np.all(np.abs(loads["insert_1_vertical_N"][rest])
                      <= np.abs(loads["wall_vertical_N"][rest]) + 1e-9)


def test_every_hopper_stretch_gets_its_own_call(shape_run):
    """The summary's ``hopper_stretches``: one entry per sloping or flat wall segment with its
    slope, its slip ratio and call, and Jenike's angle for it."""
    name, cfg, summary, _ = shape_run
    stretches = summary["hopper_stretches"]
    n = {"two slopes": 2, "insert": 1, "off-centre slot": 2}[name]
    assert len(stretches) == n
    for st in stretches:
        assert st["call"] in ("mass", "funnel") and st["jenike_call"] in ("mass", "funnel")
        assert 0.0 < st["half_angle_deg"] <= 90.0
