"""What the theory says, written once for every numerics test.

Global orders of accuracy from the spec's integrator table (Hairer, Norsett
and Wanner; the course notes for Euler and midpoint). The tests measure the
code against these, so they are spelt out here rather than read from the
integrator classes.
"""

ORDERS = {
    "euler": 1,
    "symplectic_euler": 1,
    "euler_average": 1,
    "midpoint": 2,
    "heun": 2,
    "ralston3": 3,
    "rk4": 4,
    "verlet": 2,
    "implicit_euler": 1,
}
#: how far an observed order may sit from the theory (issue 4: within 0.2)
ORDER_TOLERANCE = 0.2
