"""The licence and the citation file say what the package says of itself.

``LICENSE`` is the MIT licence that ``setup.cfg`` declares; ``CITATION.cff`` is Citation File
Format 1.2.0 with the package's own version (``fipy_hopper.__version__``) and licence.
"""

import configparser
import pathlib

import pytest

import fipy_hopper

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _declared_licence() -> str:
    setup = configparser.ConfigParser()
    setup.read(ROOT / "setup.cfg", encoding="utf-8")
    return setup["metadata"]["license"]


def test_licence_file_is_the_declared_mit_licence():
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert _declared_licence() == "MIT"
    assert text.startswith("MIT License\n")
    assert "Copyright (c) 2026 the fipy_hopper developers" in text
    assert "THE SOFTWARE IS PROVIDED \"AS IS\", WITHOUT WARRANTY OF ANY KIND" in text


def test_citation_file_names_this_version_and_licence():
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0"
    for key in ("message", "title", "authors", "version", "date-released", "license"):
        assert cff.get(key), key
    assert cff["version"] == fipy_hopper.__version__
    assert cff["license"] == _declared_licence()
    assert cff["authors"] == [{"name": "fipy_hopper developers"}]
    assert str(cff["date-released"]).startswith("2026-")
