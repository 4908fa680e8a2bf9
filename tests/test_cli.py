"""The ``fipy-hopper`` command line end to end on a coarse, short hopper (a few seconds a run).

One run of ``fipy-hopper run`` is shared by the tests of its outputs: the run directory's
files exist, the CSV and JSON files parse with the contract's columns and keys, the pictures
are non-empty PNG/GIF files, and the VTU series reads back with meshio with the named fields
at the expected times.  Then: ``validate``, ``plot``, ``--help``, overwrite protection and a
run that goes unstable (exit code 1, everything measured so far kept).
"""

import json
import os
import shutil
import subprocess
import sys
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import fipy_hopper as fh
from fipy_hopper import io, summary_text, theory
from fipy_hopper.cli import main
from fipy_hopper.config import HopperConfig
from fipy_hopper.io import read_csv

COARSE = """\
[hopper]
bin_diameter = 0.2
outlet_diameter = 0.06
bin_height = 0.25
fill_height = 0.15

[numerics]
cell_size = 0.01
gravity_ramp_time = 0.05

[run]
end_time = 0.2
output_interval = 0.02
field_interval = 0.05
"""

SUMMARY_KEYS = ("steady_discharge_rate_kg_s", "flow_mode", "mass_flow_index", "initial_mass_kg",
                "remaining_mass_kg", "mass_balance_error", "discharge_time_s", "stop_reason",
                "cells", "steps", "wall_time_s", "youngs_modulus_used")
TIMESERIES = ["t_s", "mass_in_hopper_kg", "discharged_kg", "discharge_rate_kg_s"]
WALL = ["stage", "wall", "t_s", "s_m", "r_m", "z_m", "p_n_Pa", "tau_Pa", "p_n_stress_Pa", "tau_stress_Pa",
        "p_n_raw_Pa", "tau_raw_Pa", "window_s", "hoop_force_N_m", "meridional_force_N_m"]
CELL_FIELDS = ("alpha", "layer", "velocity", "stress_rr", "stress_zz", "stress_tt", "stress_rz",
               "pressure", "plastic_strain")
REPO = Path(__file__).resolve().parents[1]


def coarse_config(folder: Path) -> Path:
    path = folder / "coarse.toml"
    path.write_text(COARSE)
    return path


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    out = folder / "run"
    code = main(["run", str(coarse_config(folder)), "--out", str(out), "--quiet"])
    assert code == 0
    return out


def test_run_directory_has_every_output(run_dir):
    for name in ("config.toml", "manifest.json", "summary.json", "summary.txt", "timeseries.csv",
                 "wall_pressure.csv", "fields/fields.pvd", "fields/snapshots.csv",
                 "flow_pattern.png", "discharge.png", "wall_pressure.png", "wall_forces.png",
                 "discharge.gif"):
        assert (run_dir / name).is_file(), name
    assert not (run_dir / "checkpoint.npz").exists()       # removed when the run finished
    assert not list(run_dir.rglob(".*.tmp*"))               # no temporary files left


def test_resolved_config_and_manifest(run_dir):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        saved = HopperConfig.from_toml(run_dir / "config.toml")
        given = HopperConfig.from_toml(run_dir.parent / "coarse.toml")
    assert saved == given
    text = tomllib.loads((run_dir / "config.toml").read_text())
    for section in ("hopper", "material", "wall", "numerics", "run"):   # every key resolved
        assert set(text[section]) == set(saved.to_dict()[section])
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["package"] == "fipy_hopper" and manifest["version"] == fh.__version__
    for dep in ("fipy", "numpy", "scipy", "numba", "matplotlib", "meshio"):
        assert manifest["dependencies"][dep]
    assert manifest["start_time"] <= manifest["end_time"]
    assert manifest["wall_time_s"] > 0
    assert manifest["status"] == "finished" and manifest["stop_reason"] == "end_time"
    # the code that ran: the commit of the checkout the package came from ("" if installed)
    assert manifest["code_commit"] == io.code_commit()
    assert manifest["sessions"][0]["code_commit"] == manifest["code_commit"]


def test_code_commit_names_the_checkout_of_the_package():
    """In a git checkout the commit is git's own short hash of HEAD, marked when the
    package's files differ from it; an installed copy (no checkout) gives ""."""
    commit = io.code_commit()
    package = Path(fh.__file__).resolve().parent
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=package,
                          capture_output=True, text=True)
    tracked = subprocess.run(["git", "ls-files", "--error-unmatch", "__init__.py"],
                             cwd=package, capture_output=True, text=True)
    if head.returncode != 0 or tracked.returncode != 0:
        assert commit == ""
        return
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "."], cwd=package,
                           capture_output=True, text=True).stdout.strip()
    assert commit == head.stdout.strip() + (" (with uncommitted changes)" if dirty else "")


def test_summary_json_contract(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    for key in SUMMARY_KEYS:
        assert key in summary, key
    assert summary["flow_mode"] in ("mass", "funnel")
    assert summary["stop_reason"] == "end_time"
    assert summary["steady_discharge_rate_kg_s"] > 0
    assert summary["mass_balance_error"] < 1e-9
    assert summary["discharge_time_s"] == pytest.approx(0.2, abs=0.005)
    assert summary["initial_mass_kg"] == pytest.approx(
        summary["remaining_mass_kg"] + summary["discharged_kg"], rel=1e-9)


def test_summary_txt_is_summary_json_as_text(run_dir):
    """``summary.txt`` is the summary's lines (:func:`summary_text.summary_lines`) of ``summary.json``:
    the same data, as the terminal shows it."""
    summary = json.loads((run_dir / "summary.json").read_text())
    text = (run_dir / "summary.txt").read_text(encoding="utf-8")
    assert text == "\n".join(summary_text.summary_lines(summary, str(run_dir))) + "\n"
    assert text.startswith("fipy-hopper: end_time after ")


def test_every_key_of_the_summary_is_defined_in_the_usage_page(run_dir):
    """Each key of a run's ``summary.json`` is named in ``docs/usage.md`` (in backticks), or
    is the discharge form ``<name>_discharge_<unit>`` of a named key that the page gives
    as ``*_discharge_*``: a number a user reads is defined where the user looks it up."""
    page = (Path(__file__).resolve().parents[1] / "docs" / "usage.md").read_text()
    assert "`*_discharge_*`" in page

    def defined(key):
        return f"`{key}`" in page or ("_discharge_" in key
                                      and f"`{key.replace('_discharge_', '_')}`" in page)

    summary = json.loads((run_dir / "summary.json").read_text())
    assert len(summary) > 40
    assert [k for k in summary if not defined(k)] == []


def test_summary_txt_holds_what_the_terminal_showed(tmp_path, capsys):
    """A run prints its summary and writes the same text to ``summary.txt``: the discharge
    rate, the flow mode and where the results are."""
    cfg = coarse_config(tmp_path)
    cfg.write_text(cfg.read_text().replace("end_time = 0.2", "end_time = 0.05"))
    out = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    text = (out / "summary.txt").read_text(encoding="utf-8")
    assert text == printed
    summary = json.loads((out / "summary.json").read_text())
    lines = text.splitlines()
    assert lines[0].startswith("fipy-hopper: end_time after ")
    assert any(line.startswith("  steady discharge rate  "
                               f"{summary['steady_discharge_rate_kg_s']:.4g} kg/s")
               for line in lines), lines
    assert any(line.startswith(f"  flow mode              {summary['flow_mode']} (")
               for line in lines), lines
    assert lines[-1] == f"  results in             {out}/"


def test_timeseries_and_wall_pressure_csv(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    header = (run_dir / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == TIMESERIES
    ts = read_csv(run_dir / "timeseries.csv")
    assert len(ts["t_s"]) >= 10 and ts["t_s"][0] == 0.0
    assert np.all(np.diff(ts["t_s"]) > 0)
    m0 = summary["initial_mass_kg"]
    np.testing.assert_allclose(ts["mass_in_hopper_kg"] + ts["discharged_kg"], m0, rtol=1e-9)
    assert ts["mass_in_hopper_kg"][-1] == pytest.approx(summary["remaining_mass_kg"], rel=1e-12)
    assert (run_dir / "wall_pressure.csv").read_text().splitlines()[0].split(",") == WALL
    loads = read_csv(run_dir / "loads.csv")
    assert set(loads["stage"]) == {"filling", "discharge"}
    assert np.all(loads["relative_residual"] < 1e-9)
    wall = read_csv(run_dir / "wall_pressure.csv")
    assert "filling" in set(wall["stage"])
    filled = wall["stage"] == "filling"
    assert filled.sum() >= 5 and np.all(wall["p_n_Pa"][filled] > 0)
    assert np.all(np.diff(wall["s_m"][filled]) > 0)


def test_pictures_are_non_empty_images(run_dir):
    from PIL import Image

    for name in ("flow_pattern.png", "discharge.png", "wall_pressure.png",
                 "wall_forces.png", "stress_pattern.png"):
        data = (run_dir / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
        with Image.open(run_dir / name) as im:
            assert im.size[0] > 300 and im.size[1] > 300
            assert len(np.unique(np.asarray(im.convert("L")))) > 10   # not a blank canvas
    with Image.open(run_dir / "discharge.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames >= 4


def test_field_series_reads_back_with_meshio(run_dir):
    import meshio

    summary = json.loads((run_dir / "summary.json").read_text())
    cfg = fh.read_results(run_dir).config
    snapshots = fh.read_results(run_dir).snapshots
    pvd = ET.parse(run_dir / "fields" / "fields.pvd").getroot()
    datasets = pvd.find("Collection").findall("DataSet")
    assert [d.get("file") for d in datasets] == [s["file"] for s in snapshots]
    times = np.array([float(d.get("timestep")) for d in datasets])
    assert np.all(np.diff(times) > 0)
    np.testing.assert_array_equal(times, [s["t_s"] for s in snapshots])

    # a snapshot when filling starts, at the start of discharge, then every field_interval of
    # simulated time (at the first check of 2 ms after it) and one of the final state
    interval = cfg.run.field_interval
    dis = [s for s in snapshots if s["stage"] == "discharge"]
    assert snapshots[0]["stage"] == "filling" and snapshots[0]["t_s"] < 0.01
    assert 0 < dis[0]["discharge_time_s"] < 0.003
    gaps = np.diff([s["discharge_time_s"] for s in dis[:-1]])
    assert np.all((gaps >= interval - 1e-9) & (gaps < interval + 0.0021))
    assert dis[-1]["step"] == summary["steps"]
    assert dis[-1]["discharge_time_s"] == pytest.approx(summary["discharge_time_s"], abs=1e-12)

    for entry in (snapshots[0], dis[-1]):
        mesh = meshio.read(run_dir / "fields" / entry["file"])
        assert len(mesh.cells_dict["quad"]) == summary["cells"]
        data = {k: v[0] for k, v in mesh.cell_data.items()}
        for name in CELL_FIELDS:
            assert name in data, name
            assert len(data[name]) == summary["cells"]
        assert data["velocity"].shape == (summary["cells"], 3)
        assert np.all((data["alpha"] >= -1e-12) & (data["alpha"] <= 1 + 1e-9))
        np.testing.assert_allclose(
            data["pressure"], -(data["stress_rr"] + data["stress_zz"] + data["stress_tt"]) / 3,
            rtol=1e-12, atol=1e-9)
        # the r-z plane: x = r >= 0, y = z, third coordinate 0
        assert mesh.points[:, 0].min() == 0.0 and np.all(mesh.points[:, 2] == 0.0)
    # material left through the outlet: less of it in the hopper at the end
    first = meshio.read(run_dir / "fields" / dis[0]["file"]).cell_data
    last = meshio.read(run_dir / "fields" / dis[-1]["file"]).cell_data
    assert np.max(last["velocity"][0][:, 1]) <= 0 or np.min(last["velocity"][0][:, 1]) < -0.1
    assert np.sum(last["alpha"][0]) != np.sum(first["alpha"][0])


def test_read_results_api(run_dir):
    res = fh.read_results(run_dir)
    assert res.summary["stop_reason"] == "end_time"
    assert set(TIMESERIES) <= set(res.timeseries)
    assert res.wall_stage("filling")["p_n_Pa"].size >= 5
    assert "alpha" in res.field(-1).cell_data


def test_plot_command(run_dir, tmp_path, capsys):
    (run_dir / "discharge.png").unlink()
    assert main(["plot", str(run_dir)]) == 0
    assert (run_dir / "discharge.png").stat().st_size > 10_000
    assert main(["plot", str(tmp_path)]) == 2
    assert "not a run directory" in capsys.readouterr().err


def test_validate_prints_derived_quantities(tmp_path, capsys):
    from fipy_hopper.mesh import build_grid

    path = coarse_config(tmp_path)
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_toml(path)
    grid = build_grid(cfg)
    bev = float(theory.beverloo_rate(1500.0, 0.06, d=cfg.material.grain_diameter)
                * theory.rose_tanaka_factor(20.0))
    theta_c = float(theory.jenike_critical_half_angle(30.0, 15.0))
    fill_mass = 1500.0 * cfg.hopper.fill_volume()
    for text in (f"{grid.n_cells} cells", "time step", "P-wave speed c_p",
                 f"{cfg.material.p_wave_speed:.4g} m/s", f"{bev:.4g} kg/s", "Rose-Tanaka",
                 f"{theta_c:.1f} deg", "mass flow", f"{fill_mass:.4g} kg",
                 "grains             d = 0.001 m, the outlet 60 grains across"):
        assert text in out.out, text
    assert "warning: only 3.0 cells across the outlet radius" in out.err
    assert "Traceback" not in out.err


def test_reference_config_file_equals_defaults():
    path = REPO / "studies" / "configs" / "reference.toml"
    assert fh.load_config(path) == HopperConfig()
    text = tomllib.loads(path.read_text())
    for section in ("hopper", "material", "wall", "numerics", "run"):
        assert set(text[section]) == set(HopperConfig().to_dict()[section])


def test_overwrite_refused_without_force(run_dir, capsys):
    before = (run_dir / "summary.json").stat().st_mtime_ns
    code = main(["run", str(run_dir.parent / "coarse.toml"), "--out", str(run_dir), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "not empty" in err and "--force" in err and "Traceback" not in err
    assert (run_dir / "summary.json").stat().st_mtime_ns == before
    assert main(["run", str(run_dir.parent / "coarse.toml"), "--out", str(run_dir),
                 "--resume"]) == 2                             # a finished run has no checkpoint


def test_force_overwrites(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "manifest.json").write_text('{"package": "fipy_hopper", "sessions": []}')
    (out / "summary.json").write_text("{}")
    (out / "notes.txt").write_text("mine")
    cfg = coarse_config(tmp_path)
    text = cfg.read_text().replace("end_time = 0.2", "end_time = 0.05")
    cfg.write_text(text)
    assert main(["run", str(cfg), "--out", str(out), "--force", "--quiet"]) == 0
    assert json.loads((out / "summary.json").read_text())["stop_reason"] == "end_time"
    assert (out / "notes.txt").read_text() == "mine"          # only its own files are replaced


def test_unstable_run_exits_1_and_keeps_its_outputs(tmp_path, monkeypatch, capsys):
    from fipy_hopper.model import HopperModel

    original = HopperModel.advance

    def blow_up(self, state, max_steps):     # a NaN appears 0.05 s into the discharge
        done = original(self, state, max_steps)
        if state.stage == "discharge":
            self._steps_open = getattr(self, "_steps_open", 0) + done
            if self._steps_open * self.dt > 0.05:
                state.v[1, 20, 3] = np.nan
        return done

    monkeypatch.setattr(HopperModel, "advance", blow_up)
    out = tmp_path / "run"
    code = main(["run", str(coarse_config(tmp_path)), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1
    assert "the run went unstable" in err and "at step" in err and "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    manifest = json.loads((out / "manifest.json").read_text())
    assert summary["stop_reason"].startswith("unstable: ") and "at step" in summary["stop_reason"]
    assert (out / "summary.txt").read_text().startswith(f"fipy-hopper: {summary['stop_reason']}")
    assert manifest["status"] == "failed" and manifest["stop_reason"] == summary["stop_reason"]
    ts = read_csv(out / "timeseries.csv")
    assert 2 <= len(ts["t_s"]) and ts["t_s"][-1] < 0.06
    snaps = fh.read_results(out).snapshots
    assert snaps[-1]["step"] == summary["steps"]             # the state that failed, for ParaView
    assert (out / "discharge.png").is_file()


def test_demo_runs_the_reference_hopper(monkeypatch):
    from fipy_hopper import api

    seen = {}

    def fake_run(config, out, **kwargs):
        seen.update(config=config, out=out, **kwargs)
        return {"stop_reason": "empty"}

    monkeypatch.setattr(api, "run", fake_run)
    assert main(["demo", "--quiet"]) == 0
    assert seen["config"] == HopperConfig() and seen["out"] == "hopper_run"
    assert seen["checkpoint_interval"] == 60.0 and not seen["force"]


@pytest.mark.slow
def test_demo_really_runs_the_reference_hopper_to_empty(tmp_path):
    """The demo itself, not a stand-in: the reference hopper from filling to empty with every
    output (about two minutes on two cores; in the slow suite)."""
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "empty" and summary["flow_mode"] == "mass"
    assert summary["mass_balance_error"] < 1e-9
    assert summary["fill_equilibrium_residual"] < 0.005
    beverloo = summary["beverloo_rate_kg_s"]
    assert abs(summary["steady_discharge_rate_kg_s"] / beverloo - 1) < 0.1
    for name in ("flow_pattern.png", "discharge.png", "wall_pressure.png", "stress_pattern.png",
                 "loads.csv", "wall_pressure.csv", "timeseries.csv", "fields/fields.pvd"):
        assert (out / name).is_file(), name


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["demo", "--help"],
                                  ["plot", "--help"], ["validate", "--help"], ["--version"]])
def test_help_everywhere(argv, capsys):
    assert main(argv) == 0
    assert "fipy-hopper" in capsys.readouterr().out


def test_force_leaves_nothing_of_the_earlier_run(run_dir, tmp_path, capsys):
    """A directory with every picture the package draws (:data:`plotting.PICTURES`: the
    discharge run's six, a Lagrangian mesh picture drawn into it, a 3D run's three (a
    rectangular plan's two more) and its ``wall_extremes.csv`` put there), then ``--force`` with a fill-only configuration, which
    draws fewer: the directory holds exactly what the same run writes into an empty one (no
    picture, table or snapshot of the earlier run)."""
    from fipy_hopper import plotting

    old = tmp_path / "old"
    shutil.copytree(run_dir, old)
    plotting._save(plotting.lagrangian_mesh(old), old / "lagrangian_mesh.png")
    for name in ("flow_plane.png", "wall_circumference.png", "wall_unrolled.png",
                 "wall_faces.png", "wall_perimeter.png"):
        shutil.copy(old / "discharge.png", old / name)          # as a 3D run's
    (old / "wall_extremes.csv").write_text("stage,s_m\n")
    every = {p.name for p in plotting.PICTURES}
    assert every <= {p.name for p in old.iterdir()}
    assert {"wall_forces.png", "lagrangian_mesh.png", "discharge.gif"} <= every
    fill = tmp_path / "fill.toml"
    fill.write_text(COARSE.replace("end_time = 0.2", "end_time = 0.0"))
    assert main(["run", str(fill), "--out", str(old), "--force", "--quiet"]) == 0
    fresh = tmp_path / "fresh"
    assert main(["run", str(fill), "--out", str(fresh), "--quiet"]) == 0

    def files(folder):
        return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))

    assert files(old) == files(fresh)
    assert "discharge.png" not in files(fresh) and "wall_pressure.png" in files(fresh)
    assert main(["plot", "--help"]) == 0
    text = capsys.readouterr().out
    for name in every:                              # the help names every picture
        assert name in text, name


def test_a_fill_only_run_draws_only_what_it_has(run_dir, tmp_path):
    """``end_time = 0``: no ``discharge.png`` (there is no discharge: no empty axes), and a
    ``wall_pressure.png`` of one panel (the overpressure panel needs a discharge envelope)
    where a discharge run's has two."""
    from fipy_hopper import plotting

    fill = tmp_path / "fill.toml"
    fill.write_text(COARSE.replace("end_time = 0.2", "end_time = 0.0"))
    out = tmp_path / "fill"
    assert main(["run", str(fill), "--out", str(out), "--quiet"]) == 0
    pictures = {p.name for p in out.iterdir() if p.suffix in (".png", ".gif")}
    assert pictures == {"wall_pressure.png", "wall_forces.png", "stress_pattern.png"}
    fig = plotting.wall_pressure(out)
    assert len(fig.axes) == 1 and fig.axes[0].get_lines()
    assert fig.get_size_inches()[0] < 8
    assert len(plotting.wall_pressure(run_dir).axes) == 2      # with a discharge: both


def unsettled(tmp_path, end_time):
    """The coarse hopper whose fill gives up (max_fill_time just past the gravity ramp)."""
    path = tmp_path / f"unsettled_{end_time}.toml"
    path.write_text(COARSE.replace("gravity_ramp_time = 0.05", "gravity_ramp_time = 0.05\n"
                                   "max_fill_time = 0.06")
                    .replace("end_time = 0.2", f"end_time = {end_time}")
                    .replace("output_interval = 0.02", "output_interval = 0.01")
                    .replace("field_interval = 0.05", "field_interval = 0.02"))
    return path


def test_a_fill_that_never_comes_to_rest_is_not_filled(tmp_path, capsys):
    """A fill-only run whose fill gives up at numerics.max_fill_time: ``stop_reason``
    ``"fill_not_at_rest"``, exit 1 and one error line naming the key (its outputs written);
    a discharge started from it finishes with exit 0 and one warning line."""
    out = tmp_path / "fill"
    assert main(["run", str(unsettled(tmp_path, 0.0)), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "cells across the outlet" not in line]
    assert len(lines) == 1 and lines[0].startswith("fipy-hopper: error: the fill did not come "
                                                   "to rest"), err
    assert "numerics.max_fill_time = 0.06 s" in lines[0] and str(out) in lines[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "fill_not_at_rest" and summary["fill_at_rest"] is False
    assert (out / "wall_pressure.png").is_file()
    out = tmp_path / "discharge"
    assert main(["run", str(unsettled(tmp_path, 0.02)), "--out", str(out), "--quiet"]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines()
             if "cells across the outlet" not in line]
    assert len(lines) == 1 and lines[0].startswith("fipy-hopper: warning: the fill did not "
                                                   "come to rest"), lines
    assert json.loads((out / "summary.json").read_text())["stop_reason"] == "end_time"


def test_the_description_names_silos_and_hoppers_of_every_shape(capsys):
    """The program's description is not that of a conical hopper only: wedges run too."""
    assert main(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "silos and hoppers" in text and "wedge" in text and "conical" in text
    assert "from a conical hopper" not in text


def test_usage_errors_exit_2(capsys):
    assert main([]) == 2
    assert main(["run"]) == 2                      # no configuration, no --out
    assert main(["frobnicate"]) == 2
    assert main(["run", "x.toml", "--out", "d", "--checkpoint-interval", "soon"]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_console_script_help():
    script = shutil.which("fipy-hopper", path=os.path.dirname(sys.executable))
    assert script, "the console script fipy-hopper is not installed next to this Python"
    done = subprocess.run([script, "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    for word in ("run", "demo", "plot", "validate", "Exit codes"):
        assert word in done.stdout


def test_wall_time_limit_stops_a_run_that_can_be_resumed(tmp_path, capsys):
    cfg = coarse_config(tmp_path)
    text = cfg.read_text().replace("end_time = 0.2", "end_time = 2.0")   # tens of seconds
    cfg.write_text(text.replace("[run]\n", "[run]\nwall_time_limit = 0.4\n"))
    out = tmp_path / "run"
    argv = ["run", str(cfg), "--out", str(out), "--checkpoint-interval", "0.1"]
    assert main(argv) == 0
    assert "--resume" in capsys.readouterr().out
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "stopped" and manifest["stop_reason"] == "wall_time_limit"
    assert (out / "checkpoint.npz").is_file()
    assert main(argv + ["--resume", "--quiet"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert len(manifest["sessions"]) == 2
    assert manifest["sessions"][1]["resumed_from_t_s"] > 0
