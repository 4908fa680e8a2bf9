"""Bad configurations: each is refused before anything runs, with exit code 2 and one clear line
on stderr that names the key (and, for a range, the value and the allowed range); never a
traceback, and no run directory is created.
"""

import pytest

from fipy_hopper.cli import main

REFERENCE_GEOMETRY = "[hopper]\nbin_diameter = 0.3\noutlet_diameter = 0.06\n"

# (id, file content or None for a missing file, words the message must contain)
CASES = [
    ("wrong type: text for a number", '[material]\ndensity = "heavy"\n',
     ["material.density", "'heavy'", "expected a number"]),
    ("wrong type: boolean for a number", "[hopper]\nbin_height = true\n",
     ["hopper.bin_height", "expected a number"]),
    ("wrong type: float for an integer", "[numerics]\nmax_transport_interval = 2.5\n",
     ["numerics.max_transport_interval", "2.5", "integer"]),
    ("wrong type: a section that is not a table", "hopper = 3\n", ["[hopper]", "table"]),
    ("wrong word for end_time", '[run]\nend_time = "forever"\n', ["run.end_time", '"empty"']),
    ("negative size", "[hopper]\nbin_diameter = -0.3\n",
     ["hopper.bin_diameter", "-0.3", "allowed range is (0, inf) m"]),
    ("negative cell size", "[numerics]\ncell_size = -0.005\n",
     ["numerics.cell_size", "-0.005", "allowed range"]),
    ("zero density", "[material]\ndensity = 0\n", ["material.density", "allowed range"]),
    ("angle out of range", "[hopper]\nhalf_angle_deg = 95\n",
     ["hopper.half_angle_deg", "95", "(0, 90]"]),
    ("wall friction out of range", "[wall]\nfriction_angle_deg = 90\n",
     ["wall.friction_angle_deg", "90", "[0, 90)"]),
    ("Poisson ratio out of range", "[material]\npoisson_ratio = 0.5\n",
     ["material.poisson_ratio", "0.5", "(-1, 0.5)"]),
    ("outlet wider than the bin", "[hopper]\nbin_diameter = 0.3\noutlet_diameter = 0.4\n",
     ["hopper.outlet_diameter", "0.4", "hopper.bin_diameter", "0.3"]),
    ("fill above the bin", "[hopper]\nbin_height = 0.35\nfill_height = 0.5\n",
     ["hopper.fill_height", "0.5", "top of the bin", "0.35"]),
    ("unknown key", "[hopper]\nbin_diamter = 0.3\n",
     ["unknown key", "hopper.bin_diamter", "did you mean 'hopper.bin_diameter'"]),
    ("unknown section", "[hoper]\nbin_diameter = 0.3\n",
     ["unknown section", "hoper", "did you mean 'hopper'"]),
    ("cell size too coarse for the outlet", "[numerics]\ncell_size = 0.02\n",
     ["numerics.cell_size", "0.02", "cells across the outlet radius", "at least 3"]),
    ("not TOML", "this is [not toml\n", ["not valid TOML"]),
    ("not TOML: a binary file", b"\x89PNG\r\n\x1a\n\x00\x00", ["not valid TOML"]),
    ("missing file", None, ["missing.toml", "cannot read configuration"]),
]


def _write(tmp_path, content):
    path = tmp_path / ("missing.toml" if content is None else "bad.toml")
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    return path


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize("name, content, words", CASES, ids=[c[0] for c in CASES])
def test_bad_config_exit_2_with_a_clear_message(tmp_path, capsys, command, name, content,
                                                words):
    path = _write(tmp_path, content)
    out = tmp_path / "run"
    argv = ["validate", str(path)] if command == "validate" else \
        ["run", str(path), "--out", str(out), "--quiet"]
    assert main(argv) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if "warning:" not in line]
    assert len(errors) == 1, captured.err
    assert errors[0].startswith("fipy-hopper: error: ")
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert "Traceback" not in captured.err and "Traceback" not in captured.out
    assert not out.exists()                      # refused before the run directory is made


def test_missing_sections_take_the_reference_values(tmp_path, capsys):
    """A section left out is not an error: it takes the reference hopper's values."""
    path = tmp_path / "partial.toml"
    path.write_text(REFERENCE_GEOMETRY)
    assert main(["validate", str(path)]) == 0
    assert "valid" in capsys.readouterr().out


def test_a_directory_is_not_a_configuration(tmp_path, capsys):
    assert main(["validate", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "is a directory" in err and "Traceback" not in err


def test_resume_with_another_configuration_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.toml").write_text("[hopper]\nbin_diameter = 0.4\n")
    (out / "checkpoint.npz").write_bytes(b"")
    path = tmp_path / "other.toml"
    path.write_text(REFERENCE_GEOMETRY)
    assert main(["run", str(path), "--out", str(out), "--resume", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "differs from the one the run" in err and "Traceback" not in err


def test_resume_without_a_checkpoint_is_refused(tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_text(REFERENCE_GEOMETRY)
    assert main(["run", str(path), "--out", str(tmp_path / "nothing"), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "cannot resume" in err and "Traceback" not in err


def test_negative_checkpoint_interval_is_refused(tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_text(REFERENCE_GEOMETRY)
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out), "--checkpoint-interval", "-5"]) == 2
    assert "--checkpoint-interval" in capsys.readouterr().err
    assert not out.exists()
