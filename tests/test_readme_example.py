"""README.md's commands and Python API example run as written; the configuration reference is
complete.

The README opens with its two commands: the first re-runnable (``--force``), the second the
one ``.ci/run`` runs (the first line of README.md matching ``^python3 -m venv .* pytest``).
The example's code block (the first ``python`` block of the README's "Python API" section)
is executed in a temporary folder; it asserts its own results.  The TOML example of
``docs/usage.md`` must hold every public key of :mod:`fipy_hopper.config` at the reference
values.
"""

import re
import warnings
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import fipy_hopper as fh

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
USAGE = ROOT / "docs" / "usage.md"
REFERENCES = ROOT / "docs" / "references.md"
CI_COMMAND = re.compile(r"^python3 -m venv .* pytest", re.M)     # as .ci/run greps it


def _section(title: str, path: Path = README) -> str:
    text = path.read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"{path.name} has no section '## {title}'"
    return match.group(1)


def _block(section: str, language: str) -> str:
    match = re.search(rf"```{language}\n(.*?)```", section, re.S)
    assert match, f"no ```{language} block"
    return match.group(1)


def test_readme_opens_with_the_two_commands():
    text = README.read_text(encoding="utf-8")
    first_block = re.search(r"```bash\n(.*?)```", text, re.S).group(1).splitlines()
    assert len(first_block) == 2
    demo, tests = first_block
    assert demo.startswith("python3 -m venv .venv && ")
    assert demo.endswith(".venv/bin/fipy-hopper demo --out hopper_run --force")
    assert tests.endswith(".venv/bin/python -m pytest -n auto --dist loadfile")
    assert CI_COMMAND.search(text).group(0) == CI_COMMAND.match(tests).group(0)
    assert text.index(tests) == CI_COMMAND.search(text).start()
    assert text.index("```bash") < text.index("\n## ", text.index("## Quick start"))


def test_the_first_command_runs_twice(tmp_path, capsys):
    """``demo --out DIR --force`` over a finished run replaces it (here a short run of the
    same command line: ``run`` shares ``demo``'s options)."""
    from fipy_hopper.cli import main

    config = tmp_path / "short.toml"
    config.write_text("[hopper]\nbin_diameter = 0.2\nbin_height = 0.06\nfill_height = 0.04\n"
                      "[numerics]\ncell_size = 0.01\ngravity_ramp_time = 0.05\n"
                      "[run]\nend_time = 0.05\nmarkers_per_side = 0\n")
    out = tmp_path / "hopper_run"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fh.ResolutionWarning)
        for _ in range(2):
            assert main(["run", str(config), "--out", str(out), "--force", "--quiet"]) == 0
        assert main(["run", str(config), "--out", str(out), "--quiet"]) == 2
    assert "--force" in capsys.readouterr().err


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
    data = tomllib.loads(_block(_section("Configuration", USAGE), "toml"))
    reference = fh.HopperConfig()
    for section in ("hopper", "material", "wall", "numerics", "run"):
        assert set(data[section]) == set(reference.to_dict()[section])
    assert fh.HopperConfig.from_dict(data) == reference


def test_references_cite_the_methods():
    cite = REFERENCES.read_text(encoding="utf-8")
    for name in ("Beverloo", "Rose", "Tanaka", "Johanson", "Jenike", "Janssen", "Walker",
                 "Walters", "EN 1991-4", "Zheng", "Yu"):
        assert name in cite, name
