"""Wall-clock throughput of a step callable, in steps per second."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np


def measure(
    step: Callable[[], None],
    *,
    steps_per_sample: int,
    samples: int,
    warmup: int,
) -> dict[str, float | list[float]]:
    """Time ``step`` with ``time.perf_counter``.

    Runs ``warmup`` untimed steps, then ``samples`` samples of
    ``steps_per_sample`` steps each. Returns steps/s as ``median``, ``p10``,
    ``p90`` (NumPy's linear-interpolated percentiles over the samples) and the
    per-sample rates in ``samples``.
    """
    if steps_per_sample < 1 or samples < 1 or warmup < 0:
        raise ValueError("need steps_per_sample >= 1, samples >= 1, warmup >= 0")
    for _ in range(warmup):
        step()
    rates = []
    for _ in range(samples):
        t0 = time.perf_counter()
        for _ in range(steps_per_sample):
            step()
        rates.append(steps_per_sample / (time.perf_counter() - t0))
    arr = np.asarray(rates)
    return {
        "median": float(np.median(arr)),
        "p10": float(np.percentile(arr, 10)),
        "p90": float(np.percentile(arr, 90)),
        "samples": rates,
    }


def steps_for(step: Callable[[], None], seconds: float, *, max_steps: int = 100_000) -> int:
    """How many steps take about ``seconds``, estimated by timing doubling batches.

    The calibration steps advance the simulation; call this as part of warm-up.
    """
    count = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(count):
            step()
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds / 4 or count >= max_steps:
            return max(1, min(max_steps, round(count * seconds / max(elapsed, 1e-9))))
        count *= 2
