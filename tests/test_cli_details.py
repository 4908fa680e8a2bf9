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
