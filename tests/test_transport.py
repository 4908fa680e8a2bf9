"""Transport on the fixed cylindrical grid: FiPy definition, fast kernels, CFL, boundedness."""

import numpy as np
import pytest
from fipy import CylindricalGrid2D, Grid2D

from fipy_hopper.transport import (FiPyTransport, Transport, max_stable_dt, redistribution,
                                   open_neighbour_pairs, outgoing_volume_flux,
                                   redistribute_overshoot)


# ------------------------------------------------------------------------------------ helpers

def cylinder_grid(nr, nz, h, z0=0.0, jitter=0.0, seed=0, cls=CylindricalGrid2D):
    """Grid from arrays of spacings (optionally non-uniform by +-jitter/2 of h)."""
    rng = np.random.default_rng(seed)
    dr = h * (1.0 + jitter * (rng.random(nr) - 0.5))
    dz = h * (1.0 + jitter * (rng.random(nz) - 0.5))
    if cls is Grid2D:      # Cartesian (origin irrelevant; a translated grid loses its shape)
        return Grid2D(dx=dr, dy=dz)
    return cls(dx=dr, dy=dz, origin=((0.0,), (z0,)))


def face_ends(mesh):
    """Coordinates (2, nFaces) of the two vertices of every face."""
    vertices = np.asarray(mesh.vertexCoords)
    ids = np.asarray(mesh.faceVertexIDs)
    return vertices[:, ids[0]], vertices[:, ids[1]]


def stream_function_velocity(mesh, psi):
    """Exact face normal velocity of the Stokes stream function ``psi(r, z)``.

    ``u_r = -(1/r) dpsi/dz``, ``u_z = (1/r) dpsi/dr``: the volume flux per radian through a
    face from vertex a to b, along the normal obtained by turning a->b clockwise, is
    ``-(psi_b - psi_a)``; dividing by FiPy's face area gives ``u_n``.  Every cell's fluxes sum
    to zero to round-off (the psi values telescope around the cell).
    """
    a, b = face_ends(mesh)
    tangent = b - a
    clockwise_normal = np.stack([tangent[1], -tangent[0]])
    sign = np.sign((clockwise_normal * np.asarray(mesh.faceNormals)).sum(0))
    flux = -sign * (psi(*b) - psi(*a))
    area = np.asarray(mesh._faceAreas)
    return np.divide(flux, area, out=np.zeros_like(flux), where=area > 0)


def line_wall_fractions(mesh, wall_z, samples=32):
    """Open fractions of cells and apertures of faces above the wall line ``z > wall_z(r)``
    (planar area / length fractions by sampling; solid below the line)."""
    vertices = np.asarray(mesh.vertexCoords)
    t = (np.arange(samples) + 0.5) / samples
    a, b = face_ends(mesh)
    r = a[0][:, None] + (b[0] - a[0])[:, None] * t
    z = a[1][:, None] + (b[1] - a[1])[:, None] * t
    aperture = (z > wall_z(r)).mean(1)
    cell_vertices = vertices[:, np.asarray(mesh._orderedCellVertexIDs)]
    r0, r1 = cell_vertices[0].min(0), cell_vertices[0].max(0)
    z0, z1 = cell_vertices[1].min(0), cell_vertices[1].max(0)
    rs = r0[:, None, None] + (r1 - r0)[:, None, None] * t[None, :, None]
    zs = z0[:, None, None] + (z1 - z0)[:, None, None] * t[None, None, :]
    kappa = (zs > wall_z(rs)).mean((1, 2))
    return kappa, aperture


def content(alpha, geom):
    return alpha * geom.kappa * geom.cell_volume


def random_setup(mesh, seed, n_fields=4):
    """Random cut cells, apertures, outflow faces, velocities and fields (smooth, step, noise)."""
    rng = np.random.default_rng(seed)
    n_cells, n_faces = mesh.numberOfCells, mesh.numberOfFaces
    kappa = np.ones(n_cells)
    cut = rng.random(n_cells) < 0.3
    kappa[cut] = 0.05 + 0.95 * rng.random(cut.sum())
    kappa[rng.choice(n_cells, 3, replace=False)] = 0.0
    aperture = np.where(rng.random(n_faces) < 0.25, rng.random(n_faces), 1.0)
    r_face, z_face = np.asarray(mesh.faceCenters)
    exterior = np.asarray(mesh.exteriorFaces.value)
    outflow = exterior & (z_face <= z_face.min() + 1e-12) & (r_face < np.median(r_face))
    u_n = rng.normal(size=n_faces)
    u_n[outflow] = np.abs(u_n[outflow])
    r, z = np.asarray(mesh.cellCenters)
    span = np.ptp(r) + np.ptp(z)
    fields = [np.sin(7 * r / span + 1) * np.cos(5 * z / span),                 # smooth
              ((r - r.mean()) ** 2 + (z - z.mean()) ** 2 < (0.3 * span) ** 2) * 1.0,  # disc
              rng.random(n_cells),                                             # noise
              np.where(z > np.median(z), 2.0, -1.0) + r / span]                # step + ramp
    names = [f"f{k}" for k in range(n_fields)]
    return kappa, aperture, outflow, u_n, dict(zip(names, fields[:n_fields]))


def relative_difference(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


# ------------------------------------------------------- (b) kernels reproduce FiPy's scheme

@pytest.mark.parametrize("scheme", ["axisymmetric", "fipy"])
@pytest.mark.parametrize("mesh_class", [CylindricalGrid2D, Grid2D])
def test_fast_kernels_reproduce_fipy_van_leer(mesh_class, scheme):
    """Numba and numpy kernels equal FiPy's TransientTerm + convection-term solve to 1e-12
    (fields and face fluxes): non-uniform grid, cut cells, apertures, outflow faces, random
    velocities, smooth / discontinuous / noisy fields, two consecutive steps.  For the
    scheme the model runs, ``"axisymmetric"``, the FiPy equations use
    ``AxisymmetricVanLeerConvectionTerm`` (FiPy's term with the planar reconstruction); for
    ``"fipy"`` FiPy's own ``VanLeerConvectionTerm``."""
    mesh = cylinder_grid(9, 8, 0.01, z0=-0.03, jitter=0.6, seed=3, cls=mesh_class)
    kappa, aperture, outflow, u_n, fields = random_setup(mesh, seed=4)
    names = list(fields)
    reference = FiPyTransport(mesh, kappa, aperture, outflow, names, scheme=scheme)
    kernels = [Transport(mesh, kappa, aperture, outflow, names, backend=b, scheme=scheme)
               for b in ("numba", "numpy")]
    dt = kernels[0].max_stable_dt(u_n, cfl=0.5)
    state = {"fipy": fields, "numba": fields, "numpy": fields}
    for step in range(2):
        ref_fields, ref_flux = reference.step(state["fipy"], u_n, dt)
        for kernel in kernels:
            new, flux = kernel.step(state[kernel.backend], u_n, dt)
            for name in names:
                assert relative_difference(new[name], ref_fields[name]) < 1e-12
                assert relative_difference(flux[name], ref_flux[name]) < 1e-12
            state[kernel.backend] = new
        state["fipy"] = ref_fields
        u_n = -0.7 * u_n
        u_n[outflow] = np.abs(u_n[outflow])


def test_reference_face_flux_accounts_for_every_change():
    """FiPy's cell changes are exactly minus the divergence of the reported face fluxes."""
    mesh = cylinder_grid(7, 6, 0.02, jitter=0.4, seed=1)
    kappa, aperture, outflow, u_n, fields = random_setup(mesh, seed=2, n_fields=2)
    reference = FiPyTransport(mesh, kappa, aperture, outflow, list(fields))
    geom = reference.geometry
    dt = max_stable_dt(geom, u_n)
    new, flux = reference.step(fields, u_n, dt)
    for name in fields:
        change = (new[name] - fields[name]) * geom.kappa_volume
        divergence = (np.bincount(geom.face_cell_1, flux[name], geom.n_cells)
                      - np.bincount(geom.face_cell_2[geom.interior], flux[name][geom.interior],
                                    geom.n_cells))
        scale = np.max(np.abs(fields[name] * geom.kappa_volume))
        assert np.max(np.abs(change + divergence)) < 1e-13 * scale


# ------------------------------------------------------------ (e) numba equals plain numpy

@pytest.mark.parametrize("scheme", ["fipy", "axisymmetric"])
def test_numba_kernel_equals_numpy_kernel(scheme):
    mesh = cylinder_grid(31, 23, 0.005, z0=-0.02, jitter=0.5, seed=7)
    kappa, aperture, outflow, u_n, fields = random_setup(mesh, seed=8)
    names = list(fields)
    fast = Transport(mesh, kappa, aperture, outflow, names, scheme=scheme)
    plain = Transport(mesh, kappa, aperture, outflow, names, backend="numpy", scheme=scheme)
    phi = np.stack([fields[n] for n in names])
    dt = fast.max_stable_dt(u_n)
    new_fast, flux_fast = fast.step_stacked(phi, u_n, dt)
    new_plain, flux_plain = plain.step_stacked(phi, u_n, dt)
    assert relative_difference(new_fast, new_plain) < 1e-13
    assert relative_difference(flux_fast, flux_plain) < 1e-13
    # writing into caller-owned buffers gives the same result
    out = (np.empty_like(phi), np.empty_like(flux_fast))
    fast.step_stacked(phi, u_n, dt, out=out)
    assert np.array_equal(out[0], new_fast) and np.array_equal(out[1], flux_fast)


def test_numba_backend_refuses_a_mesh_that_is_not_a_fipy_grid():
    from fipy import Grid1D
    with pytest.raises(Exception):
        Transport(Grid1D(nx=4), np.ones(4), np.ones(5), None, ["a"])


# ------------------------------------------------------------------- (a) rotating blob

R0, Z0, R_DISC, OMEGA_C = 0.5, 0.5, 0.4, 1.0


def rotation_psi(r, z):
    """``psi = c min(rho^2, R^2)``, rho the distance from (R0, Z0): streamlines are circles
    about (R0, Z0); the speed ``2 c rho / r`` is faster nearer the axis, but every streamline
    has the same period ``T = pi R0 / c`` (the mean of r on a circle is R0), so a blob inside
    the disc deforms and comes back exactly after T.  Still outside the disc (and on the axis).
    """
    return OMEGA_C * np.minimum((r - R0) ** 2 + (z - Z0) ** 2, R_DISC ** 2)


def run_blob_revolution(scheme, redistribute, n=50, room_min=1e-6):
    mesh = cylinder_grid(n, n, 1.0 / n)
    transport = Transport(mesh, np.ones(mesh.numberOfCells), np.ones(mesh.numberOfFaces),
                          None, ["alpha", "alpha_tracer"], scheme=scheme)
    geom = transport.geometry
    u_n = stream_function_velocity(mesh, rotation_psi)
    r, z = np.asarray(mesh.cellCenters)
    alpha0 = (((r - R0) ** 2 + (z - 0.72) ** 2) < 0.15 ** 2) * 1.0
    phi = np.stack([alpha0, alpha0 * z])             # alpha and alpha * (initial height)
    period = np.pi * R0 / OMEGA_C
    n_steps = int(np.ceil(period / transport.max_stable_dt(u_n, cfl=0.5)))
    dt = period / n_steps
    mass0 = phi @ geom.kappa_volume
    low, high, raw_high, raw_low = 0.0, 0.0, 0.0, 0.0
    for _ in range(n_steps):
        phi, _ = transport.step_stacked(phi, u_n, dt)
        raw_high, raw_low = max(raw_high, phi[0].max()), min(raw_low, phi[0].min())
        if redistribute:
            phi[0], moved = transport.redistribute_overshoot(phi[0], room_min=room_min)
            phi[1] = transport.apply_redistribution(phi[1], moved)
        low, high = min(low, phi[0].min()), max(high, phi[0].max())
    divergence = np.abs(np.bincount(geom.face_cell_1[geom.interior],
                                    geom.volume_flux(u_n)[geom.interior], geom.n_cells)
                        - np.bincount(geom.face_cell_2[geom.interior],
                                      geom.volume_flux(u_n)[geom.interior], geom.n_cells))
    return dict(mass_error=np.abs(phi @ geom.kappa_volume - mass0) / mass0,
                low=low, high=high, raw_low=raw_low, raw_high=raw_high,
                return_error=np.abs(phi[0] - alpha0) @ geom.cell_volume / mass0[0],
                divergence=divergence.max() / np.abs(geom.volume_flux(u_n)).max())


@pytest.mark.parametrize("room_min", [1e-6, 1e-3])
def test_blob_revolution_fipy_scheme_with_redistribution(room_min):
    """FiPy's scheme (the default) plus ``redistribute_overshoot`` after every step: mass and
    the tracer kept to 1e-12, 0 <= alpha <= 1 throughout, return error (V-weighted L1 of
    alpha - alpha0 over the blob mass) 0.456 at 50 x 50 cells (0.273 at 100 x 100).  Without
    the redistribution FiPy's scheme overshoots to ~1.14 and undershoots to ~-0.002 here."""
    result = run_blob_revolution("fipy", redistribute=True, room_min=room_min)
    assert result["divergence"] < 1e-13
    assert np.all(result["mass_error"] < 1e-12)
    assert result["low"] >= -1e-12 and result["high"] <= 1.0 + 1e-12
    assert result["raw_high"] > 1.001         # the redistribution did real work
    assert result["return_error"] < 0.5


def test_blob_revolution_axisymmetric_scheme_is_bounded_by_itself():
    """With planar reconstruction geometry the van Leer update is bounded for a divergence-free
    flow with no help: alpha in [0, 1] to round-off; return error 0.448 at 50 x 50."""
    result = run_blob_revolution("axisymmetric", redistribute=False)
    assert np.all(result["mass_error"] < 1e-12)
    assert result["low"] >= -1e-12 and result["high"] <= 1.0 + 1e-12
    assert result["return_error"] < 0.5


# -------------------------------------------------------------------------- (c) outflow

def test_outflow_column_loses_exactly_what_crosses_the_outflow_faces():
    """A column drains through its bottom: per step and in total, the mass lost equals the sum
    of the face fluxes on the outflow faces (round-off); walls, top and solid cells pass
    nothing although a velocity is given there; a negative u_n on an outflow face lets nothing
    in."""
    nr, nz, h = 6, 12, 0.01
    mesh = cylinder_grid(nr, nz, h, z0=-0.02)
    r, z = np.asarray(mesh.cellCenters)
    r_face, z_face = np.asarray(mesh.faceCenters)
    normal = np.asarray(mesh.faceNormals)
    exterior = np.asarray(mesh.exteriorFaces.value)
    kappa = np.where(r < 0.04, 1.0, 0.0)                     # column of radius 4 cells
    outflow = exterior & (z_face < -0.0199) & (r_face < 0.03)
    u_n = -0.5 * normal[1]                                    # u = (0, -0.5) m/s everywhere
    u_n[exterior & ~outflow] = 0.3                            # ignored: no flux there
    u_n[np.flatnonzero(outflow)[0]] = -1.0                    # inflow refused
    transport = Transport(mesh, kappa, np.ones(mesh.numberOfFaces), outflow, ["alpha"])
    geom = transport.geometry
    alpha = np.where((z > 0.0) & (kappa > 0), 1.0, 0.0)
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    mass0 = float(content(alpha, geom).sum())
    left = 0.0
    for _ in range(200):
        before = float(content(alpha, geom).sum())
        new, flux = transport.step({"alpha": alpha}, u_n, dt)
        alpha = new["alpha"]
        after = float(content(alpha, geom).sum())
        out_step = float(flux["alpha"][outflow].sum())
        assert abs((before - after) - out_step) < 1e-14 * mass0
        assert np.all(flux["alpha"][exterior & ~outflow] == 0.0)
        assert np.all(flux["alpha"][outflow] >= 0.0)
        left += out_step
    assert abs(mass0 - float(content(alpha, geom).sum()) - left) < 1e-13 * mass0
    assert left > 0.4 * mass0         # the part above the outlet really drained (the ring
                                      # r > 0.03 rests on the closed bottom)
    assert np.all(alpha[kappa == 0] == 0.0)


# ------------------------------------------------------------------ (d) cut cells, pile-up

@pytest.mark.parametrize("room_min", [1e-6, 1e-3])
def test_material_piles_onto_a_cut_cell_wall_bounded_and_conserved(room_min):
    """Loose material (alpha 0.6) falls at 0.2 m/s onto a sloped immersed wall cutting the
    cells (apertures and open fractions from the line): the compression drives the transported
    alpha above 1; ``redistribute_overshoot`` after each step keeps 0 <= alpha <= 1 while mass
    and an alpha-weighted tracer are conserved to 1e-12, and a packed bed forms on the wall."""
    nr, nz, h = 10, 16, 0.01
    mesh = cylinder_grid(nr, nz, h)
    wall = lambda r: 0.013 + 0.45 * r                         # solid below this line
    kappa, aperture = line_wall_fractions(mesh, wall)
    normal = np.asarray(mesh.faceNormals)
    u_n = -0.2 * normal[1]
    names = ["alpha", "alpha_tracer"]
    transport = Transport(mesh, kappa, aperture, None, names)
    geom = transport.geometry
    r, z = np.asarray(mesh.cellCenters)
    alpha = np.where((z > 0.09) & (z < 0.15) & (kappa > 0), 0.6, 0.0)
    phi = np.stack([alpha, alpha * r])                        # tracer: initial radius
    kappa_volume = geom.kappa * geom.cell_volume
    totals0 = phi @ kappa_volume
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    raw_high = 0.0
    for _ in range(150):
        phi, _ = transport.step_stacked(phi, u_n, dt)
        raw_high = max(raw_high, phi[0].max())
        phi[0], moved = transport.redistribute_overshoot(phi[0], room_min=room_min)
        phi[1] = transport.apply_redistribution(phi[1], moved)
        assert moved.residual_excess == 0.0 and moved.residual_deficit == 0.0
        assert phi[0].min() >= -1e-12 and phi[0].max() <= 1.0 + 1e-12
        assert np.all(np.abs(phi @ kappa_volume - totals0) < 1e-12 * np.abs(totals0))
    assert raw_high > 1.0 + 1e-3                              # the wall compressed it
    packed = (phi[0] > 1.0 - 1e-9) & (kappa > 0)
    assert packed.sum() >= 10                                 # a packed bed on the wall
    assert np.all(phi[0][kappa == 0] == 0.0)


# ------------------------------------------------------------------------ time step rule

def test_max_stable_dt_definition_and_guards():
    """dt = cfl min(max(kappa, kappa_min) V / outgoing volume flux); a sliver does not set it;
    with alpha given, only cells holding material do."""
    mesh = cylinder_grid(8, 8, 0.01, jitter=0.5, seed=5)
    kappa, aperture, outflow, u_n, _ = random_setup(mesh, seed=6)
    kappa = np.maximum(kappa, 0.2)
    probe = Transport(mesh, kappa, aperture, outflow, ["a"])
    busiest = np.argmax(outgoing_volume_flux(probe.geometry, u_n) / probe.geometry.cell_volume)
    kappa[busiest] = 0.001                                    # make the busiest cell a sliver
    transport = Transport(mesh, kappa, aperture, outflow, ["a"])
    geom = transport.geometry
    out = outgoing_volume_flux(geom, u_n)
    moving = out > 0
    for kappa_min in (0.0, 0.1):
        dt = transport.max_stable_dt(u_n, cfl=0.5, kappa_min=kappa_min)
        capacity = np.maximum(geom.kappa, kappa_min) * geom.cell_volume
        assert np.max(dt * out[moving] / capacity[moving]) == pytest.approx(0.5, rel=1e-12)
    # the guard: the sliver does not set the step
    assert transport.max_stable_dt(u_n, kappa_min=0.1) > 10 * transport.max_stable_dt(
        u_n, kappa_min=0.0)
    # material-weighted: empty cells do not limit
    alpha = np.zeros(geom.n_cells)
    assert transport.max_stable_dt(u_n, alpha=alpha) == np.inf
    alpha[:10] = 1.0
    dt_mat = transport.max_stable_dt(u_n, alpha=alpha, kappa_min=0.1)
    assert dt_mat >= transport.max_stable_dt(u_n, kappa_min=0.1)


@pytest.mark.parametrize("seed", range(5))
def test_axisymmetric_update_stays_positive_under_compression(seed):
    """Random (compressive) velocities, cut cells, fields in [0, 1], cfl = 0.5 without the
    sliver guard, uniform grid: the update is positive (outflow face values lie in
    [0, 2 phi_P]).  FiPy's scheme undershoots to -2e-2 on the same cases; on strongly
    non-uniform grids (+-25 % spacing) both can undershoot slightly, since the limiter's
    upwind slope assumes equal spacing.  ``redistribute_overshoot`` fills any deficit."""
    mesh = cylinder_grid(12, 10, 0.01, z0=-0.03, seed=seed)
    kappa, aperture, outflow, u_n, _ = random_setup(mesh, seed=seed + 10)
    rng = np.random.default_rng(seed)
    r, z = np.asarray(mesh.cellCenters)
    phi = np.stack([rng.random(mesh.numberOfCells), (z > z.mean()) * 1.0,
                    np.clip(np.sin(40 * r) + np.cos(30 * z), 0, None)])
    transport = Transport(mesh, kappa, aperture, outflow, ["a", "b", "c"], scheme="axisymmetric")
    dt = transport.max_stable_dt(u_n, cfl=0.5, kappa_min=0.0)
    new, _ = transport.step_stacked(phi, u_n, dt)
    assert new.min() >= -1e-14


# -------------------------------------------------------------------- redistribution rule

def redistribution_case(seed=0, n=12):
    mesh = cylinder_grid(n, n, 0.01, jitter=0.3, seed=seed)
    rng = np.random.default_rng(seed)
    kappa = np.where(rng.random(mesh.numberOfCells) < 0.2, 0.3 + 0.7 * rng.random(
        mesh.numberOfCells), 1.0)
    transport = Transport(mesh, kappa, np.ones(mesh.numberOfFaces), None, ["a"])
    return mesh, transport, transport.geometry


def test_redistribution_leaves_bounded_fields_alone():
    _, transport, geom = redistribution_case()
    alpha = np.random.default_rng(1).random(geom.n_cells)
    new, moved = transport.redistribute_overshoot(alpha)
    assert moved.moved == 0 and np.array_equal(new, alpha)


def test_redistribution_of_excess_and_deficit_conserves_and_bounds():
    mesh, transport, geom = redistribution_case(seed=2)
    rng = np.random.default_rng(3)
    alpha = 0.5 * rng.random(geom.n_cells)
    over = rng.choice(geom.n_cells, 15, replace=False)
    alpha[over] = 1.0 + 0.5 * rng.random(15)                  # excess, room around
    alpha[:3] = -0.05                                        # deficits next to material
    tracer = np.zeros(geom.n_cells)
    tracer[over] = 1.0
    q = alpha * tracer                                       # alpha-weighted marker of donors
    kappa_volume = geom.kappa * geom.cell_volume
    new, moved = transport.redistribute_overshoot(alpha)
    assert new.min() >= -1e-14 and new.max() <= 1.0 + 1e-14
    assert abs((new - alpha) @ kappa_volume) < 1e-14 * (np.abs(alpha) @ kappa_volume)
    q_new = transport.apply_redistribution(q, moved)
    assert abs((q_new - q) @ kappa_volume) < 1e-14 * (q @ kappa_volume)
    assert np.all(q_new <= new + 1e-14) and q_new.min() >= 0.0   # ratio of moved material kept
    # the plain function on the pairs of open faces gives the same alpha
    pairs, _ = open_neighbour_pairs(geom)
    plain, _ = redistribute_overshoot(alpha, geom.kappa, geom.cell_volume, pairs)
    assert np.array_equal(plain, new)
    # the same passes applied to alpha reproduce the redistributed alpha
    assert np.allclose(transport.apply_redistribution(alpha, moved), new, rtol=0, atol=1e-14)
    # face transfers: alpha moved across faces accounts for every cell's change
    geom_ = transport.geometry
    flux = moved.face_flux
    divergence = (np.bincount(geom_.face_cell_1, flux, geom_.n_cells)
                  - np.bincount(geom_.face_cell_2[geom_.interior], flux[geom_.interior],
                                geom_.n_cells))
    assert np.allclose((new - alpha) * kappa_volume, -divergence, rtol=0,
                       atol=1e-15 * (np.abs(alpha) @ kappa_volume))


def test_boxed_in_excess_travels_through_packed_material():
    """Excess in the middle of a packed region reaches the free surface in one call."""
    mesh, transport, geom = redistribution_case(seed=4, n=16)
    r, z = np.asarray(mesh.cellCenters)
    alpha = np.where(z < 0.1, 1.0, 0.0)
    alpha[np.argmin((r - 0.08) ** 2 + (z - 0.02) ** 2)] = 1.5  # deep inside the packing
    new, moved = transport.redistribute_overshoot(alpha)
    kappa_volume = geom.kappa * geom.cell_volume
    assert new.max() <= 1.0 + 1e-14 and new.min() >= 0.0
    assert abs((new - alpha) @ kappa_volume) < 1e-14 * (alpha @ kappa_volume)
    assert np.all(new[z > 0.11] == 0.0) and np.any(new[(z > 0.1) & (z < 0.11)] > 0.0)


def test_redistribution_never_clips_mass_without_room():
    """Everything overfull and no room anywhere: nothing is destroyed, the excess is reported."""
    _, transport, geom = redistribution_case(seed=5, n=6)
    alpha = np.full(geom.n_cells, 1.1)
    new, moved = transport.redistribute_overshoot(alpha)
    kappa_volume = geom.kappa * geom.cell_volume
    assert abs((new - alpha) @ kappa_volume) < 1e-14 * (alpha @ kappa_volume)
    assert moved.residual_excess == pytest.approx(0.1 * kappa_volume.sum(), rel=1e-12)


def test_deficit_among_empty_cells_is_filled_from_the_nearest_material():
    mesh, transport, geom = redistribution_case(seed=6, n=10)
    r, z = np.asarray(mesh.cellCenters)
    alpha = np.where(z > 0.07, 0.8, 0.0)
    alpha[np.argmin((r - 0.05) ** 2 + (z - 0.01) ** 2)] = -0.01  # far from any material
    new, moved = transport.redistribute_overshoot(alpha)
    kappa_volume = geom.kappa * geom.cell_volume
    assert new.min() >= -1e-14
    assert abs((new - alpha) @ kappa_volume) < 1e-14 * (np.abs(alpha) @ kappa_volume)


# ------------------------------------------- compiled redistribution against the numpy rule

def compacted_case(seed, n=16, deep=False, deficits=True):
    """Cut cells, a packed bed with micro-voids, an overfull band (at its surface or boxed in
    below it), deficits among empty cells and next to material, six alpha-weighted fields."""
    mesh, transport, geom = redistribution_case(seed=seed, n=n)
    rng = np.random.default_rng(seed + 100)
    r, z = np.asarray(mesh.cellCenters)
    n_cells = geom.n_cells
    alpha = np.where(z < 0.6 * z.max(), 1.0, 0.0)
    packed = alpha > 0
    voids = packed & (rng.random(n_cells) < 0.5)
    alpha[voids] -= 10.0 ** rng.uniform(-6, -3, voids.sum())
    top = z[packed].max()
    band = packed & (rng.random(n_cells) < 0.6) & (
        (z < top - 0.04) & (z > top - 0.07) if deep else (z > top - 0.03))
    alpha[band] *= 1.0 + 10.0 ** rng.uniform(-4, -1, band.sum())
    if deficits:
        empty = ~packed
        alpha[empty & (rng.random(n_cells) < 0.1)] = -1e-3 * rng.random()
    ratios = np.stack([np.sin(7 * r + k) + 2.0 * np.cos(3 * z * k) for k in range(6)])
    fields = np.ascontiguousarray(np.vstack([alpha[None], alpha * ratios]))
    return transport, geom, fields


def face_divergence(geom, flux):
    return (np.bincount(geom.face_cell_1, flux, geom.n_cells)
            - np.bincount(geom.face_cell_2[geom.interior], flux[geom.interior], geom.n_cells))


@pytest.mark.parametrize("room_min", [1e-6, 1e-3])
@pytest.mark.parametrize("seed,deep", [(0, False), (1, True), (2, False), (3, True)])
def test_compiled_redistribution_equals_numpy_rule(seed, deep, room_min):
    """The compiled kernel (transfer by transfer) and the numpy form of the rule (whole-array
    passes) give the same alpha, fields, face transfers, sweeps and residuals to round-off;
    the one-call in-place form equals the two calls exactly."""
    transport, geom, fields = compacted_case(seed, deep=deep)
    kappa_volume = geom.kappa * geom.cell_volume
    alpha_ref, ref = transport.redistribute_overshoot(fields[0], room_min=room_min,
                                                      backend="numpy")
    alpha_new, moved = transport.redistribute_overshoot(fields[0], room_min=room_min)
    scale = np.abs(fields) @ kappa_volume
    assert moved.sweeps == ref.sweeps >= 1 and moved.moved > 50
    assert np.max(np.abs(alpha_new - alpha_ref)) < 1e-12
    assert np.max(np.abs(moved.face_flux - ref.face_flux)) < 1e-12 * scale[0]
    assert moved.residual_excess == pytest.approx(ref.residual_excess, rel=1e-9, abs=1e-15)
    assert moved.residual_deficit == pytest.approx(ref.residual_deficit, rel=1e-9, abs=1e-15)
    q_ref = ref.apply(fields, kappa_volume)
    q_new = transport.apply_redistribution(fields, moved)
    for k in range(1, fields.shape[0]):
        assert np.max(np.abs(q_new[k] - q_ref[k])) < 1e-11 * np.max(np.abs(fields[k]))
    # one call, in place: the same numbers as the two calls
    work = fields.copy()
    once = transport.redistribute_fields(work, room_min=room_min)
    assert np.array_equal(work[0], alpha_new) and np.array_equal(work[1:], q_new[1:])
    assert np.array_equal(once.face_flux, moved.face_flux) and once.moved == moved.moved
    # the plain function with the fields, compiled and numpy form
    pairs, faces = open_neighbour_pairs(geom)
    for backend in ("numba", "numpy"):
        work = fields[1:].copy()
        plain, _ = redistribute_overshoot(fields[0], geom.kappa, geom.cell_volume, pairs,
                                          faces=faces, n_faces=geom.n_faces,
                                          room_min=room_min, fields=work, backend=backend)
        assert np.max(np.abs(plain - alpha_new)) < 1e-12
        assert np.max(np.abs(work - q_new[1:])) < 1e-11 * np.max(np.abs(fields[1:]))


@pytest.mark.parametrize("room_min", [1e-6, 1e-3])
@pytest.mark.parametrize("seed,deep", [(4, False), (5, True)])
def test_redistributed_fields_are_conserved_bounded_and_mixed(seed, deep, room_min):
    """In place on seven fields: every field's total conserved to round-off, alpha in
    [0, 1] (no residual), face transfers account for every cell's change of alpha, cells not
    taking part keep their values exactly, and with excess only the moved material keeps its
    donors' field ratios (every cell's ``q / alpha`` stays within the range it had)."""
    transport, geom, fields = compacted_case(seed, deep=deep)
    kappa_volume = geom.kappa * geom.cell_volume
    work = fields.copy()
    moved = transport.redistribute_fields(work, room_min=room_min)
    assert moved.residual_excess == 0.0 and moved.residual_deficit == 0.0
    assert work[0].max() <= 1.0 + 1e-14 and work[0].min() >= -1e-14
    scale = np.abs(fields) @ kappa_volume
    assert np.all(np.abs((work - fields) @ kappa_volume) < 1e-14 * scale)
    change = (work[0] - fields[0]) * kappa_volume
    assert np.max(np.abs(change + face_divergence(geom, moved.face_flux))) < 1e-15 * scale[0]
    taking_part = np.zeros(geom.n_cells, dtype=bool)
    taking_part[moved.donor] = taking_part[moved.receiver] = True
    assert np.array_equal(work[:, ~taking_part], fields[:, ~taking_part])
    # excess only: mixtures of the donors' ratios
    transport, geom, fields = compacted_case(seed, deep=deep, deficits=False)
    work = fields.copy()
    transport.redistribute_fields(work, room_min=room_min)
    held = work[0] > 1e-9
    ratio_before = fields[1:, fields[0] > 1e-9] / fields[0, fields[0] > 1e-9]
    ratio_after = work[1:, held] / work[0, held]
    assert np.all(ratio_after >= ratio_before.min(1, keepdims=True) - 1e-9)
    assert np.all(ratio_after <= ratio_before.max(1, keepdims=True) + 1e-9)


def test_redistribution_log_replays_as_simultaneous_passes():
    """``Redistribution.apply`` (compiled replay of the donor groups) equals replaying the
    log's ``passes`` the way the numpy form moves content (``np.add.at`` per pass), and the
    log reproduces alpha itself."""
    transport, geom, fields = compacted_case(7, deep=True)
    kappa_volume = geom.kappa * geom.cell_volume
    alpha, moved = transport.redistribute_overshoot(fields[0])
    content = fields * kappa_volume
    touched = np.zeros(geom.n_cells, dtype=bool)
    for donor, receiver, fraction in moved.passes:
        touched[donor] = touched[receiver] = True
        for row in content:
            amount = fraction * row[donor]
            np.subtract.at(row, donor, amount)
            np.add.at(row, receiver, amount)
    replayed = np.divide(content, kappa_volume, out=fields.copy(),
                         where=touched & (kappa_volume > 0))
    applied = transport.apply_redistribution(fields, moved)
    assert np.max(np.abs(applied - replayed) / (np.abs(fields).max(1, keepdims=True))) < 1e-13
    assert np.max(np.abs(applied[0] - alpha)) < 1e-13
    # in place through ``out``
    out = fields.copy()
    assert transport.apply_redistribution(out, moved, out=out) is out
    assert np.array_equal(out, applied)


def test_bounded_fields_return_at_once_untouched():
    _, transport, geom = redistribution_case(seed=8)
    rng = np.random.default_rng(8)
    fields = np.ascontiguousarray(rng.random((7, geom.n_cells)))
    fields[0, :5] = [0.0, 1.0, 1.0 + 1e-15, -1e-15, 0.5]        # within tol of the bounds
    work = fields.copy()
    moved = transport.redistribute_fields(work)
    assert moved.moved == 0 and moved.sweeps == 0 and np.array_equal(work, fields)
    assert np.array_equal(moved.face_flux, np.zeros(geom.n_faces))
    with pytest.raises(ValueError):
        transport.redistribute_fields(np.asfortranarray(fields))


def test_room_min_sends_boxed_in_excess_past_micro_voids():
    """A larger ``room_min`` converges where the default needs more sweeps: boxed-in excess
    goes past micro-voids to cells with real room (here the free surface)."""
    transport, geom, fields = compacted_case(9, n=20, deep=True, deficits=False)
    slow = transport.redistribute_fields(fields.copy())
    fast = transport.redistribute_fields(fields.copy(), room_min=1e-3)
    assert fast.residual_excess == 0.0 and fast.sweeps < slow.sweeps


def test_redistribution_scratch_is_reused_and_its_log_grows():
    """The compiled kernel keeps its scratch with the graph: a second call gives the same
    numbers, also when the kept log arrays are too short and grow during the call."""
    transport, geom, fields = compacted_case(1, n=24, deep=True)
    first = fields.copy()
    moved = transport.redistribute_fields(first)
    work = transport.neighbours().work
    work.log = (np.empty(1, dtype=np.int64), np.zeros(2, dtype=np.int64),
                np.empty(1, dtype=np.int64), np.empty(1))
    again = fields.copy()
    moved_again = transport.redistribute_fields(again)
    assert np.array_equal(again, first) and work.log[2].size > moved.moved
    for name in ("donor", "offsets", "receiver", "fraction", "face_flux"):
        assert np.array_equal(getattr(moved_again, name), getattr(moved, name))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_first_level_of_the_search_is_found_in_the_order_of_a_search_from_every_seed(seed):
    """``_level_one`` lists the cells a breadth-first search from every seed (taken in index
    order) reaches in one hop, in the order it reaches them, without visiting the seeds: the
    order decides the order of the hop transfers, hence their round-off."""
    _, geom, _ = compacted_case(seed, n=24)
    rng = np.random.default_rng(seed)
    n = geom.n_cells
    pairs, _ = open_neighbour_pairs(geom)       # shuffled: edges not in order of neighbour
    graph = redistribution.NeighbourGraph(pairs[:, rng.permutation(pairs.shape[1])], n)
    is_open = geom.kappa * geom.cell_volume > 0.0
    hops = np.where(is_open & (rng.random(n) < 0.5), 0, -1).astype(np.int64)
    seed_next_door = np.array([np.any(hops[graph.neighbour[graph.indptr[i]:graph.indptr[i + 1]]]
                                      == 0) for i in range(n)])
    others = np.flatnonzero(is_open & (hops == -1))
    in_need = others[rng.random(others.size) < 0.3]
    full_cells = np.setdiff1d(others, in_need)
    hops[in_need[~seed_next_door[in_need]]] = -2          # boxed in: no seed next door
    # the search as written out: every seed in index order, its edges in order
    expected, seen = [], hops.copy()
    for x in np.flatnonzero(hops == 0):
        for y in graph.neighbour[graph.indptr[x]:graph.indptr[x + 1]]:
            if seen[y] < 0 and is_open[y]:
                seen[y] = 1
                expected.append(y)
    queue = np.full(n, -1, dtype=np.int64)
    work = hops.copy()
    found = redistribution._level_one(work, in_need, in_need.size, full_cells,
                                      full_cells.size, graph.indptr, graph.neighbour, queue)
    assert found == len(expected) > 20
    assert np.array_equal(queue[:found], expected)
    assert np.array_equal(work, seen)
