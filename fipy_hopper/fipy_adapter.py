"""The one place where fipy_hopper reaches into FiPy's private API.

The transport reads geometry FiPy keeps in private mesh attributes (face areas, cell distances,
...) and :class:`~fipy_hopper.transport.fipy_term.AxisymmetricVanLeerConvectionTerm` overrides
and calls private methods of FiPy's convection terms.  Each is reached through a function here,
which names it in :data:`MESH_ATTRIBUTES` or :data:`TERM_METHODS`; a FiPy that renamed one
fails with :class:`FiPyVersionError` naming it and the tested range, and :func:`missing` lists
what the installed FiPy lacks (the test suite asserts it is empty).  ``setup.cfg`` requires
FiPy in :data:`TESTED` for this reason.
"""

from __future__ import annotations

#: the FiPy releases fipy_hopper is tested with (``setup.cfg``'s ``install_requires``)
TESTED = ">=4.0,<4.1"
#: the private attributes of a FiPy 2D mesh that the transport reads
MESH_ATTRIBUTES = ("_faceAreas", "_adjacentCellIDs", "_areaProjections", "_faceToCellDistances",
                   "_faceToCellDistanceRatio", "_cellToFaceOrientations", "_cellDistances",
                   "_orderedCellVertexIDs", "_orientedFaceNormals")
#: the private methods of FiPy's convection terms that the axisymmetric term overrides or calls
TERM_METHODS = {"ExplicitUpwindConvectionTerm": ("_getOldAdjacentValues",),
                "VanLeerConvectionTerm": ("_getOldAdjacentValues", "_getGradient",
                                          "_getGeomCoeff")}


class FiPyVersionError(RuntimeError):
    """The installed FiPy lacks a private attribute that fipy_hopper reads."""


def _fail(what: str) -> FiPyVersionError:
    import fipy

    return FiPyVersionError(f"FiPy {fipy.__version__} has no {what}, which fipy_hopper reads "
                            f"(tested with fipy{TESTED}: pip install 'fipy{TESTED}')")


def _get(obj, name: str):
    try:
        return getattr(obj, name)
    except AttributeError:
        raise _fail(f"{type(obj).__name__}.{name}") from None


def _mesh(mesh, name: str):
    assert name in MESH_ATTRIBUTES, name
    return _get(mesh, name)


def face_areas(mesh):
    """The area of each face (m^2 per radian on a cylindrical grid)."""
    return _mesh(mesh, "_faceAreas")


def adjacent_cell_ids(mesh):
    """``(id1, id2)``: the two cells of each face (a boundary face repeats its cell)."""
    return _mesh(mesh, "_adjacentCellIDs")


def area_projections(mesh):
    """The face normals times the face areas, ``(2, nFaces)``."""
    return _mesh(mesh, "_areaProjections")


def face_to_cell_distances(mesh):
    """The distances from each face to its two cells' centres, ``(2, nFaces)`` (masked)."""
    return _mesh(mesh, "_faceToCellDistances")


def face_to_cell_distance_ratio(mesh):
    """The ratio of the first cell's distance to the distance between the cells' centres."""
    return _mesh(mesh, "_faceToCellDistanceRatio")


def cell_to_face_orientations(mesh):
    """The sign of each cell's faces' normals seen from the cell, ``(4, nCells)`` (masked)."""
    return _mesh(mesh, "_cellToFaceOrientations")


def cell_distances(mesh):
    """The distance between the centres of each face's two cells."""
    return _mesh(mesh, "_cellDistances")


def ordered_cell_vertex_ids(mesh):
    """The vertices of each cell in order round it, ``(4, nCells)`` (masked)."""
    return _mesh(mesh, "_orderedCellVertexIDs")


def oriented_face_normals(mesh):
    """The face normals, oriented from the first to the second cell of the face."""
    return _mesh(mesh, "_orientedFaceNormals")


def _term_method(cls, name: str):
    assert name in TERM_METHODS.get(cls.__name__, ()), (cls.__name__, name)
    return _get(cls, name)


def upwind_adjacent_values(term, old, id1, id2, dt):
    """FiPy's explicit upwind face values of ``old`` (``ExplicitUpwindConvectionTerm``'s)."""
    from fipy.terms.explicitUpwindConvectionTerm import ExplicitUpwindConvectionTerm

    method = _term_method(ExplicitUpwindConvectionTerm, "_getOldAdjacentValues")
    return method(term, old, id1, id2, dt)


def adjacent_values(term, old, id1, id2, dt):
    """The face values of ``old`` that ``term`` (a van Leer term) convects."""
    import fipy

    _term_method(fipy.VanLeerConvectionTerm, "_getOldAdjacentValues")
    return term._getOldAdjacentValues(old, id1, id2, dt)


def limited_gradient(term, grad, grad_upwind):
    """The van Leer term's limited gradient (FiPy's monotonised-central limiter)."""
    import fipy

    return _term_method(fipy.VanLeerConvectionTerm, "_getGradient")(term, grad, grad_upwind)


def geom_coeff(term, var):
    """The term's geometric coefficient (the face volume flux) for ``var``."""
    import fipy

    return _term_method(fipy.VanLeerConvectionTerm, "_getGeomCoeff")(term, var)


def UniformGrid2D(*args, **kwargs):
    """``fipy.meshes.uniformGrid2D.UniformGrid2D`` (a module FiPy does not export)."""
    try:
        from fipy.meshes.uniformGrid2D import UniformGrid2D as grid
    except ImportError:
        raise _fail("fipy.meshes.uniformGrid2D.UniformGrid2D") from None
    return grid(*args, **kwargs)


def UniformGrid3D(*args, **kwargs):
    """``fipy.meshes.uniformGrid3D.UniformGrid3D`` (a module FiPy does not export)."""
    try:
        from fipy.meshes.uniformGrid3D import UniformGrid3D as grid
    except ImportError:
        raise _fail("fipy.meshes.uniformGrid3D.UniformGrid3D") from None
    return grid(*args, **kwargs)


def missing() -> list:
    """The private names of :data:`MESH_ATTRIBUTES` and :data:`TERM_METHODS` (and the module
    of :func:`UniformGrid2D`) that the installed FiPy lacks, checked on small meshes of both
    kinds fipy_hopper builds: [] when everything fipy_hopper reads is there."""
    import fipy
    from fipy.terms import explicitUpwindConvectionTerm

    gone = []
    try:
        plane = UniformGrid2D(dx=1.0, dy=1.0, nx=2, ny=2)
    except FiPyVersionError:
        gone.append("fipy.meshes.uniformGrid2D.UniformGrid2D")
        plane = None
    try:
        UniformGrid3D(dx=1.0, dy=1.0, dz=1.0, nx=1, ny=1, nz=1)
    except FiPyVersionError:
        gone.append("fipy.meshes.uniformGrid3D.UniformGrid3D")
    for mesh in (fipy.CylindricalGrid2D(dx=[1.0, 1.0], dy=[1.0, 1.0]), plane):
        for name in MESH_ATTRIBUTES:
            if mesh is not None and not hasattr(mesh, name):
                gone.append(f"{type(mesh).__name__}.{name}")
    classes = {"ExplicitUpwindConvectionTerm":
               explicitUpwindConvectionTerm.ExplicitUpwindConvectionTerm,
               "VanLeerConvectionTerm": fipy.VanLeerConvectionTerm}
    for cls, names in TERM_METHODS.items():
        gone += [f"{cls}.{name}" for name in names if not hasattr(classes[cls], name)]
    return list(dict.fromkeys(gone))
