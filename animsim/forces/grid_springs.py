"""Springs of grid structures as array slices: the default NumPy spring kernel.

A cloth's structural, shear and bend springs, a strand's stretch and bend
springs and a soft box's edge and diagonal springs all join each grid point
to the point at a fixed offset (``animsim.scene.structures``). On the
position grid X = x[first:first + n].reshape(shape + (3,)) such a block of
springs is the difference of two shifted sub-arrays,

    L = X[lo] - X[hi],

and its forces go back with two slice additions, F[lo] -= f; F[hi] += f,
instead of gathers through index arrays and a ``bincount`` scatter: no index
traffic, no allocation, contiguous memory. The force law is the same as
:class:`~animsim.forces.springs.Springs` (Lander 1999, Eq. 2), operation for
operation, so results agree with it to rounding (summation order only).

Blocks are recognised, not assumed: each run of springs the compiler
reports (``System.spring_families``) is split into the blocks
``_offset_pairs`` would generate, and a block is used only if its index
pairs are exactly that block's pairs. Anything else (listed springs, a layout
this module does not know) stays on the bincount path, so a change in the
generators can cost speed but never correctness.
"""

from __future__ import annotations

import types
from dataclasses import dataclass

import numpy as np

from animsim.elements import numba_helper
from animsim.forces.springs import Springs, spring_kernel
from animsim.system import System
from animsim.vec import dot3

#: the bincount-order kernel of the springs outside the blocks, compiled with the grid kernel
#: (a twin of springs.spring_kernel, so marking it leaves that module's kernel alone)
springs_kernel = numba_helper(
    types.FunctionType(spring_kernel.__code__, spring_kernel.__globals__, "springs_kernel")
)
#: einsum spec of a row-wise dot product over the last (xyz) axis
_DOT = "...k,...k->..."


def _block_slices(
    shape: tuple[int, ...], offset: tuple[int, ...]
) -> tuple[tuple[slice, ...], tuple[slice, ...]] | None:
    """Slices (lo, hi) with pairs (X[lo], X[hi]) = (p, p + offset); None if the block is empty."""
    lo: list[slice] = []
    hi: list[slice] = []
    for n, o in zip(shape, offset, strict=True):
        if abs(o) >= n:
            return None
        if o >= 0:
            lo.append(slice(0, n - o))
            hi.append(slice(o, n))
        else:
            lo.append(slice(-o, n))
            hi.append(slice(0, n + o))
    return tuple(lo), tuple(hi)


def _block_pairs(shape: tuple[int, ...], lo: tuple[slice, ...], hi: tuple[slice, ...]) -> np.ndarray:
    flat = np.arange(int(np.prod(shape)), dtype=np.int64).reshape(shape)
    return np.stack([flat[lo].ravel(), flat[hi].ravel()], axis=1)


@dataclass
class GridBlock:
    """One block of springs p -> p + offset on one structure's grid, with its work buffers.

    rest: block-shaped rest lengths (m); ks, kd: scalars when uniform over the
    block (every generated family), else block-shaped arrays.
    """

    first: int  # first particle of the structure
    count: int  # particles in the structure
    shape: tuple[int, ...]
    lo: tuple[slice, ...]
    hi: tuple[slice, ...]
    springs: slice  # the block's springs in the System's spring arrays
    rest: np.ndarray
    ks: float | np.ndarray
    kd: float | np.ndarray
    damped: bool

    def __post_init__(self) -> None:
        bshape = self.rest.shape
        self.d = np.empty((*bshape, 3))
        self.dv = np.empty((*bshape, 3))
        self.f = np.empty((*bshape, 3))
        self.length = np.empty(bshape)
        self.inv = np.empty(bshape)
        self.mag = np.empty(bshape)
        self.dot = np.empty(bshape)

    def grid(self, a: np.ndarray) -> np.ndarray:
        """The structure's rows of an (N, 3) C-contiguous array as a (shape + (3,)) view."""
        return a[self.first : self.first + self.count].reshape((*self.shape, 3))

    def accumulate(self, x: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        X = self.grid(x)
        d, length, inv, mag = self.d, self.length, self.inv, self.mag
        np.subtract(X[self.lo], X[self.hi], out=d)
        dot3(d, d, out=length)
        np.sqrt(length, out=length)
        # Coincident ends have no direction and exert no force (see springs.py);
        # the min test keeps the common case to one division.
        if length.min() > 0.0:
            np.divide(1.0, length, out=inv)
        else:
            with np.errstate(divide="ignore"):
                np.copyto(inv, np.where(length > 0.0, 1.0 / length, 0.0))
        np.subtract(length, self.rest, out=mag)
        mag *= self.ks
        if self.damped:
            V = self.grid(v)
            np.subtract(V[self.lo], V[self.hi], out=self.dv)
            dot = self.dot
            dot3(self.dv, d, out=dot)
            dot *= self.kd
            dot *= inv
            mag += dot
        mag *= inv  # |f| / |L|: f_lo = -mag * L, f_hi = +mag * L
        f = self.f
        np.multiply(d, mag[..., None], out=f)
        F = self.grid(out)
        F[self.lo] -= f
        F[self.hi] += f


def find_blocks(system: System) -> list[GridBlock]:
    """The grid blocks among the System's generated springs (see the module docstring)."""
    blocks: list[GridBlock] = []
    for first, shape, fam_start, fam_end in system.structure_grids:
        count = int(np.prod(shape))
        ndim = len(shape)
        for _label, s0, s1 in system.spring_families[fam_start:fam_end]:
            s = s0
            while s < s1:
                a, b = system.spring_index[s] - first
                if not (0 <= a < count and 0 <= b < count):
                    break
                offset = tuple(
                    int(k) for k in np.subtract(np.unravel_index(b, shape), np.unravel_index(a, shape))
                )
                sl = _block_slices(shape, offset) if len(offset) == ndim else None
                if sl is None:
                    break
                lo, hi = sl
                pairs = _block_pairs(shape, lo, hi) + first
                e = s + len(pairs)
                if e > s1 or not np.array_equal(system.spring_index[s:e], pairs):
                    break
                bshape = tuple(sl_.stop - sl_.start for sl_ in lo)
                ks = system.spring_ks[s:e]
                kd = system.spring_kd[s:e]
                blocks.append(
                    GridBlock(
                        first=first,
                        count=count,
                        shape=tuple(shape),
                        lo=lo,
                        hi=hi,
                        springs=slice(s, e),
                        rest=system.spring_rest_length[s:e].reshape(bshape).copy(),
                        ks=float(ks[0]) if np.all(ks == ks[0]) else ks.reshape(bshape).copy(),
                        kd=float(kd[0]) if np.all(kd == kd[0]) else kd.reshape(bshape).copy(),
                        damped=bool(np.any(kd > 0)),
                    )
                )
                s = e
    return blocks


#: ints per block in the numba kernel's parameters: first particle, grid shape (3), the block's
#: first lo point (3), block shape (3), offset (3), offset in flat particle numbers
BLOCK_INTS = 14


def _grid_kernel(x, v, t, out, mass, fp, ip):
    """The numba twin of GridSprings.accumulate, on the grids themselves (no index arrays).

    One structure (a run of blocks on one grid) at a time, grid row by grid row (a
    row: the points along the grid's last axis). Its positions and velocities are
    first copied to one array per axis, so the row loops below read and write
    consecutive numbers and compile to SIMD code. Then, for each row: the forces of
    every block's springs whose lo end lies in the row; and the gather of a row
    whose springs are all done by then (``lag`` rows behind, 0 for the generated
    structures, whose hi ends never lie in an earlier row than their lo ends): its
    forces so far, then block after block the lo ends' -f before the hi ends' +f,
    written back once. That is the order in which the NumPy slices add to a particle
    (block after block: every lo end, then every hi end), with the same products, so
    the backends agree to the bit; and the forces are gathered while still in cache
    (only the last ``depth`` rows of each block's forces are kept, in a ring).
    Then the other springs as springs.Springs' bincount (per particle, in the order
    of the ends, from 0).

    Grids are padded to three dimensions (a strand is 1 x 1 x n).
    ip = [blocks, BLOCK_INTS per block, S_o, N, a (S_o), b (S_o), ptr (N+1), inc (2 S_o)];
    fp = [damped, (rest, ks, kd) (count each) per block, rest, ks, kd (S_o each)].
    (The spring and gather loops index the per-axis arrays by offsets, not through
    slices: every slice is an array view whose reference count numba takes and drops,
    about 18 per block and row, which cost more than the springs themselves. The
    offsets are unsigned, so numba adds no test for a negative index and LLVM
    vectorises the loops. One evaluation on cloth 32: 78 us with slices, 49 with
    signed offsets, 24 with unsigned ones.)

    Why one long function: the row loop moved into inline helpers took 12 more
    reference-count calls per grid row (28 -> 40 in the compiled kernel), and into a
    separate function compiled without them still cost 1.9 % more instructions per
    cloth-32 step (valgrind: 804.5M against 789.7M per 2,000 steps); this kernel is
    what every cloth step runs, so it stays whole.
    """
    damped = fp[0] > 0
    nblocks = ip[0]
    k = 0
    q = 1
    while k < nblocks:
        h = 1 + BLOCK_INTS * k
        first = ip[h]
        n0 = ip[h + 1]
        n1 = ip[h + 2]
        n2 = ip[h + 3]
        count = n0 * n1 * n2
        e = k + 1
        lag = 0
        ahead = 0
        for m in range(k, nblocks):
            g = 1 + BLOCK_INTS * m
            if ip[g] != first:
                break
            e = m + 1
            rows_off = ip[g + 10] * n1 + ip[g + 11]  # rows from a lo end to its hi end
            lag = max(lag, -rows_off)
            ahead = max(ahead, rows_off)
        # The forces of the last `depth` rows of springs (by their lo ends' row), per
        # block: all that a row's gather reads, so they stay in cache.
        depth = lag + ahead + 1
        xs = x[first : first + count]
        vs = v[first : first + count]
        xv = np.empty((6, count))
        for i in range(count):
            for c in range(3):
                xv[c, i] = xs[i, c]
                xv[3 + c, i] = vs[i, c]
        x0 = xv[0]
        x1 = xv[1]
        x2 = xv[2]
        v0 = xv[3]
        v1 = xv[4]
        v2 = xv[5]
        fs = np.empty((3, (e - k) * depth * n2))
        f0 = fs[0]
        f1 = fs[1]
        f2 = fs[2]
        acc = np.empty((3, n2))
        a0 = acc[0]
        a1 = acc[1]
        a2 = acc[2]
        rows = n0 * n1
        for row in range(rows + lag):
            if row < rows:  # the springs whose lo end is in this row
                c0 = row // n1
                c1 = row - c0 * n1
                qb = q
                for m in range(k, e):
                    g = 1 + BLOCK_INTS * m
                    b0 = ip[g + 7]
                    b1 = ip[g + 8]
                    b2 = ip[g + 9]
                    nb = b0 * b1 * b2
                    r0 = c0 - ip[g + 4]
                    r1 = c1 - ip[g + 5]
                    if 0 <= r0 < b0 and 0 <= r1 < b1:
                        j = (r0 * b1 + r1) * b2
                        a = row * n2 + ip[g + 6]
                        b = a + ip[g + 13]
                        # unsigned offsets, not slices (see the docstring)
                        ua = np.uint64(a)
                        ub = np.uint64(b)
                        ur = np.uint64(qb + j)  # rest lengths, then ks, then kd
                        uk = np.uint64(qb + nb + j)
                        ud = np.uint64(qb + 2 * nb + j)
                        uf = np.uint64(((m - k) * depth + row % depth) * n2)
                        if damped:
                            for i0 in range(b2):
                                i = np.uint64(i0)
                                d0 = x0[ua + i] - x0[ub + i]
                                d1 = x1[ua + i] - x1[ub + i]
                                d2 = x2[ua + i] - x2[ub + i]
                                length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                                inv = 1.0 / length if length > 0.0 else 0.0
                                mag = (length - fp[ur + i]) * fp[uk + i]
                                dot = (
                                    (v0[ua + i] - v0[ub + i]) * d0
                                    + (v1[ua + i] - v1[ub + i]) * d1
                                    + (v2[ua + i] - v2[ub + i]) * d2
                                )
                                mag += dot * fp[ud + i] * inv
                                mag *= inv
                                f0[uf + i] = d0 * mag
                                f1[uf + i] = d1 * mag
                                f2[uf + i] = d2 * mag
                        else:  # the same without the damping terms
                            for i0 in range(b2):
                                i = np.uint64(i0)
                                d0 = x0[ua + i] - x0[ub + i]
                                d1 = x1[ua + i] - x1[ub + i]
                                d2 = x2[ua + i] - x2[ub + i]
                                length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                                inv = 1.0 / length if length > 0.0 else 0.0
                                mag = (length - fp[ur + i]) * fp[uk + i]
                                mag *= inv
                                f0[uf + i] = d0 * mag
                                f1[uf + i] = d1 * mag
                                f2[uf + i] = d2 * mag
                    qb += 3 * nb
            done = row - lag  # the row to gather: all its springs are computed
            if done < 0:
                continue
            c0 = done // n1
            c1 = done - c0 * n1
            orow = out[first + done * n2 : first + (done + 1) * n2]
            for i in range(n2):
                a0[i] = orow[i, 0]
                a1[i] = orow[i, 1]
                a2[i] = orow[i, 2]
            for m in range(k, e):
                g = 1 + BLOCK_INTS * m
                b0 = ip[g + 7]
                b1 = ip[g + 8]
                b2 = ip[g + 9]
                r0 = c0 - ip[g + 4]
                r1 = c1 - ip[g + 5]
                if 0 <= r0 < b0 and 0 <= r1 < b1:  # lo ends of the block in this row: -f
                    src = np.uint64(((m - k) * depth + done % depth) * n2)
                    dst = np.uint64(ip[g + 6])
                    for i0 in range(b2):
                        i = np.uint64(i0)
                        a0[dst + i] -= f0[src + i]
                        a1[dst + i] -= f1[src + i]
                        a2[dst + i] -= f2[src + i]
                r0 -= ip[g + 10]
                r1 -= ip[g + 11]
                if 0 <= r0 < b0 and 0 <= r1 < b1:  # hi ends: +f, of springs whose lo ends are in row `back`
                    back = done - (ip[g + 10] * n1 + ip[g + 11])
                    src = np.uint64(((m - k) * depth + back % depth) * n2)
                    dst = np.uint64(ip[g + 6] + ip[g + 12])
                    for i0 in range(b2):
                        i = np.uint64(i0)
                        a0[dst + i] += f0[src + i]
                        a1[dst + i] += f1[src + i]
                        a2[dst + i] += f2[src + i]
            for i in range(n2):
                orow[i, 0] = a0[i]
                orow[i, 1] = a1[i]
                orow[i, 2] = a2[i]
        for m in range(k, e):
            g = 1 + BLOCK_INTS * m
            q += 3 * ip[g + 7] * ip[g + 8] * ip[g + 9]
        k = e
    p = 1 + BLOCK_INTS * nblocks
    if ip[p] > 0:
        springs_kernel(x, v, t, out, mass, fp[q:], ip[p:])


def _block_ints(blk: GridBlock) -> list[int]:
    """The block's BLOCK_INTS numbers for the numba kernel (its grid padded to 3 dimensions)."""
    pad = 3 - len(blk.shape)
    shape = [1] * pad + list(blk.shape)
    lo = [0] * pad + [sl.start for sl in blk.lo]
    bshape = [1] * pad + [sl.stop - sl.start for sl in blk.lo]
    offset = [0] * pad + [h.start - sl.start for sl, h in zip(blk.lo, blk.hi, strict=True)]
    flat = (offset[0] * shape[1] + offset[1]) * shape[2] + offset[2]
    return [blk.first, *shape, *lo, *bshape, *offset, flat]


class GridSprings(Springs):
    """All of a scene's springs: grid blocks by slices, the rest by bincount.

    A :class:`Springs` over the full spring set (so ``potential``,
    ``per_spring_energy`` and anything else defined on all springs stay
    exact and shared), whose ``accumulate`` takes the slice path.
    """

    def __init__(self, system: System, blocks: list[GridBlock], label: str = ""):
        super().__init__(
            system.spring_index,
            system.spring_rest_length,
            system.spring_ks,
            system.spring_kd,
            system.particle_count,
            label,
        )
        self.blocks = blocks
        self.numba_parallel = False
        covered = np.zeros(system.spring_count, dtype=bool)
        for blk in blocks:
            covered[blk.springs] = True
        left = np.flatnonzero(~covered)
        self.grid_spring_count = int(covered.sum())
        self.others: Springs | None = None
        if left.size:
            self.others = Springs(
                system.spring_index[left],
                system.spring_rest_length[left],
                system.spring_ks[left],
                system.spring_kd[left],
                system.particle_count,
            )

    numba_source = staticmethod(_grid_kernel)
    #: serial, to add the forces in the NumPy slices' order (the backends then agree to the bit)
    numba_parallel = False

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        fps: list[np.ndarray] = [np.array([1.0 if self.has_damping else 0.0])]
        ips: list[np.ndarray] = [np.array([len(self.blocks)])]
        for blk in self.blocks:
            ips.append(np.array(_block_ints(blk)))
            fps += [blk.rest.ravel(), np.broadcast_to(blk.ks, blk.rest.shape).ravel()]
            fps += [np.broadcast_to(blk.kd, blk.rest.shape).ravel()]
        if self.others is not None:
            fo, io = self.others.numba_params()
            # the others' kernel reads its own damped flag at the end of its floats
            fps.append(fo)
            ips.append(io)
        else:
            ips.append(np.array([0]))
        return np.concatenate(fps).astype(np.float64), np.concatenate(ips).astype(np.int64)

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        # The slice views need C-contiguous (N, 3) rows; every buffer the
        # integrators own is, but a caller's strided array takes the generic path.
        if not (x.flags.c_contiguous and v.flags.c_contiguous and out.flags.c_contiguous):
            super().accumulate(x, v, t, out)
            return
        for blk in self.blocks:
            blk.accumulate(x, v, out)
        if self.others is not None:
            self.others.accumulate(x, v, t, out)


def build_spring_term(system: System, label_prefix: str, *, grid: bool = True) -> Springs:
    """The spring term for ``system``: grid slices where they apply (``grid``), else bincount."""
    blocks = find_blocks(system) if grid else []
    if not blocks:
        return Springs(
            system.spring_index,
            system.spring_rest_length,
            system.spring_ks,
            system.spring_kd,
            system.particle_count,
            f"{label_prefix}, bincount scatter",
        )
    term = GridSprings(system, blocks)
    rest = system.spring_count - term.grid_spring_count
    how = f"{term.grid_spring_count} as {len(blocks)} grid slice blocks"
    if rest:
        how += f", {rest} by bincount scatter"
    term.label = f"{label_prefix}, {how}"
    return term
