"""Validation: the published headline numbers, each held by a reduced ("sandglass") case.

Every claim of ``studies/headline.json`` (the README's validation table, ``docs/validation.md``)
is measured at full size by a study (``studies/``, reported in ``studies/REPORT.md``); here
each is held by the smallest run that still shows it, with a tolerance whose reason is
stated beside it (``docs/validation.md`` quotes these docstrings).  A claim held elsewhere:

- the rate does not depend on the fill height: ``test_discharge.py::
  test_hourglass_rate_independent_of_fill_height``;
- the outlet exponent at 4 mm cells (n = 2.5 +- 0.25): ``test_discharge.py::
  test_outlet_scaling_exponent`` (slow);
- the filled loads do not depend on E, and the wall and plate carry the weight:
  ``test_wall_loads.py``;
- the cone's pressure at rest against Walker and the profile at rest under refinement:
  ``test_wall_traction.py`` (one fixture of the reference at rest at 7.5 to 2.5 mm for every
  test of the profile at rest).

Cases: the discharge study's hopper (0.24 m bin, 0.12 m fill, 30 deg cone, phi = 30 deg,
phi_w = 15 deg, 5 mm cells, 0.8 s of discharge), the convergence study's hopper (0.2 m bin,
0.15 m fill, 30 deg cone, 0.06 m outlet).
"""

import math
import warnings

import numpy as np
import pytest

from fipy_hopper import theory
from fipy_hopper.config import HopperConfig
from fipy_hopper.diagnostics import fit_power_law
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation

RHO, PHI, PHI_W = 1500.0, 30.0, 15.0


def config(hopper: dict, cell: float, youngs_modulus: float = 5.0e6, end_time=0.8,
           wall_bin_width="auto"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")        # coarse outlets: the resolution warning
        return HopperConfig.from_dict({
            "hopper": {**hopper, "bin_height": hopper["fill_height"] + 0.02},
            "material": {"friction_angle_deg": PHI, "density": RHO,
                         "youngs_modulus": youngs_modulus},
            "wall": {"friction_angle_deg": PHI_W},
            "numerics": {"cell_size": cell},
            "run": {"end_time": end_time, "output_interval": 0.02, "markers_per_side": 0,
                    "wall_bin_width": wall_bin_width}})


def steady_rate(hopper: dict, cell: float, youngs_modulus: float = 5.0e6) -> float:
    """The steady discharge rate (kg/s) of 0.8 s of discharge after a quasi-static fill."""
    sim = Simulation(HopperModel(config(hopper, cell, youngs_modulus)), progress=False)
    sim.run()
    summary = sim.summary()
    assert summary["mass_balance_error"] < 1e-9
    return summary["steady_discharge_rate_kg_s"]


def rate_hopper(half_angle, outlet):
    return {"bin_diameter": 0.24, "fill_height": 0.12, "half_angle_deg": half_angle,
            "outlet_diameter": outlet}


CONVERGENCE_HOPPER = {"bin_diameter": 0.2, "fill_height": 0.15, "half_angle_deg": 30.0,
                      "outlet_diameter": 0.06}
OUTLETS = (0.04, 0.06, 0.08)


@pytest.fixture(scope="module")
def outlet_sweep():
    """``{(theta, D0): W}`` at 5 mm: the 30 deg cone at three outlets and a 20 deg cone."""
    cases = [(30.0, d0) for d0 in OUTLETS] + [(20.0, 0.06)]
    return {case: steady_rate(rate_hopper(*case), 0.005) for case in cases}


GRAIN = HopperConfig().material.grain_diameter       # the default grain size (m)


def beverloo_rose_tanaka(theta, d0):
    """Beverloo (C = 0.58, k = 1.5 with the material's grain size) x Rose-Tanaka (kg/s)."""
    return float(theory.beverloo_rate(RHO, d0, d=GRAIN) * theory.rose_tanaka_factor(theta))


def test_rate_against_beverloo_times_rose_tanaka(outlet_sweep):
    """The rate against Beverloo x Rose-Tanaka with the grain size (headline
    ``rate_beverloo_rose_tanaka``; k = 1.5, d = 1 mm, the material's).

    Here 4 of them: the mean |difference| below 7 % and each below 12 %.  Why so wide:
    Beverloo's C is 0.55-0.65 over the cohesionless materials it was fitted to (+-8 % about
    the 0.58 used), the smallest outlet (4 cells across its radius) runs about 10 % slow on
    this grid (the convergence study: the rate still rises by 1.4 % from 5 to 3.75 mm with 6
    cells), and the default bulk viscosity (b_1 = 0.06, eta_b proportional to h) lowers the
    5 mm rates by 2-4 %.  Measured: -5.1, -3.0, -1.8 % (30 deg; D0 = 40, 60, 80 mm) and
    -2.6 % (20 deg), mean 3.1 %."""
    diffs = {case: w / beverloo_rose_tanaka(*case) - 1 for case, w in outlet_sweep.items()}
    assert np.mean([abs(d) for d in diffs.values()]) < 0.07, diffs
    assert max(abs(d) for d in diffs.values()) < 0.12, diffs


def test_outlet_exponent_and_beverloo_constant(outlet_sweep):
    """The outlet exponent and Beverloo's C (headline ``outlet_exponent``).

    Over three outlets the exponent is 2.5 +- 0.25 (the under-resolved smallest outlet
    steepens the fit by about 0.15 at 5 mm, and the grain size's deficit, largest at the
    smallest outlet, by a little more), and C fitted with the exponent held at 5/2 on
    Beverloo's (D0 - k d) (k = 1.5, the material's d) and the Rose-Tanaka factor divided out
    is inside Beverloo's range 0.55-0.65 for cohesionless solids, less the 2-4 % by which the
    default bulk viscosity (b_1 = 0.06) lowers the 5 mm rates: [0.53, 0.65].  Measured:
    C = 0.561."""
    rates = [outlet_sweep[(30.0, d0)] for d0 in OUTLETS]
    _, n = fit_power_law(OUTLETS, rates)
    assert abs(n - 2.5) <= 0.25, (rates, n)
    factor = float(theory.rose_tanaka_factor(30.0))
    c = [w / (RHO * math.sqrt(theory.G) * (d0 - 1.5 * GRAIN) ** 2.5) / factor
         for d0, w in zip(OUTLETS, rates)]
    c_fit = float(np.exp(np.mean(np.log(c))))
    assert 0.53 <= c_fit <= 0.65, (c, c_fit)


@pytest.fixture(scope="module")
def convergence_rates():
    """``{(cell, E): W}``: 7.5, 5 and 3.75 mm at 5 MPa, and 2 and 20 MPa at 7.5 mm."""
    pairs = [(0.0075, 5e6), (0.005, 5e6), (0.00375, 5e6), (0.0075, 2e6), (0.0075, 20e6)]
    return {pair: steady_rate(CONVERGENCE_HOPPER, *pair) for pair in pairs}


def test_rate_converges_with_the_cell_size(convergence_rates):
    """The rate converges with the cell size (headline ``rate_cell_size``).

    Held: the change from 5 to 3.75 mm is below 3.5 % and smaller than the one before it
    (a first-order scheme at the free surfaces and the wall halves its error with the cell
    size, and so does the default bulk viscosity, eta_b proportional to h; 3.5 % leaves room
    for the +-1 % scatter of the steady-rate median).  Measured: 2.660 / 2.762 / 2.844 kg/s,
    +3.8 and +3.0 % (without the bulk viscosity +2.8 and +1.4 %)."""
    w75, w5, w375 = (convergence_rates[(c, 5e6)] for c in (0.0075, 0.005, 0.00375))
    first, second = abs(w5 / w75 - 1), abs(w375 / w5 - 1)
    assert second < 0.035, (w75, w5, w375)
    assert second < first, (w75, w5, w375)


def test_rate_does_not_depend_on_the_stiffness(convergence_rates):
    """The rate does not depend on the stiffness (headline ``rate_stiffness``).

    Held at 7.5 mm: the spread (max - min) / mean over E = 2, 5 and 20 MPa is below 2 %.  A
    rate-independent continuum has no time scale from E in its discharge rate; what is left
    is the elastic transient at the opening (its period scales as 1/sqrt(E)), which moves the
    steady-rate median by under 1 %; a stiffness-dependent rate would move it by sqrt(10)."""
    rates = [convergence_rates[(0.0075, e)] for e in (2e6, 5e6, 20e6)]
    spread = (max(rates) - min(rates)) / np.mean(rates)
    assert spread < 0.02, rates
