"""The 3D model's compiled step: the number of threads changes no bit (run with
``NUMBA_NUM_THREADS >= 2``; skipped with one), and the compiled momentum transport on the dual
grid equals its numpy reference."""

import numba
import numpy as np
import pytest

from fipy_hopper.space.config import small_silo
from fipy_hopper.space.model import SpaceModel


def _run(model, state, steps, threads):
    saved = numba.get_num_threads()
    model.threads = threads
    try:
        while state.step < steps:
            model.advance(state, steps - state.step)
    finally:
        numba.set_num_threads(saved)
    return state


@pytest.fixture(scope="module")
def flowing_half():
    """The small silo with its outlet 0.04 m off the axis (a half): 300 steps of fill, the
    outlet opened, 500 steps of discharge (plastic, loose, transports)."""
    model = SpaceModel(small_silo(outlet_offset=0.04), threads=1)
    state = model.initial_state()
    while state.step < 300:
        model.advance(state, 300 - state.step)
    model.transport_step(state)
    model.open_outlet(state)
    while state.step < 800:
        model.advance(state, 800 - state.step)
    return model, state


def test_threads_do_not_change_a_bit(flowing_half):
    """Two threads and one give the same state after 300 more steps of discharge (transports
    included) to the last bit: every field, the impulses and the budget."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two threads (NUMBA_NUM_THREADS >= 2)")
    model, state = flowing_half
    one = _run(model, state.copy(), state.step + 300, threads=1)
    two = _run(model, state.copy(), state.step + 300, threads=2)
    for name in ("v", "alpha", "sigma", "eps_p", "loose", "flux_z", "flux_y", "flux_x",
                 "wall_impulse", "plate_impulse", "momentum_budget"):
        assert np.array_equal(getattr(one, name), getattr(two, name)), name
    assert one.discharged == two.discharged and one.t == two.t
    assert np.abs(one.v).max() > 0.1


def test_compiled_dual_momentum_transport_equals_numpy(flowing_half):
    """The nodal momentum's transport on the dual grid over a discharge's transport interval
    (the mean face fluxes of 40 steps): the compiled kernel (on the node planes of the
    material, one and two threads) gives the numpy reference's velocities to the bit, the
    outflow and the stopped momentum to 1e-12 (their sums' order differs)."""
    from fipy_hopper.space import momentum as sm
    from fipy_hopper.space.model import dual_momentum_transport
    from fipy_hopper.space.transport import dual_momentum_transport_compiled
    from fipy_hopper.transport import material_rows
    model, state = flowing_half
    g = model.grid
    rng = np.random.default_rng(3)
    mass_old = model.node_mass(state)
    alpha_new = np.clip(state.alpha * (1.0 + 0.05 * rng.standard_normal(state.alpha.shape)),
                        0.0, 1.0) * (state.alpha > 0)
    mass_new = sm.node_mass(model.rho, alpha_new, model.open_volume)
    vz, vy, vx = sm.face_velocities(state.v)
    dt = 40 * model.dt
    fz = vz * g.aperture_z * g.h ** 2 * dt
    fy = vy * g.aperture_y * g.h ** 2 * dt
    fx = vx * g.aperture_x * g.h ** 2 * dt
    ref = dual_momentum_transport(state.v, mass_old, mass_new, fz, fy, fx, model.rho,
                                  model.light_mass)
    c0, c1 = material_rows(state.alpha.reshape(g.nz, -1), margin=1)
    assert ref[1] != 0.0 and c0 == 0 and c1 < g.nz
    for threads in ((1, 2) if numba.config.NUMBA_NUM_THREADS >= 2 else (1,)):
        for rows in (None, (c0, c1 + 1)):
            v_new, outflow, stopped = dual_momentum_transport_compiled(
                state.v, mass_old, mass_new, fz, fy, fx, model.rho, model.light_mass, rows,
                threads)
            assert np.array_equal(v_new, ref[0])
            assert outflow == pytest.approx(ref[1], rel=1e-12)
            assert stopped == pytest.approx(ref[2], rel=1e-12, abs=1e-15)
    assert np.abs(ref[0]).max() > 0.1
