"""What the runs layer refuses with (its own type, so commands report it in one line)."""

from __future__ import annotations


class RunRefusedError(ValueError):
    """A run will not start: the run directory holds another run's checkpoints, or a resume
    does not match them. Raised before anything compiles, and nothing saved is touched."""
