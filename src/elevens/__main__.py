"""``python -m elevens``: the same as the ``elevens`` command."""

from elevens.cli import main

main()
