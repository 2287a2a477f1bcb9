"""Matches in rcssserver: a checkpoint or a handcrafted team against another.

Team specs: ``naive`` (the RoboCup naive team of thesis section 6.7, :mod:`elevens.robocup.naive`),
``random`` (uniform actions), a shipped trained team (``elevens-11v11``, ``elevens-2v2``) or a
checkpoint path as ``elevens tournament`` takes it (a run directory, its ``checkpoints``
directory or one step directory, optionally ``PATH@ITERATION``).
A checkpoint trained in the simulator plays unchanged: RoboCupEnv gives it the simulator's
observation containers, and its 2-value (move, rot) actions go through the "sim" action mapping.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from elevens.env.state import Observation
from elevens.robocup.actions import ACTION_SIZES, action_mode
from elevens.robocup.naive import RoboCupNaiveTeam

ROBOCUP_HANDCRAFTED = ("naive", "random")


@dataclasses.dataclass(frozen=True)
class RandomRoboCupTeam:
    """Uniform actions in [-1, 1] (the thesis' random control team)."""

    action_size: int = 2
    name: str = "random"

    def init_carry(self, players_per_team: int) -> np.random.Generator:
        return np.random.default_rng(players_per_team)

    def act(
        self, params: object, carry: np.random.Generator, obs: Observation, key: object = None
    ) -> tuple[np.random.Generator, np.ndarray]:
        n = np.asarray(obs.self_features).shape[0]
        return carry, carry.uniform(-1.0, 1.0, (n, self.action_size)).astype(np.float32)


@dataclasses.dataclass
class _Player:
    """One side's controller: act(carry, obs, key) -> (carry, actions f32[n, a])."""

    name: str
    act: Callable[[Any, Observation, jax.Array], tuple[Any, Any]]
    init_carry: Callable[[int], Any]
    actions: int = 2  # 2: (move, rot) by the action mode; 12: the thesis's action, always


def load_robocup_team(
    spec: str,
    action: str,
    *,
    deterministic: bool = True,
    turn_scale: float = 180.0,
    any_action: bool = False,
) -> _Player:
    """A team for RoboCupEnv from a spec (see the module docstring). ``turn_scale``: the
    env's RoboCupConfig.turn_scale, which the naive team aims its turns by. A checkpoint must
    give the action mode's values unless ``any_action`` (``RoboCupTeam`` maps either kind;
    ``_Player.actions`` says which)."""
    if spec == "naive":
        naive = RoboCupNaiveTeam(action=action, turn_scale=turn_scale)
        return _Player("naive", lambda c, o, k: naive.act(None, c, o, k), naive.init_carry)
    if spec == "random":
        rand = RandomRoboCupTeam(action_size=ACTION_SIZES[action])
        return _Player("random", lambda c, o, k: rand.act(None, c, o, k), rand.init_carry)
    from elevens.runs.teams import load_team

    team = load_team(spec, deterministic=deterministic)
    wanted = action_mode(team.actions)
    if action != wanted and not any_action:
        plays = "(move, rot) actions" if team.actions == 2 else "the thesis's 12-value action"
        raise ValueError(
            f"team {spec!r} is a checkpoint: it plays {plays}, so the action mode must be "
            f"{wanted!r}, not {action!r}"
        )
    policy = team.policy
    act = jax.jit(lambda params, carry, obs, key: policy.act(params, carry, obs, key))
    return _Player(
        team.name, lambda c, o, k: act(team.params, c, o, k), policy.init_carry, team.actions
    )


@dataclasses.dataclass(frozen=True)
class EpisodeResult:
    episode: int
    goals: tuple[int, int]
    """Goals of team 0 (left) and team 1 (right)."""
    steps: int
    restarts: int
    missed: int
    wall_s: float


def play_robocup(
    team0: str,
    team1: str,
    *,
    players_per_team: int = 11,
    episodes: int = 1,
    episode_length: int = 400,
    action: str = "sim",
    keep_ball_in_play: bool = False,
    rcssserver: str | None = None,
    seed: int = 0,
    print_fn: Callable[[str], None] = print,
    env: Any = None,
) -> list[EpisodeResult]:
    """Play ``episodes`` episodes of ``team0`` (left) against ``team1`` (right) in rcssserver."""
    if episodes < 1:
        raise ValueError(f"episodes={episodes!r} is invalid: it must be >= 1")
    if action not in ("sim", "thesis12"):
        raise ValueError(f"action={action!r} is invalid: it must be 'sim' or 'thesis12'")
    teams = [load_robocup_team(spec, action) for spec in (team0, team1)]
    own_env = env is None
    if env is None:
        from elevens.robocup.env import RoboCupConfig, RoboCupEnv

        env = RoboCupEnv(
            RoboCupConfig(
                players_per_team=players_per_team,
                episode_length=episode_length,
                keep_ball_in_play=keep_ball_in_play,
                action=action,
                rcssserver=rcssserver,
            )
        )
    n = env.players_per_team
    results = []
    key = jax.random.key(seed)
    try:
        for episode in range(episodes):
            began = time.perf_counter()
            _, obs = env.reset(seed=seed + episode)
            carries = [team.init_carry(n) for team in teams]
            goals = np.zeros(2, np.int64)
            restarts = missed = steps = 0
            done = False
            while not done:
                key, *team_keys = jax.random.split(key, 3)
                actions = []
                for side, team in enumerate(teams):
                    team_obs = jax.tree.map(lambda leaf, s=side: leaf[s], obs)
                    carries[side], team_actions = team.act(carries[side], team_obs, team_keys[side])
                    actions.append(np.asarray(team_actions, np.float32))
                _, obs, _, done, info = env.step(np.stack(actions))
                steps += 1
                goals += np.asarray(info["goals"])
                missed += int(info.get("missed", 0))
                if info.get("restarted", False):
                    restarts += 1
            result = EpisodeResult(
                episode, (int(goals[0]), int(goals[1])), steps, restarts, missed,
                time.perf_counter() - began,
            )
            results.append(result)
            print_fn(
                f"episode {episode}: {teams[0].name} {result.goals[0]} - {result.goals[1]} "
                f"{teams[1].name} ({steps} steps in {result.wall_s:.1f} s, "
                f"{steps / max(result.wall_s, 1e-9):.0f} steps/s, restarts {restarts}, "
                f"missed thinks {missed})"
            )
    finally:
        if own_env:
            env.close()
    return results
