"""The viewer gets every drawable of a scene: colliders, rigid bodies as turning shapes, and the
particles' own colours and radii (the page's data, before any browser)."""

from __future__ import annotations

import numpy as np

from animsim.api import compile as compile_scene
from animsim.api import load
from animsim.export.viewer import panel_json
from animsim.panel_runs import simulate_panel
from tests.conftest import SCENES


def panel_of(scene: str, duration: float):
    sc = load(SCENES / f"{scene}.yaml")
    sc = sc.model_copy(update={"duration": duration})
    compiled = compile_scene(sc, backend="numpy", name=scene)
    return compiled, simulate_panel(compiled)


def test_a_die_is_a_box_that_turns_with_the_run() -> None:
    _, run = panel_of("die_throw", 0.4)
    traj = run.trajectory
    boxes = [s for s in run.panel.shapes if s.kind == "box"]
    assert len(boxes) == 1
    box = boxes[0]
    assert np.allclose(box.half_extents, [0.1, 0.1, 0.1])
    rows = np.flatnonzero(np.isfinite(traj.orientation).all(axis=1))
    assert len(rows) == traj.frame_count
    # the pose of every frame is the run's own, quaternion for quaternion
    assert np.allclose(box.position, traj.position[rows], rtol=0, atol=1e-12)
    q = traj.orientation[rows] / np.linalg.norm(traj.orientation[rows], axis=1, keepdims=True)
    assert np.allclose(box.orientation, q, rtol=0, atol=1e-12)
    assert not np.allclose(box.orientation[0], box.orientation[-1])  # it does turn
    assert any(s.kind == "plane" for s in run.panel.shapes)  # and the floor is there


def test_a_collider_sphere_and_the_clothes_look_reach_the_page() -> None:
    _, run = panel_of("cloth_over_sphere", 0.1)
    spheres = [s for s in run.panel.shapes if s.kind == "sphere"]
    assert len(spheres) == 1
    assert spheres[0].radius == 0.45 and np.allclose(spheres[0].position, [0, 0.5, 0])
    data = panel_json(run.panel)
    assert any(s["kind"] == "sphere" for s in data["shapes"])


def test_particles_carry_their_colour_and_size_to_the_page() -> None:
    _, run = panel_of("bouncing_balls", 0.1)
    panel = run.panel
    ids = run.trajectory.ids
    colours = {"red": "e04040", "green": "40c040", "blue": "4060f0"}
    for k, pid in enumerate(ids):
        hexa = colours[pid]
        want = [int(hexa[i : i + 2], 16) / 255 for i in (0, 2, 4)] + [1.0]
        assert np.allclose(panel.colors[:, k], want)
    assert np.allclose(panel.sizes, 0.1)  # the dots' diameters: twice the 0.05 m radius
