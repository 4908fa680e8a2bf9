"""The 3D model against the model protocol: every member that
``fipy_hopper.protocol.HopperModelProtocol`` declares, and those the loop and the diagnostics
call beyond it, present and callable on a state, with the shapes the loop expects."""

import inspect
import math
import typing

import numpy as np
import pytest

from fipy_hopper.diagnostics import FlowModeRule, OutcomeRule
from fipy_hopper.protocol import HopperModelProtocol
from fipy_hopper.space.config import small_silo
from fipy_hopper.space.model import SpaceModel

#: what the loop (fipy_hopper.simulation) and the diagnostics call beyond the protocol
EXTRA = ("contact_slip", "bin_lateral_stress_ratio", "material")


def declared():
    return sorted(typing._get_protocol_attrs(HopperModelProtocol))


def call(member, state):
    """Call a method with a state, a rule or a step count for its parameters."""
    args = []
    for name in inspect.signature(member).parameters:
        if name == "state":
            args.append(state)
        elif name == "rule":
            args.append(OutcomeRule() if member.__name__ == "empty_channel" else FlowModeRule())
        elif name == "max_steps":
            args.append(5)
        elif name == "limit":
            break
    return member(*args)


@pytest.mark.parametrize("offset", [0.0, 0.04])
def test_space_model_implements_the_protocol(offset):
    """Every declared member is present; every method runs on a state filling and in
    discharge; the sizes match the state's impulse rows."""
    model = SpaceModel(small_silo(outlet_offset=offset))
    assert isinstance(model, HopperModelProtocol)
    names = declared()
    assert len(names) >= 24 and "wall_stress_points" in names
    state = model.initial_state()
    model.advance(state, 200)
    for stage in ("filling", "discharge"):
        if stage == "discharge":
            model.open_outlet(state)
            model.advance(state, 50)
        for name in names + list(EXTRA):
            assert hasattr(model, name), name
            member = getattr(model, name)
            if callable(member) and not isinstance(member, type):
                call(member, state)
    s, normal, segment = model.wall_entries()
    n = len(state.wall_impulse)
    assert s.shape == (n,) and normal.shape == (n, 3) and segment.shape == (n,)
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0)
    assert model.wall_load_rows().shape == (n,) and model.wall_theta().shape == (n,)
    pos, w, sigma = model.wall_stress_points(state)
    assert pos.shape == w.shape == (len(sigma),) and sigma.shape[1] == 6
    slip, axis = model.contact_slip(state)
    assert slip.shape == axis.shape == (n,)
    index, stagnant = model.flow_mode_measures(state, FlowModeRule())
    assert math.isnan(index) or index > -10
    extras = model.summary_extras(state)
    assert extras["dimensions"] == 3 and extras["outlet_offset_m"] == offset
    assert model.section_factor == (4.0 if offset == 0 else 2.0)
    assert model.formulation == "eulerian" and model.n_cells == model.grid.n_cells
