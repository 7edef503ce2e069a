"""Numba kernels of the fast solver: element gradients and PSD Hessian blocks, block-sparse PCG.

The Hessian is stored as 3x3 blocks: `hdiag[V]` on the diagonal and `hpair[P]` for the vertex pairs
`pairs[P] = (i, j), i < j` (mesh edges plus the opposite vertices of each hinge), holding H[i, j]; H[j, i]
is its transpose. Every element adds a positive semi-definite approximation of its Hessian (Gauss-Newton
for strain and bending, negative curvature clamped), so the assembled matrix is SPD with the mass term and
preconditioned CG applies. The torch energies in energies.py / forces.py are the reference these match.
"""
from __future__ import annotations

import numpy as np
from numba import njit


_PREV = np.array([2, 0, 1])
_NEXT = np.array([1, 2, 0])


@njit(cache=True)
def face_q_assemble(x, faces, face_pairs, dpsi, d2psi, grad, hdiag, hpair):
    """Energies that are functions psi(q) of a face's squared-edge-length changes q_k = |x_a - x_b|^2 - L_k^2.

    Edge k joins corners k and k+1, so d q_k / d x = +2 d_k at corner k and -2 d_k at corner k+1
    (d_k = x_k - x_{k+1}). Adds grad psi and J^T d2psi J + sum_k max(dpsi_k, 0) grad^2 q_k (the compressive part
    of the second term is dropped to stay PSD). `d2psi` must be PSD.
    """
    prev = _PREV
    nxt = _NEXT
    d = np.empty((3, 3))
    u = np.empty((2, 3))
    for f in range(faces.shape[0]):
        for k in range(3):
            a = faces[f, k]
            b = faces[f, nxt[k]]
            s = 2.0 * dpsi[f, k]
            for r in range(3):
                dk = x[a, r] - x[b, r]
                d[k, r] = dk
                grad[a, r] += s * dk
                grad[b, r] -= s * dk
        # (J_c D J_c2^T) with J_c = 2 [d_c e_c^T - d_prev(c) e_prev(c)^T]:
        # block = 4 sum_{k,l} s_k s_l D_kl d_k d_l^T over k in {c, prev c}, l in {c2, prev c2}
        for c in range(3):
            pc = prev[c]
            for c2 in range(c, 3):
                pc2 = prev[c2]
                a00 = 4.0 * d2psi[f, c, c2]
                a01 = -4.0 * d2psi[f, c, pc2]
                a10 = -4.0 * d2psi[f, pc, c2]
                a11 = 4.0 * d2psi[f, pc, pc2]
                for r2 in range(3):
                    u[0, r2] = a00 * d[c2, r2] + a01 * d[pc2, r2]
                    u[1, r2] = a10 * d[c2, r2] + a11 * d[pc2, r2]
                va = faces[f, c]
                vb = faces[f, c2]
                if c == c2:
                    for r in range(3):
                        for r2 in range(3):
                            hdiag[va, r, r2] += d[c, r] * u[0, r2] + d[pc, r] * u[1, r2]
                    continue
                p = face_pairs[f, c if c2 == c + 1 else c2]
                if va < vb:
                    for r in range(3):
                        for r2 in range(3):
                            hpair[p, r, r2] += d[c, r] * u[0, r2] + d[pc, r] * u[1, r2]
                else:
                    for r in range(3):
                        for r2 in range(3):
                            hpair[p, r2, r] += d[c, r] * u[0, r2] + d[pc, r] * u[1, r2]
        # tension part: 2 dpsi_k [I, -I; -I, I] on edge k
        for k in range(3):
            t = 2.0 * dpsi[f, k]
            if t <= 0.0:
                continue
            a = faces[f, k]
            b = faces[f, nxt[k]]
            p = face_pairs[f, k]
            for r in range(3):
                hdiag[a, r, r] += t
                hdiag[b, r, r] += t
                hpair[p, r, r] -= t


@njit(cache=True)
def quadratic_q(x, faces, rest_sq, c, with_grad, dpsi):
    """psi = q^T c q per face (StVK in q form): returns the energy; with_grad writes d psi / d q = 2 c q."""
    energy = 0.0
    q = np.empty(3)
    for f in range(faces.shape[0]):
        for k in range(3):
            a = faces[f, k]
            b = faces[f, (k + 1) % 3]
            t0 = x[a, 0] - x[b, 0]
            t1 = x[a, 1] - x[b, 1]
            t2 = x[a, 2] - x[b, 2]
            q[k] = t0 * t0 + t1 * t1 + t2 * t2 - rest_sq[f, k]
        for k in range(3):
            cq = c[f, k, 0] * q[0] + c[f, k, 1] * q[1] + c[f, k, 2] * q[2]
            energy += q[k] * cq
            if with_grad:
                dpsi[f, k] += 2.0 * cq
    return energy


@njit(cache=True)
def face_q_values(x, faces, rest_sq):
    """q [F,3]: squared edge length minus rest squared length, edge k joining corners k, k+1."""
    n_faces = faces.shape[0]
    q = np.empty((n_faces, 3))
    for f in range(n_faces):
        for k in range(3):
            a = faces[f, k]
            b = faces[f, (k + 1) % 3]
            s = 0.0
            for r in range(3):
                t = x[a, r] - x[b, r]
                s += t * t
            q[f, k] = s - rest_sq[f, k]
    return q


@njit(cache=True, inline="always")
def _hinge_geometry(x, hinges, h, g, with_grad):
    """Dihedral angle of hinge h; with_grad also writes d theta / d x of its 4 vertices into g [4,3].
    Scalar code: numba heap-allocates every small array, and this runs per hinge per Newton iteration."""
    i0, i1, i2, i3 = hinges[h, 0], hinges[h, 1], hinges[h, 2], hinges[h, 3]
    ex, ey, ez = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
    ux, uy, uz = x[i2, 0] - x[i0, 0], x[i2, 1] - x[i0, 1], x[i2, 2] - x[i0, 2]
    wx, wy, wz = x[i3, 0] - x[i0, 0], x[i3, 1] - x[i0, 1], x[i3, 2] - x[i0, 2]
    nax, nay, naz = ey * uz - ez * uy, ez * ux - ex * uz, ex * uy - ey * ux        # e x u
    nbx, nby, nbz = wy * ez - wz * ey, wz * ex - wx * ez, wx * ey - wy * ex        # w x e
    le2 = ex * ex + ey * ey + ez * ez + 1e-30
    le = np.sqrt(le2)
    crx, cry, crz = nay * nbz - naz * nby, naz * nbx - nax * nbz, nax * nby - nay * nbx
    theta = np.arctan2((crx * ex + cry * ey + crz * ez) / le, nax * nbx + nay * nby + naz * nbz)
    if with_grad:
        fa = -le / (nax * nax + nay * nay + naz * naz + 1e-30)
        fb = -le / (nbx * nbx + nby * nby + nbz * nbz + 1e-30)
        t2 = (ux * ex + uy * ey + uz * ez) / le2
        t3 = (wx * ex + wy * ey + wz * ez) / le2
        g[2, 0], g[2, 1], g[2, 2] = fa * nax, fa * nay, fa * naz
        g[3, 0], g[3, 1], g[3, 2] = fb * nbx, fb * nby, fb * nbz
        for r in range(3):
            g[1, r] = -(t2 * g[2, r] + t3 * g[3, r])
            g[0, r] = -((1.0 - t2) * g[2, r] + (1.0 - t3) * g[3, r])
    return theta


@njit(cache=True)
def hinge_assemble(x, hinges, hinge_pairs, coef, rest_angle, grad, hdiag, hpair):
    """Bending coef * (theta - rest)^2 per hinge: gradient and Gauss-Newton Hessian 2 coef g g^T, g = grad theta.

    hinge_pairs[h] gives the pair index of local vertex pairs (0,1),(0,2),(1,2),(0,3),(1,3),(2,3).
    Returns the energy.
    """
    energy = 0.0
    g = np.empty((4, 3))
    for h in range(hinges.shape[0]):
        theta = _hinge_geometry(x, hinges, h, g, True)
        diff = theta - rest_angle[h]
        energy += coef[h] * diff * diff
        s = 2.0 * coef[h] * diff
        w = 2.0 * coef[h]
        for a in range(4):
            v = hinges[h, a]
            for r in range(3):
                grad[v, r] += s * g[a, r]
            for r in range(3):
                wg = w * g[a, r]
                for c in range(3):
                    hdiag[v, r, c] += wg * g[a, c]
        slot = 0
        for b in range(1, 4):
            vb = hinges[h, b]
            for a in range(b):
                va = hinges[h, a]
                p = hinge_pairs[h, slot]
                slot += 1
                # H[va, vb] = w g_a g_b^T, stored as H[min, max]
                lo, hi = (a, b) if va < vb else (b, a)
                for r in range(3):
                    wg = w * g[lo, r]
                    for c in range(3):
                        hpair[p, r, c] += wg * g[hi, c]
    return energy


@njit(cache=True)
def hinge_energy(x, hinges, coef, rest_angle):
    energy = 0.0
    g = np.empty((4, 3))
    for h in range(hinges.shape[0]):
        diff = _hinge_geometry(x, hinges, h, g, False) - rest_angle[h]
        energy += coef[h] * diff * diff
    return energy


@njit(cache=True)
def hinge_angles(x, hinges):
    """Dihedral angle of every hinge [H] (0 = flat)."""
    out = np.empty(hinges.shape[0])
    g = np.empty((4, 3))
    for h in range(hinges.shape[0]):
        out[h] = _hinge_geometry(x, hinges, h, g, False)
    return out


@njit(cache=True)
def edge_lengths(x, edges):
    """|x_i - x_j| of every edge [E]; the same bits as numpy's row norm, without its temporaries (the strain-rate
    damping evaluates it twice per energy, a tenth of a rollout's time in numpy at 600 vertices)."""
    out = np.empty(edges.shape[0])
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        a, b, c = x[i, 0] - x[j, 0], x[i, 1] - x[j, 1], x[i, 2] - x[j, 2]
        out[e] = np.sqrt(a * a + b * b + c * c)
    return out


@njit(cache=True)
def edge_assemble(x, edges, dphi, d2phi, grad, hdiag, hpair):
    """Energies phi(l) of edge lengths l = |x_i - x_j| (edge e is pair e): gradient and the PSD Hessian
    max(d2phi, 0) n n^T + max(dphi / l, 0) (I - n n^T)."""
    m = np.empty((3, 3))
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        d = x[i] - x[j]
        ln = np.sqrt(d @ d) + 1e-30
        n = d / ln
        for r in range(3):
            grad[i, r] += dphi[e] * n[r]
            grad[j, r] -= dphi[e] * n[r]
        a = max(d2phi[e], 0.0)
        b = max(dphi[e] / ln, 0.0)
        for r in range(3):
            for c in range(3):
                m[r, c] = (a - b) * n[r] * n[c]
            m[r, r] += b
        for r in range(3):
            for c in range(3):
                hdiag[i, r, c] += m[r, c]
                hdiag[j, r, c] += m[r, c]
                hpair[e, r, c] -= m[r, c]


@njit(cache=True)
def block_matvec(hdiag, hpair, pairs, free, v, out):
    n = hdiag.shape[0]
    for i in range(n):
        for r in range(3):
            out[i, r] = hdiag[i, r, 0] * v[i, 0] + hdiag[i, r, 1] * v[i, 1] + hdiag[i, r, 2] * v[i, 2]
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        vi0, vi1, vi2 = v[i, 0], v[i, 1], v[i, 2]
        vj0, vj1, vj2 = v[j, 0], v[j, 1], v[j, 2]
        for r in range(3):
            out[i, r] += hpair[p, r, 0] * vj0 + hpair[p, r, 1] * vj1 + hpair[p, r, 2] * vj2
            out[j, r] += hpair[p, 0, r] * vi0 + hpair[p, 1, r] * vi1 + hpair[p, 2, r] * vi2
    for i in range(n):
        for r in range(3):
            out[i, r] *= free[i]


@njit(cache=True)
def _inv3(a, out):
    det = (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]) - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
           + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))
    if abs(det) < 1e-300:
        for r in range(3):
            for c in range(3):
                out[r, c] = 0.0
            out[r, r] = 1.0 / max(a[r, r], 1e-300)
        return
    inv = 1.0 / det
    out[0, 0] = (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]) * inv
    out[0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * inv
    out[0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * inv
    out[1, 0] = (a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]) * inv
    out[1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * inv
    out[1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * inv
    out[2, 0] = (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]) * inv
    out[2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * inv
    out[2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * inv


@njit(cache=True)
def _sgs(dinv, hpair, lo_ptr, lo_pair, lo_nb, up_ptr, up_pair, up_nb, free, r, y, z):
    """Symmetric Gauss-Seidel preconditioner z = (D + U)^-1 D (D + L)^-1 r over 3x3 blocks in vertex order.
    One forward sweep carries a load along the mesh in a single pass (a hem's weight up to the waistband), which
    block Jacobi needs one CG iteration per ring for. Returns r . z."""
    n = r.shape[0]
    for i in range(n):
        a0, a1, a2 = r[i, 0], r[i, 1], r[i, 2]
        for s in range(lo_ptr[i], lo_ptr[i + 1]):
            p = lo_pair[s]
            j = lo_nb[s]
            y0, y1, y2 = y[j, 0], y[j, 1], y[j, 2]
            # H[i, j] = hpair[p]^T since the pair is stored as (j, i)
            a0 -= hpair[p, 0, 0] * y0 + hpair[p, 1, 0] * y1 + hpair[p, 2, 0] * y2
            a1 -= hpair[p, 0, 1] * y0 + hpair[p, 1, 1] * y1 + hpair[p, 2, 1] * y2
            a2 -= hpair[p, 0, 2] * y0 + hpair[p, 1, 2] * y1 + hpair[p, 2, 2] * y2
        f = free[i]
        y[i, 0] = (dinv[i, 0, 0] * a0 + dinv[i, 0, 1] * a1 + dinv[i, 0, 2] * a2) * f
        y[i, 1] = (dinv[i, 1, 0] * a0 + dinv[i, 1, 1] * a1 + dinv[i, 1, 2] * a2) * f
        y[i, 2] = (dinv[i, 2, 0] * a0 + dinv[i, 2, 1] * a1 + dinv[i, 2, 2] * a2) * f
    rz = 0.0
    for i in range(n - 1, -1, -1):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for s in range(up_ptr[i], up_ptr[i + 1]):
            p = up_pair[s]
            j = up_nb[s]
            z0, z1, z2 = z[j, 0], z[j, 1], z[j, 2]
            a0 += hpair[p, 0, 0] * z0 + hpair[p, 0, 1] * z1 + hpair[p, 0, 2] * z2
            a1 += hpair[p, 1, 0] * z0 + hpair[p, 1, 1] * z1 + hpair[p, 1, 2] * z2
            a2 += hpair[p, 2, 0] * z0 + hpair[p, 2, 1] * z1 + hpair[p, 2, 2] * z2
        f = free[i]
        for c in range(3):
            zc = (y[i, c] - (dinv[i, c, 0] * a0 + dinv[i, c, 1] * a1 + dinv[i, c, 2] * a2)) * f
            z[i, c] = zc
            rz += r[i, c] * zc
    return rz


@njit(cache=True)
def pcg(hdiag, hpair, pairs, sweep, free, b, x, rel_tol, max_iter):
    """Symmetric-Gauss-Seidel preconditioned CG for H x = b on the free vertices, from x (updated in place).

    `sweep` = (lo_ptr, lo_pair, lo_nb, up_ptr, up_pair, up_nb): each vertex's pairs with lower / higher index.
    Stops when |r| <= rel_tol |b|. Returns the iteration count.
    """
    lo_ptr, lo_pair, lo_nb, up_ptr, up_pair, up_nb = sweep
    n = hdiag.shape[0]
    dinv = np.empty((n, 3, 3))
    for i in range(n):
        _inv3(hdiag[i], dinv[i])
    r = np.empty((n, 3))
    block_matvec(hdiag, hpair, pairs, free, x, r)
    bnorm2 = 0.0
    rnorm2 = 0.0
    for i in range(n):
        for c in range(3):
            r[i, c] = (b[i, c] - r[i, c]) * free[i]
            bnorm2 += b[i, c] * b[i, c] * free[i]
            rnorm2 += r[i, c] * r[i, c]
    if bnorm2 == 0.0:
        x[:] = 0.0
        return 0
    tol2 = rel_tol * rel_tol * bnorm2
    y = np.empty((n, 3))
    z = np.empty((n, 3))
    rz = _sgs(dinv, hpair, lo_ptr, lo_pair, lo_nb, up_ptr, up_pair, up_nb, free, r, y, z)
    p = z.copy()
    ap = np.empty((n, 3))
    it = 0
    while it < max_iter and rnorm2 > tol2:
        block_matvec(hdiag, hpair, pairs, free, p, ap)
        pap = 0.0
        for i in range(n):
            for c in range(3):
                pap += p[i, c] * ap[i, c]
        if pap <= 0.0:
            break
        alpha = rz / pap
        rnorm2 = 0.0
        for i in range(n):
            for c in range(3):
                x[i, c] += alpha * p[i, c]
                r[i, c] -= alpha * ap[i, c]
                rnorm2 += r[i, c] * r[i, c]
        rz_new = _sgs(dinv, hpair, lo_ptr, lo_pair, lo_nb, up_ptr, up_pair, up_nb, free, r, y, z)
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            for c in range(3):
                p[i, c] = z[i, c] + beta * p[i, c]
        it += 1
    return it


@njit(cache=True)
def vertex_normals(verts, faces):
    """Area-weighted unit vertex normals."""
    vn = np.zeros_like(verts)
    for f in range(faces.shape[0]):
        ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y, e1z = verts[ib, 0] - verts[ia, 0], verts[ib, 1] - verts[ia, 1], verts[ib, 2] - verts[ia, 2]
        e2x, e2y, e2z = verts[ic, 0] - verts[ia, 0], verts[ic, 1] - verts[ia, 1], verts[ic, 2] - verts[ia, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        for k in range(3):
            vn[faces[f, k], 0] += nx
            vn[faces[f, k], 1] += ny
            vn[faces[f, k], 2] += nz
    for i in range(verts.shape[0]):
        ln = np.sqrt(vn[i, 0] ** 2 + vn[i, 1] ** 2 + vn[i, 2] ** 2)
        if ln > 0:
            for r in range(3):
                vn[i, r] /= ln
    return vn
