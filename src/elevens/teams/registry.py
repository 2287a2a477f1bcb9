"""The named teams: the handcrafted ones by name, told the field they play on."""

from __future__ import annotations

import dataclasses
import typing

from elevens.env import EnvParams
from elevens.teams.base import TeamPolicy
from elevens.teams.panel import PANEL_TEAMS
from elevens.teams.scripted import Field, NaiveTeam, RandomTeam, TeamworkTeam

HANDCRAFTED: dict[str, TeamPolicy] = {
    "random": RandomTeam(),
    "naive": NaiveTeam(),
    "teamwork": TeamworkTeam(),
    **{team.name: team for team in PANEL_TEAMS},
}

PANEL: tuple[str, ...] = tuple(team.name for team in PANEL_TEAMS)
"""The opponent panel (``elevens.teams.panel``): handcrafted teams of distinct styles that a
trained team is measured against (``elevens tournament TEAM --panel``)."""


def register_team(name: str, team: TeamPolicy) -> None:
    """Make a handcrafted team of a game above the core known by name (``resolve_team``); a
    team with an ``on_field(Field)`` method is told the field it plays on by that method."""
    HANDCRAFTED[name] = team


def action_size(team: TeamPolicy) -> int:
    """Action values a handcrafted team gives: 2, the simulator's (move, rot), or its
    ``actions`` (a registered team of another game)."""
    return int(getattr(team, "actions", 2))


def handcrafted_for(actions: int) -> list[str]:
    """The handcrafted teams' names that give ``actions`` action values."""
    return sorted(name for name, team in HANDCRAFTED.items() if action_size(team) == actions)


def resolve_team(name: str, params: EnvParams | None = None) -> TeamPolicy:
    """A handcrafted team by name, told the field of ``params`` when given.

    The scripted teams un-normalise their observations with an assumed geometry (SPEC.md's
    100 x 70 field by default); on another field they need its numbers, or they would aim at the
    wrong goal. Unknown names are a clear error that lists the allowed ones.
    """
    try:
        team = HANDCRAFTED[name]
    except KeyError:
        raise ValueError(
            f"team {name!r} is unknown: allowed are {', '.join(sorted(HANDCRAFTED))}"
        ) from None
    if params is None:
        return team
    field = Field.of(params)
    if getattr(team, "on_field", None) is None and field == Field():
        return team
    return fielded(team, field)


def on_game(team: TeamPolicy, params: EnvParams) -> TeamPolicy:
    """``team`` on the field of one drawn game (``elevens.env.randomize``), inside a trace:
    ``params``' leaves may be tracers, and the team made here is never hashed."""
    return fielded(team, Field.of(params))


def fielded(team: TeamPolicy, field: Field) -> TeamPolicy:
    """``team`` told ``field``: the scripted teams and those with an ``on_field`` method; any
    other team (a network, random) is returned as it is."""
    on_field = getattr(team, "on_field", None)
    if on_field is not None:  # a registered team that knows its own default field
        return typing.cast(TeamPolicy, on_field(field))
    if isinstance(team, NaiveTeam):
        return dataclasses.replace(team, field=field)
    if isinstance(team, TeamworkTeam):
        return dataclasses.replace(team, attack=dataclasses.replace(team.attack, field=field))
    return team
