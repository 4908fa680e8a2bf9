"""The wall's traction recovered from its reaction, stretch by stretch of straight wall.

The wall's reaction is measured exactly: the contact impulses ``m dv`` at the wall's nodes
(per radian) add up to the force of every stretch of wall.  Its *distribution* along a wall
that cuts the cells is not a traction: which node carries how much of it is set by how the
wall cuts the cells next to it (a node behind the wall, a node just in front of it, a cell
95 % or 5 % open), a pattern that repeats along the wall every few cells.  Dividing each
node's force by a wall area of its own turns that pattern into a profile that scatters by
30 % from bin to bin and does not improve under refinement (docs/physics_and_numerics.md,
section 8).

Recovery on one straight stretch (a segment between two corners), arc length ``s`` in
``[s_a, s_b]``: the traction is a clamped cubic B-spline ``t(s) = sum_k t_k B_k(s)`` on knots
spaced about the wall's bin width ``w``.  The basis is a partition of unity
(``sum_k B_k = 1``, ``B_k >= 0``); each node's force ``f_e`` is shared among the basis
functions by their values at the node's wall point ``s_e``, and each coefficient is its
share over the wall area of its basis function::

    t_k = sum_e B_k(s_e) f_e / A_k,    A_k = int B_k(s) c(s) ds,

with ``c = r`` (per radian) on an axisymmetric wall, 1 on a plane one.  Hence
``int t c ds = sum_k t_k A_k = sum_e f_e``: the recovered traction carries the stretch's
reaction exactly, and each component (normal and shear) separately.  The weights are
positive, so a node force that obeys Coulomb (``|f_t| <= mu f_n``) gives a traction that
obeys it at every point.  The spline averages the cut pattern over ``4 w`` of wall (its
support) and resolves the traction at the scale ``w``: with ``w`` fixed in metres, finer
cells put more nodes under each basis function and the profile converges bin by bin.

Bins: each stretch is divided into equal bins of about ``w``; a bin's value is the mean
traction over its wall area, ``int_bin t c ds / int_bin c ds``.  Beside it, for checking,
the *raw* bin value: the forces of the nodes whose wall points fall in the bin over its area.

Everything here is linear in the forces: one sparse matrix per stretch (bins x entries),
built once per geometry; a window's profile is one product.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.interpolate import BSpline

from .boundary import Segment

#: degree of the traction's B-spline (cubic: support 4 knot spans, C2)
DEGREE = 3
#: Gauss-Legendre points per knot span and bin piece: exact for the degree-4 integrands
#: ``B_k(s) c(s)`` (cubic times linear)
_GAUSS = np.polynomial.legendre.leggauss(3)


def bin_edges(stretch: Segment, width: float) -> np.ndarray:
    """Edges (m of arc length) of the stretch's equal bins of about ``width`` m (at least
    one)."""
    n = max(1, int(round(stretch.length / width)))
    return np.linspace(stretch.s_start, stretch.s_end, n + 1)


def knots(stretch: Segment, spacing: float) -> np.ndarray:
    """The clamped knot vector of the traction's B-spline on the stretch: equal spans of about
    ``spacing`` m (at least one), the end knots repeated ``DEGREE + 1`` times."""
    n = max(1, int(round(stretch.length / spacing)))
    inner = np.linspace(stretch.s_start, stretch.s_end, n + 1)
    return np.concatenate([[inner[0]] * DEGREE, inner, [inner[-1]] * DEGREE])


def design(knot_vector: np.ndarray, s) -> sparse.csr_matrix:
    """Values ``B_k(s)`` (len(s), n_basis, sparse: at most ``DEGREE + 1`` a row) of the
    clamped B-splines; ``s`` is clipped onto the stretch (a node just beyond a corner counts at
    the corner)."""
    lo, hi = knot_vector[DEGREE], knot_vector[-DEGREE - 1]
    s = np.clip(np.asarray(s, float).ravel(), lo, hi)
    n_basis = len(knot_vector) - DEGREE - 1
    if len(s) == 0:
        return sparse.csr_matrix((0, n_basis))
    return sparse.csr_matrix(BSpline.design_matrix(s, knot_vector, DEGREE))


def _pieces(edges_a: np.ndarray, edges_b: np.ndarray):
    """Quadrature points and weights on the common refinement of two partitions of one
    interval: ``(s (n_pieces, q), w (n_pieces, q), piece_lo (n_pieces,))``."""
    cuts = np.unique(np.concatenate([edges_a, edges_b]))
    lo, hi = cuts[:-1], cuts[1:]
    keep = hi > lo
    lo, hi = lo[keep], hi[keep]
    x, w = _GAUSS
    s = 0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * x[None, :]
    return s, 0.5 * (hi - lo)[:, None] * w[None, :], lo


@dataclass
class StretchRecovery:
    """The linear maps of one stretch: node forces -> spline coefficients -> bin means.

    ``share`` (n_basis, n_entries, sparse): ``B_k(s_e)``; ``basis_area`` (n_basis,): ``A_k``;
    ``bin_mean`` (n_bins, n_basis, sparse): ``int_bin B_k c ds / int_bin c ds``; ``raw``
    (n_bins, n_entries, sparse): 1 where the entry's wall point lies in the bin; ``bin_area``
    (n_bins,).  ``entries``: the rows of the wall's entries that belong to the stretch."""

    stretch: Segment
    entries: np.ndarray
    knot_vector: np.ndarray
    edges: np.ndarray
    share: sparse.csr_matrix
    basis_area: np.ndarray
    bin_mean: sparse.csr_matrix
    raw: sparse.csr_matrix
    bin_area: np.ndarray

    @classmethod
    def build(cls, stretch: Segment, entries, s_entries, bin_width: float,
              knot_spacing: float | None = None) -> "StretchRecovery":
        """Maps for the entries (row indices ``entries``, arc lengths ``s_entries``) of the
        stretch, bins of about ``bin_width`` m and knots every ``knot_spacing`` m, but not
        closer than the bin width."""
        entries = np.asarray(entries, dtype=np.int64)
        s_entries = np.asarray(s_entries, float)
        kv = knots(stretch, max(bin_width, knot_spacing or 0.0))
        edges = bin_edges(stretch, bin_width)
        n_bins = len(edges) - 1
        share = design(kv, s_entries).T.tocsr()
        # Gauss points on the pieces between knots and bin edges: int_bin B_k c ds
        s_q, w_q, lo = _pieces(kv[DEGREE:len(kv) - DEGREE], edges)
        piece_bin = np.clip(np.searchsorted(edges, lo, side="right") - 1, 0, n_bins - 1)
        weight = (stretch.weight(s_q) * w_q).ravel()
        point_bin = np.repeat(piece_bin, s_q.shape[1])
        gather = sparse.csr_matrix((weight, (point_bin, np.arange(len(weight)))),
                                   shape=(n_bins, len(weight)))
        bin_integral = gather @ design(kv, s_q)                   # (bins, basis)
        bin_area = np.asarray(gather.sum(axis=1)).ravel()
        basis_area = np.asarray(bin_integral.sum(axis=0)).ravel()
        bin_mean = sparse.diags(1.0 / bin_area) @ bin_integral
        in_bin = np.clip(np.searchsorted(edges, s_entries, side="right") - 1, 0, n_bins - 1)
        raw = sparse.csr_matrix((np.ones(len(entries)), (in_bin, np.arange(len(entries)))),
                                shape=(n_bins, len(entries)))
        return cls(stretch, entries, kv, edges, share, basis_area, bin_mean, raw, bin_area)

    @property
    def centres(self) -> np.ndarray:
        return 0.5 * (self.edges[1:] + self.edges[:-1])

    def coefficients(self, force: np.ndarray) -> np.ndarray:
        """Spline coefficients ``t_k`` (Pa) of the entries' forces ``force`` (n_entries, ...)
        (N per radian, or per metre of a plane wall)."""
        return (self.share @ force) / self.basis_area.reshape((-1,) + (1,) * (force.ndim - 1))

    def traction(self, force: np.ndarray) -> np.ndarray:
        """The recovered traction's mean over each bin (Pa), (n_bins, ...)."""
        return self.bin_mean @ self.coefficients(force)

    def raw_traction(self, force: np.ndarray) -> np.ndarray:
        """The forces of the entries in each bin over the bin's area (Pa), (n_bins, ...)."""
        return (self.raw @ force) / self.bin_area.reshape((-1,) + (1,) * (force.ndim - 1))

    def evaluate(self, force: np.ndarray, s) -> np.ndarray:
        """The recovered traction at arc lengths ``s`` (Pa)."""
        return design(self.knot_vector, s) @ self.coefficients(force)
