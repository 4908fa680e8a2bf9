"""A 3D run (``[hopper] dimensions = 3``) end to end through the Python API and the command
line: the small conical silo at 2 cm (a quarter when centred, the half ``y >= 0`` with its
outlet 0.04 m off the axis), filled to rest and discharged for 0.12 s; its run directory, the
files present and sane (the mass balance to 1e-9, the vertical balance at rest within 0.5 %,
every row of ``loads.csv`` to 1e-9, a row of ``wall_pressure.csv`` per stage and patch with
``theta_deg``, hexahedral snapshots of the whole silo holding its mass), ``plot`` and
``validate``; bad input refused in one line with exit 2; an interrupted run resumed with
``--resume`` ends with the files of the uninterrupted one, to the bit."""

import json
import math
import shutil
import warnings

import meshio
import numpy as np
import pytest

import fipy_hopper as fh
from fipy_hopper import api
from fipy_hopper.cli import main
from fipy_hopper.io import read_csv, read_snapshot_index, read_vtu

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

CONFIG = """\
[hopper]
bin_diameter = 0.28
half_angle_deg = 30.0
outlet_diameter = 0.12
bin_height = 0.16
fill_height = 0.1
dimensions = 3
outlet_offset = {offset}

[numerics]
cell_size = 0.02

[run]
end_time = 0.12
output_interval = 0.02
field_interval = 0.05
"""

PICTURES = ("discharge.png", "flow_plane.png", "wall_circumference.png", "wall_unrolled.png")


def write_config(folder, offset=0.0, **replace):
    text = CONFIG.format(offset=offset)
    for old, new in replace.items():
        text = text.replace(old, new)
    path = folder / f"silo_{offset:g}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def centred(tmp_path_factory):
    """The centred silo (a quarter) run by ``fh.run``."""
    folder = tmp_path_factory.mktemp("three_d")
    config = write_config(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # 3 cells across the outlet radius: a warning
        summary = fh.run(config, folder / "run", threads=1)
    return folder, config, folder / "run", summary


@pytest.fixture(scope="module")
def off_centre(tmp_path_factory):
    """The silo with its outlet 0.04 m off the axis (the half y >= 0), run by the command
    line."""
    folder = tmp_path_factory.mktemp("three_d_cli")
    config = write_config(folder, 0.04)
    assert main(["run", str(config), "--out", str(folder / "run"), "--quiet",
                 "--threads", "1"]) == 0
    return folder, config, folder / "run"


def test_the_api_run_writes_every_3d_output(centred):
    folder, config, out, summary = centred
    for name in ("config.toml", "manifest.json", "summary.json", "timeseries.csv",
                 "wall_pressure.csv", "wall_extremes.csv", "loads.csv", "wall_slip.csv",
                 "channel_windows.csv", "fields/fields.pvd", "fields/snapshots.csv") + PICTURES:
        assert (out / name).is_file(), name
    for name in ("wall_pressure.png", "wall_forces.png", "flow_pattern.png",
                 "stress_pattern.png", "discharge.gif", "checkpoint.npz"):
        assert not (out / name).exists(), name          # the sections' pictures: not 3D
    for name in PICTURES:
        assert (out / name).stat().st_size > 10_000
    saved = (out / "config.toml").read_text()
    assert "dimensions = 3" in saved and "wall_sectors = 12" in saved
    cfg = fh.load_config(config)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert fh.HopperConfig.from_dict(tomllib.loads(saved)) == cfg
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "finished"
    assert summary == json.loads((out / "summary.json").read_text())


def test_the_summary_balances(centred):
    """The mass balance to 1e-9; at rest the wall and the plate carry the weight within
    0.5 %; every interval of ``loads.csv`` closes to 1e-9 of the weight (filling and
    discharge); the 3D keys: the circumference's extremes per stage and height bin, the flow
    mode per sector."""
    summary = centred[3]
    assert summary["dimensions"] == 3 and summary["mirror_factor"] == 4.0
    assert summary["stop_reason"] == "end_time" and summary["fill_at_rest"]
    assert summary["mass_balance_error"] < 1e-9
    assert summary["fill_equilibrium_residual"] < 5e-3
    assert summary["fill_weight_N"] == pytest.approx(summary["initial_mass_kg"] * 9.81,
                                                     rel=1e-3)
    assert summary["load_balance_residual_max"] < 1e-9
    assert 5.0 < summary["steady_discharge_rate_kg_s"] < 20.0
    n_bins = len(summary["wall_bins_s_m"])
    assert n_bins == 5 and len(summary["sector_theta_deg"]) == 12
    ratio = summary["filling_wall_pressure_max_over_min"]
    assert len(ratio) == n_bins and max(ratio) < 1.03      # centred: round at rest
    assert len(summary["flow_mode_by_sector"]) == 12
    assert summary["flow_mode"] in ("mass", "funnel")
    loads = read_csv(centred[2] / "loads.csv")
    assert {"filling", "discharge"} <= set(loads["stage"])
    assert np.nanmax(loads["relative_residual"]) < 1e-9


def test_the_wall_pressure_table_has_a_row_per_stage_and_patch(centred):
    out, summary = centred[2], centred[3]
    table = read_csv(out / "wall_pressure.csv")
    for column in ("theta_deg", "segment", "tau_theta_Pa", "s_m", "z_m", "p_n_Pa"):
        assert column in table
    stages = list(dict.fromkeys(table["stage"]))
    assert stages[0] == "filling" and "discharge_envelope" in stages
    assert len(table["stage"]) == len(stages) * 5 * 12
    assert sorted(set(table["theta_deg"])) == [30.0 * k for k in range(12)]
    rest = np.asarray(table["stage"]) == "filling"
    p = np.asarray(table["p_n_Pa"])[rest].reshape(5, 12)
    assert np.allclose(p.max(axis=1), summary["filling_wall_pressure_max_Pa"])
    extremes = read_csv(out / "wall_extremes.csv")
    at_rest = np.asarray(extremes["stage"]) == "filling"
    assert np.allclose(extremes["p_max_Pa"][at_rest], p.max(axis=1))
    assert np.allclose(extremes["max_over_min"][at_rest],
                       summary["filling_wall_pressure_max_over_min"])


def test_the_snapshots_are_hexahedra_of_the_whole_silo(centred):
    """Every snapshot holds the whole silo (four times the quarter's open cells), positively
    oriented cubes; the first holds the fill's mass to 1e-9; the ParaView index lists them
    all; ``read_results`` reads them back."""
    out, summary = centred[2], centred[3]
    snaps = read_snapshot_index(out / "fields")
    assert len(snaps) >= 6 and {"filling", "discharge"} == {s["stage"] for s in snaps}
    assert (out / "fields" / "fields.pvd").read_text().count("<DataSet") == len(snaps)
    mesh = read_vtu(out / "fields" / snaps[0]["file"])
    hexes = mesh.cells_dict["hexahedron"]
    p = mesh.points[hexes]
    volume = np.einsum("ni,ni->n", np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]),
                       p[:, 4] - p[:, 0])
    assert np.allclose(volume, 0.02 ** 3)
    assert np.allclose(mesh.points[:, 0].min(), -mesh.points[:, 0].max())   # mirrored
    cd = mesh.cell_data_dict
    mass = 1500.0 * 0.02 ** 3 * float(np.sum(cd["alpha"]["hexahedron"]
                                             * cd["kappa"]["hexahedron"]))
    assert mass == pytest.approx(summary["initial_mass_kg"], rel=1e-9)
    results = fh.read_results(out)
    assert results.finished and len(results.field(-1).cells_dict["hexahedron"]) == len(hexes)


def test_the_channel_per_window_is_the_channel_of_the_windows_mean_field(tmp_path):
    """``channel_windows.csv`` of the off-centre silo discharged in windows of 0.04 s: each
    window's rows are the flow channel (``space.channel.field_channel``) of the mean over the
    window's checks of the fields the model gives the loop (its nodes' v_z, its cells' alpha),
    held here to a plain numpy mean of those fields as the loop saw them; a row per node plane
    of the bin with material, every window of the discharge, windows as long as the load
    window."""
    from fipy_hopper.space.channel import field_channel, profile_rows

    config = write_config(tmp_path, 0.04, **{"end_time = 0.12": "end_time = 0.12\n"
                                              "load_window = 0.04"})
    seen, sims = [], []

    def setup(sim):
        sims.append(sim)
        model = sim.model
        fields_of = model.channel_fields

        def recording(state):
            fields = fields_of(state)
            seen.append((state.t - sim.t_open, [np.array(f) for f in fields]))
            return fields
        model.channel_fields = recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        api.run(config, tmp_path / "run", setup=setup, plots=False, quiet=True, threads=1)
    sim = sims[0]
    rows = sim.record.channel_windows
    table = read_csv(tmp_path / "run" / "channel_windows.csv")
    assert len(table["z_m"]) == len(rows) > 0
    windows = sorted({row["window"] for row in rows})
    assert windows == list(range(1, sim.record.envelope_windows + 1)) and len(windows) >= 2
    for w in windows:
        mine = [row for row in rows if row["window"] == w]
        t0, t1 = mine[0]["t_start_s"], mine[0]["t_end_s"]
        assert t1 - t0 == pytest.approx(0.04, abs=0.003)
        checks = [f for t, f in seen if t0 + 1e-12 < t <= t1 + 1e-12]
        assert mine[0]["checks"] == len(checks) >= 10
        means = tuple(np.mean([f[k] for f in checks], axis=0) for k in range(2))
        expected = profile_rows(field_channel(sim.model, *means))
        assert len(expected) == len(mine)
        for got, want in zip(mine, expected):
            for key, value in want.items():
                assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12, nan_ok=True), key
        z_b = sim.model.boundary.bin_foot
        assert all(row["z_m"] >= z_b - 1e-12 for row in mine)
        np.testing.assert_allclose(table["area_m2"][table["window"] == w],
                                   [row["area_m2"] for row in mine], rtol=1e-15)


def test_the_command_line_runs_plots_and_validates_an_off_centre_silo(off_centre, capsys):
    folder, config, out = off_centre
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outlet_offset_m"] == 0.04 and summary["mirror_factor"] == 2.0
    assert summary["mass_balance_error"] < 1e-9 and summary["fill_equilibrium_residual"] < 5e-3
    for name in PICTURES:
        (out / name).unlink()
    capsys.readouterr()
    assert main(["plot", str(out)]) == 0
    assert sorted(p.name for p in out.glob("*.png")) == sorted(PICTURES)
    capsys.readouterr()
    assert main(["validate", str(config)]) == 0
    text = capsys.readouterr().out
    assert "grid (3D)          18 x 9 x 22 = 3,564 cubes of 0.02 m (the half y >= 0" in text
    assert "782 loaded" in text and "outlet offset      0.04 m" in text
    assert "estimated" in text and "on one thread" in text


@pytest.mark.parametrize("replace, words", [
    ({"dimensions = 3": "dimensions = 4"}, "hopper.dimensions = 4: expected 2"),
    ({"outlet_offset = 0.04": "outlet_offset = 0.09"},
     "hopper.outlet_offset = 0.09 m puts the outlet (radius 0.06 m) outside"),
    ({"cell_size = 0.02": "cell_size = 0.0005"}, "makes a 3D grid (its computed part) of"),
    ({"[run]": "[run]\nopening_time = 0.05"}, "run.opening_time = 0.05 s: the 3D model"),
])
def test_bad_3d_input_exits_2_in_one_line(tmp_path, capsys, replace, words):
    config = write_config(tmp_path, 0.04, **replace)
    for argv in (["validate", str(config)],
                 ["run", str(config), "--out", str(tmp_path / "out"), "--quiet"]):
        capsys.readouterr()
        assert main(argv) == 2
        err = [line for line in capsys.readouterr().err.splitlines()
               if "warning:" not in line]
        assert len(err) == 1 and words in err[0], err
    assert not (tmp_path / "out").exists()


def test_a_grid_that_will_not_fit_is_refused_before_anything_is_built(tmp_path, capsys,
                                                                      monkeypatch):
    """With less memory than the estimate (``fipy_hopper.space.estimate``), ``validate`` and
    ``run`` exit 2 with one line, before a grid is built or a directory made."""
    import fipy_hopper.resources as resources
    monkeypatch.setattr(resources, "available_memory", lambda: 0.1e9)
    config = write_config(tmp_path, 0.0)
    for argv in (["validate", str(config)],
                 ["run", str(config), "--out", str(tmp_path / "out"), "--quiet"]):
        capsys.readouterr()
        assert main(argv) == 2
        err = [line for line in capsys.readouterr().err.splitlines()
               if "warning:" not in line]
        assert len(err) == 1 and "more than the 0.1 GB" in err[0], err
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- resume, to the bit
def interrupt_and_resume(folder, config, name, condition):
    """Run ``config`` into ``folder / name``, checkpoint and Ctrl-C at the first check where
    ``condition(sim, state)``, then ``--resume`` it from the command line."""
    out = folder / name

    def setup(sim):
        def maybe_interrupt(sim_, state):
            if condition(sim_, state):
                sim_.checkpoint(out / "checkpoint.npz")
                raise KeyboardInterrupt
        sim.add_wall_time_callback(maybe_interrupt, 0.0)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(KeyboardInterrupt):
            api.run(config, out, setup=setup, plots=False, threads=1)
    assert json.loads((out / "summary.json").read_text())["stop_reason"] == "interrupted"
    with np.load(out / "checkpoint.npz") as archive:      # the record's 3D samples are in it
        record = json.loads(str(archive["__meta__"][()]))["record"]
    assert len(record["wall_slip_sectors"]) == len(record["t"])
    assert all(np.shape(sectors) == (1, 12) for sectors in record["wall_slip_sectors"])
    assert len(record["wall_theta"]) == len(record["wall_segment"]) == 5 * 12
    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet",
                 "--threads", "1"]) == 0
    return out


def assert_same_outputs(resumed, reference):
    a = json.loads((resumed / "summary.json").read_text())
    b = json.loads((reference / "summary.json").read_text())
    a.pop("wall_time_s"), b.pop("wall_time_s")
    assert a == b                                     # every number, bitwise (JSON repr)
    for name in ("timeseries.csv", "wall_pressure.csv", "wall_extremes.csv", "loads.csv",
                 "wall_slip.csv", "channel_windows.csv", "fields/snapshots.csv", "fields/fields.pvd", "config.toml"):
        assert (resumed / name).read_text() == (reference / name).read_text(), name
    for entry in read_snapshot_index(reference / "fields"):
        m_a = meshio.read(resumed / "fields" / entry["file"])
        m_b = meshio.read(reference / "fields" / entry["file"])
        for key in m_b.cell_data:
            np.testing.assert_array_equal(m_a.cell_data[key][0], m_b.cell_data[key][0],
                                          err_msg=f"{entry['file']}: {key}")
        np.testing.assert_array_equal(m_a.point_data["node_velocity"],
                                      m_b.point_data["node_velocity"])
    manifest = json.loads((resumed / "manifest.json").read_text())
    assert manifest["status"] == "finished" and len(manifest["sessions"]) == 2
    assert not (resumed / "checkpoint.npz").exists()


@pytest.mark.parametrize("stage", ["filling", "discharge"])
def test_an_interrupted_3d_run_resumes_to_the_bit(centred, stage):
    folder, config, reference, _ = centred
    if stage == "filling":
        condition = lambda sim, st: st.stage == "filling" and st.t >= 0.08     # noqa: E731
    else:
        condition = lambda sim, st: (st.stage == "discharge"                   # noqa: E731
                                     and st.t - sim.t_open >= 0.051)
    out = interrupt_and_resume(folder, config, stage, condition)
    assert_same_outputs(out, reference)
    shutil.rmtree(out)
