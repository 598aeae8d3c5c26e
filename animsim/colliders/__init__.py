"""Solid colliders: spheres, oriented boxes and capsules, static or keyframed.

Particles meet them at the time of impact inside the step, at any speed and angle, and
never end a step inside one (:mod:`~animsim.colliders.stage` tells how). The package:

* :mod:`~animsim.colliders.shapes`: the shapes, their signed distances and packed rows;
* :mod:`~animsim.colliders.impact`: where a step first touches a shape (the march's
  constants, the search along a grazing path, the face an edge contact runs into);
* :mod:`~animsim.colliders.numpy_rule`: the NumPy kernel (broad phase, march, response,
  projection);
* :mod:`~animsim.colliders.kernels`: its numba twin, to the same bits;
* :mod:`~animsim.colliders.stage`: the step stage, :class:`Colliders`.

The names other modules use are handed on here.
"""

from __future__ import annotations

from animsim.colliders.numpy_rule import resolve_numpy
from animsim.colliders.shapes import (
    BOX,
    CAPSULE,
    KIND_NAMES,
    PARAMS,
    SPHERE,
    Shape,
    axis_angle_quaternion,
    quaternion_matrix,
    sdf,
    shape_bounds,
    shape_of,
)
from animsim.colliders.stage import Colliders

__all__ = [
    "BOX",
    "CAPSULE",
    "KIND_NAMES",
    "PARAMS",
    "SPHERE",
    "Colliders",
    "Shape",
    "axis_angle_quaternion",
    "quaternion_matrix",
    "resolve_numpy",
    "sdf",
    "shape_bounds",
    "shape_of",
]
