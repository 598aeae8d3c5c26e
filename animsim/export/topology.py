"""Torn structures in the files: the faces and curve segments still whole at a frame.

A spring torn by ``max_strain`` no longer holds its two particles together,
so the surface between them is gone too: from the first frame in which a
spring is torn, every face that has both of its particles among its corners
(an edge of the face, or a diagonal: a cloth quad's shear springs) leaves
the mesh, and every curve segment between its particles leaves the strand,
which splits there into two curves. A vertex left with no segment on either
side is no curve (a linear curve needs two vertices) and is left out of the
strand's curves.

The exporters that keep shapes (USD, PLY, VTK) all ask :class:`TornShapes`,
so a hole is the same hole in every file. It is built once from the
trajectory header (the springs' particle pairs and each structure's faces or
curves) and answers per frame from ``Frame.spring_intact``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from animsim.record import Connectivity, TrajectoryHeader


class _Lookup:
    """Particle pairs -> 'is any spring joining them torn?', vectorised."""

    def __init__(self, spring_index: np.ndarray) -> None:
        pairs = np.sort(np.asarray(spring_index, dtype=np.int64).reshape(-1, 2), axis=1)
        self.scale = int(pairs.max()) + 1 if len(pairs) else 1
        keys = pairs[:, 0] * self.scale + pairs[:, 1]
        self.keys, self.spring_key = np.unique(keys, return_inverse=True)

    def find(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For pairs (a, b) of global rows: which have springs, and their key rows."""
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key = lo * self.scale + hi
        pos = np.clip(np.searchsorted(self.keys, key), 0, max(len(self.keys) - 1, 0))
        found = (hi < self.scale) & (self.keys[pos] == key) if len(self.keys) else np.zeros(len(key), bool)
        return found, pos

    def torn_keys(self, intact: np.ndarray) -> np.ndarray:
        torn = ~np.asarray(intact, dtype=bool)
        return np.bincount(self.spring_key, weights=torn, minlength=len(self.keys)) > 0


class _Structure:
    """One structure's faces (or curve segments) and the spring keys behind each."""

    def __init__(self, c: Connectivity, lookup: _Lookup) -> None:
        self.conn = c
        counts = np.asarray(c.vertex_counts, dtype=np.int64)
        local = np.asarray(c.vertex_indices, dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        owner: list[np.ndarray] = []
        a_list: list[np.ndarray] = []
        b_list: list[np.ndarray] = []
        if c.kind == "mesh":
            self.items = len(counts)  # faces
            for k in np.unique(counts).tolist():  # every pair of corners of each face
                faces = np.flatnonzero(counts == k)
                corners = local[starts[faces, None] + np.arange(k)]
                for i in range(k):
                    for j in range(i + 1, k):
                        owner.append(faces)
                        a_list.append(corners[:, i])
                        b_list.append(corners[:, j])
        else:
            # segments in curve order: segment s joins vertex seg_a[s] and seg_a[s] + 1 of `local`
            seg_pos = np.concatenate([np.arange(s, s + n - 1) for s, n in zip(starts, counts, strict=True)])
            self.seg_first = np.zeros(len(seg_pos), dtype=bool)
            firsts = np.cumsum(np.concatenate([[0], counts[:-1] - 1]))
            self.seg_first[firsts[counts > 1]] = True
            self.seg_a, self.seg_b = local[seg_pos], local[seg_pos + 1]
            self.items = len(seg_pos)
            owner.append(np.arange(len(seg_pos)))
            a_list.append(self.seg_a)
            b_list.append(self.seg_b)
        if owner:
            own, a, b = np.concatenate(owner), np.concatenate(a_list), np.concatenate(b_list)
        else:
            own = a = b = np.zeros(0, dtype=np.int64)
        found, pos = lookup.find(a + c.first, b + c.first)
        self.owner, self.key = own[found], pos[found]
        self.counts, self.local, self.starts = counts, local, starts

    def dead(self, torn_key: np.ndarray) -> np.ndarray:
        hit = torn_key[self.key].astype(np.float64)
        return np.bincount(self.owner, weights=hit, minlength=self.items) > 0


class TornShapes:
    """Per frame: each structure's faces or curves with the torn parts left out (module docstring)."""

    def __init__(self, header: TrajectoryHeader | None) -> None:
        extra = {} if header is None else header.extra or {}
        spring_index = np.zeros((0, 2), dtype=np.int64)
        if header is not None:
            spring_index = np.asarray(header.spring_index, dtype=np.int64).reshape(-1, 2)
        self.can_tear = bool(extra.get("springs_can_tear")) and len(spring_index) > 0
        self.structures: dict[str, _Structure] = {}
        if self.can_tear:
            lookup = _Lookup(spring_index)
            self._lookup = lookup
            for c in header.connectivity:  # type: ignore[union-attr]
                self.structures[c.name] = _Structure(c, lookup)

    def tears(self, c: Connectivity) -> bool:
        """Whether structure ``c`` may change its topology during the run."""
        s = self.structures.get(c.name)
        return s is not None and len(s.key) > 0

    def _torn(self, intact: np.ndarray | None) -> np.ndarray | None:
        if intact is None or not self.can_tear:
            return None
        # not cached: a run updates its spring_intact array in place between frames
        return self._lookup.torn_keys(intact)

    def faces(self, c: Connectivity, intact: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """``(vertex_counts, vertex_indices)`` (local) of the mesh's whole faces."""
        torn = self._torn(intact)
        s = self.structures.get(c.name)
        if torn is None or s is None:
            return np.asarray(c.vertex_counts), np.asarray(c.vertex_indices)
        alive = ~s.dead(torn)
        counts = s.counts[alive]
        rows = np.concatenate([np.arange(st, st + n) for st, n in zip(s.starts[alive], counts, strict=True)])
        return counts, s.local[rows.astype(np.int64)] if len(rows) else np.zeros(0, dtype=np.int64)

    def curves(self, c: Connectivity, intact: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """``(vertex_counts, vertices)``: the strand's whole runs of segments, as curves over the
        local vertices listed (each vertex at most once, in strand order)."""
        torn = self._torn(intact)
        s = self.structures.get(c.name)
        if torn is None or s is None:
            counts = np.asarray(c.vertex_counts)
            keep = counts > 1
            return counts[keep], _curve_vertices(np.asarray(c.vertex_indices), counts, keep)
        alive = ~s.dead(torn)
        prev_alive = np.concatenate([[False], alive[:-1]])
        start = alive & (s.seg_first | ~prev_alive)
        # each whole segment gives its end vertex, and its start vertex too when it opens a run
        emit = np.stack([start, alive], axis=1).ravel()
        verts = np.stack([s.seg_a, s.seg_b], axis=1).ravel()[emit]
        run = np.cumsum(start)[alive] - 1
        counts = np.bincount(run, minlength=int(start.sum())) + 1 if len(run) else np.zeros(0, np.int64)
        return counts.astype(np.int64), verts.astype(np.int64)

    def segments(self, c: Connectivity, intact: np.ndarray | None) -> np.ndarray:
        """(E, 2) local vertex pairs of the strand's whole segments."""
        counts, verts = self.curves(c, intact)
        if not len(counts):
            return np.zeros((0, 2), dtype=np.int64)
        ends = np.cumsum(counts)
        last = np.zeros(len(verts), dtype=bool)
        last[ends - 1] = True
        first = np.flatnonzero(~last)
        return np.stack([verts[first], verts[first + 1]], axis=1)


def _curve_vertices(local: np.ndarray, counts: np.ndarray, keep: np.ndarray) -> np.ndarray:
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    parts: Sequence[np.ndarray] = [
        local[s : s + n] for s, n, k in zip(starts, counts, keep, strict=True) if k
    ]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
