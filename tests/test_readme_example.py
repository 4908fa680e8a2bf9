"""README.md's Python API example runs as written, and its configuration example is complete.

The example's code block (the first ``python`` block of the "Python API" section) is executed
in a temporary folder; it asserts its own results.  The TOML example must hold every public
key of :mod:`fipy_hopper.config` at the reference values.
"""

import re
import warnings
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import fipy_hopper as fh

README = Path(__file__).resolve().parents[1] / "README.md"


def _section(title: str) -> str:
    text = README.read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"README.md has no section '## {title}'"
    return match.group(1)


def _block(section: str, language: str) -> str:
    match = re.search(rf"```{language}\n(.*?)```", section, re.S)
    assert match, f"no ```{language} block"
    return match.group(1)


def test_readme_opens_with_the_two_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert lines[3].endswith(".venv/bin/fipy-hopper demo --out hopper_run")
    assert lines[4].endswith(".venv/bin/python -m pytest")


def test_readme_api_example_runs(tmp_path, monkeypatch, capsys):
    code = _block(_section("Python API"), "python")
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fh.ResolutionWarning)
        exec(compile(code, str(README), "exec"), {"__name__": "readme_example"})
    out = capsys.readouterr().out
    assert "kg/s" in out and "alpha" in out
    res = fh.read_results(tmp_path / "coarse_run")
    assert res.summary["stop_reason"] == "end_time"
    assert (tmp_path / "coarse_run" / "flow_pattern.png").is_file()


def test_readme_configuration_example_is_the_complete_reference():
    data = tomllib.loads(_block(_section("Configuration"), "toml"))
    reference = fh.HopperConfig()
    for section in ("hopper", "material", "wall", "numerics", "run"):
        assert set(data[section]) == set(reference.to_dict()[section])
    assert fh.HopperConfig.from_dict(data) == reference


def test_readme_cites_the_methods():
    cite = _section("How to cite the methods it compares with")
    for name in ("Beverloo", "Rose", "Tanaka", "Johanson", "Jenike", "Janssen", "Walker",
                 "Walters", "EN 1991-4", "Zheng", "Yu"):
        assert name in cite, name
