"""Reliability in configuration, I/O and the command line: one-line errors, size checks, locks, checkpoints.

Bad paths and values give one line and exit code 2, never a traceback; the grid's size and the
number of time steps are checked before anything is allocated (against the measured memory a
cell); a run directory is locked for its run; a checkpoint is checked before it is restored;
after Ctrl-C the advice matches what can be done; the package imports where numba has no
cache folder of its own.  Seconds in all: no run here goes beyond a second of simulation.
"""

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

import fipy_hopper as fh
from fipy_hopper import cli
from fipy_hopper import config as fconfig
from fipy_hopper.cli import main
from fipy_hopper.config import ConfigError, HopperConfig
from fipy_hopper.io import (CheckpointError, RunDirectory, RunDirectoryError,
                            checkpoint_size_limit, checkpoint_template, validate_checkpoint)

REPO = Path(__file__).resolve().parents[1]

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
end_time = 0.05
output_interval = 0.01
field_interval = 0.05
"""


def coarse(folder: Path) -> Path:
    path = folder / "coarse.toml"
    path.write_text(COARSE)
    return path


def one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if "warning:" not in line]
    assert len(lines) == 1, err
    assert lines[0].startswith("fipy-hopper: error: ") and "Traceback" not in err
    return lines[0]


# ---------------------------------------------------------------- paths and CLI values
def test_a_path_component_over_255_characters_is_one_line(tmp_path, capsys):
    long = tmp_path / ("x" * 300 + ".toml")
    assert main(["validate", str(long)]) == 2
    assert "File name too long" in one_error_line(capsys.readouterr().err)
    out = tmp_path / ("o" * 300)
    assert main(["run", str(coarse(tmp_path)), "--out", str(out), "--quiet"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "cannot use" in line and "File name too long" in line and len(line) < 300
    assert main(["plot", str(out)]) == 2
    one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1"])
def test_checkpoint_interval_must_be_finite_and_not_negative(tmp_path, capsys, value):
    out = tmp_path / "run"
    argv = ["run", str(coarse(tmp_path)), "--out", str(out), f"--checkpoint-interval={value}"]
    assert main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--checkpoint-interval" in line and "finite number of seconds >= 0" in line
    assert not out.exists()


def test_empty_out_is_refused_and_the_current_directory_untouched(tmp_path, capsys,
                                                                   monkeypatch):
    config = coarse(tmp_path)
    work = tmp_path / "cwd"
    work.mkdir()
    (work / "config.toml").write_text("mine")
    (work / "summary.json").write_text("{}")
    monkeypatch.chdir(work)
    for out in ("", "  "):
        assert main(["run", str(config), "--out", out, "--force", "--quiet"]) == 2
        assert "--out" in one_error_line(capsys.readouterr().err)
    assert sorted(p.name for p in work.iterdir()) == ["config.toml", "summary.json"]
    assert (work / "config.toml").read_text() == "mine"
    with pytest.raises(RunDirectoryError, match="empty path"):
        RunDirectory("", force=True)


@pytest.mark.parametrize("name, files", [
    ("foreign timeseries", {"timeseries.csv": "date,price\n2024-01-01,3\n"}),
    ("ragged timeseries", {"timeseries.csv": "t_s,mass_in_hopper_kg,discharged_kg,"
                           "discharge_rate_kg_s\n0,1\n"}),
    ("text in a number column", {"timeseries.csv": "t_s,mass_in_hopper_kg,discharged_kg,"
                                 "discharge_rate_kg_s\n0,a,b,c\n"}),
    ("binary timeseries", {"timeseries.csv": b"\xff\xfe\x00\x01"}),
    ("empty timeseries", {"timeseries.csv": ""}),
    ("foreign config", {"config.toml": "[server]\nport = 80\n"}),
    ("broken summary", {"summary.json": "{not json"}),
    ("foreign wall pressure", {"wall_pressure.csv": "a,b\n1,2\n"}),
    ("snapshot index naming another file", {"fields/snapshots.csv":
                                            "index,file,step,t_s,discharge_time_s,stage\n"
                                            "0,../../etc/passwd,0,0.0,nan,filling\n"}),
])
def test_plot_on_a_foreign_directory_is_one_line(tmp_path, capsys, name, files):
    run = tmp_path / "run"
    (run / "fields").mkdir(parents=True)
    (run / "config.toml").write_text(HopperConfig().to_toml())
    (run / "timeseries.csv").write_text("t_s,mass_in_hopper_kg,discharged_kg,"
                                        "discharge_rate_kg_s\n0.0,1.0,0.0,0.0\n")
    for file, content in files.items():
        (run / file).write_bytes(content if isinstance(content, bytes) else content.encode())
    assert main(["plot", str(run)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(run) in line
    assert not (run / "discharge.png").exists()


# ---------------------------------------------------------------- hostile TOML
HOSTILE_TOML = [
    ("a table nested 5,000 deep", "[run]\nend_time = " + "{a = " * 5000 + "1" + "}" * 5000,
     ["nested too deeply", "line 2", "'run.end_time'"]),
    ("an array nested 5,000 deep over many lines", "[run]\nx = [\n" + "[\n" * 5000
     + "]\n" * 5001, ["nested too deeply", "'run.x'"]),
    ("a 5,000-digit integer", "[hopper]\nbin_diameter = " + "7" * 5000,
     ["line 2", "'hopper.bin_diameter'", "more than 4,300 digits"]),
    ("a key set twice", "[hopper]\nbin_diameter = 0.3\nfill_height = 0.2\n"
     "bin_diameter = 0.4\n", ["'hopper.bin_diameter' is set twice", "lines 2 and 4"]),
    ("a dotted key set again in its table", "hopper.bin_diameter = 0.3\n[hopper]\n"
     "bin_diameter = 0.4\n", ["'hopper.bin_diameter' is set twice", "lines 1 and 3"]),
    ("a table declared twice", "[run]\nend_time = 1.0\n[hopper]\nfill_height = 0.2\n"
     "[run]\nmax_time = 9.0\n", ["'[run]' is set twice", "lines 1 and 5"]),
]


@pytest.mark.parametrize("name, text, words", HOSTILE_TOML, ids=[c[0] for c in HOSTILE_TOML])
def test_hostile_toml_is_one_line_naming_the_file_and_the_key(tmp_path, capsys, name, text,
                                                              words):
    """Deep nesting (a RecursionError in the parser), an integer beyond Python's digit limit
    (a ValueError) and a key or table set twice: exit 2 with one line naming the file, the
    line and the key, from ``validate``, ``run`` and ``plot`` (a run directory's config)."""
    path = tmp_path / "hostile.toml"
    path.write_text(text)
    out = tmp_path / "run"
    for argv in (["validate", str(path)], ["run", str(path), "--out", str(out), "--quiet"]):
        assert main(argv) == 2
        line = one_error_line(capsys.readouterr().err)
        assert f"{path} is not valid TOML: " in line, line
        for word in words:
            assert word in line, (word, line)
        assert len(line) < 300
    assert not out.exists()
    out.mkdir()
    shutil.copy(path, out / "config.toml")
    (out / "timeseries.csv").write_text("t_s,mass_in_hopper_kg,discharged_kg,"
                                        "discharge_rate_kg_s\n")
    assert main(["plot", str(out)]) == 2
    assert words[0] in one_error_line(capsys.readouterr().err)


# ---------------------------------------------------------------- messages
def test_a_fill_only_run_gets_no_warning_about_field_snapshots(tmp_path, capsys):
    """``end_time = 0`` has no discharge to sample: no SamplingWarning (a short discharge
    still gets one)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", fconfig.SamplingWarning)
        HopperConfig().replace(run={"end_time": 0.0})
    with pytest.warns(fconfig.SamplingWarning, match="run.end_time = 0.01 s"):
        HopperConfig().replace(run={"end_time": 0.01, "output_interval": 0.005})
    path = tmp_path / "fill.toml"
    path.write_text(COARSE.replace("end_time = 0.05", "end_time = 0.0"))
    assert main(["validate", str(path)]) == 0
    assert "snapshot" not in capsys.readouterr().err


@pytest.mark.parametrize("field, words", [
    ("v", ["non-finite velocity", "node r = 0.05 m, z = 0.", "|v| = nan m/s"]),
    ("sigma", ["non-finite material fraction or stress", "cell r = 0.055 m, z = 0."]),
])
def test_the_instability_after_a_transport_names_the_node_or_the_cell(tmp_path, field, words):
    """A non-finite velocity names its node, a non-finite stress its cell (never ``[]``)."""
    from fipy_hopper.model import HopperModel, InstabilityError

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HopperModel(HopperConfig.from_toml(coarse(tmp_path)), threads=1)
    state = model.initial_state()
    model.advance(state, 3)
    j, i = [int(np.argmin(np.abs(model.grid.z_nodes - 0.1))),
            int(np.argmin(np.abs(model.grid.r_nodes - 0.05)))]
    if field == "v":
        state.v[1, j, i] = np.nan
    else:
        state.sigma[j, i, 0] = np.inf
    with pytest.raises(InstabilityError) as err:
        model.transport_step(state)
    message = str(err.value)
    assert "[]" not in message
    for word in words:
        assert word in message, message


@pytest.mark.parametrize("content", [b"junk", b"<?xml version='1.0'?>\n<VTKFile type=",
                                     b"\x00\xff" * 100])
def test_a_corrupt_snapshot_is_one_line_not_meshios_exit(tmp_path, capsys, content):
    """meshio.read prints and calls ``sys.exit(1)`` on a file it cannot read: ``plot`` says so
    in one line with exit 2 (nothing on stdout), :meth:`Results.field` raises the same
    :class:`RunFileError` naming the file."""
    from fipy_hopper.io import RunFileError

    run = tmp_path / "run"
    (run / "fields").mkdir(parents=True)
    (run / "config.toml").write_text(HopperConfig().to_toml())
    (run / "timeseries.csv").write_text("t_s,mass_in_hopper_kg,discharged_kg,"
                                        "discharge_rate_kg_s\n0.0,1.0,0.0,0.0\n")
    (run / "summary.json").write_text("{}")
    (run / "fields" / "snapshots.csv").write_text(
        "index,file,step,t_s,discharge_time_s,stage\n0,fields_0000.vtu,0,0.0,nan,filling\n")
    (run / "fields" / "fields_0000.vtu").write_bytes(content)
    assert main(["plot", str(run)]) == 2
    captured = capsys.readouterr()
    line = one_error_line(captured.err)
    assert "fields_0000.vtu is not a readable VTU file" in line and captured.out == ""
    with pytest.raises(RunFileError, match="fields_0000.vtu is not a readable VTU file"):
        fh.read_results(run).field(0)


# ---------------------------------------------------------------- size of a run
@pytest.mark.parametrize("changes", [
    {},
    {"numerics": {"cell_size": 0.0025}},
    {"numerics": {"cell_size": 0.0037, "free_fall_depth": 2.5}},
    {"hopper": {"half_angle_deg": 90.0, "bin_diameter": 0.23}, "numerics": {"cell_size": 0.007}},
    {"hopper": {"half_angle_deg": 10.0, "bin_diameter": 0.2}},
])
def test_grid_shape_is_the_grid_the_model_builds(changes):
    from fipy_hopper.mesh import build_grid

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig().replace(**changes)
    grid = build_grid(cfg, n_sub=2)
    assert cfg.grid_shape() == (grid.nr, grid.nz)
    assert cfg.n_cells == grid.n_cells


def test_the_reference_grid_at_2_5_mm_is_allowed():
    cfg = HopperConfig().replace(numerics={"cell_size": 0.0025})
    assert 18_000 < cfg.n_cells < 20_000 and cfg.memory_estimate() < 0.5e9


def test_grid_limit_names_the_smallest_cell_size_that_fits():
    with pytest.raises(ConfigError) as err:
        HopperConfig().replace(numerics={"cell_size": 1.2e-4})
    message = str(err.value)
    smallest = float(message.split("cell_size >= ")[1].split(" m")[0])
    assert "at most 2,000,000 cells" in message and "GB" in message
    fits = HopperConfig().replace(numerics={"cell_size": smallest})
    assert fits.n_cells <= fconfig.MAX_CELLS
    with pytest.raises(ConfigError, match="cells"):          # the bound is tight
        HopperConfig().replace(numerics={"cell_size": smallest * 0.995})


def test_validate_does_not_build_the_grid(tmp_path, capsys, monkeypatch):
    """A large admissible grid is checked and described from the configuration alone."""
    import fipy_hopper.mesh

    def refuse(*args, **kwargs):
        raise AssertionError("validate built the grid")

    monkeypatch.setattr(fipy_hopper.mesh, "build_grid", refuse)
    path = tmp_path / "fine.toml"
    path.write_text("[numerics]\ncell_size = 0.0003\n")
    started = time.perf_counter()
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    n = HopperConfig.from_toml(path).n_cells
    assert f"= {n} cells" in out and n > 1_000_000 and "GB" in out
    assert time.perf_counter() - started < 5


def test_memory_estimate_bounds_the_measured_peak():
    """The memory a model of 72,346 cells allocates while it is built (the arrays the cell
    limit guards, traced by ``tracemalloc``, which counts numpy's allocations and not the
    interpreter's, the libraries' or the compiler's): below the estimate's cost a cell, and
    not far below it (the figure is a measurement: 3.26 kB a cell at 1.25 and 2.5 mm)."""
    import tracemalloc

    from fipy_hopper.config import MEMORY_PER_CELL
    from fipy_hopper.model import HopperModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig().replace(numerics={"cell_size": 0.00125})
    assert cfg.n_cells == 72_346
    tracemalloc.start()
    try:
        HopperModel(cfg)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    per_cell = peak / cfg.n_cells
    assert 0.6 * MEMORY_PER_CELL < per_cell < MEMORY_PER_CELL, per_cell


WALL_CASES = [
    {"numerics": {"cell_size": 0.005}},
    {"hopper": {"half_angle_deg": 90.0, "bin_diameter": 0.23}, "numerics": {"cell_size": 0.007}},
    {"hopper": {"half_angle_deg": 60.0}, "numerics": {"cell_size": 0.004}},
    {"hopper": {"shape": "wedge", "bin_width": 0.3, "outlet_width": 0.06},
     "numerics": {"cell_size": 0.004}},
]


@pytest.mark.parametrize("sections", WALL_CASES)
def test_the_wall_loads_estimate_bounds_the_wall_loads(sections):
    """The estimate asks WallLoads for its size (``estimated_bytes``) on the bins of its
    sampler and a bound of its contact entries, both from the configuration alone: the bins
    are the run's, the bound is above the entries, and the bytes above what building the wall
    loads allocates (tracemalloc) for a cone, a flat bottom, a shallow cone and a wedge."""
    import tracemalloc

    from fipy_hopper import resources
    from fipy_hopper.diagnostics import WallLoads
    from fipy_hopper.model import HopperModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict(sections)
    h = cfg.numerics.cell_size
    model = HopperModel(cfg, threads=1)
    tracemalloc.start()
    try:
        loads = WallLoads(model)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    bins, entries = resources.wall_bins(cfg, h), resources.wall_entry_bound(cfg, h)
    assert bins == len(loads.centres)
    assert len(loads.entries) <= entries < 2 * len(loads.entries)
    assert peak <= WallLoads.estimated_bytes(len(loads.centres), len(loads.entries))
    kept = sum(m.data.nbytes + m.indices.nbytes + m.indptr.nbytes for rec in loads.recoveries
               for m in (rec.share, rec.raw, rec.bin_mean))
    assert 0 < kept < WallLoads.estimated_bytes(bins, entries)


def test_the_memory_estimate_bounds_what_a_run_allocates():
    """A run of 72,346 cells (markers, wall loads), traced by ``tracemalloc`` (numpy's
    allocations; the interpreter, the libraries and the compiler are MEMORY_BASE): the
    model, the simulation with its wall loads, steps, a transport, a field snapshot and a
    checkpoint stay below the estimate; the wall loads' own part of it (sparse maps, a few
    hundred bytes a contact entry) is below 2 % of it."""
    import tempfile
    import tracemalloc

    from fipy_hopper import resources
    from fipy_hopper.config import MEMORY_BASE
    from fipy_hopper.diagnostics import WallLoads
    from fipy_hopper.io import FieldWriter
    from fipy_hopper.model import HopperModel
    from fipy_hopper.simulation import Simulation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig().replace(numerics={"cell_size": 0.00125})
    tracemalloc.start()
    try:
        model = HopperModel(cfg, threads=1)
        sim = Simulation(model, progress=False)
        model.advance(sim.state, 20)
        model.transport_step(sim.state)
        with tempfile.TemporaryDirectory() as folder:
            FieldWriter(folder, model.grid).write(sim.state)
            sim.checkpoint(os.path.join(folder, "checkpoint.npz"))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    estimate = cfg.memory_estimate()
    assert estimate == resources.memory_estimate(cfg)
    assert peak < estimate - MEMORY_BASE, (peak, estimate)
    wall = WallLoads.estimated_bytes(resources.wall_bins(cfg, cfg.numerics.cell_size),
                                     resources.wall_entry_bound(cfg, cfg.numerics.cell_size))
    assert 0 < wall < 0.02 * estimate


def earlier_run(folder: Path) -> Path:
    """A directory with the files of an earlier run (to see that a refusal keeps them)."""
    out = folder / "run"
    (out / "fields").mkdir(parents=True)
    for name in ("config.toml", "summary.json", "profile.json", "discharge.png",
                 "fields/fields_0000.vtu"):
        (out / name).write_text(f"earlier {name}")
    return out


def test_a_run_that_needs_more_memory_than_there_is_is_refused(tmp_path, capsys, monkeypatch):
    """Refused in one line before the directory is touched (with --force too): what the run
    needs, what is available and a cell size that fits, which does."""
    from fipy_hopper import resources
    from fipy_hopper.config import MEMORY_BASE

    path = tmp_path / "fine.toml"
    path.write_text(COARSE.replace("cell_size = 0.01", "cell_size = 0.004"))
    cfg = HopperConfig.from_toml(path)
    have = MEMORY_BASE + 0.6 * (cfg.memory_estimate() - MEMORY_BASE)
    monkeypatch.setattr(resources, "available_memory", lambda: have)
    out = earlier_run(tmp_path)
    before = {p: p.read_text() for p in out.rglob("*") if p.is_file()}
    for argv in (["run", str(path), "--out", str(out), "--force"],
                 ["run", str(path), "--out", str(tmp_path / "new")]):
        assert main(argv) == 2
        line = one_error_line(capsys.readouterr().err)
        assert f"needs about {cfg.memory_estimate() / 1e9:.3g} GB" in line
        assert f"the {have / 1e9:.3g} GB of memory available" in line
        coarser = float(line.split("numerics.cell_size >= ")[1].split(" m")[0])
        assert 0.004 < coarser and resources.memory_estimate(cfg, coarser) <= have
    assert {p: p.read_text() for p in out.rglob("*") if p.is_file()} == before
    assert not (out / ".lock").exists() and not (tmp_path / "new").exists()
    with pytest.raises(ConfigError, match="GB of memory available"):
        fh.run(cfg, tmp_path / "api")
    assert not (tmp_path / "api").exists()


def test_validate_says_whether_the_memory_a_run_needs_is_available(tmp_path, capsys,
                                                                  monkeypatch):
    from fipy_hopper import resources

    path = coarse(tmp_path)
    need = HopperConfig.from_toml(path).memory_estimate()
    for have, words in ((2 * need, "GB available)"), (need / 2, "the run would be refused")):
        monkeypatch.setattr(resources, "available_memory", lambda: have)
        assert main(["validate", str(path)]) == 0
        grid = [line for line in capsys.readouterr().out.splitlines() if "grid" in line][0]
        assert f"about {need / 1e9:.2g} GB" in grid and words in grid, grid


def test_threads_beyond_the_cores_are_refused_before_anything(tmp_path, capsys):
    """``--threads`` above the cores this process may use (its CPU affinity, its cgroup's
    quota, NUMBA_NUM_THREADS) or below 1: one line naming the range, nothing written."""
    from fipy_hopper import resources

    limit = resources.thread_limit()
    assert limit <= len(os.sched_getaffinity(0))
    out = earlier_run(tmp_path)
    before = {p: p.read_text() for p in out.rglob("*") if p.is_file()}
    for value in (limit + 1, 999, 0, -2):
        assert main(["run", str(coarse(tmp_path)), "--out", str(out), "--force",
                     "--threads", str(value)]) == 2
        line = one_error_line(capsys.readouterr().err)
        assert f"--threads = {value}: expected a number of threads in [1, {limit}]" in line
    assert {p: p.read_text() for p in out.rglob("*") if p.is_file()} == before
    with pytest.raises(ConfigError, match=rf"threads = {limit + 1}: expected"):
        fh.run(coarse(tmp_path), tmp_path / "api", threads=limit + 1)
    assert not (tmp_path / "api").exists()


def test_the_input_configuration_in_the_run_directory_is_never_replaced(tmp_path, capsys,
                                                                        monkeypatch):
    """``--out . --force`` in the folder holding ``config.toml``: refused (the run would write
    its resolved configuration over it), the file and the folder as they were."""
    work = tmp_path / "work"
    work.mkdir()
    text = "# my hopper\n" + COARSE
    (work / "config.toml").write_text(text)
    (work / "summary.json").write_text("{}")
    monkeypatch.chdir(work)
    for argv in (["run", "config.toml", "--out", ".", "--force", "--quiet"],
                 ["run", str(work / "config.toml"), "--out", str(work), "--force", "--quiet"]):
        assert main(argv) == 2
        line = one_error_line(capsys.readouterr().err)
        assert "config.toml is the configuration being run" in line
        assert "choose another run directory" in line
    assert (work / "config.toml").read_text() == text
    assert sorted(p.name for p in work.iterdir()) == ["config.toml", "summary.json"]


def test_ctrl_c_while_the_pictures_are_drawn_advises_plot(tmp_path, capsys, monkeypatch):
    """The run is finished and written when Ctrl-C stops its pictures: exit 130 and the
    advice to draw them with ``fipy-hopper plot DIR``, not to start again with --force."""
    from fipy_hopper import plotting

    def interrupted(run):
        raise KeyboardInterrupt

    monkeypatch.setattr(plotting, "plot_run", interrupted)
    out = tmp_path / "run"
    assert main(["run", str(coarse(tmp_path)), "--out", str(out), "--quiet"]) == 130
    line = one_error_line(capsys.readouterr().err)
    assert f"fipy-hopper plot {out}" in line and "complete" in line
    assert "--force" not in line and "--resume" not in line
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "finished" and (out / "summary.json").is_file()
    assert not (out / ".lock").exists()


def test_a_run_refused_for_its_size_leaves_no_directory(tmp_path, capsys):
    path = tmp_path / "huge.toml"
    path.write_text("[numerics]\ncell_size = 1e-4\n")
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out)]) == 2
    assert "cells" in one_error_line(capsys.readouterr().err)
    assert not out.exists()


def test_a_time_step_that_cannot_finish_is_refused():
    with pytest.raises(ConfigError, match=r"at most 1e\+09 can finish"):
        HopperConfig().replace(material={"youngs_modulus": 1e12, "poisson_ratio": 0.49},
                               numerics={"cell_size": 0.002})
    cfg = HopperConfig()
    assert cfg.step_estimate() == pytest.approx(62.0 / cfg.time_step)
    assert 1e6 < cfg.step_estimate() < 1e7


@pytest.mark.parametrize("study", ["flow_mode_map", "discharge_rate", "convergence",
                                   "robustness", "wall_pressure"])
def test_the_studies_configurations_stay_valid(study):
    """Every case of every study, default and quick, passes the new checks (``setup``
    validates each case's configuration)."""
    import importlib

    sys.path.insert(0, str(REPO / "studies"))
    try:
        module = importlib.import_module(study)
        for quick in (False, True):
            assert module.setup(quick=quick)["cases"]
    finally:
        sys.path.remove(str(REPO / "studies"))


# ---------------------------------------------------------------- the lock
HOLD = """
import fcntl, os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o644)
fcntl.flock(fd, fcntl.LOCK_EX)
os.ftruncate(fd, 0); os.write(fd, f"{os.getpid()}\\n".encode())
print("locked", flush=True)
time.sleep(60)
"""


@pytest.fixture
def held(tmp_path):
    """A directory of a finished run whose lock a live process holds."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.toml").write_text(HopperConfig().to_toml())
    (out / "checkpoint.npz").write_bytes(b"PK")
    (out / "manifest.json").write_text('{"package": "fipy_hopper", "sessions": []}')
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(out / ".lock")],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "locked"
    yield out, proc
    proc.kill()
    proc.wait()


@pytest.mark.parametrize("mode", [{"force": True}, {}, {"resume": True}])
def test_a_directory_in_use_is_refused(held, mode):
    out, proc = held
    with pytest.raises(RunDirectoryError, match=rf"in use by another run \(process {proc.pid}"):
        RunDirectory(out, **mode)
    assert (out / "config.toml").is_file() and (out / "checkpoint.npz").is_file()


def test_a_second_run_with_force_is_refused_in_one_line(held, tmp_path, capsys):
    out, proc = held
    before = (out / "config.toml").read_text()
    argv = ["run", str(coarse(tmp_path)), "--out", str(out), "--force", "--quiet"]
    assert main(argv) == 2
    assert "in use by another run" in one_error_line(capsys.readouterr().err)
    assert (out / "config.toml").read_text() == before
    assert sorted(p.name for p in out.iterdir()) == [".lock", "checkpoint.npz", "config.toml",
                                                     "manifest.json"]


def test_the_lock_of_a_killed_process_does_not_block(held):
    out, proc = held
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (out / ".lock").read_text().strip() == str(proc.pid)     # stale file left behind
    with RunDirectory(out, force=True) as rundir:
        assert rundir.locked and not (out / "config.toml").exists()
    assert not (out / ".lock").exists()


def test_only_a_stale_lock_file_counts_as_empty(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / ".lock").write_text("999999999\n")
    rundir = RunDirectory(out)                # no --force needed: nothing but a dead lock
    with pytest.raises(RunDirectoryError, match="in use"):
        RunDirectory(out, force=True)         # a second object, same process: refused
    rundir.close()
    RunDirectory(out, force=True).close()


def test_the_lock_is_held_for_the_run_and_released_after(tmp_path):
    out = tmp_path / "run"
    seen = {}

    def setup(sim):
        def try_second(sim_, state):
            if "error" not in seen:
                try:
                    RunDirectory(out, force=True)
                except RunDirectoryError as exc:
                    seen["error"] = str(exc)
                else:
                    seen["error"] = None
        sim.add_callback(try_second, 0.01, stages=("filling",))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fh.run(coarse(tmp_path), out, plots=False, checkpoint_interval=0, setup=setup)
    assert seen["error"] and "in use by another run" in seen["error"]
    assert not (out / ".lock").exists()
    RunDirectory(out, force=True).close()     # free again


# ---------------------------------------------------------------- Ctrl-C advice
def test_ctrl_c_before_any_checkpoint_does_not_suggest_resume(tmp_path, capsys, monkeypatch):
    from fipy_hopper import api

    checkpoints = []

    def interrupted(config, out, **kwargs):       # Ctrl-C after writing what api.run writes
        rundir = RunDirectory(out, force=kwargs["force"])
        (rundir / "manifest.json").write_text('{"package": "fipy_hopper", "sessions": []}')
        (rundir / "config.toml").write_text(config.to_toml())
        if checkpoints:
            (rundir / "checkpoint.npz").write_bytes(b"")
        rundir.close()
        raise KeyboardInterrupt

    monkeypatch.setattr(api, "run", interrupted)
    out = tmp_path / "run"
    assert main(["run", str(coarse(tmp_path)), "--out", str(out), "--quiet"]) == 130
    line = one_error_line(capsys.readouterr().err)
    assert "--resume" not in line and "cannot be resumed" in line and "--force" in line
    checkpoints.append(True)
    assert main(["run", str(coarse(tmp_path)), "--out", str(out), "--force", "--quiet"]) == 130
    assert "--resume" in one_error_line(capsys.readouterr().err)


def test_ctrl_c_before_the_directory_exists(tmp_path):
    message = cli._interrupted_message(str(tmp_path / "none"), "fipy-hopper demo --out x",
                                       "fipy-hopper demo --out x --resume")
    assert "before the run started" in message and "--resume" not in message


# ---------------------------------------------------------------- checkpoints
@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A real checkpoint after filling (with markers and the filled wall samples)."""
    from fipy_hopper.model import HopperModel
    from fipy_hopper.simulation import Simulation

    folder = tmp_path_factory.mktemp("checkpoint")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_toml(coarse(folder))
    model = HopperModel(cfg)
    sim = Simulation(model, progress=False)
    sim.run()
    path = folder / "checkpoint.npz"
    sim.checkpoint(path)
    fresh = model.initial_state()          # what Simulation.restore has before it restores
    shapes, optional = checkpoint_template(fresh)
    return path, shapes, optional, checkpoint_size_limit(fresh, cfg)


def rewrite(source: Path, target: Path, change) -> Path:
    """A copy of a checkpoint with ``change(arrays)`` applied (arrays includes __meta__)."""
    with np.load(source) as data:
        arrays = {k: data[k] for k in data.files}
    change(arrays)
    with open(target, "wb") as fh_:
        np.savez(fh_, **arrays)
    return target


def test_a_real_checkpoint_passes_with_its_arrays_and_metadata(checkpoint):
    path, shapes, optional, limit = checkpoint
    arrays, meta = validate_checkpoint(path, shapes, limit, optional)
    with np.load(path) as data:
        assert set(arrays) == set(data.files) - {"__meta__"}
        for k in arrays:
            assert np.array_equal(arrays[k], data[k], equal_nan=True) and arrays[k].flags.writeable
        assert meta == json.loads(str(data["__meta__"]))
    assert meta["state"]["stage"] == "discharge" and "filling" in meta["wall_times"]
    assert arrays["markers"].shape[1] == 3 and len(arrays["markers"]) > 100
    assert shapes["alpha"] == arrays["alpha"].shape and shapes["markers"] == (None, 3)
    assert "loose" in optional and "alpha" not in optional


def test_read_checkpoint_checks_against_the_runs_own_state(checkpoint, tmp_path):
    """The call Simulation.restore makes: the template and the bound from its fresh state."""
    from fipy_hopper.io import read_checkpoint
    from fipy_hopper.model import HopperModel

    path = checkpoint[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_toml(coarse(tmp_path))
        model = HopperModel(cfg)
    arrays, meta = read_checkpoint(path, model.initial_state(), cfg)
    assert arrays["alpha"].shape == (model.grid.nz, model.grid.nr)

    def extra_scalar(a):
        meta_ = json.loads(str(a["__meta__"]))
        meta_["state"]["surprise"] = 1
        a["__meta__"] = np.array(json.dumps(meta_))

    bad = rewrite(path, tmp_path / "scalar.npz", extra_scalar)
    with pytest.raises(CheckpointError, match="unexpected state value 'surprise'"):
        read_checkpoint(bad, model.initial_state(), cfg)
    finer = cfg.replace(numerics={"cell_size": 0.005})
    with pytest.raises(CheckpointError, match="shape"):          # another grid's checkpoint
        read_checkpoint(path, HopperModel(finer).initial_state(), finer)


def test_measurements_beside_the_state_may_hold_nan(checkpoint, tmp_path):
    """Stress-sampled wall profiles are NaN where a bin held no material: not refused."""
    path, shapes, optional, limit = checkpoint
    nan = rewrite(path, tmp_path / "nan.npz",
                  lambda a: a.update(envelope=np.array([1.0, np.nan, 2.0])))
    arrays, _ = validate_checkpoint(nan, shapes, limit, optional)
    assert np.isnan(arrays["envelope"][1])


def test_an_older_checkpoint_without_optional_arrays_passes(checkpoint, tmp_path):
    path, shapes, optional, limit = checkpoint
    old = rewrite(path, tmp_path / "old.npz", lambda a: a.pop("loose"))
    arrays, _ = validate_checkpoint(old, shapes, limit, optional)
    assert "loose" not in arrays and "alpha" in arrays
    with pytest.raises(CheckpointError, match="'loose' is missing"):
        validate_checkpoint(old, shapes, limit)          # unless the name is optional


@pytest.mark.parametrize("name, change, words", [
    ("transposed alpha", lambda a: a.update(alpha=a["alpha"].T.copy()),
     ["'alpha'", "shape"]),
    ("another grid", lambda a: a.update(v=np.zeros((2, 10, 10))), ["'v'", "shape"]),
    ("markers of 2 columns", lambda a: a.update(markers=a["markers"][:, :2].copy()),
     ["'markers'", "shape"]),
    ("a NaN stress", lambda a: a["sigma"].__setitem__((3, 3, 0), np.nan),
     ["'sigma'", "1 non-finite"]),
    ("float32", lambda a: a.update(eps_p=a["eps_p"].astype(np.float32)), ["'eps_p'", "float32"]),
    ("a missing array", lambda a: a.pop("sigma"), ["'sigma'", "missing"]),
    ("an unexpected array", lambda a: a.update(extra=np.zeros(3)), ["unexpected", "extra"]),
    ("a measurement of 4 axes", lambda a: a.update(envelope=np.zeros((1, 2, 1, 2))),
     ["'envelope'", "4 axes"]),
    ("incomplete wall samples", lambda a: a.pop("wall__filling__4"), ["filling", "incomplete"]),
    ("no metadata", lambda a: a.pop("__meta__"), ["no metadata"]),
    ("metadata not JSON", lambda a: a.update(__meta__=np.array("{oops")), ["not JSON"]),
    ("metadata without state", lambda a: a.update(__meta__=np.array('{"record": {}}')),
     ["metadata lacks", "state"]),
])
def test_a_wrong_checkpoint_is_refused_in_one_line(checkpoint, tmp_path, name, change, words):
    path, shapes, optional, limit = checkpoint
    bad = rewrite(path, tmp_path / "bad.npz", change)
    with pytest.raises(CheckpointError) as err:
        validate_checkpoint(bad, shapes, limit, optional)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"checkpoint {bad}")
    for word in words:
        assert word in message, (word, message)


def test_an_object_array_is_never_unpickled(checkpoint, tmp_path):
    path, shapes, optional, limit = checkpoint
    bad = rewrite(path, tmp_path / "pickle.npz",
                  lambda a: a.update(alpha=np.array([{"x": 1}, None], dtype=object)))
    with pytest.raises(CheckpointError, match="Python objects"):
        validate_checkpoint(bad, shapes, limit, optional)


@pytest.mark.parametrize("damage", ["truncated", "flipped", "random", "empty", "pickle"])
def test_a_corrupt_checkpoint_is_one_line_without_the_pickle_hint(checkpoint, tmp_path,
                                                                   damage):
    path, shapes, optional, limit = checkpoint
    data = path.read_bytes()
    bad = tmp_path / "corrupt.npz"
    if damage == "truncated":
        bad.write_bytes(data[:len(data) // 2])
    elif damage == "flipped":                  # damage inside a member: the CRC catches it
        middle = bytearray(data)
        for k in range(len(data) // 3, len(data) // 3 + 64):
            middle[k] ^= 0xFF
        bad.write_bytes(bytes(middle))
    elif damage == "random":
        bad.write_bytes(np.random.default_rng(1).bytes(5000))
    elif damage == "empty":
        bad.write_bytes(b"")
    else:
        import pickle
        bad.write_bytes(pickle.dumps({"alpha": [1, 2]}))
    with pytest.raises(CheckpointError) as err:
        validate_checkpoint(bad, shapes, limit, optional)
    message = str(err.value)
    assert "\n" not in message and "allow_pickle" not in message and str(bad) in message


def test_a_zip_bomb_is_refused_before_it_is_read(checkpoint, tmp_path, monkeypatch):
    """5 MB on disk, 1.2 GB declared: refused from the zip directory, nothing decompressed."""
    path, shapes, optional, limit = checkpoint
    bomb = tmp_path / "bomb.npz"
    n = 150_000_000
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        with zf.open("alpha.npy", "w", force_zip64=True) as member:
            header = io.BytesIO()
            np.lib.format.write_array_header_1_0(
                header, {"descr": "<f8", "fortran_order": False, "shape": (n,)})
            member.write(header.getvalue())
            zeros = bytes(16 << 20)
            left = 8 * n
            while left:
                member.write(zeros[:min(left, len(zeros))])
                left -= min(left, len(zeros))
    assert bomb.stat().st_size < 20e6

    def no_reading(*args, **kwargs):
        raise AssertionError("a member was opened")

    monkeypatch.setattr(zipfile.ZipFile, "open", no_reading)
    with pytest.raises(CheckpointError, match="1,200,000,128 bytes uncompressed"):
        validate_checkpoint(bomb, shapes, limit, optional)


def test_a_checkpoint_limit_fits_real_runs(checkpoint):
    path, shapes, optional, limit = checkpoint
    with zipfile.ZipFile(path) as zf:
        assert sum(i.file_size for i in zf.infolist()) < limit < 200e6


# ---------------------------------------------------------------- the default threads
@pytest.mark.parametrize("cores, others, threads", [
    (2, 0.0, 2), (2, 0.25, 2), (2, 0.3, 1), (2, 1.0, 1), (2, 1.9, 1), (2, 3.0, 1),
    (4, 1.0, 3), (4, 1.26, 2), (4, 2.5, 1), (1, 0.0, 1), (8, 0.1, 8), (8, 6.0, 2),
])
def test_the_threads_are_the_cores_other_processes_leave(cores, others, threads):
    """A core counts as taken once other processes take more than a quarter of it."""
    from fipy_hopper.resources import threads_for

    assert threads_for(cores, others) == threads


STAT = """cpu  {all} 0 0 0 0 0 0 0 0 0
cpu0 {c0} 5 10 900 3 1 1 2 0 0
cpu1 {c1} 0 0 100 0 0 0 0 0 0
cpu2 {c2} 0 0 5 0 0 0 0 0 0
intr 123 0 0
ctxt 456
"""


def stat(c0, c1, c2):
    return STAT.format(all=c0 + c1 + c2, c0=c0, c1=c1, c2=c2)


def test_busy_time_counts_only_this_processes_cores():
    """user, nice, system, irq, softirq and steal of the cores of the affinity set; not idle
    and iowait, not other cores, not the total line."""
    from fipy_hopper.resources import busy_seconds

    text = stat(100, 40, 7)
    assert busy_seconds(text, {0}, 0.01) == pytest.approx((100 + 5 + 10 + 1 + 1 + 2) * 0.01)
    assert busy_seconds(text, {0, 2}, 0.01) == pytest.approx((119 + 7) * 0.01)
    assert busy_seconds(text, {5}, 0.01) == 0.0


def test_the_load_of_other_processes_is_the_busy_time_less_this_processes():
    """Over 1 s, cores 0 and 1 were busy for 1.6 s of which this process took 0.9 s: other
    processes took 0.7 of a core; a window below MIN_WINDOW waits for a longer one."""
    from fipy_hopper.resources import CpuLoad

    readings = {"stat": stat(0, 0, 0), "clock": 10.0, "own": 5.0}
    load = CpuLoad(cores={0, 1}, read_stat=lambda: readings["stat"],
                   clock=lambda: readings["clock"], own=lambda: readings["own"])
    load.tick = 0.01
    readings.update(stat=stat(81, 60, 500), clock=10.1, own=5.05)
    assert load.others() is None                     # 0.1 s: too short, no reading used
    readings.update(stat=stat(100 - 19, 80, 500), clock=11.0, own=5.9)
    assert load.others() == pytest.approx((0.81 + 0.80 - 0.9) / 1.0)
    readings.update(stat=stat(181, 180, 900), clock=13.0, own=7.9)   # this process alone
    assert load.others() == 0.0
    broken = CpuLoad(cores={0}, read_stat=lambda: (_ for _ in ()).throw(OSError("no /proc")))
    assert broken.others() is None


def test_the_governor_sets_the_models_threads_from_the_load():
    from fipy_hopper.resources import ThreadGovernor

    class Load:
        values = [None, 0.0, 1.0, 0.1, None]

        def others(self):
            return self.values.pop(0)

    sim = type("Sim", (), {})()
    sim.model = type("Model", (), {"threads": 0})()
    governor = ThreadGovernor(limit=2, load=Load())
    seen = []
    for _ in range(5):
        governor(sim, None)
        seen.append(sim.model.threads)
    assert seen == [2, 2, 1, 2, 2]


def test_a_run_without_threads_is_governed_and_one_with_threads_is_not(tmp_path):
    """``threads=None`` (the CLI without --threads): a ThreadGovernor among the wall-time
    callbacks, the model's threads its choice; ``threads=1``: none, and 1 thread."""
    from fipy_hopper.resources import ThreadGovernor

    seen = {}

    def setup(sim):
        governors = [e.fn for e in sim.wall_schedules if isinstance(e.fn, ThreadGovernor)]
        seen[len(seen)] = (len(governors), sim.model.threads,
                           governors[0].threads if governors else None)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_toml(coarse(tmp_path)).replace(run={"end_time": 0.0})
        fh.run(cfg, tmp_path / "governed", plots=False, setup=setup)
        fh.run(cfg, tmp_path / "fixed", plots=False, setup=setup, threads=1)
    count, threads, chosen = seen[0]
    assert count == 1 and threads == chosen and 1 <= threads
    assert seen[1] == (0, 1, None)


# ---------------------------------------------------------------- numba cache
def test_numba_cache_decision(tmp_path):
    decide = fh._numba_cache_dir
    writable = {"/pkg/__pycache__": True, "/home/u/.cache/numba": True}
    can = writable.get
    assert decide("/pkg", {"HOME": "/home/u"}, can) is None            # next to the module
    writable["/pkg/__pycache__"] = False
    assert decide("/pkg", {"HOME": "/home/u"}, can) is None            # ~/.cache/numba
    assert decide("/pkg", {"XDG_CACHE_HOME": "/home/u/.cache"}, can) is None
    writable["/home/u/.cache/numba"] = False
    assert decide("/pkg", {"NUMBA_CACHE_DIR": "/mine"}, can) is None      # the user's choice
    fallback = decide("/pkg", {"HOME": "/home/u"}, can, temp_dir=str(tmp_path))
    assert fallback == str(tmp_path / f"fipy_hopper-numba-{os.getuid()}")


def test_numba_cache_falls_back_to_a_private_temp_dir(tmp_path):
    path = fh._numba_cache_dir("/nowhere", {"XDG_CACHE_HOME": "/nowhere/cache"},
                               lambda p: False, temp_dir=str(tmp_path))
    assert path == str(tmp_path / f"fipy_hopper-numba-{os.getuid()}")
    assert os.path.isdir(path) and (os.stat(path).st_mode & 0o777) == 0o700
    other = tmp_path / "taken"
    other.mkdir()
    (other / f"fipy_hopper-numba-{os.getuid()}").write_text("not a directory")
    fresh = fh._numba_cache_dir("/nowhere", {}, lambda p: False, temp_dir=str(other))
    assert os.path.isdir(fresh) and fresh.startswith(str(other / "fipy_hopper-numba-"))


def test_import_where_neither_the_package_nor_home_is_writable(tmp_path):
    """A copy of the package whose ``__pycache__`` cannot be a folder (a file of that name;
    this holds for root too) and a home whose cache cannot be made: the kernels with
    ``cache=True`` import, with the cache in a private temporary folder."""
    package = tmp_path / "site" / "fipy_hopper"
    shutil.copytree(REPO / "fipy_hopper", package,
                    ignore=shutil.ignore_patterns("__pycache__"))
    (package / "__pycache__").write_text("")
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(HOME=str(blocker / "home"), XDG_CACHE_HOME=str(blocker / "cache"),
               TMPDIR=str(temp), PYTHONPATH=str(tmp_path / "site"), PYTHONDONTWRITEBYTECODE="1")
    script = textwrap.dedent("""
        import os, fipy_hopper, fipy_hopper.material, fipy_hopper.stepping
        assert fipy_hopper.__file__.startswith(os.environ["PYTHONPATH"]), fipy_hopper.__file__
        print(os.environ["NUMBA_CACHE_DIR"])
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == str(temp / f"fipy_hopper-numba-{os.getuid()}")
