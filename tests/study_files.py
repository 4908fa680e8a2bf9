"""What the tests of ``studies/`` share: the folder, loading a study's script as a module,
and reading what a study wrote (CSV rows, ``study.json``, PNG pictures)."""

from __future__ import annotations

import csv
import importlib.util
import json
import pathlib
import sys

STUDIES = pathlib.Path(__file__).resolve().parents[1] / "studies"
PNG = b"\x89PNG\r\n\x1a\n"


def load(name: str):
    """``studies/<name>.py`` as a fresh module (``studies/`` on ``sys.path`` for the
    modules it imports; registered in ``sys.modules``, where dataclasses look it up)."""
    if str(STUDIES) not in sys.path:
        sys.path.insert(0, str(STUDIES))
    spec = importlib.util.spec_from_file_location(f"{name}_study", STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def rows_of(path) -> list:
    """The rows of a CSV file as dictionaries of strings."""
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def study_json(folder) -> dict:
    """A study's ``study.json``."""
    with open(pathlib.Path(folder) / "study.json") as fh:
        return json.load(fh)


def assert_png(path) -> None:
    """``path`` is a PNG picture."""
    assert path.is_file(), path
    assert path.read_bytes()[:8] == PNG, path
