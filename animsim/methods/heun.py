"""Heun's method, the explicit trapezoid rule (Hairer, Norsett and Wanner, I, II.1)."""

from animsim.methods import Method, Tableau, register

register(
    Method(
        name="heun",
        rank=50,
        order=2,
        description="Heun's method (explicit trapezoid, RK2)",
        evaluations_per_step=2,
        tableau=Tableau(c=(0.0, 1.0), a=((), (1.0,)), b=(0.5, 0.5)),
    )
)
