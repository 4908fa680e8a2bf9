"""A run either gives a whole summary or says that it failed; what cannot be computed is
refused before it runs.

An error inside the summary of a run that ended as it should fails the run (exit code 1,
one line, ``stop_reason`` ``"failed: ..."``, the traceback in ``error.log``, the manifest
``"failed"``): never a summary of nulls with exit code 0.  A profile filled below its bin is
a silo like any other: its summary is computed (no Janssen switch at a transition the fill
does not reach, no load on the bin wall).  A fill too thin for the grid is refused by
``validate`` in one line naming the key, its value and the allowed range.
"""

import json
import warnings
from pathlib import Path

import pytest

from fipy_hopper import diagnostics
from fipy_hopper.cli import main
from fipy_hopper.config import ConfigError, HopperConfig

BELOW = """\
[hopper]
shape = "profile"
wall = [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]]
fill_level = {level}

[numerics]
cell_size = 0.01
gravity_ramp_time = 0.05
{numerics}
[run]
end_time = 0.1
output_interval = 0.01
field_interval = 0.05
"""


def config(folder: Path, level=0.08, numerics="") -> Path:
    path = folder / "below.toml"
    path.write_text(BELOW.format(level=level, numerics=numerics))
    return path


def error_lines(err: str) -> list:
    return [line for line in err.splitlines() if "warning:" not in line]


def test_a_profile_filled_below_its_bin_gets_a_whole_summary(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(config(tmp_path)), "--out", str(out), "--quiet"]) == 0
    assert not error_lines(capsys.readouterr().err)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "end_time"
    assert summary["flow_mode"] in ("mass", "funnel")
    for key in ("steady_discharge_rate_kg_s", "wall_slip_ratio", "mass_flow_index",
                "remaining_mass_kg", "mass_balance_error", "fill_weight_N",
                "hopper_meridional_tension_N_m"):
        assert summary[key] is not None, key
    assert summary["walker_switch_pressure_Pa"] is None       # no switch: no fill there
    assert summary["switch_peak_Pa"] is None and summary["switch_peak_s_m"] is None
    assert summary["janssen_wall_axial_compression_N_m"] == 0.0   # nothing in the bin
    assert summary["bin_wall_axial_compression_N_m"] == 0.0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "finished"


def test_an_error_in_the_summary_fails_the_run(tmp_path, capsys, monkeypatch):
    def broken(sim):
        raise ValueError("z must lie in [0, inf) m; got -0.04 m")

    monkeypatch.setattr(diagnostics, "load_summary", broken)
    out = tmp_path / "run"
    code = main(["run", str(config(tmp_path)), "--out", str(out), "--quiet"])
    err = error_lines(capsys.readouterr().err)
    assert code == 1 and len(err) == 1, err
    assert "the run failed: the results could not be computed: ValueError: z must lie" \
        in err[0] and "error.log" in err[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"].startswith("failed: the results could not be computed")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "failed" and manifest["stop_reason"] == summary["stop_reason"]
    assert "ValueError: z must lie" in (out / "error.log").read_text()
    assert not (out / ".lock").exists()


def test_the_python_api_raises_it_too(tmp_path, monkeypatch):
    from fipy_hopper import api

    def broken(sim):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(diagnostics, "load_summary", broken)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(api.ResultsError, match="ZeroDivisionError"):
            api.run(config(tmp_path), tmp_path / "run", plots=False, checkpoint_interval=0)


@pytest.mark.parametrize("hopper, words", [
    ('shape = "profile"\nwall = [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]]\nfill_level = 0.001',
     ["hopper.fill_level = 0.001 m", "less than 2 cells", "allowed range is [0.02, 0.4] m"]),
    ("half_angle_deg = 90\nbin_diameter = 0.2\noutlet_diameter = 0.06\nbin_height = 0.3\n"
     "fill_height = 0.001",
     ["hopper.fill_height = 0.001 m", "less than 2 cells", "allowed range is [0.02, 0.3] m"]),
])
def test_a_fill_thinner_than_the_grid_is_refused_by_validate(tmp_path, capsys, hopper, words):
    path = tmp_path / "thin.toml"
    path.write_text(f"[hopper]\n{hopper}\n[numerics]\ncell_size = 0.01\n")
    assert main(["validate", str(path)]) == 2
    err = error_lines(capsys.readouterr().err)
    assert len(err) == 1, err
    for word in words:
        assert word in err[0], (word, err[0])


def test_a_fill_of_two_cells_is_allowed():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        HopperConfig.from_dict({"hopper": {"shape": "profile", "fill_level": 0.02,
                                           "wall": [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]]},
                                "numerics": {"cell_size": 0.01}})


def test_the_lagrangian_mesh_refuses_a_fill_below_the_bin():
    with pytest.raises(ConfigError, match=r'"lagrangian" meshes a fill that reaches the bin; '
                                          r'hopper.fill_level = 0.08 m'):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            HopperConfig.from_dict({
                "hopper": {"shape": "profile", "fill_level": 0.08,
                           "wall": [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]]},
                "numerics": {"cell_size": 0.01, "formulation": "lagrangian",
                             "bulk_viscosity": 0.0}})
