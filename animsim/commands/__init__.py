"""The work behind the commands that show runs and files: the HTML viewer (``view``), the
phase plot, side-by-side renders and the sweep plot. They run scenes (through
:mod:`animsim.panel_runs` and :mod:`animsim.render`) and draw them with :mod:`animsim.export`,
which itself never runs the loop."""
