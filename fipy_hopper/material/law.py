"""What the model asks of a constitutive law (the material seam).

A law is an object that declares

* ``parameters()``: its parameters, ``{name: (value, unit)}`` in SI units (angles in degrees);
* ``internal_variables``: the names of the per-point state it carries besides the stress, which
  the transport must carry with the material (for Mohr–Coulomb ``("eps_p",)``, the equivalent
  plastic strain);
* ``rho`` (kg/m^3) and ``p_wave_speed`` (m/s), and ``stable_time_step(h, safety)``: the explicit
  step ``safety * h / c_p`` (s) on cells of size ``h`` (m);
* ``update(sigma, d_eps, return_status=False)``: the stress update of a strain increment on
  arrays of points ``(n, 4)`` (``rr, zz, tt, rz``, tension positive, Pa) returning the new
  stress and the plastic strain increment (and, with ``return_status``, ``ELASTIC``/``PLASTIC``/
  ``APEX`` per point), with ``update_reference`` its plain-numpy twin;
* ``kernel_parameters()``: the float array its compiled kernels read inside the fused step;
* ``rate_parameters()`` and ``overstress_reference(sigma, D, flowing)``: its rate dependence
  above the yield surface (:mod:`fipy_hopper.material.rate`: the grain size ``d``, ``rho_s``,
  ``delta_mu``, ``I_0``; zeros for a rate-independent law) and its numpy overstress
  ``2 eta D'`` (Pa) in flowing material, which the momentum balance adds to the stored stress
  in its forces (the compiled step calls the law's compiled point functions
  ``rate.overstress_factor`` and ``rate.deviatoric_rate`` with ``rate_parameters()``).

The model (:class:`fipy_hopper.model.HopperModel`) takes its time step, the fields it transports
and its stress update from the law, and keeps what is not a property of the material to
itself: the dense/loose rule (:mod:`fipy_hopper.dense_loose`) is a closure of the Eulerian
mixture, applied around the law's update.  :class:`~fipy_hopper.material.MohrCoulomb` (the
Abaqus form) is the law implemented; the compiled step is written for its internal variables
and calls its compiled point update (:func:`fipy_hopper.material.return_fast.update_points`,
the one compiled Mohr–Coulomb return) and its compiled overstress, so the compiled backend runs
a law only when those are exactly its stress update and its rate dependence
(:func:`compiled_refusal`); any other law runs on the numpy backend, which calls the law's own
``update_reference`` and ``overstress_reference``.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

#: the stress components every law updates, in the order of the state's ``sigma[..., k]``
STRESS_COMPONENTS = ("s_rr", "s_zz", "s_tt", "s_rz")


@runtime_checkable
class ConstitutiveLaw(Protocol):
    """The protocol of a constitutive law (see the module docstring)."""

    internal_variables: tuple
    rho: float

    def parameters(self) -> dict: ...

    @property
    def p_wave_speed(self) -> float: ...

    def stable_time_step(self, h: float, safety: float) -> float: ...

    def update(self, sigma: np.ndarray, d_eps: np.ndarray, return_status: bool = False): ...

    def update_reference(self, sigma: np.ndarray, d_eps: np.ndarray,
                         return_status: bool = False): ...

    def kernel_parameters(self) -> np.ndarray: ...

    def rate_parameters(self) -> np.ndarray: ...

    def overstress_reference(self, sigma: np.ndarray, D: np.ndarray, flowing) -> np.ndarray: ...


def transported_fields(law: ConstitutiveLaw, model_fields=("layer", "loose")) -> tuple:
    """The cell fields the Eulerian transport carries for ``law``: the material fraction
    ``alpha``, the stress components, the law's internal variables, then the model's own
    (the layer tracer and the loose strain of the dense/loose rule)."""
    return ("alpha",) + STRESS_COMPONENTS + tuple(law.internal_variables) + tuple(model_fields)


#: the methods of a law that make up its stress update; the compiled step fuses
#: :class:`~fipy_hopper.material.MohrCoulomb`'s
STRESS_UPDATE = ("update", "update_reference", "kernel_parameters", "rate_parameters",
                 "overstress_reference")


def compiled_refusal(law) -> str:
    """Why the compiled step cannot run ``law`` ('' when it can): the step fuses Mohr-Coulomb's
    return mapping on ``kernel_parameters()``, so it runs a
    :class:`~fipy_hopper.material.MohrCoulomb` whose stress update (:data:`STRESS_UPDATE`) is
    Mohr-Coulomb's own; a law that changes only its time step is run as it says."""
    from .mohr_coulomb import MohrCoulomb

    name = type(law).__name__
    if not isinstance(law, MohrCoulomb):
        return f"the law {name} is not a MohrCoulomb"
    changed = [m for m in STRESS_UPDATE
               if getattr(type(law), m) is not getattr(MohrCoulomb, m)]
    if changed:
        return f"the law {name} has its own {', '.join(changed)}"
    return ""
