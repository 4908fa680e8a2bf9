"""The compiled step (fipy_hopper.stepping and the compiled parts of the transport step) equals
the numpy reference, and the number of threads does not change a single bit."""

import warnings

import numba
import numpy as np
import pytest

from fipy_hopper import geometry, markers, momentum, stepping
from fipy_hopper.config import HopperConfig
from fipy_hopper.material import return_fast
from fipy_hopper.model import TRANSPORTED, HopperModel
from fipy_hopper.transport import material_rows


@pytest.fixture(scope="module")
def small_cfg():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.25,
                       "fill_height": 0.15},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.02}})


@pytest.fixture(scope="module")
def discharging(small_cfg, flowing):
    """A model and a state 0.1 s into the discharge (flowing, plastic, loose, with markers)."""
    model = HopperModel(small_cfg)
    return model, flowing(model)


def _run(model, state, steps, threads):
    saved = numba.get_num_threads()
    model.threads = threads
    try:
        done = 0
        while done < steps:
            done += model.advance(state, steps - done)
    finally:
        numba.set_num_threads(saved)
    return state


def test_threads_do_not_change_a_bit(small_cfg, discharging):
    """Two threads and one give the same state to the last bit (sums in a fixed order, one
    writer per place, returns independent of their block)."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two threads")
    model, state = discharging
    one = _run(model, state.copy(), 300, threads=1)
    two = _run(model, state.copy(), 300, threads=2)
    for name in ("v", "alpha", "sigma", "eps_p", "loose", "layer", "face_flux_sum", "markers"):
        assert np.array_equal(getattr(one, name), getattr(two, name)), name
    assert one.discharged == two.discharged and one.t == two.t


def test_compiled_steps_equal_the_numpy_reference_in_discharge(small_cfg, discharging):
    """300 steps of flowing discharge (with transports): the compiled path and the numpy
    reference agree to round-off (1e-9 relative: the returns of the two paths differ by
    their 1e-12 tolerance, and a few hundred steps of flow amplify it)."""
    model, state = discharging
    ref = HopperModel(small_cfg, backend="numpy")
    a = _run(model, state.copy(), 300, threads=1)
    b = state.copy()
    done = 0
    while done < 300:
        done += ref.advance(b, 300 - done)
    assert np.max(np.abs(a.v - b.v)) <= 1e-9 * np.max(np.abs(b.v))
    assert np.max(np.abs(a.sigma - b.sigma)) <= 1e-9 * np.max(np.abs(b.sigma))
    assert np.max(np.abs(a.alpha - b.alpha)) <= 1e-12
    assert a.discharged == pytest.approx(b.discharged, rel=1e-9)


def test_skipping_empty_cells_changes_nothing(small_cfg, discharging):
    """A step skips cells that carry nothing; the nodes and faces there stay at rest."""
    model, state = discharging
    st = state.copy()
    model.advance(st, 1)
    empty = st.alpha == 0.0
    assert empty.any()
    assert np.all(st.sigma[st.alpha < model.cfg.numerics.alpha_min] == 0.0)
    mass = model.node_mass(st)
    assert np.all(st.v[:, mass == 0.0] == 0.0)


def test_node_mass_and_dual_momentum_kernels_equal_numpy(small_cfg, discharging):
    """Bit for bit: the kernels add in the order of the numpy functions."""
    model, state = discharging
    rng = np.random.default_rng(3)
    alpha = np.clip(state.alpha + 0.01 * rng.normal(size=state.alpha.shape), 0, 1)
    ref = momentum.node_mass(model.rho, alpha, model.open_volume)
    out = np.empty_like(ref)
    momentum.node_mass_kernel(model.rho, alpha, model.open_volume, out)
    assert np.array_equal(out, ref)
    g = model.grid
    flux_z = 1e-6 * rng.normal(size=(g.nz + 1, g.nr))
    flux_r = 1e-6 * rng.normal(size=(g.nz, g.nr + 1))
    mass_old = model.node_mass(state)
    v_ref = momentum.dual_momentum_transport(state.v, mass_old, ref, flux_z, flux_r, model.rho)
    v_ref[:, ref <= model.light_mass] = 0.0
    v_new = np.empty_like(state.v)
    momentum.dual_momentum_kernel(state.v, mass_old, ref, flux_z, flux_r, model.rho,
                                  model.light_mass, v_new)
    assert np.array_equal(v_new, v_ref)


def test_pack_and_unpack_are_the_numpy_expressions(discharging):
    model, state = discharging
    n = state.alpha.size
    packed = np.empty((len(TRANSPORTED), n))
    stepping.pack_fields(state.alpha, state.sigma, state.eps_p, state.layer, state.loose,
                         packed)
    a = state.alpha
    assert np.array_equal(packed[0], a.ravel())
    assert np.array_equal(packed[2], (a * state.sigma[..., 1]).ravel())
    assert np.array_equal(packed[7], (a * state.loose).ravel())
    shape = a.shape
    outs = [np.empty(shape), np.empty(shape + (4,)), np.empty(shape), np.empty(shape),
            np.empty(shape)]
    stepping.unpack_fields(packed, model.cfg.numerics.alpha_min, *outs)
    assert np.array_equal(outs[0], a)
    present = a >= 1e-12
    safe = np.where(present, a, 1.0)
    sigma = np.where(present[..., None], (a[..., None] * state.sigma) / safe[..., None], 0.0)
    sigma[a < model.cfg.numerics.alpha_min] = 0.0
    assert np.array_equal(outs[1], sigma)
    assert np.array_equal(outs[4], np.where(present, np.maximum((a * state.loose) / safe, 0),
                                            0.0))


def test_transport_of_material_rows_equals_the_whole_grid(discharging):
    """Transport restricted to the rows that hold material (plus three empty rows each side)
    gives the whole-grid step's numbers exactly."""
    model, discharged = discharging
    state = discharged.copy()
    while state.flux_time == 0.0:             # velocities of a run: only where there is mass
        model.advance(state, 1)
    n = state.alpha.size
    packed = np.empty((len(TRANSPORTED), n))
    stepping.pack_fields(state.alpha, state.sigma, state.eps_p, state.layer, state.loose,
                         packed)
    u = state.face_flux_sum / state.flux_time
    assert np.any(u != 0.0)
    rows = material_rows(state.alpha)
    assert rows[1] - rows[0] < model.grid.nz           # the test restricts something
    full_new, full_flux = model.transport_open.step_stacked(packed, u, 1e-4)
    part_new, part_flux = model.transport_open.step_stacked(packed, u, 1e-4, rows=rows)
    assert np.array_equal(full_new, part_new)
    assert np.array_equal(full_flux, part_flux)


def test_compiled_marker_advance_equals_reference(small_cfg, discharging):
    model, state = discharging
    rng = np.random.default_rng(1)
    disp = 0.8 * model.grid.h * rng.normal(size=state.v.shape)
    pts = state.markers.copy()
    pts[:20, 0] *= -1.0                                   # across the axis too
    fast = markers.advance(pts, disp, model.grid, small_cfg.hopper)
    ref = markers.advance_reference(pts, disp, model.grid, small_cfg.hopper)
    assert np.array_equal(fast, ref)
    # the case includes markers that the midpoint rule put inside the wall
    geom, g = small_cfg.hopper, model.grid
    r_mid, z_mid = np.empty(len(pts)), np.empty(len(pts))
    bnd = geom.boundary
    markers._midpoint_kernel(pts, disp, g.r_nodes, g.z_nodes, bnd.section.mirror,
                             bnd.kernel_arrays(), bnd.table.normal, 0.0, 0, r_mid, z_mid)
    assert np.count_nonzero(geometry.in_solid(r_mid, z_mid, geom)) >= 5
    # markers that leave through the bottom are dropped, the others keep their order
    down = np.zeros_like(disp)
    down[1] = -3.0 * model.grid.h
    fast = markers.advance(pts, down, model.grid, small_cfg.hopper)
    ref = markers.advance_reference(pts, down, model.grid, small_cfg.hopper)
    assert np.array_equal(fast, ref)
    assert 0 < len(fast) < len(pts)


@pytest.mark.parametrize("filled", [(), (0,), (5,), (2, 7), (0, 11), (11,)])
def test_material_rows_brackets_the_nonzero_rows(filled):
    """``material_rows``: the rows with nonzero alpha plus three each side, clipped to the grid;
    (0, 0) for an empty grid; as its plain numpy definition."""
    alpha = np.zeros((12, 5))
    for j in filled:
        alpha[j, j % 5] = 1e-30 if j == 7 else 0.5
    rows = material_rows(alpha)
    nonzero = np.flatnonzero(np.any(alpha != 0.0, axis=1))
    expected = ((0, 0) if nonzero.size == 0 else
                (max(nonzero[0] - 3, 0), min(nonzero[-1] + 4, 12)))
    assert rows == expected


def test_stress_rotates_with_the_material_jaumann(small_cfg):
    """A rigid rotation of the nodes about a point of row j (``v_r = w (z - z0)``,
    ``v_z = -w (r - r0)``): the cells of that row have no strain (``D = 0``, their mean ``v_r``
    and divergence vanish), only spin ``w``, so their stress changes only by the Jaumann
    rotation, ``d s_rr = 2 w dt s_rz``, ``d s_zz = -2 w dt s_rz``, ``d s_rz = w dt (s_zz -
    s_rr)``, ``s_tt`` unchanged (an elastic state: no return)."""
    model = HopperModel(small_cfg)
    g, num = model.grid, small_cfg.numerics
    j = g.nz // 2
    z0 = g.z_cells[j]
    omega = 2.0                                                   # 1/s
    R, Z = np.meshgrid(g.r_nodes, g.z_nodes)
    v = np.ascontiguousarray(np.stack([omega * (Z - z0), -omega * (R - 0.3)]))
    alpha = np.where(g.kappa > 0, 1.0, 0.0)
    sigma = np.zeros((g.nz, g.nr, 4))
    sigma[...] = (-1000.0, -2000.0, -1200.0, -300.0)             # inside the yield surface
    loose, eps_p = np.zeros_like(alpha), np.zeros_like(alpha)
    carry_runs, load_runs, block_ptr, contrib, _, _ = model._work
    _, _, n_blocks, _, _ = stepping._runs(alpha, num.alpha_min, sigma, loose, v.copy(), contrib,
                                          carry_runs, load_runs, block_ptr)
    before = sigma.copy()
    stepping._stress_update(block_ptr, n_blocks, load_runs, v, sigma, loose, eps_p,
                            np.zeros_like(alpha), model.r_c, model.flux_radius, model.strain_dims, g.h, model.dt, g.kappa,
                            model._zface_aperture,
                            model._rface_aperture, model._prm,
                            return_fast._fast_constants(model._prm), np.zeros_like(alpha))
    cells = np.flatnonzero(g.kappa[j] == 1.0)
    assert cells.size >= 3
    w = omega * model.dt
    s = before[j, cells]
    expected = s.copy()
    expected[:, 0] += 2 * w * s[:, 3]
    expected[:, 1] -= 2 * w * s[:, 3]
    expected[:, 3] += w * (s[:, 1] - s[:, 0])
    assert np.max(np.abs(sigma[j, cells] - expected)) < 1e-9 * np.max(np.abs(s))
    assert np.max(np.abs(sigma[j, cells] - s)) > 1e-3 * 2 * w * 300.0   # it did rotate


def test_moving_rows_leave_out_only_rows_of_light_nodes_at_rest():
    """The node rows a compiled call updates: from the lowest to the highest row with a node
    heavier than the light mass or in motion (a light node still moving is stopped by the
    update, so its row stays in); rows of light nodes at rest beyond are left out."""
    mass = np.zeros((10, 4))
    v = np.zeros((2, 10, 4))
    light = 1e-16
    assert stepping._moving_rows(0, 10, mass, v, light) == (0, 0)
    mass[2:5, 1] = 1.0
    mass[8, 3] = 0.5 * light                         # a trace: light and at rest
    assert stepping._moving_rows(0, 10, mass, v, light) == (2, 5)
    v[1, 6, 0] = -1e-3                               # a light node still moving
    assert stepping._moving_rows(0, 10, mass, v, light) == (2, 7)
    assert stepping._moving_rows(3, 10, mass, v, light) == (3, 7)


def test_a_call_with_traces_on_the_wall_equals_the_numpy_reference(small_cfg, discharging):
    """Round-off traces of material far above the flow (light nodes at rest, outside the
    moving rows): the compiled steps equal the numpy reference's, which updates every row."""
    model, state = discharging
    ref_model = HopperModel(small_cfg, backend="numpy")
    st = state.copy()
    top = st.alpha.shape[0] - 2
    st.alpha[top, -3] = 1e-30                        # a trace cell under the top
    st.markers = None
    st2 = st.copy()
    mass = model.node_mass(st)
    assert (mass[top:top + 2] <= model.light_mass).all() and (mass[top:top + 2] > 0).any()
    for _ in range(15):
        model.step(st)
        ref_model.step(st2)
    np.testing.assert_allclose(st.v, st2.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.sigma, st2.sigma, rtol=1e-9, atol=1e-6)
    np.testing.assert_array_equal(st.alpha, st2.alpha)


def _forces_and_nodes(model, state, with_mass):
    """The node velocities after one force pass and node update of ``state``, the carry runs
    chosen with the node masses (as a compiled call does) or by ``alpha != 0`` alone."""
    g, num = model.grid, model.cfg.numerics
    carry_runs, load_runs, block_ptr, contrib, _, row_budget = model._work
    v, sigma, loose = state.v.copy(), state.sigma.copy(), state.loose.copy()
    mass = model.node_mass(state)
    extra = (mass, model.light_mass) if with_mass else ()
    n_carry = stepping._runs(state.alpha, num.alpha_min, sigma, loose, v, contrib, carry_runs,
                             load_runs, block_ptr, 1, *extra)[0]
    stepping._cell_forces(carry_runs, n_carry, state.alpha, sigma, v, model.open_volume,
                          model.r_c, g.h, model.hourglass_base, contrib, model.viscosity,
                          model.bulk_viscosity, num.alpha_min, np.zeros_like(state.alpha),
                          False, state.flowing, model._rate)
    row_nodes, _, node_i, node_ptr, normal, mu, kind, entry = model.contact_groups
    stepping._node_update(0, g.nz + 1, v, mass, contrib, 9.81, model.dt, 0.0, model.light_mass,
                          row_nodes, node_i, node_ptr, normal, mu, kind, entry, False, 0.0,
                          g.r_nodes, state.wall_impulse.copy(), state.plate_impulse.copy(),
                          row_budget)
    cells = {(int(j), i) for j, i0, i1 in carry_runs[:n_carry] for i in range(i0, i1)}
    return v, cells


def test_traces_whose_nodes_are_all_light_are_left_out_of_the_forces(discharging):
    """A cell whose four nodes are all light pushes only nodes that the update sets at rest:
    leaving its forces out changes no velocity; a trace on the material, with heavy nodes,
    keeps its forces."""
    model, state = discharging
    st = state.copy()
    top = st.alpha.shape[0] - 2
    st.alpha[top, -3] = 1e-30                        # far above the flow: four light nodes
    j, i = max((j, i) for j, i in zip(*np.nonzero(st.alpha >= 0.5)))   # the highest material
    st.alpha[j + 1, i] = 1e-30                       # ... and a trace on it
    light = model.node_mass(st) <= model.light_mass
    assert light[top:top + 2, -3:-1].all() and not light[j + 1, i:i + 2].any()
    pruned_v, pruned = _forces_and_nodes(model, st, with_mass=True)
    full_v, full = _forces_and_nodes(model, st, with_mass=False)
    assert (top, st.alpha.shape[1] - 3) in full - pruned
    assert (j + 1, i) in pruned
    assert not pruned - full
    assert np.array_equal(pruned_v, full_v)


@pytest.mark.parametrize("damping", [0.0, 40.0])
def test_node_update_sums_every_node_in_the_scatters_order(damping):
    """The node update, inner columns vectorised, equals node by node in plain Python: each
    force summed from 0 in the scatter's order (NE of the cell below left, NW below, SE left,
    SW own), light nodes at rest, the damping, the axis and the rows' impulses, to the bit."""
    rng = np.random.default_rng(7)
    nz, nr = 6, 9
    contrib = rng.normal(size=(8, nz, nr)) * 10.0 ** rng.integers(-8, 3, size=(8, nz, nr))
    mass = rng.uniform(0.5, 2.0, size=(nz + 1, nr + 1))
    light_mass = 1e-3
    mass[rng.random(mass.shape) < 0.2] = 1e-4                  # light nodes, some moving
    v = rng.normal(size=(2, nz + 1, nr + 1)) * 1e-9     # small: the forces' last bits show
    gravity, dt = 9.81, 1e-3
    expected, budget = v.copy(), np.zeros((nz + 1, 3))
    for j in range(nz + 1):
        for i in range(nr + 1):
            fr = fz = 0.0
            for dj, di, k in ((-1, -1, 4), (-1, 0, 6), (0, -1, 2), (0, 0, 0)):
                if 0 <= j + dj < nz and 0 <= i + di < nr:
                    fr += contrib[k, j + dj, i + di]
                    fz += contrib[k + 1, j + dj, i + di]
            m = mass[j, i]
            if m > light_mass:
                expected[0, j, i] = expected[0, j, i] + dt * fr / m
                expected[1, j, i] = expected[1, j, i] + dt * (fz / m - gravity)
                budget[j, 0] -= m * gravity * dt
            else:
                budget[j, 2] -= m * expected[1, j, i]
                expected[:, j, i] = 0.0
        if damping > 0.0:
            for i in range(nr + 1):
                vz = expected[1, j, i]
                expected[0, j, i] *= 1.0 / (1.0 + damping * dt)
                expected[1, j, i] = vz * (1.0 / (1.0 + damping * dt))
                budget[j, 1] += mass[j, i] * (expected[1, j, i] - vz)
        expected[0, j, 0] = 0.0
    none = np.zeros(0, dtype=np.int64)
    row_budget = np.zeros((nz + 1, 3))
    stepping._node_update(0, nz + 1, v, mass, contrib, gravity, dt, damping, light_mass,
                          np.zeros(nz + 2, dtype=np.int64), none, np.zeros(1, dtype=np.int64),
                          np.zeros((0, 2)), np.zeros(0), none, none, False, 0.0,
                          np.arange(nr + 1.0), np.zeros((1, 2)), np.zeros((1, 2)), row_budget)
    assert np.array_equal(v, expected)
    assert np.array_equal(row_budget, budget)


def test_all_finite_finds_every_nan_and_inf():
    """The compiled check after each transport: ``np.all(np.isfinite(a))`` for NaN, +inf and
    -inf anywhere in arrays of the fields' shapes, contiguous or not."""
    rng = np.random.default_rng(3)
    for shape in [(2, 9, 7), (8, 6, 4), (5,)]:
        a = rng.normal(size=shape)
        assert stepping.all_finite(a) and stepping.all_finite(a[..., ::2])
        for bad in (np.nan, np.inf, -np.inf):
            for flat in (0, a.size // 2, a.size - 1):
                b = a.copy()
                b.flat[flat] = bad
                assert not stepping.all_finite(b)
                assert stepping.all_finite(b[..., ::2]) == bool(np.all(np.isfinite(b[..., ::2])))
