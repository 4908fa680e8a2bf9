"""FiPy's private API is reached through one module, fipy_hopper.fipy_adapter: the installed FiPy
has every private name it reads, no other module reads one, a renamed one fails in one line
naming it and the tested range, and setup.cfg requires that range."""

import ast
import configparser
from pathlib import Path

import pytest

import fipy_hopper
from fipy_hopper import fipy_adapter
from fipy_hopper.fipy_adapter import FiPyVersionError

PACKAGE = Path(fipy_hopper.__file__).resolve().parent
PRIVATE = set(fipy_adapter.MESH_ATTRIBUTES).union(*fipy_adapter.TERM_METHODS.values())


def test_the_installed_fipy_has_every_private_name_the_package_reads():
    assert fipy_adapter.missing() == [], (
        f"the installed FiPy lacks {fipy_adapter.missing()}: update fipy_hopper/fipy_adapter.py "
        f"(tested with fipy{fipy_adapter.TESTED})")


def test_no_other_module_reads_a_private_fipy_name():
    """Outside the adapter, no attribute access and no import names a private FiPy member or
    module (the axisymmetric term may define FiPy's ``_getOldAdjacentValues``: an override)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "fipy_adapter.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Attribute) and node.attr in PRIVATE:
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno} .{node.attr}")
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                    ("fipy.meshes", "fipy.terms")):
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {node.module}")
    assert not found, found


def test_a_renamed_fipy_attribute_fails_in_one_line_naming_it(monkeypatch):
    """As if FiPy renamed a mesh attribute: :func:`missing` names one the meshes lack, and the
    accessor of one a mesh lacks raises :class:`FiPyVersionError` naming it, the installed
    version and the tested range."""
    import fipy

    renamed = fipy_adapter.MESH_ATTRIBUTES + ("_faceAreasRenamed",)
    monkeypatch.setattr(fipy_adapter, "MESH_ATTRIBUTES", renamed)
    assert fipy_adapter.missing() == ["CylindricalNonUniformGrid2D._faceAreasRenamed",
                                      "UniformGrid2D._faceAreasRenamed"]
    mesh = fipy.CylindricalGrid2D(dx=[1.0, 1.0], dy=[1.0, 1.0])
    monkeypatch.delattr(mesh, "_faceAreas")
    with pytest.raises(FiPyVersionError) as err:
        fipy_adapter.face_areas(mesh)
    message = str(err.value)
    assert "\n" not in message and "CylindricalNonUniformGrid2D._faceAreas" in message
    assert fipy.__version__ in message and fipy_adapter.TESTED in message


def test_setup_requires_the_tested_fipy_and_it_is_installed():
    from importlib import metadata

    from packaging.specifiers import SpecifierSet

    setup = configparser.ConfigParser()
    setup.read(PACKAGE.parent / "setup.cfg")
    requires = setup["options"]["install_requires"].split()
    assert f"fipy{fipy_adapter.TESTED}" in requires
    assert metadata.version("fipy") in SpecifierSet(fipy_adapter.TESTED)
