"""``python -m siloflow.cli``: the ``siloflow`` command."""
from . import main

main()
