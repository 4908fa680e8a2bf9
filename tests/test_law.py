"""The material seam: the model takes its time step, its transported internal variables and
its stress update from the constitutive law it is given (fipy_hopper.material.law)."""

import dataclasses

import numpy as np
import pytest

from fipy_hopper.config import HopperConfig, damped_step_factor
from fipy_hopper.material import ConstitutiveLaw, MohrCoulomb, transported_fields
from fipy_hopper.model import TRANSPORTED, HopperModel

CFG = HopperConfig.from_dict({"hopper": {"bin_diameter": 0.16, "fill_height": 0.06,
                                         "bin_height": 0.08, "half_angle_deg": 45.0},
                              "numerics": {"cell_size": 0.01}})


def test_mohr_coulomb_declares_what_the_model_asks():
    """The configuration's law is a ConstitutiveLaw that names its parameters with units, its
    internal variable (the equivalent plastic strain) and the explicit step safety h / c_p
    with c_p = sqrt(E (1 - nu) / ((1 + nu)(1 - 2 nu) rho))."""
    law = CFG.material.law()
    assert isinstance(law, ConstitutiveLaw)
    params = law.parameters()
    mat = CFG.material
    assert params["E"] == (mat.youngs_modulus, "Pa")
    assert params["phi"] == (mat.friction_angle_deg, "deg")
    assert params["c"] == (mat.cohesion, "Pa") and params["rho"] == (mat.density, "kg/m3")
    assert law.internal_variables == ("eps_p",)
    E, nu, rho = mat.youngs_modulus, mat.poisson_ratio, mat.density
    c_p = np.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * rho))
    assert law.stable_time_step(0.01, 0.4) == pytest.approx(0.4 * 0.01 / c_p, rel=1e-15)
    # the configuration's step also carries the bulk viscosity's damped-mode factor
    assert CFG.time_step == (law.stable_time_step(0.01, 0.4)
                             * damped_step_factor(CFG.bulk_viscosity))
    assert transported_fields(law) == TRANSPORTED


@dataclasses.dataclass(frozen=True)
class HalfStepLaw(MohrCoulomb):
    """Mohr–Coulomb with half the stable step, counting its numpy updates."""

    calls: list = dataclasses.field(default_factory=list)

    def stable_time_step(self, h, safety):
        return 0.5 * super().stable_time_step(h, safety)

    def update_reference(self, sigma, d_eps, return_status=False):
        self.calls.append(len(sigma))
        return super().update_reference(sigma, d_eps, return_status=return_status)


def law_of(cls, **extra):
    """A law of class ``cls`` made from the configuration's law's declared parameters (its
    rate dependence's among them: the law's parameters are complete)."""
    from fipy_hopper.material.rate import RATE_PARAMETERS, InertialRheology

    values = {k: v for k, (v, _) in CFG.material.law().parameters().items()}
    rate = {k: values.pop(k) for k in RATE_PARAMETERS if k in values}
    return cls(**values, rate=InertialRheology(**rate) if rate else None, **extra)


def test_the_model_takes_its_step_and_its_update_from_the_law():
    """A law with half the stable step halves the model's step; the numpy step calls the
    law's own update once per step, on every cell."""
    plain = HopperModel(CFG, backend="numpy")
    law = law_of(HalfStepLaw)
    model = HopperModel(CFG, backend="numpy", law=law)
    assert model.dt == 0.5 * plain.dt
    state = model.initial_state()
    model.step(state)
    model.step(state)
    assert law.calls == [model.grid.nz * model.grid.nr] * 2


@dataclasses.dataclass(frozen=True)
class DamageLaw(MohrCoulomb):
    internal_variables = ("eps_p", "damage")


def test_a_law_with_other_internal_variables_is_refused_clearly():
    """The compiled step carries Mohr-Coulomb's internal variables only: a law that declares
    another is refused by name, not run with it dropped."""
    with pytest.raises(NotImplementedError, match="damage"):
        HopperModel(CFG, law=law_of(DamageLaw))
    with pytest.raises(ValueError, match="material.density"):
        HopperModel(CFG, law=dataclasses.replace(CFG.material.law(), rho=1000.0))


@dataclasses.dataclass(frozen=True)
class ElasticLaw(MohrCoulomb):
    """Linear elasticity: Mohr-Coulomb's elastic trial, never yielding (its own update)."""

    def update_reference(self, sigma, d_eps, return_status=False):
        from fipy_hopper.material import ELASTIC, elastic_trial

        new = elastic_trial(sigma, d_eps, self)
        out = (new, np.zeros_like(d_eps))
        return out + (np.full(len(sigma), ELASTIC),) if return_status else out

    update = update_reference


class DuckLaw:
    """A law of the protocol that is not a MohrCoulomb at all."""

    def __init__(self, law):
        self._law = law
        self.rho, self.internal_variables = law.rho, law.internal_variables

    def __getattr__(self, name):
        return getattr(self._law, name)


def test_a_law_with_its_own_update_runs_on_numpy_and_is_refused_on_numba():
    """The compiled step fuses Mohr-Coulomb's return: a law whose stress update is its own
    (or that is no MohrCoulomb) is refused on the numba backend in one line naming it and the
    numpy backend, where its update is the one that runs: with the elastic law the filled
    column carries stress the Mohr-Coulomb law would have yielded."""
    for law in (law_of(ElasticLaw), law_of(HalfStepLaw), DuckLaw(CFG.material.law())):
        with pytest.raises(NotImplementedError) as err:
            HopperModel(CFG, law=law)
        message = str(err.value)
        assert type(law).__name__ in message and 'backend="numpy"' in message
        assert "\n" not in message
    results = {}
    for name, law in (("elastic", law_of(ElasticLaw)), ("mohr_coulomb", None)):
        model = HopperModel(CFG, backend="numpy", law=law)
        state = model.initial_state()
        model.advance(state, 400)
        results[name] = state.eps_p.max(), np.abs(state.sigma).max()
    assert results["elastic"][0] == 0.0 < results["mohr_coulomb"][0]
    assert results["elastic"][1] != results["mohr_coulomb"][1]


def test_a_law_that_changes_only_its_time_step_runs_compiled():
    """A MohrCoulomb that keeps Mohr-Coulomb's stress update and changes its step is run by
    the compiled backend as it says: half the step."""

    @dataclasses.dataclass(frozen=True)
    class HalfStep(MohrCoulomb):
        def stable_time_step(self, h, safety):
            return 0.5 * super().stable_time_step(h, safety)

    model = HopperModel(CFG, law=law_of(HalfStep), threads=1)
    assert model.dt == 0.5 * HopperModel(CFG, threads=1).dt
    state = model.initial_state()
    model.advance(state, 5)
    assert state.step == 5 and state.t == pytest.approx(5 * model.dt)
