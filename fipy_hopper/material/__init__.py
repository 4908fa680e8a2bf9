"""Mohr–Coulomb elastoplasticity in the Abaqus form, on arrays of axisymmetric stress states.

The stress update :func:`update` (numba) and its plain-numpy twin :func:`update_reference` perform an
elastic predictor and an implicit (backward-Euler) return in principal space; see
:func:`update_reference` for the algorithm.  The compiled update first tries a faster solve of the
same return, one scalar equation in the Lode angle iterated for a block of points at once
(:func:`~fipy_hopper.material.return_fast._fast_block`), and hands every point it does not accept
to the reference's algorithm.  :func:`element_test` drives one material point along the classical
laboratory paths with mixed stress/strain control.  Stresses ``(..., 4)`` in the order
``(rr, zz, tt, rz)``, tension positive, Pa; strains with the tensor shear component ``eps_rz``.

Modules:

* ``mohr_coulomb``: the law (parameters, invariants, yield function ``F``, flow potential ``G``
  and its gradient, elasticity, status codes) and the formulas the returns share;
* ``return_robust``: the robust compiled return of one point (``_return_sorted``);
* ``return_fast``: :func:`update`, the compiled blocked return;
* ``return_reference``: :func:`update_reference`, the numpy reference of the return;
* ``law``: what the model asks of a constitutive law (:class:`ConstitutiveLaw`), which
  :class:`MohrCoulomb` implements;
* ``element_tests``: the laboratory driver (:func:`drive`, :func:`element_test`).
"""

from . import mohr_coulomb
from .element_tests import PATHS, ElementTestResult, drive, element_test
from .law import ConstitutiveLaw, compiled_refusal, transported_fields
from .mohr_coulomb import (APEX, ELASTIC, PLASTIC, MohrCoulomb, R_mc, R_mw, elastic_stiffness,
                           elastic_trial, equivalent_plastic_strain, flow_direction,
                           flow_potential, invariants, plastic_strain_from_stress,
                           principal_stresses, yield_function)
from .return_fast import update
from .return_reference import update_reference

__all__ = [*mohr_coulomb.__all__, "ConstitutiveLaw", "compiled_refusal", "transported_fields",
           "update",
           "update_reference", "ElementTestResult", "PATHS", "drive", "element_test"]
