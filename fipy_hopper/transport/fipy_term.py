"""Transport (1) as FiPy equations: the definition the compiled and numpy kernels are held to.

:class:`FiPyTransport` builds one equation ``TransientTerm(kappa_eff) + Convection(u a) == 0`` per
field (``u`` in m/s, fields per open volume); ``Convection`` is FiPy's ``VanLeerConvectionTerm``
(``scheme="fipy"``) or :data:`AxisymmetricVanLeerConvectionTerm` (``scheme="axisymmetric"``), FiPy's
term with the bounded planar reconstruction of :mod:`fipy_hopper.transport.vanleer`.
"""

from __future__ import annotations

import numpy as np

from .. import fipy_adapter
from .geometry import TransportGeometry
from .vanleer import cell_gradient

__all__ = ["FiPyTransport"]


# --------------------------------------------------------------------------------------------
# The definition: FiPy equations
# --------------------------------------------------------------------------------------------

def _axisymmetric_term_class():
    """:class:`AxisymmetricVanLeerConvectionTerm`, built on first use (FiPy is imported late)."""
    global AxisymmetricVanLeerConvectionTerm
    if AxisymmetricVanLeerConvectionTerm is not None:
        return AxisymmetricVanLeerConvectionTerm
    import fipy
    from fipy.tools import numerix

    from .. import fipy_adapter as fa

    class _Term(fipy.VanLeerConvectionTerm):
        """FiPy's ``VanLeerConvectionTerm`` with the bounded axisymmetric reconstruction.

        Everything is FiPy's (the explicit upwind assembly, the MC limiter ``_getGradient``, the
        CFL correction, the conservative update solved by FiPy) except the two geometric
        factors of the donor's extrapolation (:mod:`fipy_hopper.transport.vanleer`): the cell
        gradient is the planar Gauss gradient ``sum n L phi_f / (dr dz)`` (:func:`cell_gradient`
        of the ``"axisymmetric"`` geometry) instead of ``phi.grad``, and the reach is
        ``V / (2 d_Pf)`` instead of the face area ``A``.  ``geometry`` is a
        :class:`TransportGeometry` of ``scheme="axisymmetric"`` for the term's mesh.
        """

        def __init__(self, coeff=1.0, var=None, geometry=None):
            super().__init__(coeff=coeff, var=var)
            if geometry is None or geometry.scheme != "axisymmetric":
                raise ValueError("the term needs the mesh's axisymmetric TransportGeometry")
            self._planar = geometry

        def _getOldAdjacentValues(self, oldArray, id1, id2, dt):    # FiPy's own override
            oldArray1, oldArray2 = fa.upwind_adjacent_values(self, oldArray, id1, id2, dt)
            mesh, geom = oldArray.mesh, self._planar
            interiorIDs = numerix.nonzero(mesh.interiorFaces)[0]
            normals = numerix.take(fa.oriented_face_normals(mesh), interiorIDs, axis=-1)
            interiorCFL = abs(numerix.take(fa.geom_coeff(self, oldArray), interiorIDs)) * dt
            gradUpwind = (oldArray2 - oldArray1) / numerix.take(fa.cell_distances(mesh),
                                                                interiorIDs)
            grad = cell_gradient(geom, np.asarray(oldArray.value, float)[None])[:, 0]
            vol1 = numerix.take(mesh.cellVolumes, id1)
            oldArray1 += 0.5 * fa.limited_gradient(
                self, numerix.dot(numerix.take(grad, id1, axis=-1), normals), gradUpwind) \
                * (vol1 - interiorCFL) / geom.reach_1
            vol2 = numerix.take(mesh.cellVolumes, id2)
            oldArray2 += 0.5 * fa.limited_gradient(
                self, numerix.dot(numerix.take(grad, id2, axis=-1), -normals), -gradUpwind) \
                * (vol2 - interiorCFL) / geom.reach_2
            return oldArray1, oldArray2

    _Term.__name__ = _Term.__qualname__ = "AxisymmetricVanLeerConvectionTerm"
    AxisymmetricVanLeerConvectionTerm = _Term
    return _Term


#: FiPy's van Leer convection term with the bounded axisymmetric reconstruction (a subclass
#: of ``fipy.VanLeerConvectionTerm``, made on first use by :func:`_axisymmetric_term_class`).
AxisymmetricVanLeerConvectionTerm = None


class FiPyTransport:
    """Transport (1) as FiPy equations, one per field, built once (the reference).

    ``TransientTerm(coeff=kappa_eff, var=phi) + Convection(coeff=u a, var=phi) == 0`` with
    ``u = u_n * mesh.faceNormals`` (a rank-1 ``FaceVariable`` updated by ``setValue``) and
    ``phi.faceGrad.constrain(0., where=outflow)``; solved with FiPy's ``LinearLUSolver`` (the
    matrix is diagonal).  ``scheme="axisymmetric"`` (the default, what the model runs):
    ``Convection`` is :class:`AxisymmetricVanLeerConvectionTerm`; ``"fipy"``: FiPy's own
    ``VanLeerConvectionTerm``.
    """

    def __init__(self, mesh, kappa, aperture, outflow_faces, field_names,
                 scheme="axisymmetric"):
        import fipy

        self.mesh = mesh
        self.scheme = scheme
        self.geometry = geom = TransportGeometry.from_mesh(mesh, kappa, aperture, outflow_faces,
                                                           scheme=scheme)
        self.field_names = tuple(field_names)
        self._velocity = fipy.FaceVariable(mesh=mesh, rank=1, value=0.0)
        self._aperture = fipy.FaceVariable(mesh=mesh, value=geom.aperture)
        kappa_eff = fipy.CellVariable(mesh=mesh, value=geom.kappa_volume / geom.cell_volume)
        coeff = self._velocity * self._aperture
        outflow = fipy.FaceVariable(mesh=mesh, value=geom.outflow_mask)
        self._solver = fipy.LinearLUSolver()
        self.variables, self.terms, self.equations = {}, {}, {}
        for name in self.field_names:
            phi = fipy.CellVariable(mesh=mesh, name=name, value=0.0, hasOld=True)
            if geom.outflow.size:
                phi.faceGrad.constrain(0.0, where=outflow)
            if scheme == "axisymmetric":
                convection = _axisymmetric_term_class()(coeff=coeff, var=phi, geometry=geom)
            else:
                convection = fipy.VanLeerConvectionTerm(coeff=coeff, var=phi)
            self.variables[name] = phi
            self.terms[name] = convection
            self.equations[name] = (fipy.TransientTerm(coeff=kappa_eff, var=phi)
                                    + convection == 0)

    def step(self, fields, u_n, dt):
        """Advance every field by ``dt`` (s) with face normal velocity ``u_n`` (m/s, nFaces).

        Returns ``(new_fields, face_flux)``: dicts of (nCells,) and (nFaces,) arrays;
        ``face_flux = dt u_n a A phi_f`` (field x m^3 per radian) along the face normals.
        """
        geom = self.geometry
        u_n = geom.outflow_velocity(u_n)
        self._velocity.setValue(u_n * geom.face_normal)
        volume_flux = geom.volume_flux(u_n)
        id1 = geom.face_cell_1[geom.interior]
        id2 = geom.face_cell_2[geom.interior]
        new_fields, face_flux = {}, {}
        for name in self.field_names:
            phi = self.variables[name]
            phi.setValue(np.asarray(fields[name], dtype=float))
            phi.updateOld()
            # FiPy's own face values (the term's explicit arithmetic), for the face fluxes
            phi1, phi2 = fipy_adapter.adjacent_values(self.terms[name], phi.old, id1, id2, dt)
            self.equations[name].solve(var=phi, dt=dt, solver=self._solver)
            new = np.array(phi.value, dtype=float)
            flux = np.zeros(geom.n_faces)
            f_int = volume_flux[geom.interior]
            flux[geom.interior] = dt * f_int * np.where(f_int > 0.0, phi1, phi2)
            out = geom.outflow
            flux[out] = dt * volume_flux[out] * new[geom.face_cell_1[out]]
            new_fields[name], face_flux[name] = new, flux
        return new_fields, face_flux
