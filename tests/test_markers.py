"""Passive layer markers: seeding, bilinear interpolation, midpoint advection with wall and
outflow handling, the marker files of the field writer and the pictures drawn from them."""

import importlib.util
import pathlib
import types
import warnings

import matplotlib
import meshio
import numpy as np
import pytest

matplotlib.use("Agg")

from fipy_hopper import geometry, markers, plotting  # noqa: E402
from fipy_hopper.config import HopperConfig  # noqa: E402
from fipy_hopper.io import FieldWriter, marker_file, read_snapshot_index  # noqa: E402
from fipy_hopper.mesh import build_grid  # noqa: E402

STUDIES = pathlib.Path(__file__).resolve().parents[1] / "studies"


def small(half_angle_deg):
    """A 0.2 m bin, 0.06 m outlet, 0.15 m fill, 1 cm cells, and its grid."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.25,
                       "fill_height": 0.15, "half_angle_deg": half_angle_deg},
            "numerics": {"cell_size": 0.01}})
    return cfg, build_grid(cfg)


@pytest.fixture(scope="module")
def flat():
    """Flat-bottomed bin: every open cell above the outlet plane is entirely open."""
    return small(90.0)


@pytest.fixture(scope="module")
def cone():
    return small(30.0)


def filled(cfg, grid, n_layers=5, seed=0):
    """alpha = 1 in the open cells up to the fill level (and 0.3 in a partial top row), with
    a layer tracer that is not an integer (the markers round it)."""
    zc = grid.z_cells[:, None] * np.ones((1, grid.nr))
    fill = cfg.hopper.fill_level
    alpha = np.where((zc > 0) & (zc < fill), 1.0, 0.0)
    alpha = np.where((zc > fill) & (zc < fill + grid.h), 0.3, alpha) * (grid.kappa > 0)
    rng = np.random.default_rng(seed)
    layer = np.floor(zc / fill * n_layers) + rng.uniform(-0.3, 0.3, zc.shape)
    return alpha, layer


def cell_of(grid, r, z):
    i = np.searchsorted(grid.r_nodes, r, side="right") - 1
    j = np.searchsorted(grid.z_nodes, z, side="right") - 1
    return j, i


def uniform(grid, d_r, d_z):
    shape = (grid.nz + 1, grid.nr + 1)
    return np.stack([np.full(shape, d_r), np.full(shape, d_z)])


def nodal(grid, f):
    """A nodal (2, nz+1, nr+1) field from a function of (r, z) returning (f_r, f_z)."""
    R, Z = np.meshgrid(grid.r_nodes, grid.z_nodes)
    return np.stack(f(R, Z))


# ------------------------------------------------------------------------------ seeding
@pytest.mark.parametrize("per_side", [1, 2, 3])
def test_seed_count_in_a_flat_bin(flat, per_side):
    cfg, grid = flat
    alpha, layer = filled(cfg, grid)
    m = markers.seed(grid, cfg.hopper, alpha, layer, per_side=per_side)
    n_full = int(np.sum((alpha > 0.5) & (grid.z_cells >= 0)[:, None]))
    assert n_full > 100
    assert m.shape == (per_side ** 2 * n_full, 3)
    # a regular sub-lattice: in each cell, the points r_i + (k + 1/2) h / per_side
    frac = (m[:, 0] / grid.h) % 1.0 * per_side - 0.5
    assert np.allclose(frac, np.round(frac), atol=1e-9)


def test_seed_in_a_cone_is_open_above_the_outlet_and_carries_the_cell_layer(cone):
    cfg, grid = cone
    alpha, layer = filled(cfg, grid)
    m = markers.seed(grid, cfg.hopper, alpha, layer)
    full = (alpha > 0.5) & (grid.z_cells >= 0)[:, None]
    cut = full & (grid.kappa < 1.0 - 1e-9)
    assert cut.sum() > 5                                  # the wall cuts some full cells
    assert 4 * (full.sum() - cut.sum()) < len(m) < 4 * full.sum()
    assert np.all(~geometry.in_solid(m[:, 0], m[:, 1], cfg.hopper))
    assert np.all(geometry.signed_distance(m[:, 0], m[:, 1], cfg.hopper) > 0)
    assert np.all(m[:, 1] >= 0.0)
    j, i = cell_of(grid, m[:, 0], m[:, 1])
    assert np.all(full[j, i])
    assert np.array_equal(m[:, 2], np.round(layer[j, i]))
    assert np.array_equal(m[:, 2], np.round(m[:, 2]))
    # deterministic
    assert np.array_equal(m, markers.seed(grid, cfg.hopper, alpha, layer))


def test_seed_rejects_a_bad_sub_grid(flat):
    cfg, grid = flat
    alpha, layer = filled(cfg, grid)
    with pytest.raises(ValueError, match="per_side"):
        markers.seed(grid, cfg.hopper, alpha, layer, per_side=0)


# ------------------------------------------------------------------------------ interpolate
def test_interpolate_is_exact_for_bilinear_fields(flat):
    _, grid = flat
    field = nodal(grid, lambda r, z: (0.3 + 2.0 * r - 1.5 * z + 7.0 * r * z,
                                      -1.0 + 0.5 * r + 3.0 * z - 4.0 * r * z))
    rng = np.random.default_rng(1)
    r = rng.uniform(grid.r_nodes[0], grid.r_nodes[-1], 500)
    z = rng.uniform(grid.z_nodes[0], grid.z_nodes[-1], 500)
    got = markers.interpolate(field, grid.r_nodes, grid.z_nodes, r, z)
    assert got.shape == (2, 500)
    assert np.allclose(got[0], 0.3 + 2.0 * r - 1.5 * z + 7.0 * r * z, rtol=0, atol=1e-12)
    assert np.allclose(got[1], -1.0 + 0.5 * r + 3.0 * z - 4.0 * r * z, rtol=0, atol=1e-12)


def test_interpolate_at_nodes_gives_nodal_values_and_clamps_outside(flat):
    _, grid = flat
    rng = np.random.default_rng(2)
    field = rng.normal(size=(2, grid.nz + 1, grid.nr + 1))
    R, Z = np.meshgrid(grid.r_nodes, grid.z_nodes)
    got = markers.interpolate(field, grid.r_nodes, grid.z_nodes, R.ravel(), Z.ravel())
    assert np.allclose(got, field.reshape(2, -1), rtol=0, atol=1e-13)
    # beyond the grid: the value at the nearest boundary point
    outside = markers.interpolate(field, grid.r_nodes, grid.z_nodes,
                                  [grid.r_nodes[-1] + 1.0, -0.5], [grid.z_nodes[0] - 1.0, 99.0])
    assert np.allclose(outside[:, 0], field[:, 0, -1])
    assert np.allclose(outside[:, 1], field[:, -1, 0])


# ------------------------------------------------------------------------------ advance
def test_uniform_displacement_translates_exactly(flat):
    cfg, grid = flat
    rng = np.random.default_rng(3)
    m = np.column_stack([rng.uniform(0.02, 0.07, 200), rng.uniform(0.02, 0.2, 200),
                         rng.integers(0, 8, 200).astype(float)])
    moved = markers.advance(m, uniform(grid, 0.004, -0.007), grid, cfg.hopper)
    assert moved.shape == m.shape
    assert np.allclose(moved[:, 0], m[:, 0] + 0.004, rtol=0, atol=1e-14)
    assert np.allclose(moved[:, 1], m[:, 1] - 0.007, rtol=0, atol=1e-14)
    assert np.array_equal(moved[:, 2], m[:, 2])


def test_rotation_keeps_the_radius_to_the_midpoint_rules_order(flat):
    """Solid-body rotation by theta per interval, ``d = theta (-(z - z_c), r - r_c)``: the
    midpoint rule's amplification ``(1 - theta^2/2) I + theta J`` scales the radius by
    ``sqrt(1 + theta^4 / 4)`` per interval (forward Euler would give ``sqrt(1 + theta^2)``)."""
    cfg, grid = flat
    r_c, z_c = 0.05, 0.12
    rng = np.random.default_rng(4)
    phi = rng.uniform(0, 2 * np.pi, 50)
    rho = rng.uniform(0.005, 0.03, 50)
    m = np.column_stack([r_c + rho * np.cos(phi), z_c + rho * np.sin(phi), np.zeros(50)])
    errors = []
    for theta in (0.04, 0.02, 0.01):
        d = nodal(grid, lambda r, z: (-theta * (z - z_c), theta * (r - r_c)))
        moved = markers.advance(m, d, grid, cfg.hopper)
        ratio = np.hypot(moved[:, 0] - r_c, moved[:, 1] - z_c) / rho
        assert np.allclose(ratio, np.sqrt(1 + theta ** 4 / 4), rtol=0, atol=1e-12)
        angle = np.arctan2(moved[:, 1] - z_c, moved[:, 0] - r_c) - phi
        assert np.allclose(np.angle(np.exp(1j * angle)), theta, rtol=0, atol=theta ** 3)
        errors.append(np.max(np.abs(ratio - 1)))
    assert errors[0] / errors[1] == pytest.approx(16, rel=0.01)
    assert errors[1] / errors[2] == pytest.approx(16, rel=0.05)


@pytest.mark.parametrize("d_r, d_z", [(0.03, 0.0), (0.02, -0.02), (0.0, -0.05)])
def test_markers_pushed_into_the_wall_end_just_inside_the_open_region(cone, d_r, d_z):
    cfg, grid = cone
    alpha, layer = filled(cfg, grid)
    m = markers.seed(grid, cfg.hopper, alpha, layer)
    moved = markers.advance(m, uniform(grid, d_r, d_z), grid, cfg.hopper)
    assert len(moved) == len(m)
    target_r, target_z = m[:, 0] + d_r, m[:, 1] + d_z
    hit = geometry.in_solid(target_r, target_z, cfg.hopper)
    assert hit.sum() > 20
    dist = geometry.signed_distance(moved[:, 0], moved[:, 1], cfg.hopper)
    gap = markers.WALL_GAP * grid.h
    assert np.all(dist > 0)
    assert np.all(dist[hit] < 1.01 * gap)
    # they moved to the nearest wall point: no farther than their depth in the wall
    depth = -geometry.signed_distance(target_r[hit], target_z[hit], cfg.hopper)
    shift = np.hypot(moved[hit, 0] - target_r[hit], moved[hit, 1] - target_z[hit])
    assert np.allclose(shift, depth + gap, rtol=1e-9, atol=1e-12)
    assert np.allclose(moved[~hit, 0], target_r[~hit], atol=1e-14)
    assert np.allclose(moved[~hit, 1], target_z[~hit], atol=1e-14)
    assert np.array_equal(moved[:, 2], m[:, 2])


def test_markers_below_the_grid_are_removed(cone):
    cfg, grid = cone
    z0 = grid.z_nodes[0]
    m = np.array([[0.01, z0 + 0.005, 1.0], [0.02, z0 + 0.02, 2.0], [0.005, z0 + 0.011, 3.0],
                  [0.015, 0.05, 4.0]])
    moved = markers.advance(m, uniform(grid, 0.0, -0.01), grid, cfg.hopper)
    assert moved[:, 2].tolist() == [2.0, 3.0, 4.0]
    assert np.allclose(moved[:, 1], m[1:, 1] - 0.01)
    assert np.all(moved[:, 1] >= z0)


def test_markers_crossing_the_axis_are_reflected(flat):
    """r = 0.008 - 0.01 is reflected to 0.002; from r = 0.004 the midpoint r = -0.001 lies
    across the axis, where the axisymmetric continuation ``d_r(-r) = -d_r(r)`` is +0.01."""
    cfg, grid = flat
    m = np.array([[0.008, 0.1, 0.0], [0.004, 0.1, 1.0], [0.03, 0.1, 2.0]])
    moved = markers.advance(m, uniform(grid, -0.01, 0.002), grid, cfg.hopper)
    assert np.allclose(moved[:, 0], [0.002, 0.014, 0.02], rtol=0, atol=1e-15)
    assert np.allclose(moved[:, 1], 0.102, rtol=0, atol=1e-15)


# ------------------------------------------------------------------------------ output
def fake_state(grid, step, t, marker_points=None):
    shape = (grid.nz, grid.nr)
    return types.SimpleNamespace(
        t=t, step=step, stage="discharge", v=np.zeros((2, grid.nz + 1, grid.nr + 1)),
        alpha=np.ones(shape), sigma=np.zeros(shape + (4,)), eps_p=np.zeros(shape),
        layer=np.zeros(shape), markers=marker_points)


def test_field_writer_writes_markers_and_resume_drops_them(tmp_path, cone):
    cfg, grid = cone
    alpha, layer = filled(cfg, grid)
    m = markers.seed(grid, cfg.hopper, alpha, layer)
    writer = FieldWriter(tmp_path, grid)
    writer.write(fake_state(grid, 10, 0.1, m), t_open=0.0)
    writer.write(fake_state(grid, 20, 0.2, m[::2]), t_open=0.0)
    writer.write(fake_state(grid, 30, 0.3, None), t_open=0.0)        # no markers: no file
    writer.write(fake_state(grid, 40, 0.4, m[:0]), t_open=0.0)       # empty: no file
    assert marker_file("fields_0001.vtu") == "markers_0001.vtu"
    assert sorted(p.name for p in tmp_path.glob("markers_*.vtu")) == ["markers_0000.vtu",
                                                                     "markers_0001.vtu"]
    back = meshio.read(tmp_path / "markers_0000.vtu")
    assert np.array_equal(back.points[:, :2], m[:, :2])
    assert np.all(back.points[:, 2] == 0)
    assert np.array_equal(np.asarray(back.point_data["layer"]).ravel(), m[:, 2])
    assert back.cells[0].type == "vertex" and len(back.cells[0].data) == len(m)
    assert [e["file"] for e in read_snapshot_index(tmp_path)] == [
        f"fields_{k:04d}.vtu" for k in range(4)]

    resumed = FieldWriter(tmp_path, grid)
    resumed.resume(step=10)
    assert [p.name for p in tmp_path.glob("markers_*.vtu")] == ["markers_0000.vtu"]
    assert [p.name for p in tmp_path.glob("fields_*.vtu")] == ["fields_0000.vtu"]
    resumed.write(fake_state(grid, 20, 0.2, m[:7]), t_open=0.0)
    assert len(meshio.read(tmp_path / "markers_0001.vtu").points) == 7


# ------------------------------------------------------------------------------ pictures
@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, cone):
    """A tiny run directory: the config and two discharge snapshots, the second with markers
    moved down by a uniform displacement and the material moving (speed rising with r)."""
    cfg, grid = cone
    run = tmp_path_factory.mktemp("run")
    (run / "config.toml").write_text(cfg.to_toml())
    alpha, layer = filled(cfg, grid, n_layers=6)
    m = markers.seed(grid, cfg.hopper, alpha, layer)
    writer = FieldWriter(run / "fields", grid)
    state = fake_state(grid, 10, 0.1, None)
    state.alpha, state.layer = alpha, layer
    writer.write(state, t_open=0.0)
    state.step, state.t = 20, 0.2
    state.markers = markers.advance(m, uniform(grid, 0.0, -0.02), grid, cfg.hopper)
    state.v = np.zeros_like(state.v)
    state.v[1] = -np.linspace(0.0, 0.5, grid.nr + 1)[None, :]
    writer.write(state, t_open=0.0)
    return run, state.markers


def test_load_snapshot_reads_the_markers(run_dir):
    run, m = run_dir
    entries = plotting.snapshots(run)
    assert plotting.load_snapshot(run, entries[0])["markers"] is None
    assert np.array_equal(plotting.load_snapshot(run, entries[1])["markers"], m)


def test_sections_draw_markers_as_discs_and_fall_back_to_the_tracer(run_dir):
    from matplotlib.collections import EllipseCollection, QuadMesh

    run, m = run_dir
    cfg = plotting._config(run)
    without, with_ = (plotting.load_snapshot(run, e) for e in plotting.snapshots(run))
    assert plotting._n_layers([with_]) == int(m[:, 2].max()) + 1
    fig = plotting._figure(6, 4)
    ax_a, ax_b = fig.subplots(1, 2)
    plotting._draw_section(ax_a, without, cfg, 6, 1.0)
    plotting._draw_section(ax_b, with_, cfg, 6, 1.0)
    fig.canvas.draw()
    assert not any(isinstance(c, EllipseCollection) for c in ax_a.collections)
    discs = [c for c in ax_b.collections if isinstance(c, EllipseCollection)]
    assert len(discs) == 1
    offsets = discs[0].get_offsets()
    assert np.allclose(offsets[:, 0], -m[:, 0]) and np.allclose(offsets[:, 1], m[:, 1])
    assert np.array_equal(np.asarray(discs[0].get_array()), m[:, 2])
    # the undeformed lattice spacing is h / 2: discs of 1.5 h / 2 fill it
    assert discs[0].get_widths()[0] == pytest.approx(plotting.MARKER_DIAMETER * 0.005)
    # only the speed, the closed cells and the wall are cell meshes on the marker section
    assert sum(isinstance(c, QuadMesh) for c in ax_b.collections) == \
        sum(isinstance(c, QuadMesh) for c in ax_a.collections) - 1


def test_animation_frames_hold_their_own_snapshot(run_dir, tmp_path, monkeypatch):
    """The animation draws the grid, the wall and the axes once and then changes only the
    speed and the layers: every frame holds its snapshot's speed, layers and title, and
    nothing of the frame before (the first snapshot has the cell tracer, the second markers)."""
    from matplotlib.animation import PillowWriter
    from matplotlib.collections import EllipseCollection, QuadMesh

    run, m = run_dir
    snaps = [plotting.load_snapshot(run, e) for e in plotting.snapshots(run)]
    frames = []
    original = PillowWriter.grab_frame

    def grab(writer, **kwargs):
        ax = writer.fig.axes[0]
        meshes = [c for c in ax.collections if isinstance(c, QuadMesh)]
        discs = [c for c in ax.collections if isinstance(c, EllipseCollection)]
        frames.append({"meshes": [np.ma.getdata(c.get_array()).copy() for c in meshes],
                       "masks": [np.ma.getmaskarray(c.get_array()).copy() for c in meshes],
                       "discs": [c.get_offsets().copy() for c in discs],
                       "title": ax.get_title()})
        original(writer, **kwargs)

    monkeypatch.setattr(PillowWriter, "grab_frame", grab)
    plotting.animate(run, tmp_path / "a.gif")
    assert len(frames) == 2
    cfg = plotting._config(run)
    for frame, snap in zip(frames, snaps):
        fig = plotting._figure(3.6, 4.6)
        ax = fig.add_subplot()
        plotting._draw_section(ax, snap, cfg, 6, 1.0)
        fresh = [c for c in ax.collections if isinstance(c, QuadMesh)]
        assert len(frame["meshes"]) == len(fresh)          # nothing left of the frame before
        speed = plotting._masked_speed(snap)
        assert any(np.array_equal(d.ravel(), np.ma.getdata(speed).ravel())
                   and np.array_equal(k.ravel(), np.ma.getmaskarray(speed).ravel())
                   for d, k in zip(frame["meshes"], frame["masks"]))
        assert frame["title"] == plotting._label(snap)
    assert not np.array_equal(np.ma.getdata(plotting._masked_speed(snaps[0])),
                              np.ma.getdata(plotting._masked_speed(snaps[1])))
    assert frames[0]["discs"] == []
    assert len(frames[1]["discs"]) == 1
    assert np.allclose(frames[1]["discs"][0], np.column_stack([-m[:, 0], m[:, 1]]))


def test_flow_pattern_and_thumbnails_with_markers(run_dir):
    run, _ = run_dir
    fig = plotting.flow_pattern(run, n=2)
    fig.canvas.draw()
    spec = importlib.util.spec_from_file_location("flow_mode_map_study",
                                                  STUDIES / "flow_mode_map.py")
    study = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(study)
    row = {"flow_mode": "mass", "run_dir": str(run), "distance_deg": -5.0, "agrees": True,
           "half_angle_deg": 30.0, "wall_friction_deg": 15.0, "jenike_mode": "mass"}
    thumbs = study.plot_thumbnails([row], 1)
    thumbs.canvas.draw()
    assert "marker points" in thumbs._suptitle.get_text()


def test_markers_stay_with_the_material_through_discharge():
    """Markers (moved by the nodal velocities) and alpha (face fluxes of the same velocities)
    hold the same share of the material in the hopper and below its mid-height.  Each marker
    stands for the seeded volume ``r_seed (h / 2)^2`` (per radian); its layer column is set to
    its index to find ``r_seed`` again.  Measured on this case: 0.779 against 0.782 in the hopper, 0.281 against 0.289 below mid-height; before the
    volumetric strain of cut cells was taken over their open volume, the markers drained much
    faster than the material (below mid-height 0.36 of the markers against 0.29 of alpha)."""
    import warnings

    from fipy_hopper.config import HopperConfig
    from fipy_hopper.model import HopperModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "bin_height": 0.2, "fill_height": 0.12},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05},
            "run": {"markers_per_side": 2}})
    model = HopperModel(cfg)
    g = model.grid
    state = model.initial_state()
    seeded = state.markers.copy()
    state.markers[:, 2] = np.arange(len(seeded))
    volume0 = seeded[:, 0] * (g.h / 2) ** 2
    while state.t < 0.3:
        model.step(state)
    model.open_outlet(state)
    while state.t < 1.0:
        model.step(state)
    model.transport_step(state)
    z_mid = 0.5 * model.cfg.hopper.fill_level
    cells = state.alpha * model.open_volume
    alpha_total = cells[g.z_cells >= 0].sum()
    alpha_low = cells[(g.z_cells >= 0) & (g.z_cells < z_mid)].sum()
    index = state.markers[:, 2].astype(int)
    z = state.markers[:, 1]
    marker_total = volume0[index[z >= 0]].sum()
    marker_low = volume0[index[(z >= 0) & (z < z_mid)]].sum()
    initial = (model.initial_state().alpha * model.open_volume)[g.z_cells >= 0].sum()
    assert alpha_total < 0.85 * initial                 # a real part of it has gone
    assert marker_total / volume0.sum() == pytest.approx(alpha_total / initial, abs=0.03)
    assert marker_low / volume0.sum() == pytest.approx(alpha_low / initial, abs=0.03)
