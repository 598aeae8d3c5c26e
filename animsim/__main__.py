"""``python -m animsim`` is the same as the ``animsim`` command."""

from animsim.startup import pause_collector

pause_collector()  # importing the command line already allocates much (animsim.startup)

from animsim.cli import main  # noqa: E402

main()
