"""The NPZ trajectory: the CSV's long form as NumPy arrays.

Arrays: ``t`` (R,), ``particle`` (R,) int64 index into ``ids`` (P,) str,
``position`` (R, 3), ``velocity`` (R, 3), ``frame_time`` (F,) and
``frame_start`` (F+1,) row offsets, so frame k is rows
``frame_start[k]:frame_start[k+1]``. Scenes with emitters add ``age`` (R,),
``size`` (R,) and ``color`` (R, 4) (NaN for particles that have none).
Scenes with rigid bodies add ``orientation`` (R, 4) quaternions [w, x, y, z]
and ``angular_velocity`` (R, 3) rad/s in the world frame (NaN for particle rows).

Scenes whose springs can tear add ``torn_spring`` (K,) int64, the springs (in
the scene's spring order: listed springs, then each structure's families) torn
during the run, and ``torn_time`` (K,), the time of the first frame in which
each is torn; a spring is drawn at a frame only while the frame's time is
before its ``torn_time``.

``drawables`` (a 0-d string array holding JSON) says what a picture needs
besides the points, so ``animsim render run.npz`` and ``animsim view
run.npz`` draw the run without its scene: ``planes`` (``[point, normal]``
pairs), ``springs`` (pairs of rows of ``ids``), per row of the header's ids
``radius`` (m, 0: none), ``color`` (``#rrggbb`` or null) and ``pinned``, and
with rigid bodies ``bodies`` (``first`` row, ``ids``, each ``shape``:
``kind`` with ``size``, ``radius`` or ``radius`` and ``length``, and each
``color``, ``#rrggbb`` or null), with solid colliders ``colliders``
(``params``: each one's packed geometry as animsim.colliders.Shape.packed
lays it out; ``moving``: keyframed or not; ``centers``: the keyframed ones'
centres at every frame), and ``surfaces`` when the scene has cloth or
meshes (pictures then default to a three-quarter 3D view).

Unlike the CSV, the NPZ keeps frames in which no particle is alive (a
particle system before its first birth), so it round-trips a run exactly.

Frames stream to raw temporary files while the run goes; the ``.npz`` (an
uncompressed zip of ``.npy`` files, as ``np.savez`` writes) is assembled at
the end, so memory stays bounded by one frame.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
import zipfile
from pathlib import Path
from typing import IO, Any

import numpy as np

from animsim.atomic import AtomicFile, writing
from animsim.bodies.export import body_info, row_columns
from animsim.export.meta import commit_with_meta
from animsim.export.trajectory import TornSprings
from animsim.record import Frame, TrajectoryHeader

_COLUMNS = {
    "t": ((), np.float64),
    "particle": ((), np.int64),
    "position": ((3,), np.float64),
    "velocity": ((3,), np.float64),
}
_EXTRA = {"age": ((), np.float64), "size": ((), np.float64), "color": ((4,), np.float64)}
#: scenes with rigid bodies: per row, NaN for particle rows
_BODY = {"orientation": ((4,), np.float64), "angular_velocity": ((3,), np.float64)}


class NpzSink:
    def __init__(self, path: str | Path, *, write_meta: bool = True):
        self.path = Path(path)
        self.write_meta = write_meta
        self._tmpdir: tempfile.TemporaryDirectory[str] | None = None
        self._raw: dict[str, IO[bytes]] = {}
        self._rows = 0
        self._frame_time: list[float] = []
        self._frame_start: list[int] = [0]
        self._ids: list[str] = []
        self._columns = dict(_COLUMNS)
        self._torn: Any = None

    def begin(self, header: TrajectoryHeader) -> None:
        if header.has_emitters:
            self._columns.update(_EXTRA)
        self._bodies = body_info(header)
        if self._bodies is not None:
            self._columns.update(_BODY)
        with writing(self.path):
            self._tmpdir = tempfile.TemporaryDirectory(prefix=".animsim-npz-", dir=self.path.parent)
            for name in self._columns:
                self._raw[name] = open(Path(self._tmpdir.name) / name, "wb")  # noqa: SIM115
        self._ids = list(header.ids)
        self._torn = TornSprings() if header.extra.get("springs_can_tear") else None
        self._drawables = drawables(header)
        # keyframed colliders: where each is at every frame, so a picture of the file alone
        # moves them as the run did
        self._colliders = scene_colliders(header)
        self._moving = (
            [] if self._colliders is None else np.flatnonzero(np.asarray(self._colliders.moving) >= 0)
        )
        self._collider_at: list[list[list[float]]] = []

    def write(self, frame: Frame) -> None:
        self._ids.extend(frame.new_ids)
        n = len(frame.index)
        # A full disk shows here (or only at close): a clear error, never a traceback.
        with writing(self.path):
            self._raw["t"].write(np.full(n, frame.time, dtype=np.float64).tobytes())
            self._raw["particle"].write(np.asarray(frame.index, dtype=np.int64).tobytes())
            self._raw["position"].write(np.ascontiguousarray(frame.position, dtype=np.float64).tobytes())
            self._raw["velocity"].write(np.ascontiguousarray(frame.velocity, dtype=np.float64).tobytes())
            if "age" in self._raw:
                for name, shape in (("age", (n,)), ("size", (n,)), ("color", (n, 4))):
                    value = getattr(frame, name)
                    arr = np.full(shape, np.nan) if value is None else np.asarray(value, dtype=np.float64)
                    self._raw[name].write(np.ascontiguousarray(arr).tobytes())
            if "orientation" in self._raw:
                self._write_bodies(frame)
        if self._torn is not None:
            self._torn.update(frame)
        if len(self._moving):
            assert self._colliders is not None
            at = self._colliders.params[self._moving, 1:4] + self._colliders.offsets(frame.time)[self._moving]
            self._collider_at.append(at.tolist())
        self._rows += n
        self._frame_time.append(frame.time)
        self._frame_start.append(self._rows)

    def _write_bodies(self, frame: Frame) -> None:
        assert self._bodies is not None
        q, w = row_columns(frame, int(self._bodies["first"]))
        self._raw["orientation"].write(np.ascontiguousarray(q).tobytes())
        self._raw["angular_velocity"].write(np.ascontiguousarray(w).tobytes())

    def close(self, meta: dict[str, Any]) -> None:
        assert self._tmpdir is not None
        out: AtomicFile | None = None
        try:
            with writing(self.path):
                for fh in self._raw.values():
                    fh.close()
                out = AtomicFile(self.path, "wb")
                with zipfile.ZipFile(out.handle, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
                    for name, (shape, dtype) in self._columns.items():
                        _write_npy(zf, name, Path(self._tmpdir.name) / name, (self._rows, *shape), dtype)
                    _write_array(zf, "ids", np.array(self._ids, dtype=str))
                    _write_array(zf, "frame_time", np.array(self._frame_time, dtype=np.float64))
                    _write_array(zf, "frame_start", np.array(self._frame_start, dtype=np.int64))
                    if len(self._moving):
                        self._drawables["colliders"]["centers"] = self._collider_at
                    _write_array(zf, "drawables", np.array(json.dumps(self._drawables, sort_keys=True)))
                    if self._torn is not None:
                        spring, time = self._torn.arrays()
                        _write_array(zf, "torn_spring", spring)
                        _write_array(zf, "torn_time", time)
        except BaseException:
            if out is not None:
                out.abort()
            self._cleanup()
            raise
        try:
            commit_with_meta(out, self.path, meta if self.write_meta else None)
        finally:
            self._cleanup()

    def abort(self) -> None:
        for fh in self._raw.values():
            with contextlib.suppress(OSError):
                fh.close()
        self._cleanup()

    def _cleanup(self) -> None:
        if self._tmpdir is not None:
            with contextlib.suppress(OSError):
                self._tmpdir.cleanup()
            self._tmpdir = None


def drawables(header: TrajectoryHeader) -> dict[str, Any]:
    """What a picture of the run needs besides its points (module docstring), as JSON values."""
    extra = header.extra or {}
    n = len(header.ids)

    def rows(values: Any, fill: Any) -> list[Any]:
        out = [fill] * n
        if values is not None:
            for i, v in enumerate(list(values)[:n]):
                out[i] = v.item() if isinstance(v, np.generic) else v
        return out

    out: dict[str, Any] = {
        "planes": [
            [np.asarray(p, dtype=float).tolist(), np.asarray(q, dtype=float).tolist()]
            for p, q in extra.get("planes", [])
        ],
        "springs": np.asarray(header.spring_index, dtype=np.int64).reshape(-1, 2).tolist(),
        "radius": [float(r) for r in rows(extra.get("particle_radius"), 0.0)],
        "color": rows(extra.get("particle_color"), None),
        "pinned": [bool(p) for p in rows(extra.get("particle_pinned"), False)],
    }
    bodies = extra.get("bodies")
    if bodies is not None:
        shapes = []
        for sh in bodies["shapes"]:
            d: dict[str, Any] = {"kind": sh.kind}
            for key in ("size", "radius", "length"):
                if hasattr(sh, key):
                    value = getattr(sh, key)
                    d[key] = [float(v) for v in value] if key == "size" else float(value)
            shapes.append(d)
        out["bodies"] = {
            "first": int(bodies["first"]),
            "ids": list(bodies["ids"]),
            "shapes": shapes,
            "colors": list(bodies.get("colors") or [None] * len(shapes)),
        }
    colliders = scene_colliders(header)
    if colliders is not None:
        out["colliders"] = {
            "params": [[float(v) for v in p] for p in colliders.params],
            "moving": [bool(m >= 0) for m in np.asarray(colliders.moving).tolist()],
        }
    if any(c.kind == "mesh" for c in header.connectivity):
        out["surfaces"] = True  # cloth and meshes: the picture is a three-quarter 3D view
    return out


def scene_colliders(header: TrajectoryHeader) -> Any:
    """The scene's solid colliders (animsim.colliders.Colliders), or None: the header carries
    their drawing function, whose owner they are."""
    surface = (header.extra or {}).get("collider_surface")
    return getattr(surface, "__self__", None)


def _write_npy(zf: zipfile.ZipFile, name: str, raw: Path, shape: tuple[int, ...], dtype: Any) -> None:
    with zf.open(f"{name}.npy", "w", force_zip64=True) as dst:
        np.lib.format.write_array_header_1_0(
            dst,
            {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False, "shape": shape},
        )
        with open(raw, "rb") as src:
            shutil.copyfileobj(src, dst, 1 << 20)


def _write_array(zf: zipfile.ZipFile, name: str, arr: np.ndarray) -> None:
    with zf.open(f"{name}.npy", "w", force_zip64=True) as dst:
        np.lib.format.write_array(dst, arr, allow_pickle=False)


def read_npz(path: str | Path) -> dict[str, Any]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
