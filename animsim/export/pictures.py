"""Static pictures with matplotlib: particle paths, and energy over time.

matplotlib is imported inside the functions (Agg backend), so importing this
module costs nothing. Figures are saved with fixed metadata so the same input
gives the same bytes (PNG, SVG or PDF, chosen by the suffix).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.errors import UsageError
from animsim.export.raster import ORTHO_VIEWS

FIGURE_SUFFIXES = {".png": "png", ".svg": "svg", ".pdf": "pdf"}
# Trails of more particles than this make a grey smear; draw an even subset.
MAX_TRAILS = 400
#: the axis-aligned views, (horizontal axis, vertical axis) of the picture ("zy": the side view
#: of a y-up scene looking along x, so that up stays up whichever horizontal axis is wider)
AXES = {v: ("xyz".index(v[0]), "xyz".index(v[1])) for v in ORTHO_VIEWS}
VIEW_NAMES = ", ".join(ORTHO_VIEWS[:-1]) + " or " + ORTHO_VIEWS[-1]
#: a scene with gravity along y or z is drawn from the side (up drawn upward) unless its
#: vertical extent is below this fraction of its wider horizontal one and is the smallest of
#: the three: then it is something flat, seen from above
SIDE_VIEW_MIN_HEIGHT = 0.25
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


def pick_view(lo: np.ndarray, hi: np.ndarray, up: str | None = None) -> str:
    """The axis-aligned view a picture of motion within ``lo``..``hi`` gets by default.

    Without an up axis (no gravity along y or z): the two largest extents. With
    one, the side view, the up axis drawn upward and the wider horizontal axis
    across (a fountain, falling sand, a swinging cloth: gravity points down the
    picture), unless the motion is flat, its height the smallest extent and
    under SIDE_VIEW_MIN_HEIGHT of its width: then the top view (a cloth lying
    flat, a galaxy's disc).
    """
    ext = np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)
    a, b = sorted(int(k) for k in np.argsort(ext, kind="stable")[-2:])
    widest = {(0, 1): "xy", (0, 2): "xz", (1, 2): "yz"}[(a, b)]
    if up not in ("y", "z"):
        return widest
    u = "xyz".index(up)
    h1, h2 = (k for k in range(3) if k != u)
    across = h2 if ext[h2] > ext[h1] else h1
    flat = u not in (a, b) and ext[u] < SIDE_VIEW_MIN_HEIGHT * ext[across]
    if flat:
        return "xz" if up == "y" else "xy"
    return "xyz"[across] + up


def plot_trajectory(
    traj: Any, path: Path, *, view: str | None = None, title: str = "", up: str | None = None
) -> None:
    """Paths of the particles (trails) and their final positions (``up``: the scene's up axis,
    for the default view, :func:`pick_view`)."""
    plt = _pyplot()
    lo, hi = traj.bounds()
    view = view or pick_view(lo, hi, up)
    if view not in AXES:
        raise UsageError(f"--view {view!r}: plot takes {VIEW_NAMES}")
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
    _drift_panel_and_save(plt, fig, bottom, times, total, conservative, path)


#: colours of the energy parts (kinetic blue, potential parts warm, total black)
PART_STYLES = {
    "kinetic": ("tab:blue", "kinetic"),
    "rotational": ("tab:cyan", "rotational kinetic"),
    "gravitational": ("tab:orange", "gravitational"),
    "spring": ("tab:green", "spring"),
    "other": ("tab:purple", "other stored (contact)"),
}


def plot_energy_parts(
    times: np.ndarray,
    parts: dict[str, np.ndarray],
    path: Path,
    *,
    title: str = "",
    conservative: bool = False,
) -> None:
    """Energy split into its parts (kinetic, rotational, gravitational, spring, other), the
    total, and the total's relative drift on a log axis below."""
    plt = _pyplot()
    total = parts["total"]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True, height_ratios=[2, 1])
    for key, (colour, name) in PART_STYLES.items():
        # a part the scene has none of (no springs, no rotation) is no line: kinetic always is one
        if key in parts and (key == "kinetic" or np.any(np.asarray(parts[key]) != 0)):
            top.plot(times, parts[key], label=name, lw=1.2, color=colour)
    top.plot(times, total, label="total", lw=1.8, color="black")
    top.set_ylabel("energy (J)")
    top.grid(True, lw=0.3, alpha=0.5)
    top.legend(loc="best", fontsize=8)
    top.set_title(title or "energy")
    _drift_panel_and_save(plt, fig, bottom, times, total, conservative, path)


#: most particles a phase plot shows by default (one row of panels each)
PHASE_DEFAULT_PARTICLES = 3
#: an axis whose positions span less than this fraction of the largest span is left out
PHASE_STILL_FRACTION = 1e-6


@dataclass
class PhaseRun:
    """One run for a phase plot: dense (F, N, 3) positions and velocities over its frames."""

    label: str
    ids: list[str]
    position: np.ndarray
    velocity: np.ndarray
    status: str = "ok"
    failure_time: float | None = None


def phase_particles(run: PhaseRun, pinned: np.ndarray, requested: list[str] | None) -> list[int]:
    """Columns to plot: the requested ids, or up to PHASE_DEFAULT_PARTICLES free ones spread evenly."""
    if requested:
        missing = [pid for pid in requested if pid not in run.ids]
        if missing:
            raise UsageError(f"--particles: no particle {missing[0]!r} in this run")
        return [run.ids.index(pid) for pid in requested]
    free = np.flatnonzero(~pinned)
    if len(free) == 0:
        raise UsageError("--kind phase: every particle is pinned, nothing moves")
    picks = np.unique(
        np.linspace(0, len(free) - 1, min(PHASE_DEFAULT_PARTICLES, len(free))).round().astype(int)
    )
    return [int(free[i]) for i in picks]


def phase_axes(runs: list[PhaseRun], rows: list[int]) -> list[int]:
    """The axes along which the chosen particles move (in any run)."""
    span = np.zeros(3)
    names = [runs[0].ids[r] for r in rows]
    for run in runs:
        cols = [run.ids.index(pid) for pid in names if pid in run.ids]
        if not cols or not len(run.position):
            continue
        p = run.position[:, cols]
        with np.errstate(invalid="ignore"):
            span = np.maximum(span, np.nan_to_num(np.nanmax(p, axis=(0, 1)) - np.nanmin(p, axis=(0, 1))))
    moving = [a for a in range(3) if span[a] > PHASE_STILL_FRACTION * max(span.max(), 1e-300)]
    return moving or [0]


def plot_phase(
    runs: list[PhaseRun],
    path: Path,
    *,
    rows: list[int],
    axes: list[int] | None = None,
    title: str = "",
) -> None:
    """Position against velocity, one panel per (particle, axis), the runs overlaid.

    A symplectic method keeps an oscillator's orbit closed; explicit Euler's
    grows outward every turn (its amplification factor per step is
    sqrt(1 + (omega dt)^2) > 1, Hairer, Lubich and Wanner, "Geometric
    Numerical Integration", I.1). A run the watchdog stopped ends in a cross.
    """
    plt = _pyplot()
    axes = axes if axes is not None else phase_axes(runs, rows)
    nrows, ncols = len(rows), len(axes)
    fig, grid = plt.subplots(nrows, ncols, figsize=(3.6 * ncols + 0.6, 3.2 * nrows + 0.6), squeeze=False)
    colours = plt.get_cmap("tab10")
    for r, row in enumerate(rows):
        for c, a in enumerate(axes):
            ax = grid[r][c]
            pid = runs[0].ids[row]
            for k, run in enumerate(runs):
                if pid not in run.ids:  # a particle system's runs may differ in who was born
                    continue
                col = run.ids.index(pid)
                x, v = run.position[:, col, a], run.velocity[:, col, a]
                ok = np.isfinite(x) & np.isfinite(v)
                colour = colours(k % 10)
                label = run.label + ("" if run.status == "ok" else f" ({run.status})")
                ax.plot(x[ok], v[ok], lw=1.0, color=colour, label=label)
                if ok.any():
                    first, last = np.flatnonzero(ok)[[0, -1]]
                    ax.plot(x[first], v[first], "o", ms=4, color=colour)
                    if run.status != "ok":
                        ax.plot(x[last], v[last], "x", ms=9, mew=2, color="tab:red")
            ax.set_xlabel(f"{'xyz'[a]} (m)")
            ax.set_ylabel(f"v{'xyz'[a]} (m/s)")
            ax.set_title(f"{runs[0].ids[row]}, {'xyz'[a]}", fontsize=9)
            ax.grid(True, lw=0.3, alpha=0.5)
    # one legend below the panels: an unstable method's orbit fills its panel, so any place
    # inside one would cover a curve
    handles, labels = grid[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=max(1, len(labels)), fontsize=7, frameon=False)
    fig.suptitle(title or "phase portrait")
    fig.tight_layout(rect=(0, 0.07 / nrows, 1, 1))
    save_figure(fig, path)
    plt.close(fig)


def _drift_panel_and_save(
    plt: Any, fig: Any, bottom: Any, times: Any, total: Any, conservative: bool, path: Path
) -> None:
    """The energy plots' lower panel, |E - E0| / |E0| on a log axis, then the figure saved and closed."""
    scale = max(abs(total[0]), np.abs(total).max() * 1e-12, 1e-300)
    drift = np.abs(total - total[0]) / scale
    bottom.semilogy(times, np.where(drift > 0, drift, np.nan), color="tab:red", lw=1.2)
    bottom.set_ylabel("|E - E0| / |E0|")
    bottom.set_xlabel("t (s)")
    bottom.grid(True, which="both", lw=0.3, alpha=0.5)
    note = "conservative scene: drift is integration error" if conservative else "forces add or remove energy"
    bottom.set_title(note, fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
