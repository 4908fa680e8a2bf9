"""Hourglass control: the checkerboard velocity mode decays at the control's stated rate.

One-point quadrature of the bilinear element leaves the checkerboard velocity mode without
stiffness: its strain rate at the cell centres is zero, so no stress resists it, and its face
velocities (edge means) are zero, so transport does not see it.  The viscous hourglass force
``kappa_hg rho sqrt(g h)`` damps it at the rate ``16 kappa_hg sqrt(g / h)`` (each node feels
four cells), 50 1/s for ``kappa_hg = 0.1`` on a 1 cm grid.

The test isolates the control: a checkerboard on material at rest, stress free, with no
gravity, no filling damping and no transport over the interval (the interval between
transports made longer than the test).  Then the control is the only thing that acts: with
``kappa_hg = 0`` the mode keeps its amplitude (a test that would pass without the control
would fail here), and with the control it decays at the stated rate (within 3 %: the rate of
a discrete explicit decay, ``-ln(1 - r dt) / dt``, differs from ``r`` by ``r dt / 2``).
"""

import math
import warnings

import numpy as np
import pytest

from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel


def checkerboard_amplitude(v, interior):
    sign = (-1.0) ** np.add.outer(np.arange(v.shape[1]), np.arange(v.shape[2]))
    return float(np.abs(np.mean((v[1] * sign)[interior])))


def decay(kappa, t_end=0.03):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "half_angle_deg": 90,
                       "bin_height": 0.22, "fill_height": 0.2},
            "numerics": {"cell_size": 0.01, "hourglass_coefficient": kappa,
                         "gravity_ramp_time": 1000.0, "max_fill_time": 1000.0,
                         "max_transport_interval": 100_000, "transport_cfl": 0.5}})
    model = HopperModel(cfg)
    model.fill_damping = 0.0              # the control alone
    model.ramp_time = math.inf            # no gravity (it rises over "infinite" time)
    st = model.initial_state()
    g = model.grid
    # the mode on every node that carries mass above the plate (a truncated checkerboard
    # would radiate elastic waves from its edges), measured away from the edges
    mass = model.node_mass(st)
    rows = np.arange(g.nz + 1)[:, None]
    moving = (mass > model.light_mass) & (rows > g.j_outlet)
    interior = np.zeros(st.v.shape[1:], bool)
    interior[g.j_outlet + 5:g.j_outlet + 14, 2:g.nr - 5] = True
    assert np.all(moving[interior])
    sign = (-1.0) ** np.add.outer(np.arange(g.nz + 1), np.arange(g.nr + 1))
    st.v[1] = np.where(moving, 1e-4 * sign, 0.0)
    a0 = checkerboard_amplitude(st.v, interior)
    steps = int(round(t_end / model.dt))
    done = 0
    while done < steps:
        done += model.advance(st, steps - done)
    assert st.flux_time > 0.0                        # no transport happened
    a1 = checkerboard_amplitude(st.v, interior)
    return a1 / a0, steps * model.dt, math.sqrt(9.81 / g.h)


def test_without_control_the_checkerboard_stays():
    ratio, _, _ = decay(0.0)
    assert ratio == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("kappa", [0.1, 0.05])
def test_checkerboard_decays_at_the_stated_rate(kappa):
    ratio, t, scale = decay(kappa)
    measured = -math.log(ratio) / t
    assert measured == pytest.approx(16 * kappa * scale, rel=0.03)
