"""The work behind the API's calls (:mod:`animsim.api` documents each and imports its
module only when called): a scene on its way in (``inputs``: load, overrides, pre-flight,
output checks), ``simulation``, one module per command (``run_command``,
``explain_command``, ``render_command``, ``viewer_command``, ``plot_command``,
``sweep_command``, ``compare_command``) and what the calls return (``outcomes``); and the
work behind the commands that show runs and files: the HTML viewer (``view``), the phase
plot, side-by-side renders and the sweep plot. They run scenes (through
:mod:`animsim.panel_runs` and :mod:`animsim.render`) and draw them with
:mod:`animsim.export`, which itself never runs the loop."""
