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
     ["hopper.bin_diameter", "-0.3", "allowed range is [0.001, 100] m"]),
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
    # absurd magnitudes: a range error, never a traceback or an allocation
    ("a 400-digit integer", "[hopper]\nbin_diameter = " + "9" * 400 + "\n",
     ["hopper.bin_diameter", "an integer of 400 digits", "[0.001, 100] m"]),
    ("a 400-digit integer for an integer key",
     "[numerics]\nmax_transport_interval = " + "9" * 400 + "\n",
     ["numerics.max_transport_interval", "an integer of 400 digits", "[1, 100000]"]),
    ("a huge length", "[hopper]\nbin_diameter = 1e300\n",
     ["hopper.bin_diameter", "1e+300", "[0.001, 100] m"]),
    ("lengths in millimetres", "[hopper]\nbin_diameter = 300\noutlet_diameter = 60\n"
     "bin_height = 350\nfill_height = 300\n", ["hopper.bin_diameter", "300", "[0.001, 100] m"]),
    ("the smallest float as density", "[material]\ndensity = 5e-324\n",
     ["material.density", "[1, 20000] kg/m3"]),
    ("a tiny density", "[material]\ndensity = 1e-300\n", ["material.density", "1e-300"]),
    ("a modulus beyond 1 TPa", "[material]\nyoungs_modulus = 1e15\n",
     ["material.youngs_modulus", "[1000, 1e+12] Pa"]),
    ("a tiny half-angle", "[hopper]\nhalf_angle_deg = 5e-324\n",
     ["hopper.half_angle_deg", "higher than 100 m", "allowed range is [0.0688, 90] deg"]),
    ("a grid of 11 million cells", "[numerics]\ncell_size = 1e-4\n",
     ["numerics.cell_size", "11,111,796 cells", "at most 2,000,000", "cell_size >= 0.000237 m"]),
    ("a cell size below 0.1 mm", "[numerics]\ncell_size = 1e-7\n",
     ["numerics.cell_size", "1e-07", "[0.0001, 10] m"]),
    ("a time step that cannot finish", "[material]\nyoungs_modulus = 1e12\n"
     "[numerics]\ncell_size = 0.001\n",
     ["numerics.cell_size", "steps", "at most 1e+09", "numerics.cell_size >= 0.00494 m"]),
    ("end_time beyond max_time", "[run]\nend_time = 100.0\nmax_time = 60.0\n",
     ["run.end_time", "100", "run.max_time = 60", "[0, 60] s"]),
    ("a negative end time", "[run]\nend_time = -1.0\n", ["run.end_time", "[0, 1e+06] s"]),
    ("a load window longer than the discharge", "[run]\nend_time = 0.5\nload_window = 1.0\n",
     ["run.load_window", "run.end_time = 0.5", "[0.0001, 0.5] s"]),
    ("a ramp that is neither seconds nor auto", '[numerics]\ngravity_ramp_time = "slow"\n',
     ["numerics.gravity_ramp_time", '"auto"']),
    ("a ramp of periods beyond the fill time", "[numerics]\ngravity_ramp_periods = 100\n",
     ["numerics.gravity_ramp_periods", "numerics.max_fill_time = 2", "at least"]),
    ("end_time of 1e9 s", "[run]\nend_time = 1e9\n", ["run.end_time", "[0, 1e+06] s"]),
    ("output_interval longer than end_time", "[run]\nend_time = 0.1\noutput_interval = 0.2\n",
     ["run.output_interval", "0.2", "run.end_time = 0.1", "[0.0001, 0.1] s"]),
    ("field_interval longer than the whole run", "[run]\nfield_interval = 100.0\n",
     ["run.field_interval", "100", "[0.001, 60] s"]),
    ("gravity ramp beyond the fill time", "[numerics]\ngravity_ramp_time = 3.0\n",
     ["numerics.gravity_ramp_time", "numerics.max_fill_time = 2", "[0, 2] s"]),
    ("a string of a thousand characters", '[material]\ndensity = "' + "x" * 1000 + '"\n',
     ["material.density", "expected a number"]),
    # a wall profile (shape = "profile"; tests/test_boundary.py has every case)
    ("a profile wall that descends", '[hopper]\nshape = "profile"\nfill_level = 0.1\n'
     "wall = [[0.03, 0.0], [0.1, 0.2], [0.15, 0.1]]\n",
     ["hopper.wall[2] = [0.15, 0.1]", "must not descend"]),
    ("a left wall in a half-section", '[hopper]\nshape = "profile"\nfill_level = 0.3\n'
     "wall = [[0.03, 0.0], [0.15, 0.2], [0.15, 0.6]]\n"
     "left_wall = [[-0.03, 0.0], [-0.15, 0.2], [-0.15, 0.6]]\n",
     ["hopper.left_wall", 'hopper.section = "full"']),
    ("an insert reaching below the outlet plane", '[hopper]\nshape = "profile"\n'
     "fill_level = 0.3\nwall = [[0.03, 0.0], [0.15, 0.2], [0.15, 0.6]]\n"
     "[[hopper.inserts]]\noutline = [[0.0, 0.05], [0.02, -0.01], [0.0, -0.02]]\n",
     ["hopper.inserts[0].outline[1] = [0.02, -0.01]", "below the outlet plane"]),
    ("a segment friction list of the wrong length",
     "[wall]\nsegment_friction_deg = [15.0, 20.0, 25.0]\n",
     ["wall.segment_friction_deg has 3 values", "2 segments"]),
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
