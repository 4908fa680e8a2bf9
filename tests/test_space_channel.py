"""The flow channel measured in horizontal slices (fipy_hopper.space.channel) on constructed
velocity fields: a channel that is a circle of radius r_c centred e_c off the axis (EN 1991-4's
three channels), a centred channel, a channel along the wall over a known arc that is not a
circle, mass flow and no flow; reflected fields give mirrored results; a stack of slices and a
half unfolded across its mirror plane; the 3D model's grid and state."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fipy_hopper import theory as th
from fipy_hopper.space import channel as ch

R, H = 0.5, 0.01                         # the section's radius and the grid spacing (m)
N = int(round((R + 2 * H) / H))
X1 = H * np.arange(-N, N + 1)            # symmetric to the bit: x and -x are both nodes
X, Y = np.meshgrid(X1, X1)
MU, PHI = 0.491, 33.6                    # the worked example's wall and internal friction


def circle_field(r_c, e_c, angle_deg=0.0, x=X, y=Y):
    """Downward speed 1 at the channel's centre falling as 1 - 0.9 (d / r_c)^2: exactly a
    tenth of the largest at the circle of radius r_c (zero beyond 1.05 r_c)."""
    a = math.radians(angle_deg)
    d = np.hypot(x - e_c * math.cos(a), y - e_c * math.sin(a))
    return np.clip(1.0 - 0.9 * (d / r_c) ** 2, 0.0, None)


def sector_field(half_angle_deg, width, angle_deg=0.0):
    """A channel along the wall: the annular sector within ``width`` of the wall and within
    ``half_angle_deg`` of ``angle_deg``; the speed 0.1 + 0.9 s / width (clipped to [0, 1]),
    s = min(width - (R - rho), R (half angle - |phi|)) its distance-like depth inside."""
    rho = np.hypot(X, Y)
    phi = np.angle(np.exp(1j * (np.arctan2(Y, X) - math.radians(angle_deg))))
    s = np.minimum(width - (R - rho), R * (math.radians(half_angle_deg) - np.abs(phi)))
    return np.clip(0.1 + 0.9 * s / width, 0.0, 1.0)


@pytest.mark.parametrize("G", th.EN1991_ECCENTRIC_G)
@pytest.mark.parametrize("angle", [0.0, 37.0])
def test_circular_channel_recovers_r_c_e_c_theta_c(G, angle):
    en = th.en1991_eccentric_channel(R, G, MU, PHI)
    s = ch.slice_channel(X1, X1, circle_field(G * R, en.e_c, angle), R)
    assert s.touches_wall
    # within a cell: theta_c along the wall, r_c, e_c, the contact's direction
    assert abs(math.radians(s.theta_c - en.theta_c)) * R < H
    assert abs(s.r_c - G * R) < H
    assert abs(s.e_c - en.e_c) < H
    assert abs(math.radians(s.contact_angle - angle)) * R < H
    # measured (h = R/50): within a tenth of a cell
    assert abs(math.radians(s.theta_c - en.theta_c)) * R < 0.1 * H
    assert abs(s.r_c - G * R) < 0.1 * H and abs(s.e_c - en.e_c) < 0.1 * H
    # the area is A_c within a cell's width along the outline
    assert abs(s.area - en.A_c) < H * (en.U_sc + en.U_wc)
    # a circle: the fit agrees and the outline lies on it
    assert abs(s.fit_r - G * R) < H and s.fit_rms < 0.1 * H
    a = math.radians(angle)
    assert np.hypot(s.fit_centre[0] - en.e_c * math.cos(a),
                    s.fit_centre[1] - en.e_c * math.sin(a)) < H
    # EN 1991-4's circle of the measurement has the measured contact and area
    g = th.eccentric_channel_geometry(R, s.r_c, s.e_c)
    assert g.theta_c == pytest.approx(s.theta_c, abs=1e-7)
    assert g.A_c == pytest.approx(s.area, rel=1e-9)
    assert s.n_regions == 1
    assert s.r_eq == pytest.approx(math.sqrt(s.area / math.pi))
    # the outline's extent: the circle's, cut by the wall (its far side inside, within a
    # cell), and never beyond the section
    x_min, x_max, y_min, y_max = s.extent
    cx, cy = en.e_c * math.cos(a), en.e_c * math.sin(a)
    if angle == 0.0:
        assert abs(x_min - (cx - G * R)) < H and x_max <= R + 1e-12
        assert abs(y_max - min(G * R, R)) < H and abs(y_min + y_max) < H
    assert R * -1 - 1e-12 <= x_min < x_max <= R + 1e-12


def test_centred_channel_has_no_contact():
    s = ch.slice_channel(X1, X1, circle_field(0.2, 0.0), R)
    assert s.theta_c == 0.0 and not s.touches_wall and math.isnan(s.contact_angle)
    assert s.r_c == s.r_eq and abs(s.r_c - 0.2) < H
    assert s.e_c < 1e-9 and np.hypot(*s.centroid) < 1e-9
    assert s.area == pytest.approx(math.pi * 0.04, rel=2 * H / 0.2)
    # off the axis but clear of the wall: still no contact, the centre found
    s = ch.slice_channel(X1, X1, circle_field(0.2, 0.25, 120.0), R)
    assert s.theta_c == 0.0
    assert abs(s.e_c - 0.25) < H and abs(s.r_c - 0.2) < H
    assert abs(math.degrees(math.atan2(s.centroid[1], s.centroid[0])) - 120.0) < 0.1


@pytest.mark.parametrize("half_angle", [15.0, 40.0, 75.0])
def test_channel_along_the_wall_over_a_known_arc(half_angle):
    width = 0.1
    s = ch.slice_channel(X1, X1, sector_field(half_angle, width, -20.0), R)
    assert abs(math.radians(s.theta_c - half_angle)) * R < H
    assert abs(math.radians(s.contact_angle + 20.0)) * R < H
    exact = math.radians(half_angle) * (R * R - (R - width) ** 2)
    assert s.area == pytest.approx(exact, rel=0.02)
    assert s.fit_rms > 0.3 * H                # the outline is far from a circle
    # not a circle: EN 1991-4's circle through the arc's ends with the measured area ...
    t = math.radians(s.theta_c)
    segment = R * R * (t - math.sin(t) * math.cos(t))
    if s.area > segment:
        g = th.eccentric_channel_geometry(R, s.r_c, abs(s.e_c))
        assert g.theta_c == pytest.approx(s.theta_c, abs=1e-7)
        assert g.A_c == pytest.approx(s.area, rel=1e-9)
    else:
        # ... where there is one: a band along the wall thinner than the segment its arc's
        # chord cuts off has none (75 deg: 0.118 against 0.265 m^2)
        assert half_angle == 75.0
        assert math.isnan(s.r_c) and math.isnan(s.e_c)


def test_mass_flow_and_no_flow():
    s = ch.slice_channel(X1, X1, np.ones_like(X), R)
    assert s.theta_c == 180.0 and math.isnan(s.r_c) and math.isnan(s.contact_angle)
    assert s.area == pytest.approx(math.pi * R * R, rel=1e-3)
    s = ch.slice_channel(X1, X1, np.zeros_like(X), R)
    assert s.area == 0.0 and s.theta_c == 0.0 and math.isnan(s.r_c) and s.n_regions == 0
    s = ch.slice_channel(X1, X1, np.full_like(X, np.nan), R)
    assert s.area == 0.0
    # an upward-moving field has no channel either
    assert ch.slice_channel(X1, X1, -np.ones_like(X), R).area == 0.0


def test_reflected_fields_give_mirrored_results():
    en = th.en1991_eccentric_channel(R, 0.4, MU, PHI)
    field = circle_field(0.2, en.e_c, 25.0)
    s = ch.slice_channel(X1, X1, field, R)
    sy = ch.slice_channel(X1, X1, field[::-1, :], R)       # y -> -y
    sx = ch.slice_channel(X1, X1, field[:, ::-1], R)       # x -> -x
    for m in (sy, sx):
        for name in ("theta_c", "r_c", "e_c", "area", "fit_r", "fit_rms"):
            assert getattr(m, name) == pytest.approx(getattr(s, name), rel=1e-9, abs=1e-12)
    assert sy.contact_angle == pytest.approx(-s.contact_angle, abs=1e-9)
    assert sx.contact_angle == pytest.approx(180.0 - s.contact_angle, abs=1e-9)
    assert sy.centroid[0] == pytest.approx(s.centroid[0], abs=1e-12)
    assert sy.centroid[1] == pytest.approx(-s.centroid[1], abs=1e-12)
    assert sx.centroid[0] == pytest.approx(-s.centroid[0], abs=1e-12)
    # the sector along the wall, reflected
    f = sector_field(30.0, 0.08, 60.0)
    a, b = ch.slice_channel(X1, X1, f, R), ch.slice_channel(X1, X1, f[::-1, :], R)
    assert b.theta_c == pytest.approx(a.theta_c, rel=1e-9)
    assert b.contact_angle == pytest.approx(-a.contact_angle, abs=1e-9)


def test_field_known_only_inside_the_section():
    # NaN outside the wall: the contact read from the inside nodes (one-sided) -- measured
    # within 1.6 cells along the wall (G = 0.6, where the channel meets the wall at 17 deg),
    # r_c and e_c within a cell
    for G in th.EN1991_ECCENTRIC_G:
        en = th.en1991_eccentric_channel(R, G, MU, PHI)
        f = circle_field(G * R, en.e_c)
        f[np.hypot(X, Y) > R] = np.nan
        s = ch.slice_channel(X1, X1, f, R)
        assert abs(math.radians(s.theta_c - en.theta_c)) * R < 2 * H
        assert abs(s.r_c - G * R) < H and abs(s.e_c - en.e_c) < H


def test_two_channels_the_larger_is_the_channel():
    f = np.maximum(circle_field(0.15, 0.0), 0.8 * circle_field(0.05, 0.3, 90.0))
    s = ch.slice_channel(X1, X1, f, R)
    assert s.n_regions == 2
    assert abs(s.r_c - 0.15) < H and s.theta_c == 0.0


def test_profile_of_slices_and_unfolding():
    # a cone-shaped channel: r_c growing with height, centred 0.3 m along +x
    z = np.array([0.1, 0.3, 0.5, 0.7])
    r_c = np.array([0.12, 0.2, 0.25, 0.28])
    e_c = np.array([th.en1991_eccentric_channel(R, rc / R, MU, PHI).e_c for rc in r_c])
    down = np.stack([circle_field(rc, ec) for rc, ec in zip(r_c, e_c)])
    down[2] = 0.0                                             # a slice where nothing flows
    p = ch.channel_profile(X1, X1, z, down, R)
    keep = [0, 1, 3]
    np.testing.assert_array_less(np.abs(p.r_c[keep] - r_c[keep]), H)
    np.testing.assert_array_less(np.abs(p.e_c[keep] - e_c[keep]), H)
    assert p.area[2] == 0.0 and np.isnan(p.theta_c[2]) and np.isnan(p.r_c[2])
    np.testing.assert_allclose(p.G()[keep], r_c[keep] / R, atol=H / R)
    assert len(p.outlines) == 4 and len(p.outlines[2]) == 0
    # the half y >= 0 unfolded across its mirror plane gives the whole field's result
    j0 = N                                                    # the node row y = 0
    x, y, full = ch.unfold(X1, X1[j0:], down[:, j0:, :], mirror_y=True)
    np.testing.assert_array_equal(y, X1)
    np.testing.assert_array_equal(full, down)
    # and a quarter of a centred channel across both
    sym = circle_field(0.2, 0.0)
    x, y, q = ch.unfold(X1[N:], X1[N:], sym[N:, N:], mirror_x=True, mirror_y=True)
    np.testing.assert_array_equal(x, X1)
    np.testing.assert_array_equal(q, sym)
    with pytest.raises(ValueError, match="mirror plane"):
        ch.unfold(X1, X1, down, mirror_x=True)


def test_argument_checks():
    with pytest.raises(ValueError, match="down"):
        ch.slice_channel(X1, X1, np.zeros((3, 3)), R)
    with pytest.raises(ValueError, match="fraction"):
        ch.slice_channel(X1, X1, np.zeros_like(X), R, fraction=1.5)
    with pytest.raises(ValueError, match="radius"):
        ch.slice_channel(X1, X1, np.zeros_like(X), R, wall_inset=R)
    with pytest.raises(ValueError, match="nz"):
        ch.channel_profile(X1, X1, [0.0, 1.0], np.zeros((3,) + X.shape), R)


def test_the_3d_models_grid_and_state():
    """The flat-bottomed silo of tests/test_space_loads.py (bin 0.28 m, outlet 0.04 m off the
    axis, 2 cm cells, the half y >= 0) with a constructed state: every open cell full, the
    nodes moving down in EN 1991-4's G = 0.6 channel (the package's wall angle 0 towards the
    outlet, +x) and up (not flowing) elsewhere; the channel found within a cell at every node
    plane of the bin."""
    from fipy_hopper.space.boundary import SiloBoundary
    from fipy_hopper.space.grid import build_grid

    b = SiloBoundary.from_profile(((0.06, 0.0), (0.14, 0.0), (0.14, 0.4)), 0.26, 0.04, 20.0)
    g = build_grid(b, 0.02, 1.0, 0.0, "auto")
    assert not g.mirror_x and g.mirror_y
    Rb, h = b.radius, g.h
    en = th.en1991_eccentric_channel(Rb, 0.6, MU, PHI)
    Z, Yn, Xn = np.meshgrid(g.z_nodes, g.y_nodes, g.x_nodes, indexing="ij")
    v = np.zeros((3,) + Z.shape)
    v[2] = -circle_field(0.6 * Rb, en.e_c, 0.0, Xn, Yn)
    alpha = np.where(g.kappa > 0, 1.0, 0.0)
    alpha[g.centres(2) > 0.26] = 0.0                         # filled to 0.26 m
    model = SimpleNamespace(grid=g, boundary=b)
    p = ch.model_channel(model, SimpleNamespace(v=v, alpha=alpha))
    assert np.all(p.z > 0.0) and p.z.max() <= 0.26 + h + 1e-12
    assert len(p.z) >= 12
    assert np.all(np.abs(np.radians(p.theta_c - en.theta_c)) * Rb < h)
    assert np.all(np.abs(p.r_c - 0.6 * Rb) < h) and np.all(np.abs(p.e_c - en.e_c) < h)
    np.testing.assert_allclose(p.contact_angle, 0.0, atol=1e-9)   # the outlet's side
    # nodes without material do not flow: the same field in an empty silo has no channel
    empty = ch.model_channel(model, SimpleNamespace(v=v, alpha=np.zeros_like(alpha)))
    assert len(empty.z) == 0
    # node_material: the mean alpha of the open cells round a node
    m = ch.node_material(alpha, g.kappa)
    assert m.shape == tuple(n + 1 for n in alpha.shape)
    assert np.nanmax(m) == 1.0 and np.isnan(m).any()


def test_the_window_table_has_every_measure_of_a_profile():
    """``channel_windows.csv``'s columns (``io.CHANNEL_WINDOWS_COLUMNS``) are the window's
    own and then every measure a profile row has (``channel.PROFILE_COLUMNS``), in order; a
    profile's rows carry them all, one row per height."""
    from fipy_hopper import io as fio

    names = tuple(name for name, _ in ch.PROFILE_COLUMNS)
    assert fio.CHANNEL_WINDOWS_COLUMNS == ("window", "t_start_s", "t_end_s", "checks") + names
    x = np.linspace(-R, R, 41)
    X, Y = np.meshgrid(x, x)
    down = np.where(np.hypot(X, Y) < 0.5 * R, 1.0, 0.0)
    p = ch.channel_profile(x, x, [0.1, 0.2], np.stack([down, down]), R)
    rows = ch.profile_rows(p)
    assert [tuple(row) for row in rows] == [names, names]
    assert [row["z_m"] for row in rows] == [0.1, 0.2]
    assert rows[1]["r_eq_m"] == pytest.approx(0.5 * R, rel=0.05)
