"""Every model against the model protocol (``fipy_hopper.protocol``): the Eulerian section
(``HopperModel``), the Lagrangian section (``LagrangianModel``) and the 3D silo
(``SpaceModel``, centred and with an off-centre outlet).  Every member that
``HopperModelProtocol`` declares is present, and every method runs on a state filling and in
discharge with the shapes the loop expects; the state holds only what a checkpoint can (float64
arrays, plain scalars: the Eulerian models', whose runs are checkpointed); the model's wall loads (``wall_measures``) implement
``WallLoadsProtocol`` on two readings of the run."""

import inspect
import math
import typing
import warnings

import numpy as np
import pytest

from fipy_hopper.config import HopperConfig
from fipy_hopper.diagnostics import FlowModeRule, OutcomeRule
from fipy_hopper.protocol import HopperModelProtocol, WallLoadsProtocol

SECTION = {"hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.25,
                      "fill_height": 0.1}, "numerics": {"cell_size": 0.01}}


def declared(protocol):
    return sorted(typing._get_protocol_attrs(protocol))


def call(member, state):
    """Call a method with a state, a rule, a step count or no previous impulse."""
    args = []
    for name in inspect.signature(member).parameters:
        if name == "state":
            args.append(state)
        elif name == "rule":
            args.append(OutcomeRule() if member.__name__ == "empty_channel" else FlowModeRule())
        elif name == "max_steps":
            args.append(5)
        elif name == "previous_impulse":
            args.append(None)
        elif name == "means":
            args.append(member.__self__.channel_fields(state))
        elif name in ("limit", "full"):
            break
    return member(*args)


def make(kind):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if kind == "eulerian":
            from fipy_hopper.model import HopperModel
            return HopperModel(HopperConfig.from_dict(SECTION), threads=1)
        if kind == "lagrangian":
            from fipy_hopper.lagrangian import LagrangianModel
            data = dict(SECTION, numerics={"cell_size": 0.01, "formulation": "lagrangian"})
            return LagrangianModel(HopperConfig.from_dict(data))
        from fipy_hopper.space.config import small_silo
        from fipy_hopper.space.model import SpaceModel
        return SpaceModel(small_silo(outlet_offset=0.04 if kind == "3d-off-centre" else 0.0),
                          threads=1)


@pytest.mark.parametrize("kind", ["eulerian", "lagrangian", "3d-centred", "3d-off-centre"])
def test_every_model_implements_the_protocol(kind):
    model = make(kind)
    assert isinstance(model, HopperModelProtocol)
    names = declared(HopperModelProtocol)
    for member in ("contact_slip", "bin_lateral_stress_ratio", "material", "dimensions",
                   "wall_measures", "wall_slip_measures", "material_speed", "heap_angle",
                   "wall_stress_points"):
        assert member in names, member
    sampler, loads = model.wall_measures()
    assert isinstance(loads, WallLoadsProtocol)
    state = model.initial_state()
    for key, value in vars(state).items():      # what a checkpoint holds (the Eulerian
        if kind == "lagrangian":                 # models'; a Lagrangian run has none)
            break
        assert (isinstance(value, np.ndarray) and value.dtype == np.float64) or isinstance(
            value, (int, float, str, bool)), key
    model.advance(state, 200)
    first = loads.reading(model, state)
    for stage in ("filling", "discharge"):
        if stage == "discharge":
            model.open_outlet(state)
            model.advance(state, 50)
        for name in names:
            assert hasattr(model, name), name
            member = getattr(model, name)
            if callable(member) and not isinstance(member, type):
                call(member, state)
    d = model.dimensions
    assert d == (3 if kind.startswith("3d") else 2)
    n = len(state.wall_impulse)
    s, normal, segment = model.wall_entries()
    assert s.shape == (n,) and normal.shape == (n, d) and segment.shape == (n,)
    assert state.wall_impulse.shape == (n, d)
    assert model.wall_load_rows().shape == (n,)
    slip, axis = model.contact_slip(state)
    assert slip.shape == axis.shape == (n,)
    measures = model.wall_slip_measures(state, first["wall"], FlowModeRule())
    assert len(measures) == 6 and (measures[5] is None) == (d == 2)
    assert math.isfinite(model.material_speed(state))
    fields = model.channel_fields(state)          # the channel per window: 3D only
    assert (len(fields) == 2) == (d == 3)
    rows = model.channel_measures(fields)
    assert (len(rows) > 0) == (d == 3)
    assert all(set(row) == set(rows[0]) for row in rows)
    # the wall loads over a window, per bin (3D: per patch)
    last = loads.reading(model, state)
    nb = len(sampler.centres)
    values = loads.profile(first, last)
    assert len(values) == (6 if d == 3 else 5) and all(len(v) == nb for v in values)
    assert all(len(v) == nb for v in loads.raw_profile(first, last))
    assert all(len(v) == nb for v in sampler.profile_all(state))
    balance = loads.balance(first, last)
    assert balance["relative_residual"] < 1e-9
    assert len(sampler.bins.wall) == nb
    assert (sampler.theta is None) == (d == 2)
    extras = model.summary_extras(state)
    if d == 3:
        assert extras["dimensions"] == 3 and extras["outlet_offset_m"] == (
            0.04 if kind == "3d-off-centre" else 0.0)
        assert model.section_factor == (2.0 if kind == "3d-off-centre" else 4.0)
        assert model.n_cells == model.grid.n_cells
