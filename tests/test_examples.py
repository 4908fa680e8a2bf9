"""Every ``examples/*.toml`` validates and runs a short setting that still shows its point.

Each example is checked as a user would first meet it: ``fipy-hopper validate FILE`` accepts it
(exit 0), and the file, read by ``fh.load_config`` and shortened through the API (1 cm cells,
no marker points, a short or capped discharge: ``SHORT``), runs to its own outcome:

* ``wedge``: plane flow, results per metre, mass flow (a 20 deg wedge, steeper than Jenike's
  plane-flow angle for these frictions);
* ``cohesive_arching``: the outlet opens and the flow stops on an arch (``no_flow``) with
  nearly all the mass standing;
* ``flat_bottom``: a flat floor (no hopper factor: Rose-Tanaka's is 1) discharges near
  Beverloo's flat-bottom rate (a correlation with C = 0.58 from a range of 0.55-0.65, on a
  grid of 3 cells across the outlet radius, over the first 0.4 s: within 25 %);
* ``fill_only``: stops filled and at rest, the walls and the plate carrying the weight, with
  the wall loads at rest written;
* ``lagrangian``: the moving mesh distorts early in the discharge and the run says so (its
  time step is a fifth of the grid's, so here gravity is ramped over 0.1 s, not ten column
  periods);
* ``fine_2p5mm``: its own grid has four times the demo's cells; on the short setting it is the
  reference hopper and discharges near Beverloo x Rose-Tanaka;
* ``off_centre_3d``: the whole silo in 3D (2 cm cubes on the short setting), its outlet off the
  axis: the wall pressure around the circumference at rest and in discharge, the flow mode per
  sector, the mass balance.

A new example must get its case here (``test_every_example_has_a_short_case``).  About 30 s
on one thread with the kernels compiled.
"""

import math
import pathlib
import warnings

import pytest

import fipy_hopper as fh
from fipy_hopper.cli import main

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"
REFERENCE = pathlib.Path(__file__).resolve().parents[1] / "studies" / "configs" / "reference.toml"

# the short setting of each example: run-section overrides (cells: 1 cm, no markers)
SHORT = {
    "wedge": {"end_time": 0.3},
    "cohesive_arching": {"end_time": "empty", "max_time": 1.5},
    "flat_bottom": {"end_time": 0.4},
    "fill_only": {},
    "lagrangian": {"end_time": "empty", "max_time": 0.5},
    "fine_2p5mm": {"end_time": 0.3},
    "off_centre_3d": {"end_time": 0.15, "output_interval": 0.025},
}
SHORT_NUMERICS = {"lagrangian": {"gravity_ramp_time": 0.1}, "off_centre_3d": {"cell_size": 0.02}}


def short_run(name, tmp_path):
    cfg = fh.load_config(EXAMPLES / f"{name}.toml")
    run = {"markers_per_side": 0, "field_interval": 0.1, **SHORT[name]}
    if cfg.run.end_time == 0.0:
        run.pop("field_interval")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # 3 cells across the outlet radius are few
        numerics = {"cell_size": 0.01, **SHORT_NUMERICS.get(name, {})}
        short = cfg.replace(numerics=numerics, run=run)
        summary = fh.run(short, tmp_path / name, force=True)
    return cfg, summary


def test_every_example_has_a_short_case():
    assert sorted(p.stem for p in EXAMPLES.glob("*.toml")) == sorted(SHORT)
    readme = (EXAMPLES / "README.md").read_text(encoding="utf-8")
    for name in SHORT:
        assert f"`{name}.toml`" in readme, name


@pytest.mark.parametrize("name", sorted(SHORT))
def test_example_validates(name, capsys):
    assert main(["validate", str(EXAMPLES / f"{name}.toml")]) == 0
    assert f"{name}.toml: valid" in capsys.readouterr().out


def test_wedge_discharges_in_mass_flow_per_metre(tmp_path):
    cfg, s = short_run("wedge", tmp_path)
    assert cfg.hopper.shape == "wedge"
    assert s["flow_mode"] == "mass"
    assert s["steady_discharge_rate_kg_s_m"] > 0.0 and "steady_discharge_rate_kg_s" not in s
    assert s["mass_balance_error"] < 1e-9


def test_cohesive_powder_arches(tmp_path):
    cfg, s = short_run("cohesive_arching", tmp_path)
    assert cfg.material.cohesion > 0.0
    assert s["jenike_critical_outlet_m"] > cfg.hopper.outlet_diameter
    assert s["flow_mode"] == "no_flow" and s["stop_reason"] == "at_rest"
    assert s["remaining_mass_fraction"] > 0.9


def test_flat_bottom_discharges_near_beverloo(tmp_path):
    cfg, s = short_run("flat_bottom", tmp_path)
    assert cfg.hopper.half_angle_deg == 90.0
    assert fh.api.expected_quantities(cfg)["rose_tanaka_factor"] == 1.0
    assert s["steady_discharge_rate_kg_s"] == pytest.approx(s["beverloo_rate_kg_s"], rel=0.25)


def test_fill_only_stops_at_rest_with_the_wall_loads(tmp_path):
    cfg, s = short_run("fill_only", tmp_path)
    assert cfg.run.end_time == 0.0
    assert s["stop_reason"] == "filled" and s["fill_at_rest"] is True
    assert s["fill_equilibrium_residual"] < 5e-3
    at_rest = fh.read_results(tmp_path / "fill_only").wall_stage("filling")
    assert len(at_rest["p_n_Pa"]) > 10 and min(at_rest["p_n_Pa"]) >= 0.0
    assert max(at_rest["p_n_Pa"]) > 0.0


def test_lagrangian_mesh_distorts_early(tmp_path):
    cfg, s = short_run("lagrangian", tmp_path)
    assert cfg.numerics.formulation == "lagrangian"
    assert s["stop_reason"] == "mesh_distorted"
    assert s["remaining_mass_fraction"] > 0.7


def test_fine_example_is_the_reference_at_half_the_cell_size(tmp_path):
    reference = fh.load_config(REFERENCE)
    fine = fh.load_config(EXAMPLES / "fine_2p5mm.toml")
    assert fine.numerics.cell_size == reference.numerics.cell_size / 2
    assert fine.replace(numerics={"cell_size": reference.numerics.cell_size}) == reference
    _, s = short_run("fine_2p5mm", tmp_path)
    assert s["steady_discharge_rate_kg_s"] == pytest.approx(s["beverloo_rate_kg_s"], rel=0.15)
    assert math.isfinite(s["mass_flow_index"])


def test_off_centre_3d_maps_the_wall_around_the_circumference(tmp_path):
    """The 3D example on 2 cm cubes: the half y >= 0 computed, the wall pressure in 12 sectors
    at rest and in discharge with its largest over smallest around the circumference, the
    flow mode per sector, the mass balance, the 3D pictures."""
    cfg, summary = short_run("off_centre_3d", tmp_path)
    assert summary["dimensions"] == 3 and summary["outlet_offset_m"] == 0.06
    assert summary["mirror_factor"] == 2.0 and summary["mass_balance_error"] < 1e-9
    assert len(summary["flow_mode_by_sector"]) == 12
    ratio = summary["filling_wall_pressure_max_over_min"]
    assert all(r >= 1.0 for r in ratio if r is not None)
    assert summary["discharge_envelope_wall_pressure_max_over_min_largest"] > 1.0
    for name in ("flow_plane.png", "wall_circumference.png", "wall_unrolled.png",
                 "wall_extremes.csv"):
        assert (tmp_path / "off_centre_3d" / name).is_file(), name

