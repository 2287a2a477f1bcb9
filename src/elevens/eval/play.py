"""Play one recorded game between two teams and draw it (`elevens play`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp

import elevens
from elevens.env import EnvParams, State
from elevens.eval.match import MatchRecord, play_match
from elevens.teams.base import TeamPolicy
from elevens.teams.scripted import Field, NaiveTeam, RandomTeam, TeamworkTeam

HANDCRAFTED: dict[str, TeamPolicy] = {
    "random": RandomTeam(),
    "naive": NaiveTeam(),
    "teamwork": TeamworkTeam(),
}


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
    field = Field(
        half_length=float(params.half_length),
        half_width=float(params.half_width),
        goal_half_width=float(params.goal_width) / 2,
        turn_speed=float(params.turn_speed),
        ball_friction=float(params.ball_friction),
    )
    if field == Field():
        return team
    if isinstance(team, NaiveTeam):
        return dataclasses.replace(team, field=field)
    if isinstance(team, TeamworkTeam):
        return dataclasses.replace(team, attack=dataclasses.replace(team.attack, field=field))
    return team


def states_from_record(record: MatchRecord, game: int, params: EnvParams) -> State:
    """The per-step States ``[T, ...]`` of one recorded game, for drawing.

    The record keeps what pictures need; velocities and start points are not recorded, so they
    are zero here, and last actions come from the recorded actions.
    """
    positions = record.positions[game]
    steps = positions.shape[0]
    num_players = positions.shape[1]
    return State(
        positions=positions,
        headings=record.headings[game],
        velocities=jnp.zeros_like(positions),
        last_actions=record.actions[game].reshape(steps, num_players, 2),
        start_positions=jnp.broadcast_to(positions[:1], positions.shape),
        ball_position=record.ball_position[game],
        ball_velocity=record.ball_velocity[game],
        score=record.score[game],
        step=jnp.arange(steps, dtype=jnp.int32),
    )


def play_and_render(
    home: str = "naive",
    away: str = "teamwork",
    players: int = 11,
    out: Path = Path("game.gif"),
    seed: int = 0,
    steps: int | None = None,
    fps: int = 20,
    scale: int = 6,
    view: int | None = None,
) -> Path:
    """Play one game (home on side 0) and write it as a GIF or MP4 with a progress bar."""
    from rich.console import Console

    from elevens.env.render import frames_from_states, save_video

    console = Console(stderr=True)
    out = Path(out)
    if out.suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"out={str(out)!r} is invalid: the suffix must be .gif or .mp4")
    overrides = {} if steps is None else {"episode_length": steps}
    env, params = elevens.make(f"{players}v{players}", **overrides)
    home_team, away_team = resolve_team(home, params), resolve_team(away, params)
    if view is not None and not 0 <= view < params.num_players:
        raise ValueError(
            f"view={view} is invalid: it must be a player row from 0 to {params.num_players - 1}"
        )
    with console.status(f"playing {home} v {away}, {players} a side"):
        result = play_match(
            env, params, home_team, away_team, jax.random.key(seed), num_games=1,
            swap_sides=False, record=True,
        )
    assert result.record is not None
    states = states_from_record(result.record, 0, params)
    goals_for, goals_against = int(result.goals_for[0]), int(result.goals_against[0])
    console.print(f"{home} {goals_for} : {goals_against} {away}")
    frames = frames_from_states(
        states, params, player=view, progress=True, team_names=(home, away), scale=scale
    )
    save_video(frames, out, fps=fps)
    console.print(f"wrote {out} ({len(frames)} frames)")
    return out
