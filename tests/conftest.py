"""Shared helpers of the tests."""

import os

import pytest

if os.environ.get("PYTEST_XDIST_WORKER"):
    # a process per core, each with numba's OpenMP threads: idle threads that spin waiting
    # for the next parallel loop take the other process's core; let them sleep instead (set
    # before the first parallel kernel starts the OpenMP runtime)
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


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


#: the test files with the longest shared runs (module fixtures), longest first: collected
#: first, so that the README's test command (a process per core, each file in one process:
#: ``-n auto --dist loadfile``; not in ``addopts``, where pytest-benchmark would take xdist
#: for on and refuse ``--benchmark-only``) starts them on different cores and fills in with the short files,
#: rather than leaving two of them for the end on one core.  The order within a file is kept.
LONG_FILES = ("test_wall_traction.py", "test_studies.py", "test_validation.py", "test_wedge.py",
              "test_cli.py", "test_bench_emptying.py", "test_lagrangian.py",
              "test_bench_emptying_3d.py", "test_wall_loads.py", "test_any_silo.py",
              "test_examples.py", "test_study_arching.py", "test_discharge.py",
              "test_stepping.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FILES)))
