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
