"""``python -m animsim`` is the same as the ``animsim`` command."""

from animsim.cli import main

main()
