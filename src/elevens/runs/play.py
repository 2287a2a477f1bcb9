"""Play one recorded game between two teams given by spec and draw it (`elevens play`)."""

from __future__ import annotations

from pathlib import Path

import jax

import elevens
from elevens.eval.match import play_match
from elevens.eval.play import states_from_record


def play_and_render(
    home: str = "naive",
    away: str = "teamwork",
    players: int = 11,
    out: Path | None = Path("game.gif"),
    seed: int = 0,
    steps: int | None = None,
    fps: int = 20,
    scale: int = 6,
    view: int | None = None,
    replay: Path | None = None,
    deterministic: bool | None = None,
    follow_ball: float | None = None,
) -> Path | None:
    """Play one game (home on side 0) and write it as a GIF or MP4 with a progress bar, and as
    a replay file (``elevens view`` opens it) when ``replay`` is given. Teams are specs of
    ``elevens.runs.teams``: random, naive, teamwork, a shipped trained team or a checkpoint.
    Returns the video's path (None when ``out`` is None)."""
    from rich.console import Console

    from elevens.env.render import frames_from_states, save_video, with_full_time
    from elevens.eval.replay import SUFFIX, replay_from_match, save_replay
    from elevens.runs.teams import (
        check_team_size,
        common_field,
        fit_to_field,
        load_team,
        unique_names,
    )

    console = Console(stderr=True)
    if out is None and replay is None:
        raise ValueError("nothing to write: give out (a .gif or .mp4) or replay (a .npz)")
    if out is not None and Path(out).suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"out={str(out)!r} is invalid: the suffix must be .gif or .mp4")
    if replay is not None and Path(replay).suffix.lower() != SUFFIX:
        raise ValueError(f"replay={str(replay)!r} is invalid: the suffix must be {SUFFIX}")
    teams = [load_team(spec, deterministic=deterministic) for spec in (home, away)]
    for team in teams:
        check_team_size(team, players)
    home_name, away_name = unique_names(teams)
    overrides: dict[str, float] = dict(common_field(teams))
    if steps is not None:
        overrides["episode_length"] = steps
    env, params = elevens.make(f"{players}v{players}", **overrides)
    home_team, away_team = (fit_to_field(team, params) for team in teams)
    if view is not None and not 0 <= view < params.num_players:
        raise ValueError(
            f"view={view} is invalid: it must be a player row from 0 to {params.num_players - 1}"
        )
    with console.status(f"playing {home_name} v {away_name}, {players} a side"):
        result = play_match(
            env, params, home_team.policy, away_team.policy, jax.random.key(seed), num_games=1,
            home_params=home_team.params, away_params=away_team.params, swap_sides=False,
            record=True,
        )
    assert result.record is not None
    goals_for, goals_against = int(result.goals_for[0]), int(result.goals_against[0])
    # The result on stdout (the status above is on stderr, as progress is).
    print(f"{home_name} {goals_for} : {goals_against} {away_name}", flush=True)
    if replay is not None:
        saved = save_replay(
            replay_from_match(result, params, 0, home_name, away_name, {"seed": seed}), replay
        )
        print(f"wrote {saved}", flush=True)
    if out is None:
        return None
    states = with_full_time(states_from_record(result.record, 0, params),
                            (goals_for, goals_against))  # home on side 0
    frames = frames_from_states(
        states, params, player=view, progress=True, team_names=(home_name, away_name),
        scale=scale, follow_ball=follow_ball,
    )
    save_video(frames, Path(out), fps=fps)
    print(f"wrote {out} ({len(frames)} frames)", flush=True)
    return Path(out)
