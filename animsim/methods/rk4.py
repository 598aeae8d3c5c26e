"""The classical fourth-order Runge-Kutta method (Kutta 1901; Hairer, Norsett and Wanner, I, II.1)."""

from animsim.methods import Method, Tableau, register

register(
    Method(
        name="rk4",
        rank=70,
        order=4,
        description="classical fourth-order Runge-Kutta",
        evaluations_per_step=4,
        tableau=Tableau(
            c=(0.0, 0.5, 0.5, 1.0),
            a=((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)),
            b=(1 / 6, 1 / 3, 1 / 3, 1 / 6),
        ),
        suggest_rank=3,
        aliases=("rk", "runge_kutta", "runge_kutta_4"),
    )
)
