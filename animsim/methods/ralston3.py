"""Ralston's third-order method: the three-stage explicit Runge-Kutta method with the smallest
bound on its local error among those of order 3 (A. Ralston, "Runge-Kutta methods with
minimum error bounds", Mathematics of Computation 16, 1962, 431-437).

Its stability function is R(z) = 1 + z + z^2/2 + z^3/6, as for every three-stage method of
order 3, so it is stable on an undamped oscillator up to omega dt = sqrt(3).
"""

from animsim.methods import Method, Tableau, register

register(
    Method(
        name="ralston3",
        rank=60,
        order=3,
        description="Ralston's third-order Runge-Kutta (minimum error bound)",
        evaluations_per_step=3,
        tableau=Tableau(
            c=(0.0, 0.5, 0.75),
            a=((), (0.5,), (0.0, 0.75)),
            b=(2 / 9, 1 / 3, 4 / 9),
        ),
        aliases=("rk3", "ralston"),
    )
)
