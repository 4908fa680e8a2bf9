"""Shared helpers of the tests."""

import pytest


@pytest.fixture(scope="session")
def flowing():
    """``flowing(model)``: a state of ``model`` filled for 500 steps, with the outlet opened
    and 0.1 s of discharge (flowing, plastic, loose, with markers)."""
    def make(model, fill_steps=500, discharge_time=0.1):
        state = model.initial_state()
        while state.step < fill_steps:
            model.advance(state, fill_steps - state.step)
        model.transport_step(state)
        model.open_outlet(state)
        t_end = state.t + discharge_time
        while state.t < t_end:
            model.advance(state, 50)
        return state
    return make
