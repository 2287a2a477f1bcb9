"""The ``elevens`` command: one module per command group (train, eval, robocup, bench), the
dispatch in ``main`` and the shared one-line error handling in ``checks``."""

from __future__ import annotations

from typing import Any


def main(argv: list[str] | None = None) -> Any:
    """The ``elevens`` console script (``elevens.cli.app.main``, imported on use)."""
    from elevens.cli.app import main as run

    return run(argv)
