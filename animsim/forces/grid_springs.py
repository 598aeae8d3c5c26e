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
from animsim.forces.springs import Springs
from animsim.forces.springs import _kernel as _springs_kernel
from animsim.system import System
from animsim.vec import dot3

#: the bincount-order kernel of the springs outside the blocks, compiled with the grid kernel
#: (a twin of springs._kernel, so marking it leaves that module's kernel alone)
springs_kernel = numba_helper(
    types.FunctionType(_springs_kernel.__code__, _springs_kernel.__globals__, "springs_kernel")
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


def _grid_kernel(x, v, t, out, mass, fp, ip):
    """The numba twin of GridSprings.accumulate, summing in the same order as the NumPy
    slices (block after block: every lo end, then every hi end), so the backends agree
    to the bit; then the other springs as springs.Springs' bincount (per particle, in
    the order of the ends, from 0).

    ip = [blocks, (count, lo (count), hi (count)) per block, S_o, N, a (S_o), b (S_o),
    ptr (N+1), inc (2 S_o)]; fp = [damped, (rest, ks, kd) (count each) per block,
    rest, ks, kd (S_o each)].
    """
    damped = fp[0] > 0
    nblocks = ip[0]
    p = 1
    q = 1
    for _ in range(nblocks):
        count = ip[p]
        lo = ip[p + 1 : p + 1 + count]
        hi = ip[p + 1 + count : p + 1 + 2 * count]
        rest = fp[q : q + count]
        ks = fp[q + count : q + 2 * count]
        kd = fp[q + 2 * count : q + 3 * count]
        p += 1 + 2 * count
        q += 3 * count
        fs = np.empty((count, 3))
        for s in range(count):
            a = lo[s]
            b = hi[s]
            d0 = x[a, 0] - x[b, 0]
            d1 = x[a, 1] - x[b, 1]
            d2 = x[a, 2] - x[b, 2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            inv = 1.0 / length if length > 0.0 else 0.0
            mag = (length - rest[s]) * ks[s]
            if damped:
                dot = (v[a, 0] - v[b, 0]) * d0 + (v[a, 1] - v[b, 1]) * d1 + (v[a, 2] - v[b, 2]) * d2
                mag += dot * kd[s] * inv
            mag *= inv
            fs[s, 0] = d0 * mag
            fs[s, 1] = d1 * mag
            fs[s, 2] = d2 * mag
        for s in range(count):
            a = lo[s]
            out[a, 0] -= fs[s, 0]
            out[a, 1] -= fs[s, 1]
            out[a, 2] -= fs[s, 2]
        for s in range(count):
            b = hi[s]
            out[b, 0] += fs[s, 0]
            out[b, 1] += fs[s, 1]
            out[b, 2] += fs[s, 2]
    if ip[p] > 0:
        springs_kernel(x, v, t, out, mass, fp[q:], ip[p:])


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
            pairs = _block_pairs(blk.shape, blk.lo, blk.hi) + blk.first
            count = len(pairs)
            ips += [np.array([count]), pairs[:, 0], pairs[:, 1]]
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
