"""The membrane statics at the walls' corners, written once (diagnostics.membrane_statics):
the ring force at the transition of a wall of several slopes against the statics by hand, and
the summary's transition numbers the same as the transition corner's.

By hand, for a uniform normal pressure ``p`` and shear ``tau`` (up the wall) on a conical
segment from radius ``r1`` to ``r2`` at ``beta`` from the vertical, the material's downward load
on it per radian is ``int (p sin(beta) + tau cos(beta)) r ds = (p + tau cot(beta)) (r2^2 -
r1^2) / 2`` (``ds = dr / sin(beta)``).  The hopper below a corner at radius ``r`` hangs from it
with ``N = V / (r cos(beta))`` on each side; the ring there takes the inward pull ``N_b
sin(beta_b) - N_a sin(beta_a)`` times ``r``: ``V (tan(beta_b) - tan(beta_a))``, and at the
transition (a vertical bin wall above) ``V tan(beta)`` of the slope under it.
"""

import math
import types
import warnings

import numpy as np
import pytest

from fipy_hopper import diagnostics
from fipy_hopper.config import HopperConfig
from fipy_hopper.simulation import RunRecord

TWO_SLOPES = [[0.03, 0.0], [0.06, 0.1], [0.15, 0.2], [0.15, 0.5]]
THREE_SLOPES = [[0.03, 0.0], [0.05, 0.05], [0.1, 0.1], [0.16, 0.15], [0.16, 0.5]]
P, TAU = 2000.0, 300.0                    # Pa, uniform on every bin


def profile(wall, symmetry="axisymmetric"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({"hopper": {"shape": "profile", "wall": wall,
                                                  "symmetry": symmetry, "fill_level": 0.4},
                                       "numerics": {"cell_size": 0.01}})


def hanging_load(wall, upto: int) -> float:
    """``V`` per radian of the segments below point ``upto`` of the wall, by hand."""
    total = 0.0
    for (x1, z1), (x2, z2) in zip(wall[:upto], wall[1:upto + 1]):
        cot = (z2 - z1) / (x2 - x1)
        total += (P + TAU * cot) * (x2 * x2 - x1 * x1) / 2.0
    return total


def slope(wall, k):
    """``tan(beta)`` of segment ``k``."""
    (x1, z1), (x2, z2) = wall[k], wall[k + 1]
    return (x2 - x1) / (z2 - z1)


def statics(cfg):
    bins = diagnostics.wall_bins(cfg)
    n = len(bins.s)
    return diagnostics.membrane_statics(cfg.boundary, bins, np.full(n, P), np.full(n, TAU))


@pytest.mark.parametrize("wall", [TWO_SLOPES, THREE_SLOPES], ids=["two slopes", "three slopes"])
def test_the_ring_at_the_transition_is_the_statics_of_the_slope_under_it(wall):
    """The ring compression at the transition is ``V tan(beta)`` of the slope under it (not of
    the lowest slope: for the two-slope wall that was 57 % low), every corner below it
    ``V (tan(beta_b) - tan(beta_a))``, and the hopper's tension ``V / (r cos(beta))``."""
    _, corners = statics(profile(wall))
    assert [c["r_m"] for c in corners] == [p[0] for p in wall[1:-1]]
    for k, c in enumerate(corners, start=1):
        V, r = hanging_load(wall, k), wall[k][0]
        below, above = slope(wall, k - 1), (slope(wall, k) if k < len(wall) - 2 else 0.0)
        assert c["transition"] == (k == len(wall) - 2)
        assert c["ring_compression_N"] == pytest.approx(V * (below - above), rel=1e-9)
        assert c["meridional_below_N_m"] == pytest.approx(
            V / (r * math.cos(math.atan(below))), rel=1e-9)
    top = corners[-1]
    V = hanging_load(wall, len(wall) - 2)
    assert top["ring_compression_N"] == pytest.approx(V * slope(wall, len(wall) - 3), rel=1e-9)
    lowest = slope(wall, 0)
    if wall is TWO_SLOPES:     # what the lowest slope's sine gave: 57 % low
        wrong = top["meridional_below_N_m"] * math.sin(math.atan(lowest)) * wall[-1][0]
        assert wrong / top["ring_compression_N"] == pytest.approx(0.43, abs=0.01)


def _summary(cfg, corners) -> dict:
    """:func:`diagnostics.load_summary` of a record holding only these corner rows (at rest
    and in both discharge stages)."""
    rows = [{k: v for k, v in c.items() if k != "transition"} for c in corners]
    record = RunRecord(corner_forces={"filling": rows, "early_discharge": rows,
                                      "mid_discharge": rows})
    model = types.SimpleNamespace(cfg=cfg, mu_wall=cfg.wall.friction_coefficient)
    return diagnostics.load_summary(types.SimpleNamespace(record=record, model=model))


@pytest.mark.parametrize("wall", [TWO_SLOPES, THREE_SLOPES], ids=["two slopes", "three slopes"])
def test_the_summary_gives_the_transition_corners_numbers(wall):
    """``transition_ring_compression_N``, the hopper's tension and the bin wall's
    compression at the top level of the summary are the transition corner's, in every
    stage; the corners of the summary carry the flag."""
    cfg = profile(wall)
    _, corners = statics(cfg)
    summary = _summary(cfg, corners)
    at = corners[-1]
    V = hanging_load(wall, len(wall) - 2)
    for suffix in ("", "_discharge"):
        assert summary[f"transition_ring_compression{suffix}_N"] == at["ring_compression_N"]
        assert summary[f"transition_ring_compression{suffix}_N"] == pytest.approx(
            V * slope(wall, len(wall) - 3), rel=1e-9)
        assert summary[f"hopper_meridional_tension{suffix}_N_m"] == at["meridional_below_N_m"]
        assert summary[f"bin_wall_axial_compression{suffix}_N_m"] == \
            -at["meridional_above_N_m"]
    assert [c["transition"] for c in summary["corners"]] == [c["transition"] for c in corners]


def test_a_plane_wall_has_no_ring_and_a_wall_without_a_bin_no_transition():
    """In plane flow the corners take a horizontal pull but no ring; a wall whose top slopes
    has no transition: NaN at the top level."""
    cfg = profile(TWO_SLOPES, symmetry="plane")
    _, corners = statics(cfg)
    assert all(math.isnan(c["ring_compression_N"]) for c in corners)
    V = sum((P + TAU * (z2 - z1) / (x2 - x1)) * (x2 - x1) for (x1, z1), (x2, z2)
            in zip(TWO_SLOPES[:2], TWO_SLOPES[1:3]))   # per metre: int (p sin + tau cos) ds
    assert corners[-1]["horizontal_pull_N_m"] == pytest.approx(V * slope(TWO_SLOPES, 1),
                                                               rel=1e-9)
    cone = profile([[0.03, 0.0], [0.06, 0.1], [0.15, 0.5]])
    _, corners = statics(cone)
    assert cone.boundary.transition("wall") is None and not corners[0]["transition"]
    assert math.isnan(_summary(cone, corners)["transition_ring_compression_N"])
