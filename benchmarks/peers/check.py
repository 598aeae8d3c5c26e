"""Smoke check of the peers: same physics, then rough throughput.

Run ``python -m benchmarks.peers.check``. It steps every available peer's
16 x 16 cloth 200 steps from one ``make_cloth(16)`` state and prints the
largest position difference from the plain NumPy peer (about 1e-12 or less
in float64, 1e-5 in float32), then steps/s for cloth 32 and 128 and for 1e5
and 1e6 particles. Exits 1 if a difference is over tolerance.
"""

from __future__ import annotations

import importlib.metadata
import platform
import sys
from types import ModuleType

import numpy as np

from . import PeerUnavailable, Stepper, load_peers
from .cloth import make_cloth
from .timing import measure, steps_for

CHECK_N = 16
CHECK_STEPS = 200
TOLERANCE = {"float64": 1e-9, "float32": 1e-4}
WORKLOADS = (
    ("cloth", 32),
    ("cloth", 128),
    ("particles", 100_000),
    ("particles", 1_000_000),
)
SAMPLE_SECONDS = 0.3
SAMPLES = 5


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def _stepper(peer: ModuleType, workload: str, n: int) -> Stepper:
    return peer.cloth_stepper(n) if workload == "cloth" else peer.particles_stepper(n)


def same_physics(peers: list[ModuleType]) -> bool:
    """Print each peer's max |x - x_plain_numpy| after CHECK_STEPS cloth steps.

    Drops from ``peers`` (in place) any peer whose stepper cannot be built.
    """
    problem = make_cloth(CHECK_N)
    results = {}
    for peer in list(peers):
        try:
            stepper = peer.cloth_stepper(CHECK_N, problem)
        except PeerUnavailable as exc:
            print(f"skip {peer.NAME}: {exc}")
            peers.remove(peer)
            continue
        for _ in range(CHECK_STEPS):
            stepper.step()
        results[peer.NAME] = (stepper.state()["x"], stepper.meta["dtype"])
    reference, _ = results["plain_numpy"]
    moved = np.abs(reference - problem.x0).max()
    print(f"cloth {CHECK_N}x{CHECK_N}, {CHECK_STEPS} steps (max displacement {moved:.4f} m)")
    if len(results) == 1:
        print("  no other peer to compare with plain_numpy")
    ok = True
    for name, (x, dtype) in results.items():
        if name == "plain_numpy":
            continue
        diff = float(np.abs(x - reference).max())
        passed = diff <= TOLERANCE[dtype]
        ok &= passed
        verdict = "ok" if passed else f"FAIL (tolerance {TOLERANCE[dtype]:g})"
        print(f"  max |x_{name} - x_plain_numpy| = {diff:.3e} m  [{dtype}] {verdict}")
    return ok


def throughput(peers: list[ModuleType]) -> None:
    """Print median [p10, p90] steps/s for each peer and workload."""
    for workload, n in WORKLOADS:
        size = f"{n}x{n}" if workload == "cloth" else f"{n:.0e}"
        for peer in peers:
            stepper = _stepper(peer, workload, n)
            per_sample = steps_for(stepper.step, SAMPLE_SECONDS)  # also the warm-up
            r = measure(stepper.step, steps_per_sample=per_sample, samples=SAMPLES, warmup=0)
            line = (
                f"  {workload:9} {size:7} {peer.LABEL:32} {r['median']:10.1f} steps/s"
                f"  [p10 {r['p10']:.1f}, p90 {r['p90']:.1f}]"
            )
            if workload == "particles":
                line += f"  = {r['median'] * n / 1e6:.1f} M particle-steps/s"
            print(line, flush=True)


def main() -> int:
    print(f"python {platform.python_version()}, numpy {np.__version__}, ", end="")
    print(f"warp-lang {_version('warp-lang')}, numba {_version('numba')}")
    peers = []
    for peer in load_peers():
        if peer.AVAILABLE:
            peers.append(peer)
        else:
            print(f"skip {peer.NAME}: {peer.REASON}")
    ok = same_physics(peers)
    print(f"throughput ({SAMPLES} samples of ~{SAMPLE_SECONDS} s each)")
    throughput(peers)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
