"""Transport of the 3D model (fipy_hopper.space.transport): the compiled kernel against the
numpy reference (bit for bit) and FiPy's VanLeerConvectionTerm on Grid3D, conservation and
bounds, on a coarse cut-cell silo."""

import numpy as np
import pytest

from fipy_hopper.space import momentum as sm
from fipy_hopper.space.boundary import SiloBoundary
from fipy_hopper.space.grid import build_grid
from fipy_hopper.space.transport import SpaceTransport
from fipy_hopper.transport import FiPyTransport, material_rows

WALL = ((0.06, 0.0), (0.14, 0.1), (0.14, 0.24))


@pytest.fixture(scope="module")
def case():
    """An eccentric silo's half on 2 cm cells, a smooth node velocity field (a swirl and a
    downward flow), its face velocities in FiPy's orientation, and alpha-weighted fields."""
    b = SiloBoundary.from_profile(WALL, 0.2, outlet_offset=0.03)
    g = build_grid(b, 0.02)
    Z, Y, X = np.meshgrid(g.z_nodes, g.y_nodes, g.x_nodes, indexing="ij")
    v = np.stack([-0.3 * Y + 0.1 * X, 0.3 * X, -0.5 - 0.2 * np.cos(8 * X) * (1 + Z)])
    v[1, :, 0, :] = 0.0                       # the mirror plane y = 0
    vz, vy, vx = sm.face_velocities(v)
    normals = np.asarray(g.mesh.faceNormals)
    nz_, ny_, _ = g.n_faces
    u_n = np.concatenate([vz.ravel() * normals[2, :nz_], vy.ravel() * normals[1, nz_:nz_ + ny_],
                          vx.ravel() * normals[0, nz_ + ny_:]])
    outflow = np.zeros(sum(g.n_faces), bool)
    outflow[:g.nx * g.ny] = g.outflow_z.ravel()
    rng = np.random.default_rng(4)
    alpha = np.where(g.kappa > 0, rng.uniform(0.3, 1.0, g.kappa.shape), 0.0)
    alpha[g.centres(2) > 0.18] = 0.0
    fields = np.stack([alpha.ravel(), (alpha * rng.normal(size=alpha.shape)).ravel(),
                       (alpha * -1e3).ravel()])
    return g, u_n, outflow, fields


def test_compiled_equals_numpy_to_the_bit(case):
    g, u_n, outflow, fields = case
    kw = dict(mesh=g.mesh, kappa=g.kappa.ravel(), aperture=g.face_aperture,
              outflow_faces=outflow)
    fast, ref = SpaceTransport(backend="numba", **kw), SpaceTransport(backend="numpy", **kw)
    dt = 0.2 * g.h / 1.0
    a, fa = fast.step_stacked(fields, u_n, dt)
    b, fb = ref.step_stacked(fields, u_n, dt)
    assert np.array_equal(a, b) and np.array_equal(fa, fb)
    rows = material_rows(fields[0].reshape(g.nz, g.ny * g.nx))
    assert rows[1] - rows[0] < g.nz
    c, fc = fast.step_stacked(fields, u_n, dt, rows=rows)
    assert np.array_equal(a, c) and np.array_equal(fa, fc)


def test_numpy_equals_fipy_definition(case):
    """The reference against FiPy's own equations (TransientTerm + VanLeerConvectionTerm on the
    Grid3D): the same numbers to 1e-12 (FiPy's sparse solve of the diagonal system)."""
    g, u_n, outflow, fields = case
    ref = SpaceTransport(g.mesh, g.kappa.ravel(), g.face_aperture, outflow, backend="numpy")
    names = ("alpha", "a", "b")
    fipy = FiPyTransport(g.mesh, g.kappa.ravel(), g.face_aperture, outflow, names,
                         scheme="fipy")
    dt = 0.2 * g.h
    new, flux = ref.step_stacked(fields, u_n, dt)
    defined, dflux = fipy.step(dict(zip(names, fields)), u_n, dt)
    for k, name in enumerate(names):
        scale = np.abs(fields[k]).max()
        assert np.allclose(new[k], defined[name], rtol=0, atol=1e-12 * scale)
        assert np.allclose(flux[k], dflux[name], rtol=0, atol=1e-12 * scale * g.h ** 3)


def test_mass_is_conserved_and_alpha_is_bounded_after_redistribution(case):
    """Ten steps: the open-volume content of alpha plus what left through the bottom is
    constant to 1e-12; after the redistribution alpha lies in [0, 1] to round-off and the
    content is unchanged."""
    g, u_n, outflow, fields = case
    tr = SpaceTransport(g.mesh, g.kappa.ravel(), g.face_aperture, outflow, backend="numba")
    vol = tr.kappa_volume
    phi = fields.copy()
    start = float(np.sum(phi[0] * vol))
    left = 0.0
    dt = 0.2 * g.h
    for _ in range(10):
        phi, flux = tr.step_stacked(phi, u_n, dt)
        left += float(np.sum(flux[0][outflow]))
        content = float(np.sum(phi[0] * vol))
        record = tr.redistribute_fields(phi)
        assert abs(float(np.sum(phi[0] * vol)) - content) <= 1e-13 * start
        assert phi[0].max() <= 1.0 + 1e-12 and phi[0].min() >= -1e-12
    assert abs(float(np.sum(phi[0] * vol)) + left - start) <= 1e-12 * start
    assert left > 0.0
