"""Cost of one transport step of six fields (alpha and five alpha-weighted fields).

Run the measurement with ``.venv/bin/pytest tests/benchmarks/test_bench_transport.py
--benchmark-only -o addopts="" -p no:cacheprovider``;
the default test command runs each benchmark once on a small mesh (``--benchmark-disable``).
Sizes: ~5,000 cells (70 x 71, the 5 mm reference hopper) and ~20,000 cells (141 x 142).

The redistribution benchmarks (``-k redistrib``) include the hopper's own use: seven stacked
fields (alpha and six alpha-weighted ones) on the 5,000-cell grid with a compacted band,
redistributed and moved in one call (``redistribute_fields``) or in the two calls of the model
(``redistribute_overshoot`` + ``apply_redistribution``), compiled and with the numpy reference.
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


def relative_difference(a, b) -> float:
    """``max |a - b| / max |b|`` (0 when both vanish)."""
    scale = float(np.max(np.abs(b)))
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) / scale if scale else 0.0


def assert_equals_numpy_reference(new, mesh, kappa, aperture, outflow, u_n, phi, dt):
    """The measured compiled step equals the numpy reference step (to round-off)."""
    reference, _ = Transport(mesh, kappa, aperture, outflow, FIELDS,
                             backend="numpy").step_stacked(phi, u_n, dt)
    assert relative_difference(new, reference) < 1e-12


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_numba_step(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    out = (np.empty_like(phi), np.empty((len(FIELDS), mesh.numberOfFaces)))
    transport.step_stacked(phi, u_n, dt, out=out)            # compile / load the cache
    benchmark(transport.step_stacked, phi, u_n, dt, out=out)
    assert_equals_numpy_reference(out[0], mesh, kappa, aperture, outflow, u_n, phi, dt)


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_numba_step_allocating(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    transport.step_stacked(phi, u_n, dt)
    new, _ = benchmark(transport.step_stacked, phi, u_n, dt)
    assert_equals_numpy_reference(new, mesh, kappa, aperture, outflow, u_n, phi, dt)


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_numpy_step(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS, backend="numpy")
    dt = transport.max_stable_dt(u_n, cfl=0.5)
    new, _ = benchmark(transport.step_stacked, phi, u_n, dt)
    compiled, _ = Transport(mesh, kappa, aperture, outflow, FIELDS).step_stacked(phi, u_n, dt)
    assert relative_difference(new, compiled) < 1e-12


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_fipy_reference_step(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    reference = FiPyTransport(mesh, kappa, aperture, outflow, FIELDS)
    fields = dict(zip(FIELDS, phi))
    dt = Transport(mesh, kappa, aperture, outflow, FIELDS).max_stable_dt(u_n, cfl=0.5)
    reference.step(fields, u_n, dt)                           # FiPy builds its matrices
    new, _ = benchmark.pedantic(reference.step, args=(fields, u_n, dt), rounds=5,
                                iterations=1)
    compiled, _ = Transport(mesh, kappa, aperture, outflow, FIELDS).step_stacked(phi, u_n, dt)
    for k, name in enumerate(FIELDS):                          # FiPy's solve is the definition
        assert relative_difference(compiled[k], new[name]) < 1e-12, name


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


HOPPER_FIELDS = ("alpha", "s_rr", "s_zz", "s_tt", "s_rz", "eps_p", "layer")


def compacted_hopper(benchmark, depth, seed=0):
    """The 5k grid of ``case`` filled to 70 %, compacted as transport compacts the hopper.

    The packing is not quite full: half of its cells are short by 1e-6..1e-3 (log-uniform),
    as in the hopper's packed material (micro-voids).  A band four rows deep of packed cells,
    60 % of them overfull by 1e-4..1e-2 (log-uniform, ~170 cells), lies at the free surface
    (``"surface"``: room next door) or ten rows below it (``"deep"``: boxed in, the excess
    travels hop by hop); 2 % of the empty cells are 1e-12 below zero.  Returns the transport
    (axisymmetric scheme, as the hopper) and the seven stacked fields (alpha, alpha * stress
    (4), alpha * plastic strain, alpha * layer).
    """
    mesh, kappa, aperture, outflow, _, _ = case(benchmark, "5k")
    transport = Transport(mesh, kappa, aperture, outflow, HOPPER_FIELDS, scheme="axisymmetric")
    rng = np.random.default_rng(seed)
    r, z = np.asarray(mesh.cellCenters)
    n, nz = mesh.numberOfCells, mesh.shape[1]
    alpha = np.where(z > -0.05 + 0.7 * nz * H, 0.0, 1.0) * (kappa > 0)
    packed = alpha > 0
    voids = packed & (rng.random(n) < 0.5)
    alpha[voids] -= 10.0 ** rng.uniform(-6, -3, voids.sum())
    surface = z[packed].max() + 0.5 * H
    below = 0 if depth == "surface" else 10
    band = (packed & (z < surface - below * H) & (z > surface - (below + 4) * H)
            & (rng.random(n) < 0.6))
    alpha[band] *= 1.0 + 10.0 ** rng.uniform(-4, -2, band.sum())
    empty = (kappa > 0) & ~packed
    alpha[empty & (rng.random(n) < 0.02)] = -1e-12
    stress = -1e3 * (1.0 + np.sin(5 * r / 0.35) * np.cos(3 * z / 0.35))
    fields = np.stack([alpha] + [alpha * stress * (1 + 0.1 * k) for k in range(4)]
                      + [alpha * np.abs(np.sin(r + z)), alpha * np.floor(8 * (z + 0.05) / 0.25)])
    return transport, np.ascontiguousarray(fields)


def check_redistributed(benchmark, transport, before, after, moved):
    """Conserved, bounded where converged; the excess left (``residual_excess``: the default
    ``room_min`` needs more than its 50 sweeps in the ``deep`` case) goes to the report."""
    kappa_volume = transport.geometry.kappa * transport.geometry.cell_volume
    assert moved.moved > 0 and moved.residual_deficit == 0.0
    assert after[0].min() >= -1e-12
    if moved.residual_excess == 0.0:
        assert after[0].max() <= 1.0 + 1e-12
    totals = np.abs(before) @ kappa_volume
    assert np.all(np.abs((after - before) @ kappa_volume) <= 1e-12 * totals)
    benchmark.extra_info["residual_excess_of_total"] = moved.residual_excess / totals[0]


@pytest.mark.parametrize("room_min", [1e-6, 1e-3])
@pytest.mark.parametrize("depth", ["surface", "deep"])
def test_bench_redistribute_fields(benchmark, depth, room_min):
    """The hopper's call: alpha back into [0, 1] and six alpha-weighted fields moved with it,
    in place, face transfers summed (compiled, one call).  ``room_min``: the room (of kappa V)
    a cell needs to be a target of hop-by-hop transfers (1e-6: the default; 1e-3: boxed-in
    excess skips micro-voids, far fewer sweeps)."""
    transport, fields = compacted_hopper(benchmark, depth)
    work = fields.copy()
    transport.redistribute_fields(work, room_min=room_min)   # compile / load the cache

    def setup():
        work[...] = fields
        return (work,), {"room_min": room_min}

    moved = benchmark.pedantic(transport.redistribute_fields, setup=setup, rounds=300,
                               warmup_rounds=3)
    check_redistributed(benchmark, transport, fields, work, moved)
    benchmark.extra_info["transfers"] = moved.moved
    benchmark.extra_info["sweeps"] = moved.sweeps
    if room_min == 1e-3:
        assert moved.residual_excess == 0.0 and moved.sweeps <= 10


@pytest.mark.parametrize("backend", ["numba", "numpy"])
@pytest.mark.parametrize("depth", ["surface", "deep"])
def test_bench_redistribute_and_apply(benchmark, depth, backend):
    """The same in the model's two calls: ``redistribute_overshoot`` of alpha, then
    ``apply_redistribution`` of the seven fields; ``numpy``: the reference form of the rule."""
    transport, fields = compacted_hopper(benchmark, depth)
    options = {} if backend == "numba" else {"backend": "numpy"}

    def both():
        alpha, moved = transport.redistribute_overshoot(fields[0], **options)
        new = transport.apply_redistribution(fields, moved)
        new[0] = alpha
        return new, moved

    both()
    if backend == "numba":
        new, moved = benchmark(both)
    else:
        new, moved = benchmark.pedantic(both, rounds=5, iterations=1)
    check_redistributed(benchmark, transport, fields, new, moved)


@pytest.mark.parametrize("size", list(SIZES))
def test_bench_max_stable_dt(benchmark, size):
    mesh, kappa, aperture, outflow, u_n, phi = case(benchmark, size)
    transport = Transport(mesh, kappa, aperture, outflow, FIELDS)
    dt = benchmark(transport.max_stable_dt, u_n, 0.5)
    assert np.isfinite(dt) and dt > 0
