"""Teams: handcrafted baselines and trained policies behind one TeamPolicy interface."""

from elevens.teams.base import TeamPolicy

__all__ = ["TeamPolicy"]
