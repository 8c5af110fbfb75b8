"""Kelvin kernels and triangle quadrature for the 3-D elastostatic BEM (linear triangles).

Kelvin fundamental solution (shear modulus mu, Poisson ratio nu; r = y - x from the source
x to the field point y, d = r/|r|, n the outward normal at y):

    u*_ij = [(3 - 4 nu) delta_ij + d_i d_j] / (16 pi mu (1 - nu) r)
    p*_ij = -[dr/dn ((1 - 2 nu) delta_ij + 3 d_i d_j) - (1 - 2 nu)(d_i n_j - d_j n_i)] / (8 pi (1 - nu) r^2)

One kernel row block (source x) integrates u* N_k and p* N_k over every flat triangle with
vertex shape functions N_k (1 - xi - eta, xi, eta). The rule is chosen per element from
q = |x - centroid| / longest edge:

* singular (x is a vertex of the element): Duffy transform with the collapsed corner at x,
  8 x 8 Gauss-Legendre points; the 1/r of u* and, for the two other vertices, p* N_k are
  bounded there. p* N_k of the vertex x itself is strongly singular and is skipped: the
  rigid-body trick (bem.assemble) sets the diagonal blocks of H;
* q >= 8: 3-point degree-2 rule; 2.5 <= q < 8: 7-point degree-5 rule (Radon/Dunavant);
* near-singular (q < 2.5): the element is split into four, recursively (up to 7 levels),
  until every piece passes the 7-point test.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

# barycentric (xi, eta) and weights (summing to 1) of the triangle rules
_R3 = np.array([[1 / 6, 1 / 6, 1 / 3], [2 / 3, 1 / 6, 1 / 3], [1 / 6, 2 / 3, 1 / 3]])
_A1, _B1, _W1 = 0.059715871789770, 0.470142064105115, 0.132394152788506
_A2, _B2, _W2 = 0.797426985353087, 0.101286507323456, 0.125939180544827
_R7 = np.array(
    [
        [1 / 3, 1 / 3, 0.225],
        [_B1, _B1, _W1],
        [_A1, _B1, _W1],
        [_B1, _A1, _W1],
        [_B2, _B2, _W2],
        [_A2, _B2, _W2],
        [_B2, _A2, _W2],
    ]
)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
GL_X = 0.5 * (_GL_X + 1.0)  # Gauss-Legendre on [0, 1]
GL_W = 0.5 * _GL_W
FAR, NEAR, MAX_LEVEL = 8.0, 2.5, 7


class Panel(NamedTuple):
    """A flat triangle as the quadrature sees it: y(xi, eta) = v0 + xi e1 + eta e2 (m)."""

    v0: np.ndarray  #: (3,) the first vertex
    e1: np.ndarray  #: (3,) edge to the second vertex
    e2: np.ndarray  #: (3,) edge to the third vertex
    nrm: np.ndarray  #: (3,) unit outward normal


class Blocks(NamedTuple):
    """The kernel matrices being filled and two 3x3 scratch blocks."""

    H: np.ndarray  #: p* N_k integrals (3 sources x 3 nodes)
    G: np.ndarray  #: u* N_k integrals
    ku: np.ndarray  #: 3x3 scratch
    kp: np.ndarray  #: 3x3 scratch


class Rules(NamedTuple):
    """Triangle rules (rows xi, eta, weight): far (degree 2) and near (degree 5)."""

    rule3: np.ndarray
    rule7: np.ndarray


class GaussLegendre(NamedTuple):
    """Gauss-Legendre points and weights on [0, 1] (the Duffy rule's factors)."""

    x: np.ndarray
    w: np.ndarray


class Surface(NamedTuple):
    """The boundary mesh: vertices (m), triangles, unit normals and areas (m^2)."""

    V: np.ndarray
    F: np.ndarray
    normals: np.ndarray
    areas: np.ndarray


@nb.njit(cache=True)
def _add_point(x, panel, xi, eta, wa, row, nodes, skip, consts, out):
    """Add u* N_k, p* N_k at parametric (xi, eta) of the Panel with physical weight ``wa``
    (m^2) to the 3x3 blocks (row, nodes[k]) of G and H of ``out`` (Blocks); node index
    ``skip`` (local 0..2) gets no H term."""
    v0, e1, e2, nrm = panel
    H, G, ku, kp = out
    cu, a, cp, b = consts[0], consts[1], consts[2], consts[3]
    r0 = v0[0] + xi * e1[0] + eta * e2[0] - x[0]
    r1 = v0[1] + xi * e1[1] + eta * e2[1] - x[1]
    r2 = v0[2] + xi * e1[2] + eta * e2[2] - x[2]
    rr = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    d = (r0 / rr, r1 / rr, r2 / rr)
    dn = d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2]
    su = cu * wa / rr
    sp = cp * wa / (rr * rr)
    for p in range(3):
        for q in range(3):
            dd = d[p] * d[q]
            delta = 1.0 if p == q else 0.0
            ku[p, q] = su * (a * delta + dd)
            kp[p, q] = sp * (dn * (b * delta + 3.0 * dd) - b * (d[p] * nrm[q] - d[q] * nrm[p]))
    for k in range(3):
        c = 3 * nodes[k]
        nk = 1.0 - xi - eta if k == 0 else (xi if k == 1 else eta)
        for p in range(3):
            for q in range(3):
                G[3 * row + p, c + q] += nk * ku[p, q]
                if k != skip:
                    H[3 * row + p, c + q] += nk * kp[p, q]


@nb.njit(cache=True)
def _dist_ratio(x, v0, e1, e2, t):
    """|x - centroid| / longest edge of the parametric sub-triangle t = (xi0, eta0, ..., xi2, eta2)."""
    cx = (t[0] + t[2] + t[4]) / 3.0
    cy = (t[1] + t[3] + t[5]) / 3.0
    dist2 = 0.0
    for k in range(3):
        dk = v0[k] + cx * e1[k] + cy * e2[k] - x[k]
        dist2 += dk * dk
    h2 = 0.0
    for m in range(3):
        mm = (m + 1) % 3
        dxi, deta = t[2 * mm] - t[2 * m], t[2 * mm + 1] - t[2 * m + 1]
        s = 0.0
        for k in range(3):
            dk = dxi * e1[k] + deta * e2[k]
            s += dk * dk
        h2 = max(h2, s)
    return math.sqrt(dist2 / h2)


@nb.njit(cache=True)
def _rule(x, panel, scale, t, rule, row, nodes, skip, consts, out):
    """Apply a triangle rule (rows xi, eta, weight) on the parametric sub-triangle t."""
    for g in range(rule.shape[0]):
        s, u, w = rule[g, 0], rule[g, 1], rule[g, 2]
        xi = t[0] + s * (t[2] - t[0]) + u * (t[4] - t[0])
        eta = t[1] + s * (t[3] - t[1]) + u * (t[5] - t[1])
        _add_point(x, panel, xi, eta, w * scale, row, nodes, skip, consts, out)


@nb.njit(cache=True)
def _regular(x, panel, area, row, nodes, consts, rules, out, stack):
    """Integrate one element that does not contain x, subdividing near-singular pieces."""
    v0, e1, e2, _ = panel
    rule3, rule7 = rules
    stack[0, :6] = (0.0, 0.0, 1.0, 0.0, 0.0, 1.0)
    stack[0, 6] = 0.0
    top = 1
    t = np.empty(7)
    while top > 0:
        top -= 1
        t[:] = stack[top]
        q = _dist_ratio(x, v0, e1, e2, t)
        level = int(t[6])
        if q < NEAR and level < MAX_LEVEL:
            m01 = (0.5 * (t[0] + t[2]), 0.5 * (t[1] + t[3]))
            m12 = (0.5 * (t[2] + t[4]), 0.5 * (t[3] + t[5]))
            m20 = (0.5 * (t[4] + t[0]), 0.5 * (t[5] + t[1]))
            kids = (
                (t[0], t[1], m01[0], m01[1], m20[0], m20[1]),
                (m01[0], m01[1], t[2], t[3], m12[0], m12[1]),
                (m20[0], m20[1], m12[0], m12[1], t[4], t[5]),
                (m12[0], m12[1], m20[0], m20[1], m01[0], m01[1]),
            )
            for kid in kids:
                for k in range(6):
                    stack[top, k] = kid[k]
                stack[top, 6] = level + 1
                top += 1
            continue
        rule = rule3 if q >= FAR else rule7
        _rule(x, panel, area * 0.25**level, t, rule, row, nodes, -1, consts, out)


@nb.njit(cache=True)
def _singular(x, panel, area, row, nodes, consts, gauss, out):
    """Duffy-transformed rule for an element whose local vertex 0 is the source x."""
    glx, glw = gauss
    for i in range(glx.shape[0]):
        u = glx[i]
        for j in range(glx.shape[0]):
            w = glx[j]
            wa = 2.0 * area * u * glw[i] * glw[j]
            _add_point(x, panel, u * (1.0 - w), u * w, wa, row, nodes, 0, consts, out)


@nb.njit(parallel=True, cache=True)
def integrate_rows(X, xvert, surface, consts, rules, gauss, H, G):
    """Add to H, G (3 len(X) x 3 len(V), zeroed by the caller) the integrals of p* N_k and
    u* N_k over all elements of the Surface for sources X; xvert[i] is the mesh vertex at
    X[i] or -1; rules: the Rules, gauss: the GaussLegendre of the singular elements."""
    V, F, normals, areas = surface
    rule3, rule7 = rules
    whole = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0])
    for i in nb.prange(X.shape[0]):
        x = X[i]
        stack = np.empty((4 * MAX_LEVEL + 4, 7))
        nodes = np.empty(3, dtype=np.int64)
        ku = np.empty((3, 3))
        kp = np.empty((3, 3))
        e1 = np.empty(3)
        e2 = np.empty(3)
        for e in range(F.shape[0]):
            loc = -1
            for k in range(3):
                if F[e, k] == xvert[i]:
                    loc = k
            for k in range(3):  # cyclic rotation keeps the orientation
                nodes[k] = F[e, (k + max(loc, 0)) % 3]
            v0 = V[nodes[0]]
            for k in range(3):
                e1[k] = V[nodes[1], k] - v0[k]
                e2[k] = V[nodes[2], k] - v0[k]
            panel = Panel(v0, e1, e2, normals[e])
            out = Blocks(H, G, ku, kp)
            area = areas[e]
            if loc >= 0:
                _singular(x, panel, area, i, nodes, consts, gauss, out)
                continue
            q = _dist_ratio(x, v0, e1, e2, whole)
            if q >= FAR:
                _rule(x, panel, area, whole, rule3, i, nodes, -1, consts, out)
            elif q >= NEAR:
                _rule(x, panel, area, whole, rule7, i, nodes, -1, consts, out)
            else:
                _regular(x, panel, area, i, nodes, consts, rules, out, stack)


def kernel_constants(shear: float, nu: float) -> np.ndarray:
    """(1/(16 pi mu (1-nu)), 3 - 4 nu, -1/(8 pi (1-nu)), 1 - 2 nu) for the kernels."""
    return np.array(
        [
            1.0 / (16.0 * math.pi * shear * (1.0 - nu)),
            3.0 - 4.0 * nu,
            -1.0 / (8.0 * math.pi * (1.0 - nu)),
            1.0 - 2.0 * nu,
        ]
    )


def integrate(X, xvert, V, F, normals, areas, shear: float, nu: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, G) row blocks (3 len(X) x 3 len(V)) for sources X (m); xvert as in integrate_rows.
    H has no free term and no p* N_k of an element's own source vertex (see module doc)."""
    m, n = X.shape[0], V.shape[0]
    H = np.zeros((3 * m, 3 * n))
    G = np.zeros((3 * m, 3 * n))
    integrate_rows(
        np.ascontiguousarray(X, dtype=np.float64),
        np.asarray(xvert, dtype=np.int64),
        Surface(V, F, normals, areas),
        kernel_constants(shear, nu),
        Rules(_R3, _R7),
        GaussLegendre(GL_X, GL_W),
        H,
        G,
    )
    return H, G
