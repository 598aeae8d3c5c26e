"""Structure generators: counts, ids, rest lengths and pins."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.scene.models import Cloth, SoftBox, Strand
from animsim.scene.structures import expand, local_index


def cloth(nx, ny, **families):
    fam = {k: {"ks": 1.0} for k in families}
    return Cloth.model_validate(
        {
            "type": "cloth",
            "id": "c",
            "size": [2.0, 1.0],
            "resolution": [nx, ny],
            "mass": 0.1,
            "pin": ["c[0,0]"],
            **fam,
        }
    )


@pytest.mark.parametrize(("nx", "ny"), [(2, 2), (3, 5), (20, 20)])
def test_cloth_spring_counts(nx, ny):
    e = expand(cloth(nx, ny, structural=1, shear=1, bend=1))
    counts = {g.family.split(": ")[1]: len(g.index) for g in e.springs}
    assert counts["structural"] == (nx - 1) * ny + nx * (ny - 1)
    assert counts["shear"] == 2 * (nx - 1) * (ny - 1)
    assert counts["bend"] == max(nx - 2, 0) * ny + nx * max(ny - 2, 0)
    assert len(e.ids) == nx * ny
    assert e.ids[0] == "c[0,0]" and e.ids[1] == "c[0,1]" and e.ids[ny] == "c[1,0]"


def test_cloth_geometry_and_rest_lengths():
    e = expand(cloth(3, 3, structural=1, shear=1, bend=1))
    # plane xz: u along x (size 2), v along z (size 1)
    np.testing.assert_allclose(e.position[local_index(cloth(3, 3), "c[2,2]")], [2.0, 0.0, 1.0])
    lengths = {}
    for g in e.springs:
        d = e.position[g.index[:, 0]] - e.position[g.index[:, 1]]
        lengths[g.family.split(": ")[1]] = np.unique(np.round(np.linalg.norm(d, axis=1), 12))
    np.testing.assert_allclose(lengths["structural"], [0.5, 1.0])
    np.testing.assert_allclose(lengths["shear"], [np.hypot(1.0, 0.5)])
    np.testing.assert_allclose(lengths["bend"], [1.0, 2.0])
    assert e.pinned.sum() == 1 and e.pinned[0]


def test_omitted_family_is_left_out():
    e = expand(cloth(4, 4, structural=1))
    assert [g.family for g in e.springs] == ["cloth c: structural"]


def test_strand_stretch_and_bend():
    s = Strand.model_validate(
        {
            "type": "strand",
            "id": "h",
            "start": [0, 0],
            "end": [0, -1],
            "count": 5,
            "mass": 1,
            "stretch": {"ks": 1},
            "bend": {"ks": 1},
        }
    )
    e = expand(s)
    stretch, bend = e.springs
    assert stretch.index.tolist() == [[0, 1], [1, 2], [2, 3], [3, 4]]
    assert bend.index.tolist() == [[0, 2], [1, 3], [2, 4]]
    assert e.ids == ["h[0]", "h[1]", "h[2]", "h[3]", "h[4]"]


def test_soft_box_counts():
    n = 4
    b = SoftBox.model_validate(
        {
            "type": "soft_box",
            "id": "j",
            "size": [1, 1, 1],
            "resolution": [n, n, n],
            "mass": 1,
            "edge": {"ks": 1},
            "face_diagonal": {"ks": 1},
            "body_diagonal": {"ks": 1},
        }
    )
    e = expand(b)
    counts = {g.family.split(": ")[1]: len(g.index) for g in e.springs}
    assert counts["edge"] == 3 * n * n * (n - 1)
    assert counts["face_diagonal"] == 3 * 2 * n * (n - 1) ** 2
    assert counts["body_diagonal"] == 4 * (n - 1) ** 3
    np.testing.assert_allclose(e.position.min(axis=0), -0.5)
    np.testing.assert_allclose(e.position.max(axis=0), 0.5)
    # every spring of a family has one length
    for g in e.springs:
        d = np.linalg.norm(e.position[g.index[:, 0]] - e.position[g.index[:, 1]], axis=1)
        assert np.ptp(d) < 1e-12
