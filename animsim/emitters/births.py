"""The births of one emitter in time: the rate, the birth shapes and the seeded streams.

:class:`RateSchedule` (births per second, constant or keyframed),
:class:`ShapeSampler` (uniform birth positions in a point, sphere, box or disc),
:class:`Births` (a batch of birth events in time order) and :class:`BirthStream`
(an emitter's births drawn chunk by chunk in absolute time from its own random
streams, so they do not depend on dt), with the constants that size the chunks
and the rejection sampling.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.scene import models as m

#: The rate noise (``rate_spread``) is held for this span of simulated time, s.
RATE_NOISE_WINDOW = 0.1
#: Births are generated in chunks of about this many candidates, so memory is
#: bounded by the chunk, not the run (a noise window is split if needed).
CHUNK_BIRTHS = 4096
#: Rate-noise draws above this many standard deviations are rare enough to
#: ignore when sizing chunks (sizing only; it never truncates the noise).
RATE_NOISE_SIGMAS = 4.0
#: Volume of the unit ball over that of the cube [-1, 1]^3 (pi/6): the
#: acceptance rate of sphere rejection sampling; the disc's is pi/4.
BALL_ACCEPTANCE = np.pi / 6.0
DISC_ACCEPTANCE = np.pi / 4.0
#: Oversampling of rejection batches so one batch nearly always suffices.
REJECTION_MARGIN = 1.2
REJECTION_EXTRA = 16
#: Tag that separates emitter streams from other uses of the scene seed.
EMITTER_STREAM_TAG = 0x656D_6974  # "emit"
#: Words of the name hash mixed into the seed (4 x 32 bits).
NAME_HASH_WORDS = 4


def _name_words(name: str) -> list[int]:
    digest = hashlib.sha256(name.encode("utf-8")).digest()
    return [int.from_bytes(digest[4 * i : 4 * i + 4], "little") for i in range(NAME_HASH_WORDS)]


@dataclass(frozen=True)
class RateSchedule:
    """Piecewise-linear births per second; holds the end values outside the keyframes.

    ``times`` non-decreasing (s); equal times make a jump (right-continuous).
    """

    times: np.ndarray
    values: np.ndarray

    @classmethod
    def from_spec(cls, rate: float | list[list[float]]) -> RateSchedule:
        if isinstance(rate, list):
            kf = np.array(rate, dtype=np.float64).reshape(-1, 2)
            return cls(kf[:, 0].copy(), kf[:, 1].copy())
        return cls(np.array([0.0]), np.array([float(rate)]))

    @functools.cached_property
    def constant(self) -> bool:
        return bool(np.all(self.values == self.values[0]))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        if self.constant:
            # what the interpolation gives, v + w * 0.0 = v, without its eight passes (a
            # fountain's 2,500 events a chunk: 40 us)
            return np.full(t.shape, self.values[0])
        return self._interpolate(t)

    def _interpolate(self, t: np.ndarray) -> np.ndarray:
        k = np.searchsorted(self.times, t, side="right")
        lo = np.clip(k - 1, 0, len(self.times) - 1)
        hi = np.clip(k, 0, len(self.times) - 1)
        t0, t1 = self.times[lo], self.times[hi]
        span = t1 - t0
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(span > 0, (t - t0) / np.where(span > 0, span, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)
        return self.values[lo] + w * (self.values[hi] - self.values[lo])

    def max_over(self, a: float, b: float) -> float:
        """An upper bound (the maximum) of the rate over [a, b]."""
        if self.constant:
            return float(self.values[0])
        return self._max_interpolated(a, b)

    def _max_interpolated(self, a: float, b: float) -> float:
        inside = (self.times >= a) & (self.times <= b)
        ends = self(np.array([a, b]))
        return float(max(ends.max(), self.values[inside].max() if inside.any() else 0.0))

    def describe(self) -> str:
        if len(self.times) == 1:
            return f"{self.values[0]:g}/s"
        return "keyframes " + ", ".join(
            f"{v:g}/s at {t:g} s" for t, v in zip(self.times, self.values, strict=True)
        )


class ShapeSampler:
    """Uniform birth positions in an emitter shape (constrained randomization).

    Built from the scene's shape once (compile time); sampling reads plain numbers.
    """

    def __init__(self, shape: m.PointShape | m.SphereShape | m.BoxShape | m.DiscShape):
        self.kind = shape.type
        if self.kind == "point":
            self.center = np.array(shape.position, dtype=np.float64)
            self.text = f"point {list(shape.position)}"
        elif self.kind == "box":
            self.lo = np.array(shape.min, dtype=np.float64)
            self.hi = np.array(shape.max, dtype=np.float64)
            self.text = f"box {list(shape.min)}..{list(shape.max)}"
        elif self.kind == "sphere":
            self.center, self.radius = np.array(shape.center, dtype=np.float64), float(shape.radius)
            self.text = f"sphere at {list(shape.center)} r = {shape.radius:g} m (uniform inside, rejection)"
        else:  # disc
            self.center, self.radius = np.array(shape.center, dtype=np.float64), float(shape.radius)
            n = np.array(shape.normal) / np.linalg.norm(shape.normal)
            # Any vector not parallel to n gives the in-plane basis (e1, e2).
            helper = np.eye(3)[int(np.argmin(np.abs(n)))]
            e1 = np.cross(n, helper)
            e1 /= np.linalg.norm(e1)
            self.basis = np.stack([e1, np.cross(n, e1)])  # (2, 3)
            self.text = (
                f"disc at {list(shape.center)} normal {list(shape.normal)} r = {shape.radius:g} m (rejection)"
            )

    def describe(self) -> str:
        return self.text

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.kind == "point":
            return np.tile(self.center, (n, 1))
        if self.kind == "box":
            return self.lo + (self.hi - self.lo) * rng.random((n, 3))
        if self.kind == "sphere":
            unit = _inside_unit_ball(rng, n, 3, BALL_ACCEPTANCE)
            return self.center + self.radius * unit
        unit = _inside_unit_ball(rng, n, 2, DISC_ACCEPTANCE)
        return self.center + self.radius * (unit @ self.basis)


def _inside_unit_ball(rng: np.random.Generator, n: int, dim: int, acceptance: float) -> np.ndarray:
    """n points uniform in the unit ball of ``dim`` dimensions.

    The notes' constrained randomization: draw in the cube [-1, 1]^dim and
    re-randomize what falls outside the radius, in vectorised batches.
    """
    out = np.empty((n, dim))
    have = 0
    while have < n:
        want = n - have
        batch = rng.uniform(-1.0, 1.0, (int(want * REJECTION_MARGIN / acceptance) + REJECTION_EXTRA, dim))
        # np.compress: the rows a boolean index would pick, at a sixth of its time on rows
        keep = np.compress(np.einsum("ij,ij->i", batch, batch) <= 1.0, batch, axis=0)[:want]
        out[have : have + len(keep)] = keep
        have += len(keep)
    return out


def positive_gaussian(rng: np.random.Generator, n: int, mean: float, spread: float) -> np.ndarray:
    """n draws of mean + spread*N(0, 1), each redrawn while <= 0 (a truncated Gaussian)."""
    if spread == 0.0:
        return np.full(n, mean)
    out = np.empty(n)
    have = 0
    while have < n:
        want = n - have
        batch = mean + spread * rng.standard_normal(want + REJECTION_EXTRA)
        keep = batch[batch > 0.0][:want]
        out[have : have + len(keep)] = keep
        have += len(keep)
    return out


@dataclass
class Births:
    """Birth events in time order: times (k,) s, position (k, 3), velocity (k, 3), lifetime (k,)."""

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    lifetime: np.ndarray

    @classmethod
    def empty(cls) -> Births:
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))

    def __len__(self) -> int:
        return len(self.time)

    def split(self, before: float) -> tuple[Births, Births]:
        k = int(np.searchsorted(self.time, before, side="left"))
        head = Births(self.time[:k], self.position[:k], self.velocity[:k], self.lifetime[:k])
        tail = Births(self.time[k:], self.position[k:], self.velocity[k:], self.lifetime[k:])
        return head, tail

    def kept(self, keep: np.ndarray, n: int) -> Births:
        """The events where ``keep`` (bool, ``n`` of them True) holds; itself when all do."""
        if n == len(self):
            return self
        return Births(
            self.time[keep],
            np.compress(keep, self.position, axis=0),
            np.compress(keep, self.velocity, axis=0),
            self.lifetime[keep],
        )

    @staticmethod
    def concat(parts: Sequence[Births]) -> Births:
        if len(parts) == 1:
            return parts[0]
        return Births(
            np.concatenate([p.time for p in parts]),
            np.concatenate([p.position for p in parts]),
            np.concatenate([p.velocity for p in parts]),
            np.concatenate([p.lifetime for p in parts]),
        )


class BirthStream:
    """The births of one emitter, generated chunk by chunk in absolute time.

    Chunk c covers [c h, (c+1) h); the chunk length h divides the rate-noise
    window. Both are fixed by the scene, never by dt, and each chunk draws
    from the streams in a fixed order, so the events (and their attributes)
    are a function of the seed and the scene only.
    """

    def __init__(self, spec: m.Emitter, seed: int):
        # Plain numbers only: the stream draws while stepping and never reads the scene.
        self.name = spec.name
        self.v_spread = float(spec.velocity.spread)
        self.life_mean = float(spec.lifetime.mean)
        self.life_spread = float(spec.lifetime.spread)
        self.seed = seed
        self.rate = RateSchedule.from_spec(spec.rate)
        self.spread = float(spec.rate_spread)
        self.shape = ShapeSampler(spec.shape)
        bound = float(self.rate.values.max()) + RATE_NOISE_SIGMAS * self.spread
        self.chunks_per_window = max(1, int(np.ceil(bound * RATE_NOISE_WINDOW / CHUNK_BIRTHS)))
        self.chunk_length = RATE_NOISE_WINDOW / self.chunks_per_window
        self.v_mean = np.array(spec.velocity.mean)
        self.reset()

    def reset(self) -> None:
        root = np.random.SeedSequence([self.seed, EMITTER_STREAM_TAG, *_name_words(self.name)])
        birth_ss, attr_ss = root.spawn(2)
        self.rng_birth = np.random.default_rng(birth_ss)
        self.rng_attr = np.random.default_rng(attr_ss)
        self.next_chunk = 0
        self.noise = 0.0
        self.pending = Births.empty()

    def _chunk(self) -> Births:
        c = self.next_chunk
        self.next_chunk += 1
        a = c * self.chunk_length
        b = (c + 1) * self.chunk_length
        rb = self.rng_birth
        if self.spread > 0 and c % self.chunks_per_window == 0:
            self.noise = self.spread * float(rb.standard_normal())
        lam_max = max(0.0, self.rate.max_over(a, b) + self.noise)
        count = int(rb.poisson(lam_max * (b - a)))
        t = np.sort(a + (b - a) * rb.random(count))
        u = rb.random(count)  # thinning: keep with probability lambda(t) / lambda_max
        if count:
            lam = np.maximum(self.rate(t) + self.noise, 0.0)
            t = t[u * lam_max < lam]
        k = len(t)
        ra = self.rng_attr
        position = self.shape.sample(ra, k)
        velocity = self.v_mean + self.v_spread * ra.standard_normal((k, 3))
        lifetime = positive_gaussian(ra, k, self.life_mean, self.life_spread)
        return Births(t, position, velocity, lifetime)

    def snapshot(self) -> tuple[Any, ...]:
        """Everything a later draw depends on (the generators' states, the chunk counter, the rate
        noise and the events drawn but not taken), so :meth:`restore` repeats the same births."""
        return (
            self.rng_birth.bit_generator.state,
            self.rng_attr.bit_generator.state,
            self.next_chunk,
            self.noise,
            self.pending,
        )

    def restore(self, snap: tuple[Any, ...]) -> None:
        birth, attr, self.next_chunk, self.noise, self.pending = snap
        self.rng_birth.bit_generator.state = birth
        self.rng_attr.bit_generator.state = attr

    def take(self, t1: float) -> Births:
        """Every birth event with time < t1 not taken yet, in time order."""
        parts = [self.pending]
        while self.next_chunk * self.chunk_length < t1:
            parts.append(self._chunk())
        events, self.pending = Births.concat(parts).split(t1)
        return events
