"""The contact of a node at a wall corner (fipy_hopper.stepping._contact_node and its numpy
twin fipy_hopper.momentum.contact_nodes) on constructed corners: the compiled contact equals
the numpy reference to the bit; each wall's impulse lies in its own Coulomb cone; the
velocity after it presses into neither wall and the node loses speed; a node the corner
holds shares its impulse by the walls' lengths with the same friction mobilised on both;
without friction it is the closest velocity that presses into neither wall."""

import math

import numpy as np
import pytest

from fipy_hopper import momentum, stepping


def corner(interior_deg):
    """The unit normals (into the walls) of a concave corner at the origin of the given
    interior angle: wall ``a`` a floor running to -r (material above it), wall ``b`` rising
    from the corner at ``interior_deg`` from the floor through the material."""
    n_a = np.array([0.0, -1.0])
    angle = math.radians(180.0 - interior_deg)             # direction of wall b
    d_b = np.array([math.cos(angle), math.sin(angle)])
    n_b = np.array([d_b[1], -d_b[0]])                      # clockwise: away from material
    return n_a, n_b


def groups_of(n_nodes, n_a, n_b, mu_a, mu_b, w_a=0.5, w_b=0.5):
    """Contact groups of ``n_nodes`` nodes (one row), each held by the two walls."""
    node_ptr = np.arange(0, 2 * n_nodes + 1, 2, dtype=np.int64)
    normal = np.tile(np.array([[*n_a, w_a], [*n_b, w_b]]), (n_nodes, 1))
    mu = np.tile([mu_a, mu_b], n_nodes).astype(float)
    kind = np.zeros(2 * n_nodes, dtype=np.int8)
    entry = np.arange(2 * n_nodes, dtype=np.int64)
    return (np.array([0, n_nodes], dtype=np.int64), np.zeros(n_nodes, dtype=np.int64),
            np.arange(n_nodes, dtype=np.int64), node_ptr, np.ascontiguousarray(normal), mu,
            kind, entry)


def both(v, mass, groups):
    """The compiled contact, node by node, and the numpy reference: velocities and
    impulses of each."""
    _, node_j, node_i, node_ptr, normal, mu, kind, entry = groups
    n_entries = len(kind)
    plate = np.zeros((1, 2))
    fast_v, fast_j = v.copy(), np.zeros((n_entries, 2))
    for q in range(len(node_j)):
        stepping._contact_node(fast_v, node_j[q], node_i[q], mass, node_ptr[q],
                               node_ptr[q + 1], normal, mu, kind, entry, True, fast_j, plate)
    ref_v, ref_j = v.copy(), np.zeros((n_entries, 2))
    momentum.contact_nodes(ref_v, mass, groups, True, ref_j, plate.copy())
    return (fast_v, fast_j), (ref_v, ref_j)


def random_velocities(n, seed):
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.0, 2.0 * math.pi, n)
    speed = 10.0 ** rng.uniform(-3.0, 0.0, n)
    v = np.zeros((2, 1, n))
    v[0, 0], v[1, 0] = speed * np.cos(angle), speed * np.sin(angle)
    mass = rng.uniform(0.5, 2.0, size=(1, n))
    return v, mass


CASES = [(90.0, 0.3, 0.3), (120.0, 0.27, 0.4), (160.0, 0.268, 0.268)]


@pytest.mark.parametrize("interior, mu_a, mu_b", CASES, ids=["90", "120", "160"])
def test_a_corner_shares_its_impulse_inside_both_cones(interior, mu_a, mu_b):
    """2,000 nodes at a 90, 120 and 160 deg corner (the last: the reference hopper's
    transition) with friction, velocities in every direction: the compiled contact equals
    the numpy reference to the bit; every wall's impulse pushes out of it and lies inside its
    Coulomb cone (|J_t| <= mu J_n, in that wall's frame); the impulses add up to m dv; the new
    velocity presses into neither wall and is no faster than the old one.  The rule's
    outcomes occur: free, held by the corner; at the 160 deg corner every slide has both
    walls' friction, at 90 and 120 deg none (the other wall's normal would push the node
    along its slide: it slides on one wall alone)."""
    n_a, n_b = corner(interior)
    n = 2000
    v, mass = random_velocities(n, seed=int(interior))
    groups = groups_of(n, n_a, n_b, mu_a, mu_b, w_a=0.45, w_b=0.55)
    (fast_v, fast_j), (ref_v, ref_j) = both(v, mass, groups)
    assert np.array_equal(fast_v, ref_v)
    assert np.array_equal(fast_j, ref_j)
    new, old = fast_v[:, 0].T, v[:, 0].T                          # (n, 2)
    J = fast_j.reshape(n, 2, 2)                                   # node, wall, component
    scale = mass[0] * np.hypot(old[:, 0], old[:, 1])
    np.testing.assert_allclose(J.sum(axis=1), mass[0][:, None] * (new - old), rtol=0,
                               atol=1e-13 * scale.max())
    for k, (n_k, mu_k) in enumerate(((n_a, mu_a), (n_b, mu_b))):
        t_k = np.array([-n_k[1], n_k[0]])
        j_n, j_t = -(J[:, k] @ n_k), J[:, k] @ t_k
        assert np.all(j_n >= -1e-13 * scale)
        assert np.all(np.abs(j_t) <= mu_k * j_n + 1e-12 * scale)
        assert np.all(new @ n_k <= 1e-13 * scale / mass[0])
    assert np.all(np.hypot(new[:, 0], new[:, 1]) <= np.hypot(old[:, 0], old[:, 1]) * (1 + 1e-12))
    held = np.all(new == 0.0, axis=1)
    shared = np.all(np.abs(J).sum(axis=2) > 0, axis=1)
    free = np.all(new == old, axis=1)
    assert np.count_nonzero(held & shared) > 50                  # 2: held by the corner
    assert np.count_nonzero(~held & shared) > (20 if interior > 150 else -1)   # 3: slides
    assert np.count_nonzero(~held & ~shared & ~free) > (50 if interior < 150 else -1)  # 4
    assert np.count_nonzero(free) > 50                           # 1: free


@pytest.mark.parametrize("interior, mu_a, mu_b", CASES, ids=["90", "120", "160"])
def test_a_node_the_corner_holds_shares_by_length_with_friction_alike(interior, mu_a, mu_b):
    """A node pressed into the corner along the bisector of the two walls' normals stops;
    the normal impulses are in the ratio of the walls' lengths (0.45 : 0.55) and each wall's
    friction is the same fraction of its Coulomb limit."""
    n_a, n_b = corner(interior)
    bisector = (n_a + n_b) / np.linalg.norm(n_a + n_b)
    v = np.zeros((2, 1, 1))
    v[:, 0, 0] = 0.02 * bisector + 0.001 * np.array([-bisector[1], bisector[0]])
    mass = np.array([[1.5]])
    groups = groups_of(1, n_a, n_b, mu_a, mu_b, w_a=0.45, w_b=0.55)
    (fast_v, fast_j), (ref_v, ref_j) = both(v, mass, groups)
    assert np.array_equal(fast_j, ref_j) and np.array_equal(fast_v, ref_v)
    assert np.all(fast_v == 0.0)
    shares = []
    for k, (n_k, mu_k) in enumerate(((n_a, mu_a), (n_b, mu_b))):
        t_k = np.array([-n_k[1], n_k[0]])
        shares.append((-(fast_j[k] @ n_k), fast_j[k] @ t_k / mu_k))
    (na_, fa), (nb_, fb) = shares
    assert na_ / nb_ == pytest.approx(0.45 / 0.55, rel=1e-12)
    assert fa / na_ == pytest.approx(fb / nb_, rel=1e-9, abs=1e-12)
    assert abs(fa / na_) < 1.0


def closest_feasible(v, n_a, n_b):
    """The velocity closest to ``v`` that presses into neither wall (the projection onto the
    cone ``w . n_a <= 0``, ``w . n_b <= 0``), from the candidates: ``v``, its projections
    onto each wall's line, and rest."""
    candidates = [v, v - (v @ n_a) * n_a, v - (v @ n_b) * n_b, np.zeros(2)]
    feasible = [c for c in candidates if c @ n_a <= 1e-15 and c @ n_b <= 1e-15]
    return min(feasible, key=lambda c: np.linalg.norm(c - v))


@pytest.mark.parametrize("interior", [90.0, 120.0, 160.0])
def test_without_friction_the_corner_gives_the_closest_feasible_velocity(interior):
    """Frictionless walls: the velocity after the contact is the closest to the free one
    that presses into neither wall, and the impulses are normal to their walls."""
    n_a, n_b = corner(interior)
    n = 500
    v, mass = random_velocities(n, seed=7)
    groups = groups_of(n, n_a, n_b, 0.0, 0.0)
    (fast_v, fast_j), (ref_v, ref_j) = both(v, mass, groups)
    assert np.array_equal(fast_v, ref_v) and np.array_equal(fast_j, ref_j)
    for q in range(n):
        want = closest_feasible(v[:, 0, q], n_a, n_b)
        np.testing.assert_allclose(fast_v[:, 0, q], want, rtol=0, atol=1e-15)
    J = fast_j.reshape(n, 2, 2)
    for k, n_k in enumerate((n_a, n_b)):
        assert np.all(np.abs(J[:, k] @ np.array([-n_k[1], n_k[0]])) <= 1e-15)
