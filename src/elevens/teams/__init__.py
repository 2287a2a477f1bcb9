"""Teams: handcrafted baselines and trained policies behind one TeamPolicy interface."""

from elevens.teams.base import TeamPolicy
from elevens.teams.scripted import NaiveTeam, RandomTeam, TeamworkTeam

__all__ = ["NaiveTeam", "RandomTeam", "TeamPolicy", "TeamworkTeam"]
