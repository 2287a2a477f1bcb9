"""Gameplay metrics of a team (thesis table 6.4), computed from recorded matches.

Every quantity is measured in the team's OWN frame (the world point-reflected for a team on side
1, so each team defends x = -L/2 and attacks +x); distances do not care, but "own goal" does.
Per step ``t`` of game ``g``, for the team's ``n`` players:

=================  ===========================================================  =======  ======
metric             per-step value                                               unit     better
=================  ===========================================================  =======  ======
move               ``|move| * move_speed`` of each player                       m/step   lower
rotation           ``|rot| * turn_speed`` of each player                        rad/step lower
ball_distance      distance of each player's centre to the ball's               m        higher
team_distance      distance between each pair of teammates (n(n-1)/2 pairs)     m        higher
closest_to_ball    the smallest player-ball distance of the team                m        lower
closest_to_goal    the smallest distance of a player to its own goal's centre   m        lower
outcome            per game: win 1, draw 0.5, loss 0                            -        higher
possession         per game: the team's share of the steps either team had the  -        higher
                   ball (see below)
passes             per game: the team's kicks whose next touch is a teammate's  count    higher
shots_on_target    per game: the team's touches followed by its goal, and its   count    higher
                   kicks aimed into the goal mouth with the reach to get there
goals              per game: the team's goals (all from open play: the game has count    higher
                   no set pieces)
=================  ===========================================================  =======  ======

The last four come from the touches the env reports each step (``StepInfo.kicks`` and
``pushes``, recorded by ``play_match(record=True)``). A touch is a kick or a push. A step in
which players of both teams touch the ball is contested: nobody has it after it. Otherwise the
touching team has the ball from that step until the other team touches it or a goal restarts
play; if several of its players touch in one step, the toucher is the first kicker among them
(else the first pusher). A pass is a kick by player A whose next touch (before any goal) is by
a teammate B != A. A touch is a shot on target when the team scores before the next touch, or
when it is a kick after which the ball heads for the attacked goal line and crosses it inside
the mouth within its rolling reach (speed * f / (1 - f) with friction f, SPEC.md). So every
goal counts as a shot on target, but own goals (the other team touched the ball last) and a
goal in the last step (which the record does not hold). Matches
recorded without touches (replays) give NaN for these four.

(The "better" column is the thesis' reading of table 6.4; rows 3 and 4 are "higher is better"
because spread-out teams do not bunch up.) The actions are the ones the env applied (clipped).

Each metric is reported as ``mean ± std`` where the mean and the std run over every per-step
value of every game pooled (the thesis' numbers are of this kind: a random team's move is
0.50 ± 0.29, the mean and std of ``|U(-1, 1)|``), and ``game_std`` is the std of the per-game
means (how much the mean itself varies from game to game). For ``outcome`` both stds are the std
over games. ``team_distance`` is NaN for a team of one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from elevens.env.params import EnvParams
from elevens.eval.match import MatchRecord, MatchResult


@dataclasses.dataclass(frozen=True)
class MetricInfo:
    """What a metric means, for tables."""

    name: str
    label: str
    unit: str
    better: str  # "lower" or "higher"


METRICS: tuple[MetricInfo, ...] = (
    MetricInfo("move", "Move", "m/step", "lower"),
    MetricInfo("rotation", "Rotation", "rad/step", "lower"),
    MetricInfo("ball_distance", "Ball distance", "m", "higher"),
    MetricInfo("team_distance", "Team distance", "m", "higher"),
    MetricInfo("closest_to_ball", "Closest to ball", "m", "lower"),
    MetricInfo("closest_to_goal", "Closest to goal", "m", "lower"),
    MetricInfo("outcome", "Average outcome", "win 1, draw 0.5, loss 0", "higher"),
    MetricInfo("possession", "Possession", "share of possessed steps", "higher"),
    MetricInfo("passes", "Passes", "per game", "higher"),
    MetricInfo("shots_on_target", "Shots on target", "per game", "higher"),
    MetricInfo("goals", "Goals", "per game", "higher"),
)
METRIC_NAMES: tuple[str, ...] = tuple(info.name for info in METRICS)


@dataclasses.dataclass(frozen=True)
class TeamTrajectories:
    """One team's games, in its own frame (it attacks +x)."""

    positions: np.ndarray  # f64[G, T, n, 2] the team's players
    opponents: np.ndarray  # f64[G, T, n, 2] the other team's players
    ball: np.ndarray  # f64[G, T, 2]
    actions: np.ndarray  # f64[G, T, n, 2] (move, rot) as applied
    outcome: np.ndarray  # f64[G] the team's outcome
    ball_velocity: np.ndarray | None = None  # f64[G, T, 2]
    goals_for: np.ndarray | None = None  # i64[G, T] the team's goals so far
    goals_against: np.ndarray | None = None  # i64[G, T]
    kicks: np.ndarray | None = None  # bool[G, T, n] the team's kicks in step t
    pushes: np.ndarray | None = None  # bool[G, T, n]
    opponent_touches: np.ndarray | None = None  # bool[G, T, n] the other team's kicks or pushes
    final_goals_for: np.ndarray | None = None  # i64[G] the team's goals at the final whistle


@dataclasses.dataclass(frozen=True)
class MetricStat:
    """One metric of one team: mean and std over pooled per-step values, std of game means."""

    mean: float
    std: float
    game_std: float

    def text(self, digits: int = 2) -> str:
        return f"{self.mean:.{digits}f}±{self.std:.{digits}f}"


@dataclasses.dataclass(frozen=True)
class TeamMetrics:
    """Table 6.4's column of one team against one opponent."""

    team: str
    opponent: str
    games: int
    players_per_team: int
    stats: dict[str, MetricStat]

    def as_dict(self) -> dict[str, Any]:
        return {
            "team": self.team,
            "opponent": self.opponent,
            "games": self.games,
            "players_per_team": self.players_per_team,
            "metrics": {name: dataclasses.asdict(stat) for name, stat in self.stats.items()},
        }


def team_trajectories(result: MatchResult, which: str = "home") -> TeamTrajectories:
    """The ``home`` (or ``away``) team's recorded games in its own frame.

    result: a match played with ``record=True`` (``MatchRecord`` fields ``[G, T, ...]``).
    The team's side in game ``g`` is ``home_side[g]`` (``1 - home_side[g]`` for away); on side 1
    the world is point-reflected (``p -> -p``), which is how that team observes it.
    """
    if which not in ("home", "away"):
        raise ValueError(f"which={which!r} is invalid: use 'home' or 'away'")
    record: MatchRecord | None = result.record
    if record is None:
        raise ValueError("the match has no record: play it with record=True")
    home_side = np.asarray(result.home_side, np.int64)
    side = home_side if which == "home" else 1 - home_side  # i64[G]
    positions = np.asarray(record.positions, np.float64)  # [G, T, 2n, 2]
    actions = np.asarray(record.actions, np.float64)  # [G, T, 2, n, 2]
    n = actions.shape[3]
    sign = np.where(side == 0, 1.0, -1.0)[:, None, None, None]  # [G, 1, 1, 1]

    def rows_of(team_side: np.ndarray) -> np.ndarray:
        index = team_side[:, None] * n + np.arange(n)[None, :]  # [G, n]
        return np.take_along_axis(positions, index[:, None, :, None], axis=2)

    own = rows_of(side) * sign
    other = rows_of(1 - side) * sign
    ball = np.asarray(record.ball_position, np.float64) * sign[:, :, :, 0]
    own_actions = np.take_along_axis(actions, side[:, None, None, None, None], axis=2)[:, :, 0]
    outcome = np.asarray(result.outcome, np.float64)
    if which == "away":
        outcome = 1.0 - outcome
    score = np.asarray(record.score, np.int64)  # [G, T, 2] by side
    goals_for = np.take_along_axis(score, side[:, None, None], axis=2)[..., 0]
    goals_against = np.take_along_axis(score, 1 - side[:, None, None], axis=2)[..., 0]
    extra: dict[str, np.ndarray] = {}
    if record.kicks is not None and record.pushes is not None:
        kicks, pushes = np.asarray(record.kicks, bool), np.asarray(record.pushes, bool)

        def players_of(flags: np.ndarray, team_side: np.ndarray) -> np.ndarray:
            index = team_side[:, None] * n + np.arange(n)[None, :]  # [G, n]
            return np.take_along_axis(flags, index[:, None, :], axis=2)

        extra = {
            "kicks": players_of(kicks, side),
            "pushes": players_of(pushes, side),
            "opponent_touches": players_of(kicks | pushes, 1 - side),
        }
    return TeamTrajectories(
        positions=own, opponents=other, ball=ball, actions=own_actions, outcome=outcome,
        ball_velocity=np.asarray(record.ball_velocity, np.float64) * sign[:, :, :, 0],
        goals_for=goals_for, goals_against=goals_against, **extra,
        final_goals_for=np.asarray(
            result.goals_for if which == "home" else result.goals_against, np.int64
        ),
    )


def per_step_values(traj: TeamTrajectories, params: EnvParams) -> dict[str, np.ndarray]:
    """Every metric's raw values: ``f64[G, T, k]`` (k values per step) or ``f64[G, 1]`` for the
    outcome. See the module docstring for the definitions."""
    positions, ball = traj.positions, traj.ball
    g, t, n, _ = positions.shape
    to_ball = np.linalg.norm(positions - ball[:, :, None, :], axis=-1)  # [G, T, n]
    own_goal = np.array([-float(params.half_length), 0.0])
    to_goal = np.linalg.norm(positions - own_goal, axis=-1)  # [G, T, n]
    first, second = np.triu_indices(n, k=1)
    if first.size:
        team = np.linalg.norm(positions[:, :, first] - positions[:, :, second], axis=-1)
    else:
        team = np.full((g, t, 1), np.nan)
    return {
        "move": np.abs(traj.actions[..., 0]) * float(params.move_speed),
        "rotation": np.abs(traj.actions[..., 1]) * float(params.turn_speed),
        "ball_distance": to_ball,
        "team_distance": team,
        "closest_to_ball": to_ball.min(axis=-1, keepdims=True),
        "closest_to_goal": to_goal.min(axis=-1, keepdims=True),
        "outcome": traj.outcome[:, None],
        **match_statistics(traj, params),
    }


def match_statistics(traj: TeamTrajectories, params: EnvParams) -> dict[str, np.ndarray]:
    """Possession share, passes, shots on target and goals of the team, ``f64[G, 1]`` each
    (see the module docstring); NaN where the record has no touches."""
    games = traj.positions.shape[0]
    names = ("possession", "passes", "shots_on_target", "goals")
    if traj.kicks is None or traj.pushes is None or traj.opponent_touches is None:
        return {name: np.full((games, 1), np.nan) for name in names}
    assert traj.ball_velocity is not None and traj.goals_for is not None
    assert traj.goals_against is not None
    out = {name: np.zeros((games, 1)) for name in names}
    for game in range(games):
        stats = _game_statistics(
            traj.kicks[game], traj.pushes[game], traj.opponent_touches[game],
            traj.ball[game], traj.ball_velocity[game], traj.goals_for[game],
            traj.goals_against[game], params,
        )
        for name, value in zip(names[:3], stats, strict=True):
            out[name][game, 0] = value
    out["goals"][:, 0] = traj.final_goals_for if traj.final_goals_for is not None else np.nan
    return out


def _on_target(position: np.ndarray, velocity: np.ndarray, params: EnvParams) -> bool:
    """Does a ball at ``position`` moving at ``velocity`` (own frame, after friction) roll over
    the attacked goal line (x = +L/2) inside the mouth before it stops?"""
    if velocity[0] <= 0:
        return False
    half_length, goal_half = float(params.half_length), float(params.goal_width) / 2
    friction = float(params.ball_friction)
    steps_to_line = (half_length - position[0]) / velocity[0]
    y = position[1] + velocity[1] * steps_to_line
    reach = float(np.hypot(*velocity)) / (1.0 - friction)
    travel = float(np.hypot(half_length - position[0], y - position[1]))
    return abs(y) <= goal_half and travel <= reach


def _flags(values: Any) -> list[bool]:
    return [bool(value) for value in values]


def _game_statistics(
    kicks: np.ndarray, pushes: np.ndarray, opponent_touches: np.ndarray, ball: np.ndarray,
    ball_velocity: np.ndarray, goals_for: np.ndarray, goals_against: np.ndarray,
    params: EnvParams,
) -> tuple[float, int, int]:
    """One game's (possession share, passes, shots on target); arrays over its T steps."""
    steps = kicks.shape[0]
    touches = kicks | pushes
    # Python lists: the loop reads one flag at a time, which numpy scalars make slow.
    own_touch, own_kick = _flags(touches.any(axis=1)), _flags(kicks.any(axis=1))
    other_touch = _flags(opponent_touches.any(axis=1))
    scored_for = _flags(np.diff(goals_for, prepend=goals_for[:1]))
    scored_against = _flags(np.diff(goals_against, prepend=goals_against[:1]))
    holder = 0  # who has the ball: 1 the team, -1 the opponent, 0 nobody
    held = [0, 0, 0]  # steps held by nobody, the team, the opponent (indexed by holder)
    last: tuple[int, int, bool] | None = None  # (team 1 / opponent -1, player, kicked)
    passes = shots = 0
    # The team's last touch, until the next event (a touch or a goal) says whether it was a
    # shot on target: a goal for the team, or a kick aimed into the mouth with the reach.
    pending = aimed = False
    for t in range(steps):
        if scored_for[t] or scored_against[t]:  # a goal in step t - 1: play restarts
            shots += pending and (scored_for[t] or aimed)
            pending = aimed = False
            holder, last = 0, None
        if own_touch[t] or other_touch[t]:
            shots += pending and aimed  # on target, but it did not go in
            pending = aimed = False
        if own_touch[t] and other_touch[t]:  # contested: still a touch of the team's
            holder, last, pending = 0, None, True
        elif own_touch[t]:
            kicked = own_kick[t]
            player = int(np.flatnonzero(kicks[t] if kicked else touches[t])[0])
            if last is not None and last[0] == 1 and last[2] and last[1] != player:
                passes += 1
            pending = True
            aimed = kicked and t + 1 < steps and not (scored_for[t + 1] or scored_against[
                t + 1]) and _on_target(ball[t + 1], ball_velocity[t + 1], params)
            holder, last = 1, (1, player, kicked)
        elif other_touch[t]:
            holder, last = -1, (-1, 0, False)
        held[holder] += 1
    shots += pending and aimed
    possessed = held[1] + held[-1]
    share = held[1] / possessed if possessed else float("nan")
    return float(share), passes, shots


def _stat(values: np.ndarray) -> MetricStat:
    """values f64[G, ...]: pooled mean and std, and the std of the per-game means."""
    if np.all(np.isnan(values)):
        return MetricStat(mean=float("nan"), std=float("nan"), game_std=float("nan"))
    per_game = values.reshape(values.shape[0], -1).mean(axis=1)
    return MetricStat(
        mean=float(values.mean()), std=float(values.std()), game_std=float(per_game.std())
    )


def compute_metrics(
    result: MatchResult,
    params: EnvParams,
    *,
    team: str = "home",
    team_name: str = "home",
    opponent_name: str = "away",
) -> TeamMetrics:
    """Table 6.4's metrics of the ``home`` (or ``away``) team of a recorded match."""
    traj = team_trajectories(result, team)
    values = per_step_values(traj, params)
    return TeamMetrics(
        team=team_name,
        opponent=opponent_name,
        games=int(traj.outcome.size),
        players_per_team=int(traj.positions.shape[2]),
        stats={name: _stat(values[name]) for name in METRIC_NAMES},
    )


def print_metrics(rows: Sequence[TeamMetrics], console: Any = None) -> None:
    """Table 6.4 as a rich table: one column per team, ``mean ± std`` (pooled per step)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console if console is not None else Console()
    opponents = sorted({row.opponent for row in rows})
    games = sorted({row.games for row in rows})
    table = Table(
        title=escape(f"Gameplay metrics against {', '.join(opponents)}"),
        caption=escape(
            f"{', '.join(map(str, games))} games, team's own frame; mean ± std over every step "
            "of every game (outcome: over games); [std of the per-game means]"
        ),
        title_justify="left",
        caption_justify="left",
    )
    table.add_column("metric", style="bold")
    table.add_column("unit")
    table.add_column("better")
    for row in rows:
        table.add_column(escape(row.team), justify="right")
    for info in METRICS:
        cells = []
        for row in rows:
            stat = row.stats[info.name]
            cells.append(escape(f"{stat.text()} [{stat.game_std:.2f}]"))
        table.add_row(info.label, info.unit if info.name != "outcome" else "-", info.better,
                      *cells)
    console.print(table)


def save_metrics(rows: Sequence[TeamMetrics], path_stem: str | Any) -> dict[str, Any]:
    """Write ``<stem>.csv`` (long: team, opponent, metric, unit, mean, std, game_std, games)
    and ``<stem>.json``; returns their paths."""
    import csv
    import json
    from pathlib import Path

    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    units = {info.name: info.unit for info in METRICS}
    with csv_path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["team", "opponent", "metric", "unit", "mean", "std", "game_std",
                         "games"])
        for row in rows:
            for name, stat in row.stats.items():
                writer.writerow([row.team, row.opponent, name, units[name], f"{stat.mean:.6g}",
                                 f"{stat.std:.6g}", f"{stat.game_std:.6g}", row.games])
    payload = {
        "format": "elevens-metrics",
        "version": 1,
        "definitions": {info.name: dataclasses.asdict(info) for info in METRICS},
        "teams": [row.as_dict() for row in rows],
    }
    json_path.write_text(json.dumps(payload, indent=2) + "\n", encoding="utf-8")
    return {"csv": csv_path, "json": json_path}
