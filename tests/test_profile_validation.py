"""A profile's validation: shapes that crashed it, shapes it misread, and its cost.

A full plane section whose right wall rises straight up from its lip, and a profile with
nine or more inserts, validate (they ended in ``StopIteration``); a wall segment along the
outlet plane over the outlet, and a sliver of a segment (which at the lip became the hopper's
slope), are refused in one line naming the key, the value and the allowed range.  The
geometric checks are near-linear: a wall of 10,000 vertices validates (the time is printed,
not asserted), and the vectorised checks give the answers of the pairwise ones they replace.
"""

import math
import time
import warnings

import numpy as np
import pytest

from fipy_hopper import boundary
from fipy_hopper.boundary import (first_meeting, profile_rows, segments_meet, self_crossing,
                                  wall_x)
from fipy_hopper.cli import main
from fipy_hopper.config import ConfigError, HopperConfig


def load(hopper: dict, **sections) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({"hopper": hopper, **sections})


def one_line(message: str, *words):
    assert "\n" not in message
    for word in words:
        assert word in message, (word, message)


# ---------------------------------------------------------------- shapes that crashed
FULL_VERTICAL = {"shape": "profile", "symmetry": "plane", "section": "full",
                 "wall": [[0.03, 0.0], [0.03, 0.4]],
                 "left_wall": [[-0.03, 0.0], [-0.15, 0.2], [-0.15, 0.4]], "fill_level": 0.3}


def test_a_full_section_whose_right_wall_rises_straight_up_validates(tmp_path, capsys):
    cfg = load(FULL_VERTICAL, numerics={"cell_size": 0.01})
    geom = cfg.hopper
    # a full section is no cone or wedge under a bin: no shorthand angle (the closed forms
    # are left out), but the outlet's width and the run are there
    assert geom.half_angle_deg is None
    assert geom.outlet_diameter == pytest.approx(0.06)
    path = tmp_path / "eccentric.toml"
    path.write_text(cfg.to_toml())
    assert main(["validate", str(path)]) == 0
    out, err = capsys.readouterr()
    assert "valid" in out and "Traceback" not in err


def nine_inserts(n=9) -> dict:
    inserts = [{"outline": [[0.02, z], [0.03, z], [0.025, z + 0.01]]}
               for z in 0.13 + 0.02 * np.arange(n)]
    return {"shape": "profile", "wall": [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]],
            "fill_level": 0.35, "inserts": inserts}


@pytest.mark.parametrize("n", [9, 12])
def test_nine_and_more_inserts_validate_and_draw(tmp_path, capsys, n):
    path = tmp_path / "inserts.toml"
    path.write_text(load(nine_inserts(n), numerics={"cell_size": 0.01}).to_toml())
    picture = tmp_path / "g.png"
    assert main(["validate", str(path), "--picture", str(picture)]) == 0
    out, err = capsys.readouterr()
    assert f"insert_{n}" in out and "Traceback" not in err
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------- shapes it misread
@pytest.mark.parametrize("hopper, words", [
    ({"wall": [[0.06, 0.0], [0.03, 0.0], [0.1, 0.12], [0.1, 0.4]]},
     ["hopper.wall[1] = [0.03, 0]", "along the outlet plane", "over the outlet",
      "hopper.wall[0] = [0.06, 0]", "allowed on z = 0: x >= 0.06 m"]),
    ({"symmetry": "plane", "section": "full",
      "wall": [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]],
      "left_wall": [[-0.03, 0.0], [0.0, 0.0], [-0.1, 0.12], [-0.1, 0.4]]},
     ["hopper.left_wall[1] = [0, 0]", "over the outlet", "allowed on z = 0: x <= -0.03 m"]),
    ({"wall": [[0.03, 0.0], [0.030001, 0.0], [0.1, 0.12], [0.1, 0.4]]},
     ["hopper.wall: segment 0, [0.03, 0] to [0.030001, 0], is 1e-06 m long",
      "allowed range is [0.001, 100] m", "sliver"]),
    ({"wall": [[0.03, 0.0], [0.0300005, 0.000001], [0.1, 0.12], [0.1, 0.4]]},
     ["segment 0", "allowed range is [0.001, 100] m"]),
    ({"wall": [[0.03, 0.0], [0.1, 0.12], [0.1, 0.3], [0.1001, 0.3], [0.1001, 0.4]]},
     ["segment 2", "is 0.0001 m long"]),
])
def test_what_a_wall_cannot_be_is_refused_in_one_line(hopper, words):
    with pytest.raises(ConfigError) as err:
        load({"shape": "profile", "fill_level": 0.3, **hopper})
    one_line(str(err.value), *words)


def test_a_flat_floor_on_the_outlet_plane_away_from_the_outlet_is_a_flat_bottom():
    cfg = load({"shape": "profile", "wall": [[0.03, 0.0], [0.1, 0.0], [0.1, 0.4]],
                "fill_level": 0.3})
    assert cfg.hopper.outlet_diameter == pytest.approx(0.06) and cfg.hopper.half_angle_deg == 90


# ---------------------------------------------------------------- cost
def curved_wall(n: int, height=20.0, r0=0.3, r=3.0, top=25.0) -> list:
    """A curved hopper of ``n - 1`` points (x = r0 + (r - r0) sqrt(z / height)) under a bin
    wall: segments of 2-27 mm."""
    z = np.linspace(0.0, height, n - 1)
    x = r0 + (r - r0) * np.sqrt(z / height)
    x[-1] = r                                         # the bin wall rises straight from it
    return [[float(a), float(b)] for a, b in zip(x, z)] + [[r, top]]


def test_a_wall_of_10000_vertices_validates(tmp_path, capsys):
    """Near-linear checks: the configuration and ``validate`` of a 10,000-vertex wall (they
    took 85 s of wall time before, 58 s of CPU; the time is printed, not asserted) and the
    self-crossing check still finds a crossing at its top."""
    wall = curved_wall(10_000)
    hopper = {"shape": "profile", "wall": wall, "fill_level": 22.0,
              "inserts": [{"outline": [[0.0, 5.0], [0.5, 6.0], [0.0, 7.0]]}]}
    numerics = {"cell_size": 0.075, "gravity_ramp_time": 0.2, "max_fill_time": 0.5}
    started = time.perf_counter()
    cfg = load(hopper, numerics=numerics)
    built = time.perf_counter() - started
    assert cfg.hopper.n_wall_segments == 9_999
    path = tmp_path / "curved.toml"
    path.write_text(cfg.to_toml())
    started = time.perf_counter()
    assert main(["validate", str(path)]) == 0
    validated = time.perf_counter() - started
    out, err = capsys.readouterr()
    assert "valid" in out and "Traceback" not in err
    print(f"\n10,000-vertex wall: configuration {built:.2f} s, validate {validated:.2f} s")
    back = wall[:-1] + [[1.0, 21.0], [3.5, 10.0]]          # back down across the curve
    i, j = self_crossing(back, closed=False)
    assert j == 9_999 and segments_meet(*back[i:i + 2], *back[j:j + 2])
    folded = wall[:-1] + [[2.0, 20.0], [4.0, 20.0], [4.0, 25.0]]    # folds back on itself
    with pytest.raises(ConfigError, match="crosses itself: its segment 9997 .* meets segment 9999"):
        load({**hopper, "wall": folded}, numerics=numerics)


# ---------------------------------------------------------------- same answers
def reference_self_crossing(points, closed):
    """The pairwise check the vectorised one replaces (every pair of segments)."""
    p = [tuple(map(float, q)) for q in points]
    n = len(p) if closed else len(p) - 1
    seg = [(p[k], p[(k + 1) % len(p)]) for k in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            adjacent = j == i + 1 or (closed and i == 0 and j == n - 1)
            if adjacent:
                (a, b), (c, d) = (seg[i], seg[j]) if j == i + 1 else (seg[j], seg[i])
                d1, d2 = (b[0] - a[0], b[1] - a[1]), (d[0] - c[0], d[1] - c[1])
                if d1[0] * d2[1] - d1[1] * d2[0] == 0 and d1[0] * d2[0] + d1[1] * d2[1] < 0:
                    return i, j
                if n > 2 and (segments_meet(a, a, c, d) or segments_meet(a, b, d, d)):
                    return i, j
            elif segments_meet(*seg[i], *seg[j]):
                return i, j
    return None


def random_shapes(seed, count=400):
    """Polylines and polygons on a coarse lattice (so that points, touches and collinear
    overlaps are frequent), of 3 to 14 points."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        k = int(rng.integers(3, 15))
        pts = rng.integers(0, 6, size=(k, 2)).astype(float) * 0.25
        keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])
        pts = pts[keep]
        if len(pts) >= 3:
            yield pts


@pytest.mark.parametrize("closed", [False, True])
def test_self_crossing_gives_the_pairwise_answer(closed):
    found = 0
    for pts in random_shapes(7 + closed):
        expected = reference_self_crossing(pts, closed)
        assert self_crossing(pts, closed) == expected, (pts.tolist(), closed)
        found += expected is not None
    assert found > 100        # the shapes do cross and touch


def test_first_meeting_gives_the_pairwise_answer(monkeypatch):
    rng = np.random.default_rng(3)
    monkeypatch.setattr(boundary, "_PAIRS_AT_ONCE", 7)       # many small chunks too
    for _ in range(300):
        n1, n2 = rng.integers(1, 12, size=2)
        a1, b1 = (rng.integers(0, 8, size=(n1, 2)) * 0.5 for _ in range(2))
        a2, b2 = (rng.integers(0, 8, size=(n2, 2)) * 0.5 for _ in range(2))
        a2[0], b2[0] = (0.0, -1.0), (0.5, 9.0)                 # one much taller than the rest
        p1, p2, q1, q2 = (v.tolist() for v in (a1, b1, a2, b2))
        expected = next(((i, j) for i in range(n1) for j in range(n2)
                         if segments_meet(p1[i], p2[i], q1[j], q2[j])), None)
        assert first_meeting(a1, b1, a2, b2) == expected


def test_wall_x_gives_the_row_by_row_answer():
    rng = np.random.default_rng(5)
    for _ in range(50):
        k = int(rng.integers(2, 30))
        z = np.concatenate([[0.0], np.cumsum(rng.choice([0.0, 0.05, 0.1, 0.3], size=k - 1))])
        x = 0.05 + rng.random(k) * 0.3
        rows = profile_rows(np.column_stack([x, z]))
        heights = np.concatenate([rng.uniform(-0.1, z[-1] + 0.2, 200), z, [np.nan, 1e3]])
        slow = np.full(heights.shape, x[0])
        for za, zb, xa, slope, lo, hi in rows[::-1]:
            slow = np.where((heights >= za) & (heights <= zb),
                            np.clip(xa + (heights - za) * slope, lo, hi), slow)
        assert np.array_equal(wall_x(heights, rows, x[0]), slow)          # bit for bit
        assert float(wall_x(heights[0], rows, x[0])) == slow[0]           # a scalar too


def test_the_wall_pressure_picture_draws_a_curved_wall_as_few_curves():
    """Walker's stretch-by-stretch curves of a wall of thousands of points are drawn as one
    curve a mode (they were thousands of lines and legend entries: minutes to draw); a wall
    of a few stretches keeps its curve per stretch."""
    from fipy_hopper.plotting import _few_curves, theory_wall_pressure

    wall = curved_wall(2_000, height=4.0, r0=0.06, r=0.6, top=5.0)
    cfg = load({"shape": "profile", "wall": wall, "fill_level": 4.5},
               numerics={"cell_size": 0.015, "gravity_ramp_time": 0.2, "max_fill_time": 0.5})
    curves = theory_wall_pressure(cfg)
    stretches = [name for name in curves if " stretch " in name]
    assert len(stretches) > 1000
    few = _few_curves(curves)
    assert sorted(n for n in few if n.startswith("Walker")) == [
        "Walker, cone stretches, discharge", "Walker, cone stretches, filling"]
    s, p = few["Walker, cone stretches, filling"]
    points = sum(len(curves[n][0]) for n in stretches if n.endswith("filling"))
    assert np.isfinite(s).sum() == points and np.all(np.diff(s[np.isfinite(s)]) >= 0)
    two = {f"Walker, cone stretch {k}, filling": (np.arange(3.0), np.ones(3)) for k in range(2)}
    assert _few_curves(two) == two
