"""Damped springs between particle pairs.

Lander, "Collision Response: Bouncy, Trouncy, Fun" (Game Developer, 1999), Eq. 2:

    L = x_a - x_b,  Ldot = v_a - v_b
    f_a = -[ks (|L| - R) + kd (Ldot . L) / |L|] L / |L|,   f_b = -f_a

Springs whose ends coincide (|L| = 0) have no direction and exert no force,
so a zero-rest spring between coincident particles gives 0, never NaN.

Forces are scattered with one ``np.bincount`` per axis over the concatenated
end indices; ``out[idx] += f`` would apply a repeated index only once.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from animsim.elements import ELASTIC, ClosedFormTerms, ForceElement
from animsim.vec import dot3, take_rows

if TYPE_CHECKING:  # SciPy loads only when implicit Euler asks for a Jacobian
    import scipy.sparse as sp

prange = range  # numba's prange once the kernel is compiled (see animsim.elements.jit_kernel)


def spring_kernel(x, v, t, out, mass, fp, ip):
    """Lander Eq. 2 per spring (in parallel), then each particle gathers its springs (CSR).

    fp = [rest (S), ks (S), kd (S), damped]; ip = [S, N, a (S), b (S), ptr (N+1), inc (2S)],
    where inc lists, per particle, spring s for an end a and S + s for an end b.
    """
    ns = ip[0]
    n = ip[1]
    sa = ip[2 : 2 + ns]
    sb = ip[2 + ns : 2 + 2 * ns]
    ptr = ip[2 + 2 * ns : 3 + 2 * ns + n]
    inc = ip[3 + 2 * ns + n :]
    rest = fp[:ns]
    ks = fp[ns : 2 * ns]
    kd = fp[2 * ns : 3 * ns]
    damped = fp[3 * ns] > 0
    fs = np.empty((ns, 3))
    for s in prange(ns):
        a = sa[s]
        b = sb[s]
        d0 = x[a, 0] - x[b, 0]
        d1 = x[a, 1] - x[b, 1]
        d2 = x[a, 2] - x[b, 2]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        inv = 1.0 / length if length > 0.0 else 0.0
        mag = ks[s] * (length - rest[s])
        if damped:
            dot = (v[a, 0] - v[b, 0]) * d0 + (v[a, 1] - v[b, 1]) * d1 + (v[a, 2] - v[b, 2]) * d2
            mag += kd[s] * dot * inv
        scale = -mag * inv
        fs[s, 0] = scale * d0
        fs[s, 1] = scale * d1
        fs[s, 2] = scale * d2
    for i in prange(n):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for k in range(ptr[i], ptr[i + 1]):
            s = inc[k]
            if s < ns:
                f0 += fs[s, 0]
                f1 += fs[s, 1]
                f2 += fs[s, 2]
            else:
                f0 -= fs[s - ns, 0]
                f1 -= fs[s - ns, 1]
                f2 -= fs[s - ns, 2]
        out[i, 0] += f0
        out[i, 1] += f1
        out[i, 2] += f2


def _energy(x, x_ref, u_ref, mass, fp, ip):  # numba: ENERGY_SIGNATURE
    """The potential sum 1/2 ks (|L| - R)^2 (Springs.potential), summed in spring order.

    fp = [rest (S), ks (S)]; ip = [S, a (S), b (S)] (Springs.numba_energy_params).
    """
    ns = ip[0]
    total = 0.0
    for s in range(ns):
        a = ip[1 + s]
        b = ip[1 + ns + s]
        d0 = x[a, 0] - x[b, 0]
        d1 = x[a, 1] - x[b, 1]
        d2 = x[a, 2] - x[b, 2]
        stretch = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2) - fp[s]
        total += fp[ns + s] * (stretch * stretch)
    return 0.5 * total


#: springs from which the numba kernel runs its loops in parallel; below, a
#: parallel region's start-up costs more than it saves
PARALLEL_MIN_SPRINGS = 20_000


class Springs(ForceElement):
    def __init__(
        self,
        index: np.ndarray,
        rest_length: np.ndarray,
        ks: np.ndarray,
        kd: np.ndarray,
        particle_count: int,
        label: str = "",
    ):
        self.a = np.ascontiguousarray(index[:, 0])
        self.b = np.ascontiguousarray(index[:, 1])
        self.rest = rest_length
        self.ks = ks
        self.kd = kd
        self.n = particle_count
        self.ends = np.concatenate([self.a, self.b])
        self.has_damping = bool(np.any(kd > 0))
        s = len(self.a)
        # One bincount for all three axes: bin 3 i + axis. Within a bin the weights
        # come in the order of the ends, as in one bincount per axis, so the sums
        # are the same to the bit.
        self._weights = np.empty((2 * s, 3))
        self._flat_ends = (3 * self.ends[:, None] + np.arange(3)).ravel()
        # CSR structure of the Jacobians, built on first use (explicit methods never need it).
        self._jac: tuple[sp.csr_matrix, np.ndarray, np.ndarray] | None = None
        self.label = label or f"springs: {s} (Hooke + damping, Lander Eq. 2)"
        self.numba_parallel = s >= PARALLEL_MIN_SPRINGS
        # tearing (animsim.tearing): the unbroken ks and kd, and the numba parameters in use
        self._base: tuple[np.ndarray, np.ndarray] | None = None
        self._fp: np.ndarray | None = None

    def set_intact(self, intact: np.ndarray) -> None:
        """Broken springs (``intact`` False) exert no force and hold no energy: their ks and kd
        become 0 in the live parameters of both kernels (NumPy arrays and the numba fp)."""
        if self._base is None:
            self._base = (np.array(self.ks, dtype=np.float64), np.array(self.kd, dtype=np.float64))
            self.ks = self._base[0].copy()
            self.kd = self._base[1].copy()
        np.multiply(self._base[0], intact, out=self.ks)
        np.multiply(self._base[1], intact, out=self.kd)
        if self._fp is not None:
            ns = len(self.a)
            self._fp[ns : 2 * ns] = self.ks
            self._fp[2 * ns : 3 * ns] = self.kd

    #: between particles only (springs to bodies are animsim.bodies.springs): no body feels them
    lets_bodies_sleep = True
    watch_role = ELASTIC
    energy_part = "spring"
    #: springs take part in closed forms through the system's spring arrays (no uniform part)
    closed_form: ClosedFormTerms | None = {}  # noqa: RUF012 - read-only allow-list entry

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        """Gershgorin rows of M^-1/2 K M^-1/2: spring k adds k (1/m_a + 1/sqrt(m_a m_b)) on row a."""
        a, b, n = self.a, self.b, len(k_rows)
        ia, ib = inv_mass[a], inv_mass[b]
        cross = np.sqrt(ia * ib)
        for coef, rows in ((self.ks, k_rows), (self.kd, c_rows)):
            rows += np.bincount(a, weights=coef * (ia + cross), minlength=n)
            rows += np.bincount(b, weights=coef * (ib + cross), minlength=n)

    numba_source = staticmethod(spring_kernel)
    numba_energy_source = staticmethod(_energy)

    def numba_energy_params(self) -> tuple[np.ndarray, np.ndarray]:
        """All the springs' rest lengths, stiffnesses and ends, in _energy's layout (grid
        springs too: they are Springs over the full spring set)."""
        fp = np.concatenate([self.rest, self.ks]).astype(np.float64)
        ip = np.concatenate([[len(self.a)], self.a, self.b]).astype(np.int64)
        return fp, ip

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        ns, n = len(self.a), self.n
        ends = self.ends
        order = np.argsort(ends, kind="stable")
        ptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(ends, minlength=n), out=ptr[1:])
        fp = np.concatenate([self.rest, self.ks, self.kd, [1.0 if self.has_damping else 0.0]])
        ip = np.concatenate([[ns, n], self.a, self.b, ptr, order]).astype(np.int64)
        self._fp = fp  # kept: tearing zeroes broken springs' ks and kd in it (set_intact)
        return fp, ip

    def _geometry(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # rows gathered with np.take (take_rows): the same values as x[self.a], faster
        d = take_rows(x, self.a) - take_rows(x, self.b)
        length = np.sqrt(dot3(d, d))
        # 1/|L|, and 0 for a spring with coincident ends (no direction, no force)
        inv = np.zeros_like(length)
        np.divide(1.0, length, out=inv, where=length > 0)
        return d, length, inv

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        d, length, inv = self._geometry(x)
        magnitude = self.ks * (length - self.rest)
        if self.has_damping:
            dv = take_rows(v, self.a) - take_rows(v, self.b)
            magnitude += self.kd * dot3(dv, d) * inv
        # force on a = -magnitude * unit; on b the opposite
        scale = -magnitude * inv
        s = len(self.a)
        w = self._weights
        np.multiply(d, scale[:, None], out=w[:s])
        np.negative(w[:s], out=w[s:])
        out += np.bincount(self._flat_ends, weights=w.ravel(), minlength=3 * self.n).reshape(self.n, 3)

    def potential(self, x: np.ndarray) -> float:
        _, length, _ = self._geometry(x)
        return float(0.5 * np.sum(self.ks * (length - self.rest) ** 2))

    def per_spring_energy(self, x: np.ndarray) -> np.ndarray:
        _, length, _ = self._geometry(x)
        return 0.5 * self.ks * (length - self.rest) ** 2

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix | None]:
        """dF/dx and dF/dv (3N x 3N), Baraff and Witkin 1998, section 4.2 (spring conditions).

        With u the unit vector from b to a, the block of dF_a/dx_a is

            -ks [u u^T + max(1 - R/|L|, 0) (I - u u^T)]

        (the transverse "geometric" term is clamped at 0 for compressed springs,
        so the matrix stays negative semidefinite and the implicit system SPD), and
        of dF_a/dv_a is -kd u u^T; dF_b/dx_b equals dF_a/dx_a and the mixed
        blocks are their negatives. The damping force's dependence on x is left
        out, as Baraff and Witkin do. A zero-rest spring between coincident
        particles is the linear force -ks L, so its block is -ks I.
        """
        d, length, inv = self._geometry(x)
        u = np.ascontiguousarray((d * inv[:, None]).T)  # (3, S): one row per axis
        ratio = np.where(
            length > 0, np.maximum(1.0 - self.rest * inv, 0.0), np.where(self.rest == 0, 1.0, 0.0)
        )
        # -ks [ratio I + (1 - ratio) u u^T], as a scaled u u^T plus a diagonal; blocks are
        # stored entry by entry, (9, S), so every product below runs over contiguous rows
        scale = -self.ks * (1.0 - ratio)
        diagonal = self.ks * ratio
        jx = np.empty((9, len(ratio)))
        jv = np.empty((9, len(ratio))) if self.has_damping else None
        for i in range(3):
            for j in range(i, 3):
                uu = u[i] * u[j]
                np.multiply(uu, scale, out=jx[3 * i + j])
                if i == j:
                    jx[3 * i + j] -= diagonal
                else:
                    jx[3 * j + i] = jx[3 * i + j]
                if jv is not None:
                    np.multiply(uu, -self.kd, out=jv[3 * i + j])
                    jv[3 * j + i] = jv[3 * i + j]
        kx = self._assemble(jx)
        if jv is None:
            return kx, None
        return kx, self._assemble(jv)

    def _assemble(self, block: np.ndarray) -> sp.csr_matrix:
        """The (3N, 3N) matrix with +block at (a,a) and (b,b) and -block at (a,b) and (b,a).

        The CSR structure is computed once (:meth:`_jacobian_layout`); each call is
        then one sparse product that sums every spring's block into its four places
        (duplicates, such as two springs on one pair, add up as the derivative of a
        sum should).
        """
        import scipy.sparse as sp

        size = 3 * self.n
        if self._jac is None:
            self._jac = self._jacobian_layout()
        gather, indices, indptr = self._jac
        data = gather @ block.reshape(-1)  # block: (9, S), entry 3 i + j of spring s at [3 i + j, s]
        mat = sp.csr_matrix((data, indices, indptr), shape=(size, size))
        mat.has_canonical_format = True  # sorted, one entry per place: spare SciPy the check
        return mat

    def _jacobian_layout(self) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        """(gather, indices, indptr): the Jacobians' CSR structure, and the (entries x 9 S)
        matrix of +1 and -1 taking each spring's block (stored (9, S)) to its four places.

        Built from the particle pairs (a 3 x 3 block per distinct pair, its rows in
        column order), so the only sort is of 4 S pairs, not of 36 S entries.
        """
        n, ns = self.n, len(self.a)
        first = np.concatenate([self.a, self.a, self.b, self.b])
        second = np.concatenate([self.a, self.b, self.a, self.b])
        pairs, which = np.unique(first * n + second, return_inverse=True)
        prow, pcol = pairs // n, pairs % n
        per_row = np.bincount(prow, minlength=n)  # distinct pairs (3 x 3 blocks) in a particle's row
        start = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(per_row, out=start[1:])
        # entry (3 r + i, 3 c + j) of pair u = (r, c), the m-th pair of row r, is at
        # 9 start[r] + 3 i per_row[r] + 3 m + j
        r = prow[:, None, None]
        i, j = np.arange(3)[None, :, None], np.arange(3)[None, None, :]
        place = 9 * start[r] + 3 * i * per_row[r] + 3 * (np.arange(len(pairs))[:, None, None] - start[r]) + j
        nnz = 9 * len(pairs)
        itype = np.int32 if max(nnz, 3 * n) < np.iinfo(np.int32).max else np.int64
        indices = np.empty(nnz, dtype=itype)
        indices[place.ravel()] = np.broadcast_to(3 * pcol[:, None, None] + j, place.shape).ravel()
        indptr = np.empty(3 * n + 1, dtype=itype)
        indptr[:-1] = (9 * start[:-1, None] + 3 * np.arange(3)[None, :] * per_row[:, None]).ravel()
        indptr[-1] = nnz
        # gather^T: block entry e = (3 i + j) S + s has its four places, signs + - - +
        places = place[which.reshape(4, ns)]  # (4, S, 3, 3)
        rows_t = np.ascontiguousarray(places.transpose(2, 3, 1, 0)).reshape(-1)
        signs = np.tile([1.0, -1.0, -1.0, 1.0], 9 * ns)
        import scipy.sparse as sp

        gather_t = sp.csr_matrix((signs, rows_t, np.arange(0, 36 * ns + 1, 4)), shape=(9 * ns, nnz))
        return gather_t.T.tocsr(), indices, indptr  # CSR: a product gathers, it does not scatter
