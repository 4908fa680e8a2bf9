"""Cost of one transport step of six fields (alpha and five alpha-weighted fields).

Run the measurement with ``.venv/bin/pytest tests/benchmarks/test_bench_transport.py
--benchmark-only -o addopts="" -p no:cacheprovider``;
the default test command runs each benchmark once on a small mesh (``--benchmark-disable``).
Sizes: ~5,000 cells (70 x 71, the 5 mm reference hopper) and ~20,000 cells (141 x 142).
"""

import numpy as np
import pytest
from fipy import CylindricalGrid2D

from fipy_hopper.transport import FiPyTransport, Transport

FIELDS = ("alpha", "s_rr", "s_zz", "s_tt", "s_rz", "eps_p")
SIZES = {"5k": (70, 71), "20k": (141, 142)}
SMALL = (12, 10)
H = 0.005


def case(benchmark, size, seed=0):
    """Mesh, cut cells at a sloped wall, outflow faces, a smooth flow and smooth fields."""
    nr, nz = SMALL if benchmark.disabled else SIZES[size]
    mesh = CylindricalGrid2D(dx=np.full(nr, H), dy=np.full(nz, H), origin=((0.0,), (-0.05,)))
    r, z = np.asarray(mesh.cellCenters)
    r_face, z_face = np.asarray(mesh.faceCenters)
    normal = np.asarray(mesh.faceNormals)
    z_bottom, radius = -0.05, nr * H
    wall = lambda rr: z_bottom + 0.5 * (rr - 0.3 * radius)    # a cone wall: solid below
    kappa = np.clip((z - wall(r)) / H + 0.5, 0.0, 1.0)
    aperture = np.clip((z_face - wall(r_face)) / H + 0.5, 0.0, 1.0)
    exterior = np.asarray(mesh.exteriorFaces.value)
    outflow = exterior & (z_face < z_face.min() + 1e-9) & (r_face < 0.2 * radius)
    u_n = (-0.5 - 0.2 * np.cos(r_face / radius)) * normal[1] + 0.1 * np.sin(z_face) * normal[0]
    u_n[outflow] = np.abs(u_n[outflow])
    alpha = np.where(z > z_bottom + 0.7 * nz * H, 0.0, 1.0) * (kappa > 0)  # filled to 70 %
    stress = -1e3 * (1.0 + np.sin(5 * r / (nr * H)) * np.cos(3 * z / (nz * H)))
    phi = np.stack([alpha] + [alpha * stress * (1 + 0.1 * k) for k in range(4)]
                   + [alpha * np.abs(np.sin(r + z))])
    return mesh, kappa, aperture, outflow, u_n, phi


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_numba_step(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    out = (np.empty_like(phi), np.empty((len(FIELDS), mesh.numberOfFaces)))
    transport.step_stacked(phi, u_n, dt, out=out)            # compile / load the cache
    benchmark(transport.step_stacked, phi, u_n, dt, out=out)
    assert np.all(np.isfinite(out[0]))


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_numba_step_allocating(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    transport.step_stacked(phi, u_n, dt)
    new, _ = benchmark(transport.step_stacked, phi, u_n, dt)
    assert np.all(np.isfinite(new))


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_numpy_step(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS, backend="numpy")
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    new, _ = benchmark(transport.step_stacked, phi, u_n, dt)
    assert np.all(np.isfinite(new))


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_fipy_reference_step(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    reference = FiPyTransport(mesh, kappa, aperture, outflow, FIELDS)
    fields = dict(zip(FIELDS, phi))
    dt = Transport(mesh, kappa, aperture, outflow, FIELDS).max_stable_dt(u_n, cfl=0.5)
    reference.step(fields, u_n, dt)                           # FiPy builds its matrices
    new, _ = benchmark.pedantic(reference.step, args=(fields, u_n, dt), rounds=5,
                                iterations=1)
    assert np.all(np.isfinite(new["alpha"]))


@pytest.mark.parametrize("depth", ["surface", "deep"])
@pytest.mark.parametrize("size", list(SIZES))
def test_bench_redistribute_overshoot(benchmark, size, depth):
    """Compaction: packed material 2 % overfull in three rows just below its free surface
    (room next door) or ten rows deep (boxed in: the excess travels up through packing)."""
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    r, z = np.asarray(mesh.cellCenters)
    surface = z[phi[0] > 0].max() + 0.5 * H
    below = (3 if depth == "surface" else 13) * H
    band = (z < surface - below + 3 * H) & (z > surface - below)
    alpha = phi[0] * np.where(band, 1.02, 1.0)
    transport.redistribute_overshoot(alpha)
    new, moved = benchmark(transport.redistribute_overshoot, alpha)
    assert new.max() <= 1.0 + 1e-12 and moved.residual_excess == 0.0


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_max_stable_dt(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    dt = benchmark(transport.max_stable_dt, u_n, 0.5)
    assert np.isfinite(dt) and dt > 0
