"""The 3D run's estimates from its settings alone: the grid's shape and loaded cells against
the built model's, the memory against tracemalloc's peak, and the one-line refusal."""

import gc
import tracemalloc

import pytest

from fipy_hopper.config import HopperGeometry, NumericsConfig
from fipy_hopper.space import estimate
from fipy_hopper.space.config import SpaceConfig, small_silo
from fipy_hopper.space.model import SpaceModel


@pytest.mark.parametrize("cfg", [small_silo(), small_silo(outlet_offset=0.04),
                                 small_silo(mirror_planes="none"),
                                 SpaceConfig(hopper=HopperGeometry(),
                                             numerics=NumericsConfig(cell_size=0.01))],
                         ids=["quarter", "eccentric-half", "whole", "reference-1cm"])
def test_grid_shape_and_loaded_cells_are_the_models(cfg):
    """The shape equals the built grid's; the loaded cells the initial state's within 1 %
    (measured 395/395, 782/783, 1580/1580, 8198/8200)."""
    model = SpaceModel(cfg)
    assert estimate.grid_shape(cfg) == (model.grid.nx, model.grid.ny, model.grid.nz)
    loaded = int((model.initial_state().alpha >= cfg.numerics.alpha_min).sum())
    assert abs(estimate.loaded_cells(cfg) / loaded - 1.0) < 0.01


def test_memory_estimate_bounds_the_peak():
    """The estimate less the import baseline bounds tracemalloc's peak of building the model,
    120 steps with two transports and its wall loads (small silo, whole, 2 cm)."""
    cfg = small_silo(mirror_planes="none")
    warm = SpaceModel(cfg)
    s = warm.initial_state()
    warm.advance(s, 5)
    warm.transport_step(s)
    del warm, s
    gc.collect()
    tracemalloc.start()
    try:
        model = SpaceModel(cfg)
        s = model.initial_state()
        for _ in range(2):
            model.advance(s, 60)
            model.transport_step(s)
        model.wall_loads
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    need = estimate.memory_estimate(cfg)
    assert need["cells"] == model.n_cells
    assert peak < need["bytes"] - estimate.MEMORY_BASE


def test_a_grid_too_large_for_memory_is_refused_in_one_line():
    cfg = SpaceConfig(hopper=HopperGeometry(), numerics=NumericsConfig(cell_size=0.001))
    with pytest.raises(MemoryError) as err:
        estimate.check_memory(cfg, available=8e9)
    text = str(err.value)
    assert "\n" not in text and "cells" in text and "GB" in text
    estimate.check_memory(small_silo(), available=8e9)
