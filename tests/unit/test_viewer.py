"""The HTML viewer's Python side: encoding, validation, network-free pages, energy parts."""

from __future__ import annotations

import base64
import json
import re
import zlib
from types import SimpleNamespace

import numpy as np
import pytest

from animsim.export.viewer import (
    QUANT_DEAD,
    QUANT_MAX,
    Shape,
    ViewerPanel,
    delta_shuffle,
    dense_frames,
    panels_html,
    quantise_positions,
    viewer_html,
)
from animsim.measures.energy_parts import energy_parts, rotational_energy
from tests.conftest import simulate_text


def page_data(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="animsim-data">(.*?)</script>', page, re.S)
    assert m is not None
    return json.loads(m.group(1))


def blob_bytes(desc: dict) -> bytes:
    raw = base64.b64decode(desc["b64"])
    return zlib.decompress(raw) if desc["z"] else raw


def undo_delta_shuffle(data: bytes, frames: int) -> np.ndarray:
    """An independent inverse of delta_shuffle: what the page's script does."""
    b = np.frombuffer(data, dtype=np.uint8)
    half = len(b) // 2
    d = (b[:half].astype(np.int64) | (b[half:].astype(np.int64) << 8)).reshape(frames, -1)
    return (np.cumsum(d, axis=0) % 65536).astype(np.uint16)


def swirl(frames: int = 6, n: int = 5, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, frames)
    pos = rng.normal(size=(1, n, 3)) + t[:, None, None] * rng.normal(size=(1, n, 3))
    return t, pos


def test_quantisation_error_is_at_most_half_a_step_and_dead_rows_are_marked():
    t, pos = swirl()
    pos[2, 1] = np.nan  # particle 1 not alive in frame 2
    codes, lo, hi = quantise_positions(pos)
    assert codes.dtype == np.uint16
    assert (codes[2, 1] == QUANT_DEAD).all()
    alive = np.isfinite(pos).all(axis=-1)
    assert (codes[alive] <= QUANT_MAX).all()
    back = lo + codes.astype(np.float64) * (hi - lo) / QUANT_MAX
    step = (hi - lo) / QUANT_MAX
    assert (np.abs(back[alive] - pos[alive]) <= step / 2 + 1e-12).all()


def test_delta_shuffle_is_exactly_invertible():
    rng = np.random.default_rng(11)
    codes = rng.integers(0, 65536, size=(7, 9, 3)).astype(np.uint16)
    back = undo_delta_shuffle(delta_shuffle(codes).tobytes(), 7)
    np.testing.assert_array_equal(back.reshape(codes.shape), codes)


def test_page_is_self_contained_and_round_trips_the_positions():
    t, pos = swirl()
    page = viewer_html(t, pos, title="swirl", label="a </script> label")
    # Nothing that could reach the network: no address, no external script or style, no fetch.
    for needle in ("http://", "https://", "//cdn", "<link", " src=", "fetch(", "XMLHttpRequest", "import("):
        assert needle not in page
    data = page_data(page)  # the label's "</script>" was escaped, so the block parses
    (panel,) = data["panels"]
    assert panel["label"] == "a </script> label"
    assert panel["n"] == 5 and len(panel["times"]) == 6
    codes = undo_delta_shuffle(blob_bytes(panel["pos"]), 6).reshape(6, 5, 3)
    lo, hi = np.array(panel["pos"]["lo"]), np.array(panel["pos"]["hi"])
    back = lo + codes * (hi - lo) / QUANT_MAX
    assert np.abs(back - pos).max() <= (hi - lo).max() / QUANT_MAX


def test_colours_and_sizes_go_once_when_they_never_change():
    t, pos = swirl()
    still = np.broadcast_to([1.0, 0.0, 0.0, 1.0], (6, 5, 4))
    moving = np.random.default_rng(2).random((6, 5, 4))
    sizes = np.full((6, 5), 0.02)
    a = page_data(viewer_html(t, pos, colors=still, sizes=sizes))["panels"][0]
    assert a["colors"]["per_frame"] is False and len(blob_bytes(a["colors"])) == 5 * 4
    assert a["sizes"]["per_frame"] is False and len(blob_bytes(a["sizes"])) == 5 * 4
    b = page_data(viewer_html(t, pos, colors=moving))["panels"][0]
    assert b["colors"]["per_frame"] is True and len(blob_bytes(b["colors"])) == 6 * 5 * 4
    np.testing.assert_array_equal(
        np.frombuffer(blob_bytes(b["colors"]), dtype=np.uint8).reshape(6, 5, 4), np.rint(moving * 255)
    )


def test_shapes_and_panels_are_embedded():
    t, pos = swirl()
    ball = Shape("sphere", radius=0.5, position=np.zeros((6, 3)))
    box = Shape("box", half_extents=(0.1, 0.2, 0.3), orientation=(1.0, 0.0, 0.0, 0.0))
    ground = Shape("plane", point=(0, -1, 0), normal=(0, 2, 0))
    pill = Shape("capsule", radius=0.1, half_length=0.4)
    panels = [
        ViewerPanel(t, pos, label="one", shapes=[ball, box, ground, pill]),
        ViewerPanel(t[:4], pos[:4], label="two", status="unstable", failure_time=0.7),
    ]
    data = page_data(panels_html(panels, title="two runs", up="z", view="xz"))
    assert [p["label"] for p in data["panels"]] == ["one", "two"]
    assert data["up"] == "z" and data["view"] == "xz" and data["duration"] == 1.0
    kinds = [s["kind"] for s in data["panels"][0]["shapes"]]
    assert kinds == ["sphere", "box", "plane", "capsule"]
    assert data["panels"][0]["shapes"][2]["normal"] == [0.0, 1.0, 0.0]
    assert len(data["panels"][0]["shapes"][0]["position"]) == 6 * 3
    assert data["panels"][1]["mark"] == "unstable at t = 0.700 s"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"positions": np.zeros((3, 2))}, "positions must be"),
        ({"springs": [[0, 9]]}, "spring indices"),
        ({"pinned": [True]}, "pinned must have"),
        ({"colors": np.zeros((6, 5, 2))}, "colors must be"),
        ({"sizes": np.zeros((6, 4))}, "sizes must be"),
        ({"energies": {"kinetic": [1.0]}}, "one value per frame"),
        ({"status": "exploded"}, "status must be"),
        ({"shapes": [Shape("sphere", radius=1, position=np.zeros((2, 3)))]}, "one row per frame"),
    ],
)
def test_bad_panels_are_refused(kwargs, message):
    t, pos = swirl()
    args = {"times": t, "positions": pos, **kwargs}
    with pytest.raises(ValueError, match=message):
        ViewerPanel(**args)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "torus"}, "shape kind"),
        ({"kind": "plane", "point": (0, 0, 0)}, "needs point and normal"),
        ({"kind": "plane", "point": (0, 0, 0), "normal": (0, 0, 0)}, "non-zero"),
        ({"kind": "sphere"}, "needs radius"),
        ({"kind": "sphere", "radius": -1.0}, "radius must be"),
        ({"kind": "box", "half_extents": (1, 1)}, "half_extents"),
        ({"kind": "capsule", "radius": 0.1}, "needs half_length"),
        ({"kind": "sphere", "radius": 1.0, "orientation": (1, 1, 0, 0)}, "unit quaternions"),
    ],
)
def test_bad_shapes_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Shape(**kwargs)


def test_ids_must_name_every_particle():
    t, pos = swirl()
    with pytest.raises(ValueError, match="ids must name"):
        viewer_html(t, pos, ids=["a", "b"])


PENDULUM = """
name: bob
duration: 0.2
dt: 0.01
record: {every: 5}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 2.0, position: [0.8, -0.3, 0], velocity: [0.5, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 60, kd: 0, rest: 0.6}
forces:
  - {type: gravity}
"""


def test_energy_parts_match_closed_forms_and_add_up():
    compiled, _result, _sink = simulate_text(PENDULUM)
    state = compiled.fresh_state()
    parts = energy_parts(compiled.dynamics, state)
    # m g h with h the height above y = 0, 1/2 k (L - rest)^2, 1/2 m v^2.
    assert parts["gravitational"] == pytest.approx(2.0 * 9.81 * -0.3, rel=1e-12)
    assert parts["spring"] == pytest.approx(0.5 * 60 * (np.hypot(0.8, 0.3) - 0.6) ** 2, rel=1e-12)
    assert parts["kinetic"] == pytest.approx(0.5 * 2.0 * 0.25, rel=1e-12)
    x, v = state.particle_position, state.particle_velocity
    assert parts["total"] == pytest.approx(compiled.dynamics.energy(x, v), rel=1e-12)
    assert parts["potential"] == pytest.approx(compiled.dynamics.potential_energy(x), rel=1e-12)
    assert "rotational" not in parts


def test_rotational_energy_uses_the_body_frame():
    # A quarter turn about z: the body's x axis points along world y, so a world spin about y
    # is a spin about the body's x axis (moment 1), not its y axis (moment 2).
    half = np.sqrt(0.5)
    state = SimpleNamespace(
        body_orientation=np.array([[half, 0.0, 0.0, half]]), body_angular_velocity=np.array([[0.0, 3.0, 0.0]])
    )
    system = SimpleNamespace(body_inertia=np.array([[1.0, 2.0, 5.0]]))
    assert rotational_energy(system, state) == pytest.approx(0.5 * 1.0 * 9.0, rel=1e-12)
    assert rotational_energy(SimpleNamespace(), SimpleNamespace()) is None


def test_dense_frames_fill_dead_particles_with_nan():
    from animsim.export.trajectory import Trajectory

    traj = Trajectory(
        ids=["a", "b"],
        t=np.array([0.0, 0.1, 0.1]),
        particle=np.array([0, 0, 1]),
        position=np.arange(9, dtype=float).reshape(3, 3),
        velocity=np.ones((3, 3)),
        frame_start=np.array([0, 1, 3]),
    )
    dense = dense_frames(traj)
    assert dense["position"].shape == (2, 2, 3)
    assert np.isnan(dense["position"][0, 1]).all()
    np.testing.assert_array_equal(dense["position"][1, 1], [6, 7, 8])
    assert dense["color"] is None


def test_iframe_wraps_the_page_for_a_notebook():
    from html import unescape

    from animsim.export.viewer import iframe_html

    t, pos = swirl()
    page = viewer_html(t, pos, label='say "hi" & <b>')
    frame = iframe_html(page, height=500)
    m = re.fullmatch(
        r'<iframe srcdoc="([^"]*)" sandbox="allow-scripts" [^>]*height: 500px[^>]*></iframe>', frame
    )
    assert m is not None
    assert unescape(m.group(1)) == page
    with pytest.raises(ValueError, match="height"):
        iframe_html(page, height=0)


def test_a_simulated_trajectory_shows_itself_in_a_notebook():
    from html import unescape

    import animsim

    traj = animsim.simulate(animsim.loads(PENDULUM, name="bob"))
    frame = traj._repr_html_()
    assert frame.startswith("<iframe srcdoc=")
    page = unescape(re.search(r'srcdoc="([^"]*)"', frame).group(1))
    (panel,) = page_data(page)["panels"]
    assert panel["n"] == 2 and len(panel["times"]) == len(traj.times)
    assert panel["springs"] is not None and panel["pinned"] is not None
    # The energy of every frame, from the frames, matches the scene's own energy at the start.
    compiled = traj.compiled
    state = compiled.fresh_state()
    start = compiled.dynamics.energy(state.particle_position, state.particle_velocity)
    assert panel["energy"]["total"][0] == pytest.approx(start, rel=1e-6)


@pytest.mark.parametrize(("frames", "particles"), [(0, 3), (3, 0)])
def test_empty_runs_make_a_page(frames, particles):
    data = page_data(viewer_html(np.zeros(frames), np.zeros((frames, particles, 3))))
    (panel,) = data["panels"]
    assert panel["n"] == particles and panel["times"] == [0.0] * frames
    assert panel["pos"]["empty"] is True
