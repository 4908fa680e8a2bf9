"""The boundary as data (:mod:`fipy_hopper.boundary`) and the profile configuration.

The conical and wedge shorthands give the closed-form cone written out by hand
(``tests/closed_cone.py``) bit for bit, and a profile of the same vertices the shorthand; distances, normals and contact sets against
points computed by hand; open fractions against exact areas; fill masses against closed
forms; the mirror symmetry of a full section; the compiled one-point kernels against the
numpy methods; the picture and the description; every bad input in one line naming the key.
"""

import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from fipy_hopper import boundary as fb
from fipy_hopper import mesh
from fipy_hopper.cli import main
from fipy_hopper.config import ConfigError, HopperConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
import closed_cone as geometry  # noqa: E402  (the closed-form reference)

RHO = 1500.0
#: a two-slope hopper: a steep stretch, a shallow one, a bin
TWO_SLOPE = [[0.03, 0.0], [0.08, 0.12], [0.15, 0.2], [0.15, 0.6]]
#: a double cone on the axis (a diamond in the half-section)
DIAMOND = [[0.0, 0.16], [0.05, 0.12], [0.0, 0.08]]
REF_WEDGE = {"shape": "wedge", "bin_width": 0.2, "outlet_width": 0.06, "half_angle_deg": 20.0,
             "bin_height": 0.17, "fill_height": 0.15}


def config(hopper=None, wall=None, cell=0.005):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # coarse outlets: the resolution warning
        return HopperConfig.from_dict({"hopper": hopper or {}, "wall": wall or {},
                                       "numerics": {"cell_size": cell}})


def profile(wall=TWO_SLOPE, fill_level=0.45, inserts=(), **hopper):
    return config({"shape": "profile", "wall": wall, "fill_level": fill_level,
                   "inserts": [{"outline": o} for o in inserts], **hopper})


def grid_lines(cfg):
    """Node lines of :func:`fipy_hopper.mesh.build_grid` (without building FiPy's mesh)."""
    h, geom = cfg.numerics.cell_size, cfg.hopper
    nr, nz = cfg.grid_shape()
    n_below = max(int(math.ceil(cfg.numerics.free_fall_depth * geom.outlet_diameter / h
                                - 1e-9)), 3)
    x = h * np.arange(nr + 1)
    z = -n_below * h + h * np.arange(nz + 1)
    z[n_below] = 0.0
    return x, z


class Today:
    """The closed-form cone (``closed_cone``) where mesh wants a boundary."""

    def __init__(self, geom):
        self.geom, self.section = geom, geom.boundary.section

    def in_solid(self, x, z):
        return geometry.in_solid(x, z, self.geom)


def same_contacts(c1, c2):
    return len(c1) == len(c2) and all(
        k1 == k2 and np.array_equal(m1, m2) and (n1, z1) == (n2, z2)
        for (k1, m1, n1, z1), (k2, m2, n2, z2) in zip(c1, c2))


def geometry_arrays(b, cfg):
    """What the grid takes from a boundary: sub-sampled open fractions of cells and faces,
    node distances, normals and contact sets."""
    x, z = grid_lines(cfg)
    X, Z = np.meshgrid(x, z)
    return (mesh._open_fraction_cells(b, x, z, 16), *mesh._open_fraction_faces(b, x, z, 16),
            b.signed_distance(X, Z), *b.wall_normal(X, Z),
            b.segment_contacts(X, Z, 0.5 * cfg.numerics.cell_size))


# ---------------------------------------------------------------- the shorthands are today's
@pytest.mark.parametrize("hopper, cell", [({}, 0.005), (REF_WEDGE, 0.01),
                                          ({"half_angle_deg": 90.0}, 0.005)],
                         ids=["reference cone", "reference wedge", "flat-bottomed bin"])
def test_the_shorthand_is_todays_geometry_bit_for_bit(hopper, cell):
    cfg = config(hopper, cell=cell)
    geom, b = cfg.hopper, cfg.hopper.boundary
    x, z = grid_lines(cfg)
    X, Z = np.meshgrid(x, z)
    sub = (np.arange(16) + 0.5) / 16
    xs = (x[:-1, None] + np.diff(x)[:, None] * sub).ravel()
    zs = (z[:-1, None] + np.diff(z)[:, None] * sub).ravel()
    assert np.array_equal(b.in_solid(xs[None, :], zs[:, None]),
                          geometry.in_solid(xs[None, :], zs[:, None], geom))
    assert np.array_equal(mesh._open_fraction_cells(b, x, z, 16),
                          mesh._open_fraction_cells(Today(geom), x, z, 16))
    for new, old in zip(mesh._open_fraction_faces(b, x, z, 16),
                        mesh._open_fraction_faces(Today(geom), x, z, 16)):
        assert np.array_equal(new, old)
    assert np.array_equal(b.signed_distance(X, Z), geometry.signed_distance(X, Z, geom))
    for new, old in zip(b.wall_normal(X, Z), geometry.wall_normal(X, Z, geom)):
        assert np.array_equal(new, old)
    reach = 0.5 * cell
    assert same_contacts(b.segment_contacts(X, Z, reach),
                         geometry.segment_contacts(X, Z, geom, reach))
    assert np.array_equal(b.table.a[:, 1], [-1e3, 0.0, geom.cone_height])
    assert list(b.table.chain) == [0, 1, 1] and list(b.table.segment) == [0, 0, 1]


def test_a_profile_of_the_shorthands_vertices_is_the_shorthand():
    """The reference cone and wedge written as profiles give the same table, open fractions,
    distances, normals, contacts and grid, and the same sizes the rest of the code reads."""
    for hopper, cell in (({}, 0.005), (REF_WEDGE, 0.01)):
        short = config(hopper, cell=cell)
        geom = short.hopper
        same = config({"shape": "profile", "symmetry": geom.symmetry,
                       "wall": [list(p) for p in geom.wall_points],
                       "fill_level": geom.fill_level}, cell=cell)
        for key in ("bin_radius", "outlet_radius", "half_angle_deg", "cone_height", "top",
                    "fill_level", "axisymmetric"):
            assert getattr(same.hopper, key) == getattr(geom, key), key
        assert same.grid_shape() == short.grid_shape()
        t1, t2 = same.boundary.table, short.boundary.table
        for key in ("a", "b", "normal", "chain", "segment", "s0", "friction_deg", "concave"):
            assert np.array_equal(getattr(t1, key), getattr(t2, key)), key
        for new, old in zip(geometry_arrays(same.hopper.boundary, same)[:-1],
                            geometry_arrays(geom.boundary, short)[:-1]):
            assert np.array_equal(new, old)
        assert same_contacts(geometry_arrays(same.hopper.boundary, same)[-1],
                             geometry_arrays(geom.boundary, short)[-1])
        assert same.hopper.fill_volume() == pytest.approx(geom.fill_volume(), rel=1e-14)


# ---------------------------------------------------------------- hand-computed points
def test_distances_and_normals_on_a_two_slope_hopper_with_an_insert():
    b = profile(inserts=[DIAMOND]).hopper.boundary
    n0 = np.array([0.12, -0.05]) / 0.13                     # segment 0 into the wall
    d1 = np.array([0.07, 0.08]) / math.hypot(0.07, 0.08)
    n1 = np.array([d1[1], -d1[0]])
    wall = b.chain_index("wall")
    # in front of segment 0's middle and behind segment 1's middle
    for p, dist, n, seg in (((0.055, 0.06) - 0.01 * n0, 0.01, n0, 0),
                            ((0.115, 0.16) + 0.005 * n1, -0.005, n1, 1)):
        assert b.signed_distance(*p) == pytest.approx(dist, abs=1e-15)
        assert np.allclose(b.wall_normal(*p), n, atol=1e-14)
        px, pz, chain, segment, s = b.nearest(*p)
        assert (chain, segment) == (wall, seg)
        assert np.allclose([px, pz], np.asarray(p) + dist * n, atol=1e-15)
    assert b.nearest(*((0.055, 0.06) - 0.01 * n0))[4] == pytest.approx(0.065, abs=1e-15)
    # the convex corner (0.08, 0.12): beyond both segments, the normal points at the corner
    bis = (n0 + n1) / np.linalg.norm(n0 + n1)
    p = np.array([0.08, 0.12]) - 0.004 * bis
    assert b.signed_distance(*p) == pytest.approx(0.004, abs=1e-15)
    assert np.allclose(b.wall_normal(*p), bis, atol=1e-12)
    # the bin wall from the axis; the free-fall tube below the lip
    assert b.signed_distance(0.0, 0.45) == pytest.approx(0.15, abs=1e-15)
    assert np.allclose(b.wall_normal(0.0, 0.45), (1.0, 0.0))
    assert b.signed_distance(0.04, -0.02) == pytest.approx(-0.01, abs=1e-15)
    # the insert: below its lower tip on the axis, and inside it near the axis (the edge on
    # the axis is no wall: the nearest wall is a sloping edge, 0.0016 / 0.06403 m away)
    insert = b.chain_index("insert_1")
    assert b.signed_distance(0.0, 0.05) == pytest.approx(0.03, abs=1e-15)
    assert np.allclose(b.wall_normal(0.0, 0.05), (0.0, 1.0))
    assert b.nearest(0.0, 0.05)[2:] == (insert, 0, 0.0)
    assert b.in_solid(0.01, 0.12) and not b.in_solid(0.06, 0.12)
    assert b.signed_distance(0.01, 0.12) == pytest.approx(-0.0016 / math.hypot(0.05, 0.04),
                                                          abs=1e-15)
    # the insert's lower edge: its normal points up and to the axis, into the insert
    n_ins = np.array([-0.04, 0.05]) / math.hypot(0.04, 0.05)
    p = np.array([0.025, 0.10]) - 0.01 * n_ins
    assert b.signed_distance(*p) == pytest.approx(0.01, abs=1e-15)
    assert np.allclose(b.wall_normal(*p), n_ins, atol=1e-14)


def test_contact_sets_at_a_concave_and_a_convex_corner():
    """Near the concave corner (0.15, 0.2) a point is held by both segments, also one just
    beyond the corner on the shallow segment's line, behind the bin wall; beyond the convex
    corner (0.08, 0.12) a point on the material side belongs to neither segment."""
    b = profile().hopper.boundary
    reach = 0.0025
    d0 = np.array([0.05, 0.12]) / 0.13
    d1 = np.array([0.07, 0.08]) / math.hypot(0.07, 0.08)
    n0, n1 = np.array([d0[1], -d0[0]]), np.array([d1[1], -d1[0]])
    corner, knee = np.array([0.15, 0.2]), np.array([0.08, 0.12])
    points = np.array([corner + (-0.001, 0.0), corner + 0.001 * d1,
                       knee - 0.001 * (n0 + n1) / np.linalg.norm(n0 + n1), knee + 0.001 * d0])
    masks = {k: m for k, m, _, _ in b.segment_contacts(points[:, 0], points[:, 1], reach)}
    rows = {tuple(int(v) for v in key): k for k, key in
            enumerate(zip(b.table.chain, b.table.segment))}
    steep, shallow, bin_ = (masks[rows[(1, k)]] for k in (0, 1, 2))
    assert list(shallow) == [True, True, False, True]       # the last: just in front of it
    assert list(bin_) == [True, True, False, False]
    assert list(steep) == [False, False, False, False]
    assert list(b.table.concave[rows[(1, 1)]]) == [False, True]       # convex knee, concave
    assert [(c.point, c.concave) for c in b.chain("wall").corners] == [
        ((0.08, 0.12), False), ((0.15, 0.2), True)]
    turn = math.degrees(math.atan2(0.07, 0.08) - math.atan2(0.05, 0.12))
    assert b.chain("wall").corners[0].turn_deg == pytest.approx(turn, abs=1e-12)


# ---------------------------------------------------------------- areas and volumes
@pytest.mark.parametrize("symmetry", ["axisymmetric", "plane"])
def test_open_fractions_sum_to_the_exact_area(symmetry):
    """The sub-sampled open volume of the cells between the outlet plane and z = 0.4 m is the
    exact (Pappus) volume of the region below 0.4 m, insert out, within a strip of width
    h / n_sub along the boundary."""
    cfg = profile(inserts=[DIAMOND], symmetry=symmetry)
    b = cfg.hopper.boundary
    h, n_sub = 0.005, 16
    x, z = h * np.arange(41), h * np.arange(81)
    kappa = mesh._open_fraction_cells(b, x, z, n_sub)
    xc = 0.5 * (x[1:] + x[:-1])
    volume = b.section.weight(xc)[None, :] * h * h
    sampled = b.section.factor * float(np.sum(kappa * volume))
    exact = b.fill_volume(0.4)
    strip = sum(c.length for c in b.chains if c.kind != "tube") * h / n_sub * (
        b.section.factor * (0.15 if symmetry == "axisymmetric" else 1.0))
    assert abs(sampled - exact) < strip
    assert abs(sampled - exact) > 0.0                              # it is sampled, not exact


def test_fill_masses_against_closed_forms():
    cone = config()
    g = cone.hopper
    R0, R, hc = g.outlet_radius, g.bin_radius, g.cone_height
    closed = math.pi * hc / 3 * (R0 ** 2 + R0 * R + R ** 2) + math.pi * R ** 2 * g.fill_height
    assert g.boundary.fill_mass(RHO) == pytest.approx(RHO * closed, rel=1e-13)
    wedge = config(REF_WEDGE, cell=0.01).hopper
    closed = 2 * (0.5 * (0.03 + 0.1) * wedge.cone_height + 0.1 * 0.15)           # per metre
    assert wedge.boundary.fill_mass(RHO) == pytest.approx(RHO * closed, rel=1e-13)

    def frustum(r0, r1, height):
        return math.pi * height / 3 * (r0 * r0 + r0 * r1 + r1 * r1)
    two = frustum(0.03, 0.08, 0.12) + frustum(0.08, 0.15, 0.08) + math.pi * 0.15 ** 2 * 0.25
    diamond = 2 * math.pi * 0.05 ** 2 * 0.04 / 3
    assert profile().hopper.boundary.fill_mass(RHO) == pytest.approx(RHO * two, rel=1e-13)
    with_insert = profile(inserts=[DIAMOND])
    assert with_insert.boundary.fill_mass(RHO) == pytest.approx(RHO * (two - diamond),
                                                                rel=1e-13)
    assert with_insert.hopper.fill_volume() == pytest.approx(two - diamond, rel=1e-13)
    # a plane two-slope hopper, per metre, and an insert cut by the fill level
    plane = 2 * (0.5 * (0.03 + 0.08) * 0.12 + 0.5 * (0.08 + 0.15) * 0.08 + 0.15 * 0.25)
    assert profile(symmetry="plane").boundary.fill_mass(RHO) == pytest.approx(RHO * plane,
                                                                              rel=1e-13)
    cut = profile(symmetry="plane", fill_level=0.12, inserts=[DIAMOND]).boundary
    below = 2 * (0.5 * (0.03 + 0.08) * 0.12 - 0.5 * 0.05 * 0.04)
    assert cut.fill_mass(RHO) == pytest.approx(RHO * below, rel=1e-13)


def test_wall_points_and_wall_area_along_a_chain():
    b = profile().hopper.boundary
    s_knee, s_corner = 0.13, 0.13 + math.hypot(0.07, 0.08)
    assert np.allclose(b.wall_point("wall", [0.0, s_knee, s_corner, s_corner + 0.1])[:2],
                       [[0.03, 0.08, 0.15, 0.15], [0.0, 0.12, 0.2, 0.3]], atol=1e-15)
    nx, nz = b.wall_point("wall", s_knee)[2:]             # a vertex takes the segment below
    assert (nx, nz) == pytest.approx((0.12 / 0.13, -0.05 / 0.13))
    lateral = 0.13 * 0.055 + math.hypot(0.07, 0.08) * 0.115 + 0.4 * 0.15   # int r ds
    assert b.wall_area("wall", 0.0, b.chain("wall").length) == pytest.approx(lateral,
                                                                            rel=1e-14)
    assert b.wall_area("wall", 0.0, 0.065) == pytest.approx(0.065 * 0.5 * (0.03 + 0.055),
                                                            rel=1e-14)
    plane = profile(symmetry="plane").boundary
    assert plane.wall_area("wall", 0.1, 0.3) == pytest.approx(0.2, rel=1e-14)


# ---------------------------------------------------------------- sections
def test_a_full_section_with_a_centred_slot_is_its_own_mirror_image():
    half = [[0.03, 0.0], [0.1, 0.12], [0.1, 0.4]]
    full = config({"shape": "profile", "symmetry": "plane", "section": "full", "wall": half,
                   "left_wall": [[-x, z] for x, z in half], "fill_level": 0.3})
    b = full.boundary
    assert (b.section.factor, b.section.has_axis, b.section.centreline) == (1.0, False, 0.0)
    assert b.outlet == (-0.03, 0.03)
    x = 0.0025 * np.arange(-48, 49)
    z = 0.0025 * np.arange(-8, 170)
    X, Z = np.meshgrid(x, z)
    assert np.array_equal(b.in_solid(X, Z), b.in_solid(-X, Z))
    assert np.array_equal(b.signed_distance(X, Z), b.signed_distance(-X, Z))
    nx, nz = b.wall_normal(X, Z)
    mx, mz = b.wall_normal(-X, Z)
    off = X != 0.0                      # on the centreline the two walls tie: the right's
    assert np.array_equal(nx[off], -mx[off]) and np.array_equal(nz[off], mz[off])
    contacts = {(int(b.table.chain[k]), int(b.table.segment[k])): m
                for k, m, _, _ in b.segment_contacts(X, Z, 0.00125)}
    for seg in range(2):
        assert np.array_equal(contacts[(1, seg)], contacts[(3, seg)][:, ::-1])
    plane_half = config({"shape": "profile", "symmetry": "plane", "wall": half,
                         "fill_level": 0.3}).boundary
    assert b.fill_mass(RHO) == pytest.approx(plane_half.fill_mass(RHO), rel=1e-14)
    assert [c.concave for c in b.corners] == [True, True]
    off = config({"shape": "profile", "symmetry": "plane", "section": "full",
                  "wall": [[0.1, 0.0], [0.3, 0.0], [0.3, 0.5]],
                  "left_wall": [[0.05, 0.0], [-0.2, 0.0], [-0.2, 0.5]], "fill_level": 0.4})
    assert off.boundary.section.centreline == pytest.approx(0.075)
    assert off.hopper.outlet_diameter == pytest.approx(0.05)
    assert off.hopper.x_extent == (-0.2, 0.3) and off.hopper.width == 0.5
    assert off.hopper.bin_diameter is None and off.hopper.half_angle_deg is None


def test_sections_own_the_axis_the_mirror_and_the_factor():
    axi = fb.Section("axisymmetric")
    half, full = fb.Section("plane"), fb.Section("plane", half=False, centreline=0.1)
    assert [s.factor for s in (axi, half, full)] == [2 * math.pi, 2.0, 1.0]
    assert [s.has_axis for s in (axi, half, full)] == [True, True, False]
    x = np.array([-0.1, 0.2])
    assert list(axi.reflect(x)) == [0.1, 0.2] and list(full.reflect(x)) == [-0.1, 0.2]
    assert list(axi.weight(x)) == [-0.1, 0.2] and list(half.weight(x)) == [1.0, 1.0]
    with pytest.raises(ValueError, match="half-section"):
        fb.Section("axisymmetric", half=False)


# ---------------------------------------------------------------- compiled kernels
def test_the_compiled_one_point_kernels_are_the_numpy_methods():
    rng = np.random.default_rng(7)
    for b in (profile(inserts=[DIAMOND, [[0.07, 0.3], [0.1, 0.3], [0.1, 0.35]]]).boundary,
              config({"shape": "profile", "symmetry": "plane", "section": "full",
                      "wall": [[0.1, 0.0], [0.3, 0.1], [0.3, 0.5]],
                      "left_wall": [[0.05, 0.0], [-0.2, 0.0], [-0.2, 0.5]],
                      "fill_level": 0.4}).boundary):
        x = rng.uniform(-0.25, 0.35, 3000)
        z = rng.uniform(-0.05, 0.55, 3000)
        args = b.kernel_arrays()
        solid = [fb.in_solid_point(xi, zi, *args) for xi, zi in zip(x, z)]
        assert solid == list(b.in_solid(x, z))
        near = np.array([fb.nearest_point(xi, zi, *args[:2]) for xi, zi in zip(x, z)])
        px, pz, chain, segment, _ = b.nearest(x, z)
        assert np.allclose(near[:, 0], px, rtol=0, atol=1e-15)
        assert np.allclose(near[:, 1], pz, rtol=0, atol=1e-15)
        rows = near[:, 2].astype(int)
        assert np.array_equal(b.table.chain[rows], chain)


# ---------------------------------------------------------------- for people
def test_describe_and_draw_the_boundary(tmp_path):
    cfg = config(
        {"shape": "profile", "wall": TWO_SLOPE, "fill_level": 0.45,
         "inserts": [{"outline": DIAMOND, "friction_angle_deg": 20.0}]},
        wall={"segment_friction_deg": [15.0, 15.0, 25.0]})
    text = cfg.boundary.describe(RHO)
    for words in ("axisymmetric half-section", "x in [0, 0.03] m on z = 0", "z = 0.45 m",
                  "insert_1", "open along the axis", "friction 25 deg", "friction 20 deg",
                  "turns 18.6 deg, convex", "concave", "frictionless",
                  f"{cfg.boundary.fill_mass(RHO):.4g} kg"):
        assert words in text, words
    path = tmp_path / "geometry.png"
    cfg.boundary.draw(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 20_000
    assert "from [wall]" in cfg.hopper.boundary.describe()            # no friction yet
    assert list(cfg.boundary.table.friction_deg) == [0.0, 15.0, 15.0, 25.0, 20.0, 20.0]


def test_validate_describes_and_draws_the_boundary(tmp_path, capsys):
    path = tmp_path / "silo.toml"
    path.write_text(profile(inserts=[DIAMOND]).to_toml())
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    assert "insert_1" in out and "outlet       x in [0, 0.03] m" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["silo.toml"]   # nothing written
    assert main(["validate", str(path), "--picture", str(tmp_path / "silo.png")]) == 0
    assert (tmp_path / "silo.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------- configuration
def test_profiles_round_trip_through_toml(tmp_path):
    for cfg in (config({"shape": "profile", "wall": TWO_SLOPE, "fill_level": 0.45,
                        "inserts": [{"outline": DIAMOND, "friction_angle_deg": 20.0},
                                    {"outline": [[0.06, 0.3], [0.1, 0.3], [0.08, 0.35],
                                                 [0.06, 0.3]]}]},
                       wall={"segment_friction_deg": [15.0, 15.0, 25.0]}),
                config({"shape": "profile", "symmetry": "plane", "section": "full",
                        "wall": [[0.1, 0.0], [0.3, 0.0], [0.3, 0.5]],
                        "left_wall": [[0.05, 0.0], [-0.2, 0.0], [-0.2, 0.5]],
                        "fill_level": 0.4}),
                config({"inserts": [{"outline": DIAMOND}]})):
        path = tmp_path / "c.toml"
        path.write_text(cfg.to_toml())
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            again = HopperConfig.from_toml(path)
        assert again == cfg and again.to_dict() == cfg.to_dict()
    assert len(cfg.hopper.inserts[0].outline) == 3
    assert set(config().to_dict()["hopper"]) == {"bin_diameter", "half_angle_deg",
                                                 "outlet_diameter", "bin_height",
                                                 "fill_height", "shape"}


def test_a_profiles_shorthand_sizes_exist_only_for_the_shapes_they_describe():
    """A two-slope wall has no one half-angle, cone height or bin diameter (None, and not a
    silo the classic theories cover); the boundary gives every silo its sizes (width,
    transition).  A cone under a bin drawn with a 1.4 mm sliver at its lip (45 deg; shorter
    ones are refused) is a cone: its half-angle is the cone's by length, not the sliver's; a
    wall whose top slopes has none."""
    g = profile().hopper
    assert (g.bin_diameter, g.half_angle_deg, g.cone_height, g.bin_height, g.fill_height) == \
        (None,) * 5
    assert (g.outlet_radius, g.top, g.width) == (0.03, 0.6, 0.3) and not g.classic
    assert g.boundary.transition_height() == 0.2 and g.boundary.hopper_shape is None
    assert g.axisymmetric and g.n_wall_segments == 3
    cone = [[0.03, 0.0], [0.15, 0.2], [0.15, 0.6]]
    for wall, theta in ((cone, math.degrees(math.atan2(0.12, 0.2))),
                        ([[0.03, 0.0], [0.031, 0.001]] + cone[1:],
                         math.degrees(math.atan2(0.119, 0.199)))):
        c = profile(wall=wall).hopper
        assert c.classic and c.half_angle_deg == pytest.approx(theta, abs=1e-3)
        assert (c.bin_radius, c.cone_height, c.outlet_radius) == (0.15, 0.2, 0.03)
        assert c.fill_height == pytest.approx(0.25) and c.bin_height == pytest.approx(0.4)
    spout = profile(wall=[[0.03, 0.0], [0.03, 0.02], [0.15, 0.1], [0.12, 0.3]],
                    fill_level=0.25).hopper
    assert spout.half_angle_deg is None and spout.cone_height is None
    assert spout.boundary.transition_height() == 0.3 and spout.width == 0.3
    cfg = profile()
    assert cfg.hopper.boundary is cfg.hopper.boundary and cfg.boundary is cfg.boundary


T, H = "hopper", {"shape": "profile", "wall": TWO_SLOPE, "fill_level": 0.45}
FULL = {**H, "symmetry": "plane", "section": "full", "left_wall": [[-0.06, 0.0],
                                                                    [-0.15, 0.05],
                                                                    [-0.15, 0.6]]}
BAD = [
    ("a wall that descends", {**H, "wall": [[0.03, 0.0], [0.1, 0.2], [0.15, 0.1]]}, None,
     ["hopper.wall[2] = [0.15, 0.1]", "must not descend"]),
    ("a wall that crosses the axis", {**H, "wall": [[0.03, 0.0], [-0.01, 0.1], [0.15, 0.6]]},
     None, ["hopper.wall[1] = [-0.01, 0.1]", "crosses the axis"]),
    ("a wall that crosses itself",
     {**H, "wall": [[0.03, 0.0], [0.1, 0.1], [0.2, 0.1], [0.05, 0.1], [0.05, 0.6]]}, None,
     ["hopper.wall crosses itself", "segment 0 [0.03, 0]-[0.1, 0.1] meets segment 2"]),
    ("a lip off the outlet plane", {**H, "wall": [[0.03, 0.01], [0.15, 0.2], [0.15, 0.6]]},
     None, ["hopper.wall[0] = [0.03, 0.01]", "outlet plane, z = 0"]),
    ("a wall point that is not a point", {**H, "wall": [[0.03, 0.0], [0.15]]}, None,
     ["hopper.wall[1] = [0.15]", "[x, z]"]),
    ("a wall point repeated", {**H, "wall": [[0.03, 0.0], [0.15, 0.2], [0.15, 0.2]]}, None,
     ["hopper.wall[2] = [0.15, 0.2]", "repeats"]),
    ("an outlet as wide as the silo", {**H, "wall": [[0.15, 0.0], [0.15, 0.6]]}, None,
     ["hopper.wall", "as wide as"]),
    ("an insert cutting the wall", {**H, "inserts": [{"outline": [[0.05, 0.3], [0.2, 0.3],
                                                                  [0.1, 0.4]]}]}, None,
     ["hopper.inserts[0].outline[1] = [0.2, 0.3]", "in or on the wall", "hopper.wall"]),
    ("an insert edge cutting the wall",
     {**H, "inserts": [{"outline": [[0.0745, 0.11], [0.0842, 0.125], [0.06, 0.12]]}]}, None,
     ["hopper.inserts[0].outline cuts hopper.wall"]),
    ("an insert below the outlet plane",
     {**H, "inserts": [{"outline": [[0.0, 0.05], [0.02, -0.01], [0.0, -0.02]]}]}, None,
     ["hopper.inserts[0].outline[1] = [0.02, -0.01]", "below the outlet plane"]),
    ("an insert of two points", {**H, "inserts": [{"outline": [[0.0, 0.1], [0.05, 0.2]]}]},
     None, ["hopper.inserts[0].outline has 2 points", "at least 3"]),
    ("an insert that does not enclose an area",
     {**H, "inserts": [{"outline": [[0.0, 0.1], [0.02, 0.2], [0.04, 0.3]]}]}, None,
     ["hopper.inserts[0].outline encloses no area", "closed polygon"]),
    ("an insert that crosses itself",
     {**H, "inserts": [{"outline": [[0.02, 0.3], [0.08, 0.4], [0.08, 0.3], [0.02, 0.4]]}]},
     None, ["hopper.inserts[0].outline crosses itself"]),
    ("a bow-tie insert (its signed area exactly 0)",
     {**H, "inserts": [{"outline": [[0.0625, 0.25], [0.125, 0.3125], [0.125, 0.25],
                                    [0.0625, 0.3125]]}]},
     None, ["hopper.inserts[0].outline crosses itself"]),
    ("an insert across the axis",
     {**H, "inserts": [{"outline": [[-0.02, 0.3], [0.05, 0.3], [0.0, 0.4]]}]}, None,
     ["hopper.inserts[0].outline[0] = [-0.02, 0.3]", "crosses the axis"]),
    ("inserts overlapping",
     {**H, "inserts": [{"outline": DIAMOND}, {"outline": [[0.0, 0.1], [0.06, 0.1],
                                                           [0.0, 0.2]]}]}, None,
     ["hopper.inserts[1].outline overlaps hopper.inserts[0]"]),
    ("an insert with an unknown key", {**H, "inserts": [{"outline": DIAMOND, "mu": 0.3}]},
     None, ["unknown key", "hopper.inserts[0].mu"]),
    ("an insert friction out of range",
     {**H, "inserts": [{"outline": DIAMOND, "friction_angle_deg": 95.0}]}, None,
     ["hopper.inserts[0].friction_angle_deg = 95 deg", "[0, 90) deg"]),
    ("a left wall right of the right wall",
     {**FULL, "left_wall": [[-0.06, 0.0], [0.1, 0.05], [-0.15, 0.6]]}, None,
     ["hopper.left_wall[1] = [0.1, 0.05]", "right of (or on) the right wall"]),
    ("a left lip right of the right lip", {**FULL, "left_wall": [[0.04, 0.0], [-0.15, 0.6]]},
     None, ["hopper.left_wall[0] = [0.04, 0]", "not left of the right one"]),
    ("a left wall crossing the right wall between points",
     {**FULL, "wall": [[0.03, 0.0], [0.15, 0.2], [0.15, 0.6]],
      "left_wall": [[-0.06, 0.0], [0.16, 0.22], [0.16, 0.24], [-0.15, 0.6]]}, None,
     ["hopper.left_wall"]),
    ("a fill level above the top", {**H, "fill_level": 0.7}, None,
     ["hopper.fill_level = 0.7 m", "above the top of the wall, z = 0.6 m"]),
    ("a fill level on the outlet plane", {**H, "fill_level": 0.0}, None,
     ["hopper.fill_level = 0 m", "allowed range is [0.001, 0.6] m"]),
    ("a profile without a fill level", {"shape": "profile", "wall": TWO_SLOPE}, None,
     ["hopper.fill_level is required"]),
    ("a profile without a wall", {"shape": "profile", "fill_level": 0.3}, None,
     ["hopper.wall is required"]),
    ("a left wall in a half-section", {**H, "left_wall": FULL["left_wall"]}, None,
     ["hopper.left_wall is for hopper.section = \"full\""]),
    ("a full section without a left wall", {**H, "symmetry": "plane", "section": "full"},
     None, ["hopper.left_wall is required"]),
    ("a full axisymmetric section", {**FULL, "symmetry": "axisymmetric"}, None,
     ["hopper.section = \"full\"", "hopper.symmetry = \"plane\""]),
    ("an unknown symmetry", {**H, "symmetry": "cylindrical"}, None,
     ["hopper.symmetry = 'cylindrical'", "'axisymmetric', 'plane'"]),
    ("a plane cone", {"symmetry": "plane"}, None,
     ["hopper.symmetry = \"plane\" does not fit hopper.shape = \"conical\""]),
    ("a profile with a shorthand key", {**H, "bin_diameter": 0.3}, None,
     ["hopper.bin_diameter is for the conical and wedge shorthands"]),
    ("a shorthand with a profile key", {"fill_level": 0.4}, None,
     ["hopper.fill_level is for shape = \"profile\"", "hopper.fill_height"]),
    ("a segment friction list of the wrong length", H,
     {"segment_friction_deg": [15.0, 25.0]},
     ["wall.segment_friction_deg has 2 values", "hopper.wall has 3 segments"]),
    ("a segment friction list for a cone", {}, {"segment_friction_deg": [15.0, 15.0, 25.0]},
     ["wall.segment_friction_deg has 3 values", "2 segments"]),
    ("a segment friction angle out of range", H,
     {"segment_friction_deg": [15.0, 95.0, 25.0]},
     ["wall.segment_friction_deg[1] = 95 deg", "[0, 90) deg"]),
    ("a segment friction that is not a list", H, {"segment_friction_deg": 15.0},
     ["wall.segment_friction_deg = 15", "one per segment"]),
]


@pytest.mark.parametrize("hopper, wall, words", [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_boundaries_are_refused_in_one_line_naming_the_key(hopper, wall, words):
    with pytest.raises(ConfigError) as err:
        HopperConfig.from_dict({"hopper": hopper, "wall": wall or {}})
    message = str(err.value)
    assert "\n" not in message
    for word in words:
        assert word in message, (word, message)


def test_a_bad_boundary_stops_validate_in_one_line(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text('[hopper]\nshape = "profile"\nwall = [[0.03, 0.0], [0.1, 0.2], '
                    '[0.15, 0.1]]\nfill_level = 0.1\n')
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "hopper.wall[2] = [0.15, 0.1]" in err[0]
    assert not (tmp_path / "geometry.png").exists()


def test_the_lagrangian_mode_meshes_a_cone_as_a_profile_and_refuses_the_rest():
    """A cone under a bin drawn as a profile meshes; a two-slope wall, an insert in the
    material and a plane section are refused in one line naming the formulation."""
    cone = {"shape": "profile", "wall": [[0.03, 0.0], [0.15, 0.33], [0.15, 0.68]],
            "fill_level": 0.6}
    cfg = HopperConfig.from_dict({"hopper": cone, "numerics": {"formulation": "lagrangian"}})
    assert cfg.hopper.classic
    insert = {**cone, "inserts": [{"outline": [[0.0, 0.4], [0.05, 0.35], [0.0, 0.3]]}]}
    for hopper in (H, insert, {**cone, "symmetry": "plane"}):
        with pytest.raises(ConfigError, match="numerics.formulation = \"lagrangian\"") as err:
            HopperConfig.from_dict({"hopper": hopper, "numerics": {"formulation": "lagrangian"}})
        assert "\n" not in str(err.value) and "eulerian" in str(err.value)
