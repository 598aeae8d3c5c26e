"""The explicit midpoint method (the course notes' "Midpoint method"): derivative at t + dt/2."""

from animsim.methods import Method, Tableau, register

register(
    Method(
        name="midpoint",
        rank=40,
        order=2,
        description="explicit midpoint (RK2): derivative taken at t + dt/2",
        evaluations_per_step=2,
        tableau=Tableau(c=(0.0, 0.5), a=((), (0.5,)), b=(0.0, 1.0)),
    )
)
