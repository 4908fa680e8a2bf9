"""Small things a demanding user meets: ``validate`` writes nothing unless asked, a file that
begins with a byte-order mark, no command at all, ``replace`` across shapes, arguments of
``run`` checked before anything is made, and reading a run that did not finish."""

import json
import warnings
from pathlib import Path

import pytest

import fipy_hopper as fh
from fipy_hopper import api
from fipy_hopper.cli import main
from fipy_hopper.config import ConfigError, HopperConfig

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


def error_lines(err: str) -> list:
    return [line for line in err.splitlines() if "warning:" not in line]


def listing(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


# ---------------------------------------------------------------- validate writes nothing
def test_validate_writes_nothing_unless_asked(tmp_path, capsys):
    config = tmp_path / "silo.toml"
    config.write_text(COARSE)
    (tmp_path / "geometry.png").write_bytes(b"the user's own picture")
    before = listing(tmp_path)
    assert main(["validate", str(config)]) == 0
    assert listing(tmp_path) == before                  # nothing written, nothing replaced
    assert "drawn to" not in capsys.readouterr().out
    picture = tmp_path / "pictures" / "silo.png"
    picture.parent.mkdir()
    assert main(["validate", str(config), "--picture", str(picture)]) == 0
    assert f"drawn to {picture}" in capsys.readouterr().out
    assert picture.read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "geometry.png").read_bytes() == b"the user's own picture"


@pytest.mark.parametrize("name, words", [
    ("silo.jpg", ["--picture = ", "silo.jpg", "expected the name of a PNG file"]),
    ("missing/silo.png", ["cannot write", "missing/silo.png", "No such file or directory"]),
])
def test_a_picture_that_cannot_be_written_is_one_line(tmp_path, capsys, name, words):
    config = tmp_path / "silo.toml"
    config.write_text(COARSE)
    assert main(["validate", str(config), "--picture", str(tmp_path / name)]) == 2
    err = error_lines(capsys.readouterr().err)
    assert len(err) == 1, err
    for word in words:
        assert word in err[0], (word, err[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["silo.toml"]


# ---------------------------------------------------------------- odd input
def test_a_byte_order_mark_is_accepted(tmp_path, capsys):
    plain, marked = tmp_path / "plain.toml", tmp_path / "marked.toml"
    plain.write_text(COARSE, encoding="utf-8")
    marked.write_bytes(b"\xef\xbb\xbf" + COARSE.encode("utf-8"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert fh.load_config(marked) == fh.load_config(plain)
    assert main(["validate", str(marked)]) == 0
    assert "valid" in capsys.readouterr().out


def test_no_command_is_one_clear_line(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("fipy-hopper: error:")]
    assert len(lines) == 1 and "no command given" in lines[0]
    for command in ("run", "demo", "plot", "validate", "--help"):
        assert command in lines[0]
    assert err.startswith("usage: fipy-hopper")


# ---------------------------------------------------------------- replace across shapes
def test_replace_switches_a_cone_to_a_wedge_and_back():
    cone = HopperConfig().replace(hopper={"half_angle_deg": 25.0, "fill_height": 0.2})
    wedge = cone.replace(hopper={"shape": "wedge", "bin_width": 0.3, "outlet_width": 0.06})
    geom = wedge.hopper
    assert geom.shape == "wedge" and geom.symmetry == "plane" and not geom.axisymmetric
    assert (geom.half_angle_deg, geom.fill_height) == (25.0, 0.2)     # carried over
    back = wedge.replace(hopper={"shape": "conical", "bin_diameter": 0.3,
                                 "outlet_diameter": 0.06})
    assert back == cone
    with pytest.raises(ConfigError, match="hopper.bin_width is required"):
        cone.replace(hopper={"shape": "wedge"})       # a wedge's sizes are its own


def test_replace_switches_to_a_profile_and_back():
    wedge = HopperConfig().replace(hopper={"shape": "wedge", "bin_width": 0.3,
                                           "outlet_width": 0.06})
    wall = [[0.03, 0.0], [0.15, 0.33], [0.15, 0.68]]
    profile = wedge.replace(hopper={"shape": "profile", "wall": wall, "fill_level": 0.6})
    assert profile.hopper.symmetry == "plane" and profile.hopper.shape == "profile"
    cone = profile.replace(hopper={"shape": "conical"})       # the shorthand's defaults
    assert cone.hopper == HopperConfig().hopper


# ---------------------------------------------------------------- run's arguments
@pytest.mark.parametrize("kwargs, words", [
    ({"checkpoint_interval": "60"}, ["checkpoint_interval = '60'", "finite number of seconds"]),
    ({"checkpoint_interval": float("nan")}, ["checkpoint_interval = nan"]),
    ({"checkpoint_interval": -1}, ["checkpoint_interval = -1"]),
    ({"checkpoint_interval": True}, ["checkpoint_interval = True"]),
    ({"force": "yes"}, ["force = 'yes'", "True or False"]),
    ({"quiet": 0}, ["quiet = 0", "True or False"]),
    ({"setup": "print"}, ["setup = 'print'", "a function"]),
])
def test_run_checks_its_arguments_before_it_makes_anything(tmp_path, kwargs, words):
    out = tmp_path / "run"
    with pytest.raises(ConfigError) as err:
        api.run(HopperConfig(), out, **kwargs)
    for word in words:
        assert word in str(err.value), (word, str(err.value))
    assert not out.exists()
    with pytest.raises(ConfigError, match="out = 3"):
        api.run(HopperConfig(), 3)


# ---------------------------------------------------------------- unfinished runs
@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    folder = tmp_path_factory.mktemp("unfinished")
    config = folder / "coarse.toml"
    config.write_text(COARSE)
    out = folder / "run"
    assert main(["run", str(config), "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize("status, reason, words", [
    ("running", "", ["has not finished", "'running'"]),
    ("interrupted", "interrupted", ["was interrupted", "--resume"]),
    ("stopped", "wall_time_limit", ["was stopped (wall_time_limit)", "--resume"]),
    ("failed", "unstable: runaway velocity", ["did not finish: failed (unstable: runaway"]),
    (None, "", ["has no manifest.json"]),
])
def test_reading_an_unfinished_run_warns(finished, tmp_path, status, reason, words):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(finished, out)
    manifest = json.loads((out / "manifest.json").read_text())
    if status is None:
        (out / "manifest.json").unlink()
    else:
        manifest.update(status=status, stop_reason=reason)
        (out / "manifest.json").write_text(json.dumps(manifest))
    with pytest.warns(api.UnfinishedRunWarning) as caught:
        res = fh.read_results(out)
    message = str(caught[0].message)
    assert str(out) in message and "not a finished run's results" in message
    for word in words:
        assert word in message, (word, message)
    assert not res.finished and len(res.timeseries["t_s"]) > 0     # read all the same


def test_reading_a_finished_run_is_silent(finished):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = fh.read_results(finished)
    assert res.finished
