"""animsim: physically based animation from a text file.

The flow is one-way: load (``animsim.scene``) -> compile (``animsim.compile``)
-> simulate (``animsim.simulate``) -> record (``animsim.record``) -> export
(``animsim.export``).
"""

__version__ = "0.1.0"
