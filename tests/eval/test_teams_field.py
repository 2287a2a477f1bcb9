"""Matches between checkpoints are played on the field the checkpoints trained on."""

from __future__ import annotations

import dataclasses

import pytest

import elevens
from elevens.runs.teams import Team, common_field, fit_to_field, load_team
from elevens.teams.scripted import Field, NaiveTeam


def checkpoint_like(name: str, field: tuple[float, float, float]) -> Team:
    return Team(name=name, policy=NaiveTeam(), params={"params": {}}, field=field, spec=name)


def test_handcrafted_teams_alone_keep_the_spec_field() -> None:
    teams = [load_team("naive"), load_team("teamwork")]
    assert common_field(teams) == {}


def test_checkpoints_set_the_field_and_handcrafted_teams_follow_it() -> None:
    small = (50.0, 35.0, 20.0)
    teams = [checkpoint_like("a", small), checkpoint_like("b", small), load_team("naive")]
    field = common_field(teams)
    assert field == {"field_length": 50.0, "field_width": 35.0, "goal_width": 20.0}
    _, params = elevens.make("1v1", **field)
    fitted = fit_to_field(teams[2], params)
    assert isinstance(fitted.policy, NaiveTeam)
    assert fitted.policy.field == Field(
        half_length=25.0, half_width=17.5, goal_half_width=10.0,
        turn_speed=float(params.turn_speed), ball_friction=float(params.ball_friction),
    )
    # Checkpoints are left as they are.
    assert fit_to_field(teams[0], params) is teams[0]


def test_checkpoints_of_different_fields_are_refused_by_name() -> None:
    teams = [checkpoint_like("small", (50.0, 35.0, 20.0)),
             checkpoint_like("full", (100.0, 70.0, 40.0))]
    with pytest.raises(ValueError, match="different fields.*small.*full"):
        common_field(teams)
    assert dataclasses.replace(teams[1], field=None).field is None
