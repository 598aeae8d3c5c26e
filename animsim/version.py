"""animsim's version, in a module of its own so that the modules that write it into
their outputs (metadata, PLY and USD headers) need not import the package's face,
which reaches the whole API."""

__version__ = "0.2.0"
