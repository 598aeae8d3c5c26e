"""Explicit (forward) Euler: x += dt v(t); v += dt a(t) (the course notes' Euler method)."""

import numpy as np

from animsim.methods import Method, Tableau, register


def closed_form_limit(omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """|1 + h lambda| <= 1 for the complex pair lambda: h <= 2 zeta / omega; overdamped, the
    fast real root sets it: h |lambda_fast| <= 2."""
    fast = omega * (zeta + np.sqrt(np.maximum(zeta * zeta - 1.0, 0.0)))
    with np.errstate(divide="ignore"):
        return np.asarray(np.where(zeta < 1.0, 2.0 * zeta / omega, 2.0 / fast))


register(
    Method(
        name="euler",
        rank=10,
        order=1,
        description="explicit (forward) Euler: x += dt*v(t); v += dt*a(t)",
        evaluations_per_step=1,
        tableau=Tableau(c=(0.0,), a=((),), b=(1.0,)),
        closed_form_limit=closed_form_limit,
        aliases=("explicit_euler", "forward_euler"),
    )
)
