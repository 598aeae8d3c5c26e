"""Static pictures with matplotlib: particle paths, and energy over time.

matplotlib is imported inside the functions (Agg backend), so importing this
module costs nothing. Figures are saved with fixed metadata so the same input
gives the same bytes (PNG, SVG or PDF, chosen by the suffix).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.errors import UsageError

FIGURE_SUFFIXES = {".png": "png", ".svg": "svg", ".pdf": "pdf"}
# Trails of more particles than this make a grey smear; draw an even subset.
MAX_TRAILS = 400
AXES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}
#: up to this many paths, each gets its own colour and its particle's name in the legend
NAMED_PATHS = 10
#: the part of the sequential colour map used for many paths (its last fifth is too pale on white)
SEQUENTIAL_RANGE = 0.8


def figure_format(path: Path) -> str:
    fmt = FIGURE_SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise UsageError(f"{path}: the picture format comes from the suffix: .png, .svg or .pdf")
    return fmt


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Deterministic SVG ids, no timestamps.
    matplotlib.rcParams["svg.hashsalt"] = "animsim"
    return plt


def save_figure(fig: Any, path: Path) -> None:
    """Save atomically with metadata that does not change from run to run."""
    fmt = figure_format(path)
    metadata: dict[str, Any] = {
        "png": {"Software": None},
        "svg": {"Date": None, "Creator": None},
        "pdf": {"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None},
    }[fmt]
    out = AtomicFile(path, "wb")
    try:
        fig.savefig(out.handle, format=fmt, metadata=metadata, dpi=120)
    except BaseException:
        out.abort()
        raise
    out.commit()


def pick_view(lo: np.ndarray, hi: np.ndarray) -> str:
    """The axis-aligned view showing the two largest extents."""
    ext = np.asarray(hi) - np.asarray(lo)
    a, b = sorted(np.argsort(ext)[-2:])
    return {(0, 1): "xy", (0, 2): "xz", (1, 2): "yz"}[(int(a), int(b))]


def plot_trajectory(traj: Any, path: Path, *, view: str | None = None, title: str = "") -> None:
    """Paths of the particles (trails) and their final positions."""
    plt = _pyplot()
    lo, hi = traj.bounds()
    view = view or pick_view(lo, hi)
    if view not in AXES:
        raise UsageError(f"--view {view!r}: plot takes xy, xz or yz")
    a, b = AXES[view]
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    order = np.argsort(traj.particle, kind="stable")
    pid = traj.particle[order]
    cuts = np.flatnonzero(np.diff(pid)) + 1
    groups = np.split(order, cuts)
    step = max(1, len(groups) // MAX_TRAILS)
    drawn = groups[::step]
    named = len(drawn) <= NAMED_PATHS
    if named:
        # Few paths: each in a distinct colour of a qualitative palette, named in the legend.
        from matplotlib.colors import is_color_like

        palette = plt.get_cmap("tab10")
        names = [traj.ids[int(traj.particle[rows[0]])] for rows in drawn]
        # A particle named after a colour (red, green, blue) is drawn in it.
        colors = [
            name if is_color_like(name) and not name.replace(".", "").isdigit() else palette(k % 10)
            for k, name in enumerate(names)
        ]
    else:
        # Many paths: a sequential map stopped short of its pale end, which vanishes on white.
        cmap = plt.get_cmap("viridis")
        colors = [cmap(SEQUENTIAL_RANGE * k / max(1, len(drawn) - 1)) for k in range(len(drawn))]
    for rows, color in zip(drawn, colors, strict=True):
        pts = traj.position[rows]
        label = traj.ids[int(traj.particle[rows[0]])] if named else None
        ax.plot(pts[:, a], pts[:, b], lw=1.0 if named else 0.8, alpha=0.85, color=color, label=label)
    last = slice(traj.frame_start[-2], traj.frame_start[-1])
    ax.scatter(
        traj.position[last, a], traj.position[last, b], s=6, color="black", zorder=3, label="last frame"
    )
    ax.set_xlabel(f"{'xyz'[a]} (m)")
    ax.set_ylabel(f"{'xyz'[b]} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title(title or "trajectories")
    if named:
        ax.legend(loc="best", fontsize=8)
    else:
        every = f", every {step}th" if step > 1 else ""
        ax.legend(loc="best", fontsize=8, title=f"paths of {len(groups)} particles{every}", title_fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def plot_energy(
    times: np.ndarray,
    kinetic: np.ndarray,
    potential: np.ndarray,
    path: Path,
    *,
    title: str = "",
    conservative: bool = False,
) -> None:
    """Kinetic, potential and total energy, and the relative drift on a log axis."""
    plt = _pyplot()
    total = kinetic + potential
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True, height_ratios=[2, 1])
    top.plot(times, kinetic, label="kinetic", lw=1.2)
    top.plot(times, potential, label="potential", lw=1.2)
    top.plot(times, total, label="total", lw=1.8, color="black")
    top.set_ylabel("energy (J)")
    top.grid(True, lw=0.3, alpha=0.5)
    top.legend(loc="best", fontsize=8)
    top.set_title(title or "energy")
    scale = max(abs(total[0]), np.abs(total).max() * 1e-12, 1e-300)
    drift = np.abs(total - total[0]) / scale
    shown = np.where(drift > 0, drift, np.nan)
    bottom.semilogy(times, shown, color="tab:red", lw=1.2)
    bottom.set_ylabel("|E - E0| / |E0|")
    bottom.set_xlabel("t (s)")
    bottom.grid(True, which="both", lw=0.3, alpha=0.5)
    note = "conservative scene: drift is integration error" if conservative else "forces add or remove energy"
    bottom.set_title(note, fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
