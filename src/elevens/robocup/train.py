"""Training in rcssserver: the same PPO as in the simulator, fed by games on server processes.

The thesis (sections 4.5 and 6.7) trains its algorithm unchanged in the official server. Here
``G`` RoboCupEnv games, each on its own rcssserver process, play one episode each per iteration
on the host (a separate process cannot be compiled), recorded and packed as the compiled
rollout's are; the run is ``elevens.runs.loop.train``'s with these games in place of the
compiled ones (``HostGames``): the learner's ``improve``, logs, checkpoints, resume, time budget.

Every game is reset at the start of an iteration and ends after ``episode_length`` steps. A
server that dies mid-episode is restarted with a fresh episode, marked as an end and a start.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.state import Observation
from elevens.play import NetworkActor, home_sides, pick_side, place_sides
from elevens.robocup.actions import action_mode
from elevens.runs.layout import RunLayout
from elevens.runs.loop import Collect, HostGames, TrainResult, train
from elevens.train.config import (
    LearnerConfig,
    RunConfig,
    TrainConfig,
    apply_overrides,
    make_config,
    validate,
)
from elevens.train.learner import Learner, TrainState, make_learner
from elevens.train.rollout import Rollout, StepRecord, collected

EPISODE_FIELDS = (
    "iteration", "game", "learner_side", "goals_for", "goals_against", "steps", "server_cycles",
    "restarts", "missed", "malformed", "ball_returned", "wall_s",
)
"""Columns of episodes.csv. server_cycles: how far the server's clock moved during the episode;
it equals steps unless play stopped (after a goal the clock stands for the respawn) or actions
slipped, so a lockstep run shows server_cycles <= steps with small, explained gaps."""


@dataclasses.dataclass(frozen=True)
class ServerConfig:
    """What only a run in rcssserver has: the servers' rules, binary and threads, and an
    external opponent. One server process plays each game of an iteration
    (``games_per_iteration`` servers)."""

    episodes: str = "drill"
    """"drill": episodes spawned by the trainer into play_on, a goal respawns everyone (the
    thesis' training in the server). "match": episodes played as a regulation match is, from a
    kick-off, with the referee's restarts and the match routines (set pieces, the goalie's
    catch and guard, stamina pacing) that ``elevens robocup match`` plays with
    (elevens.robocup.env.RoboCupConfig.episodes)."""
    keep_ball_in_play: bool = True
    """In drills: put the ball back at the lines instead of kick-ins (the thesis did this
    while shaping). Match episodes always have the referee's kick-ins."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""
    threads: bool = True
    """Step the games' servers from a thread pool, so one server simulates while Python parses
    another's messages."""
    opponent_cmd: str | None = None
    """Learn against another team's binaries instead of ``opponent.kind``: its start command,
    with {host}, {port}, {coach_port} and {team} filled in (elevens.robocup.external), started
    beside every server, e.g. "HELIOS/start.sh -p {port} -P {coach_port} -t {team}". The
    learner then always plays the left side."""
    opponent_name: str = "opponent"
    """The external opponent's team name."""

    def __post_init__(self) -> None:
        from elevens.robocup.env import EPISODE_MODES

        if self.episodes not in EPISODE_MODES:
            raise ValueError(
                f"server.episodes={self.episodes!r} is invalid: allowed values are "
                f"{EPISODE_MODES}"
            )
        if self.opponent_cmd is not None and not self.opponent_cmd.strip():
            raise ValueError(
                f"server.opponent_cmd={self.opponent_cmd!r} is invalid: it must be None or a "
                "start command"
            )
        if self.opponent_name in ("", "elevens_l"):
            raise ValueError(
                f"server.opponent_name={self.opponent_name!r} is invalid: it must be a team "
                "name other than elevens_l"
            )


# The EnvParams fields elevens robocup train passes to its servers' RoboCupEnv
# (_default_env_factory); rcssserver sets every other one (field, bodies, ball, view).
SERVER_GAME_FIELDS = (
    "players_per_team", "episode_length", "spawn", "ball_spawn", "goal_reward",
    "ball_shaping_weight", "approach_shaping_weight", "possession_shaping_weight",
    "possession_radius", "possession_by",
)
ROBOCUP_CONFIG_JSON = "robocup_config.json"  # the whole RoboCupTrainConfig, beside config.json
# The EnvConfig fields that only the simulator's game reads (EnvConfig.game and the shaping
# schedule's are honoured); robocup train refuses them rather than ignore them.
SERVER_ENV_FIELDS = ("mix", "mix_shares", "physics")


def _robocup_learner() -> LearnerConfig:
    # The simulator's 2v2 learner with table 6.1's learning rate, 200-cycle drills, one game
    # (server) per minibatch and one iteration per step of the host loop.
    learner = make_config("2v2").learner
    return dataclasses.replace(
        learner,
        env=dataclasses.replace(
            learner.env,
            game=dataclasses.replace(learner.env.game, episode_length=200, spawn="formation"),
        ),
        ppo=dataclasses.replace(learner.ppo, learning_rate=1e-4, minibatch_size=2),
        games_per_iteration=2,
        iterations_per_chunk=1,
    )


ROBOCUP_RUN = RunConfig(
    iterations=1000, max_minutes=10.0, eval_teams=(), checkpoint_every=5,
    run_dir="runs/robocup", write_plot=True, write_gif=False,
)
"""The host loop's defaults in rcssserver: 10 minutes, no evaluation in the simulator (give
``run.eval_teams`` to track the policy there), a checkpoint every 5 iterations."""


@dataclasses.dataclass(frozen=True)
class RoboCupTrainConfig:
    """A training run in rcssserver: the simulator's learner and host-loop configs (the same
    flags as ``elevens train``) plus the server's."""

    learner: LearnerConfig = dataclasses.field(default_factory=_robocup_learner)
    """What is computed: the game (``env.players_per_team``, ``env.episode_length`` in server
    cycles, the shaping weights), networks, PPO, opponent; ``games_per_iteration`` servers."""
    run: RunConfig = ROBOCUP_RUN
    """Length (iterations, max_minutes), checkpoints, seed, init_from (a simulator checkpoint or
    team: the thesis' transfer), run directory; evaluation in the simulator with eval_teams."""
    server: ServerConfig = ServerConfig()
    """The servers and an external opponent."""

    def validate(self) -> RoboCupTrainConfig:
        """``elevens.train.config.validate`` on the learner and run, and the run fields this
        loop cannot honour; raises ``ValueError`` naming the field."""
        validate(self.train_config())
        if self.run.devices not in (0, 1):
            raise ValueError(
                f"run.devices={self.run.devices!r} is invalid in elevens robocup train: the "
                "games play on the host and the update on one device; use 0 or 1"
            )
        if self.learner.network.actions == 12:
            # Both play games in the simulator, which has no 12-value action.
            for flag, value in (("run.eval_teams", self.run.eval_teams),
                                ("run.write_gif", self.run.write_gif)):
                if value:
                    raise ValueError(
                        f"{flag}={value!r} is invalid with network.actions=12: it plays the "
                        "simulator, whose players take the 2-value (move, rot) action; leave "
                        "it out (evaluate a 12-value team with elevens robocup match)"
                    )
        env, default_env = self.learner.env, _robocup_learner().env
        for name in SERVER_ENV_FIELDS:
            value = getattr(env, name)
            if value != getattr(default_env, name):
                raise ValueError(
                    f"env.{name}={value!r} is invalid in elevens robocup train: it sets up the "
                    "simulator's game, and here rcssserver plays one team size with its own "
                    "bodies, stamina, view and goalies (the match routines, with "
                    "--server.episodes match); leave it out"
                )
        game, default = env.game, default_env.game
        for field in dataclasses.fields(game):
            value = getattr(game, field.name)
            if field.name not in SERVER_GAME_FIELDS and value != getattr(default, field.name):
                raise ValueError(
                    f"env.{field.name}={value!r} is invalid in elevens robocup train: "
                    "rcssserver sets the field, the bodies and the ball; the game fields it "
                    f"takes are {', '.join(SERVER_GAME_FIELDS)}"
                )
        if game.possession_shaping_weight > 0 and game.possession_by != "near":
            raise ValueError(
                f"env.possession_by={game.possession_by!r} is invalid in elevens robocup train "
                "with env.possession_shaping_weight > 0: the trainer sees the server's "
                "positions, not who touched the ball; use --env.possession-by near"
            )
        if self.learner.env.game.episode_length < 2:
            raise ValueError(
                f"env.episode_length={self.learner.env.game.episode_length!r} is invalid in "
                "elevens robocup train: it must be at least 2 server cycles"
            )
        return self

    def train_config(self) -> TrainConfig:
        """The TrainConfig saved with every checkpoint (a resume compares it)."""
        return TrainConfig(preset="robocup", learner=self.learner, run=self.run)


def make_robocup_config(**overrides: Any) -> RoboCupTrainConfig:
    """The default ``RoboCupTrainConfig`` with fields replaced by their flags' names, as
    ``elevens.train.config.make_config`` names them (``env.players_per_team``,
    ``games_per_iteration``, ``run.iterations``, ...) plus ``server.NAME``; validated."""
    return apply_overrides(RoboCupTrainConfig(), overrides).validate()


@dataclasses.dataclass
class RoboCupTrainResult(TrainResult):
    """``elevens.runs.loop.train``'s result and this call's server games and restarts."""

    episodes: int = 0
    restarts: int = 0


EnvFactory = Callable[[int], Any]  # game g -> its RoboCupEnv (reset, step, global_state)


def _default_env_factory(config: RoboCupTrainConfig) -> EnvFactory:
    from elevens.robocup.env import RoboCupConfig, RoboCupEnv

    game, server = config.learner.env.game, config.server
    env_config = RoboCupConfig(
        # The loop ends episodes itself; the env's own limit only has to lie beyond.
        episode_length=game.episode_length + 1,
        **{name: getattr(game, name) for name in SERVER_GAME_FIELDS
           if name not in ("episode_length", "possession_by")},  # "near", the env's
        episodes=server.episodes,
        keep_ball_in_play=server.keep_ball_in_play and server.episodes == "drill",
        action=action_mode(config.learner.network.actions),
        rcssserver=server.rcssserver,
        opponent_cmd=server.opponent_cmd,
        team_names=("elevens_l", server.opponent_name if server.opponent_cmd else "elevens_r"),
    )
    return lambda index: RoboCupEnv(env_config)


def train_robocup(
    config: RoboCupTrainConfig, *, resume: bool = False, env_factory: EnvFactory | None = None,
    progress: bool = True,
) -> RoboCupTrainResult:
    """Run ``config`` with ``elevens.runs.loop.train``, every iteration's games played on G
    servers (``env_factory``: how to start game g's, by default a RoboCupEnv), then the
    learner's ``improve``; logging, evaluation in the simulator (``run.eval_teams``),
    checkpoints, ``resume``, ``run.max_minutes`` (summed over sessions), Ctrl-C and the
    learning curve are the loop's, as in ``elevens train``."""
    config.validate()
    servers = ServerGames(config, env_factory or _default_env_factory(config))
    host = HostGames(
        make_learner=lambda learner, env: make_learner(
            learner, env, devices=1, external_games=True
        ),
        open=servers.open,
    )
    result = train(config.train_config(), resume=resume, progress=progress, host=host)
    fields = {field.name: getattr(result, field.name) for field in dataclasses.fields(result)}
    return RoboCupTrainResult(**fields, episodes=servers.episodes, restarts=servers.restarts)


_TERMS = ("goal_reward", "ball_shaping", "approach_shaping", "possession_shaping", "holder",
          "scripted")  # the StepRecord fields a server step's info gives for both sides
_COUNTS = ("restarted", "missed", "malformed", "ball_returned")  # episodes.csv's, from info


class ServerGames:
    """The games of a server run, one per env of ``factory``: ``open`` (``HostGames.open``)
    starts them and gives ``collect``, one episode of every game played as ``elevens.play``'s
    step plays the simulator's (the sides of ``home_sides``, one network call per team and
    step), recorded and packed as the compiled rollout is. With ``server.opponent_cmd`` the
    learner plays the left side of every game."""

    def __init__(self, config: RoboCupTrainConfig, factory: EnvFactory) -> None:
        self.config, self.factory = config, factory
        self.envs: list[Any] = []
        self.episodes = self.restarts = 0
        self.began = time.perf_counter()

    @contextlib.contextmanager
    def open(self, learner: Learner) -> Iterator[Collect]:
        config, games = self.config, self.config.learner.games_per_iteration
        layout = RunLayout.of(config.run.run_dir)
        layout.root.mkdir(parents=True, exist_ok=True)
        written = json.dumps(dataclasses.asdict(config), indent=2)
        (layout.root / ROBOCUP_CONFIG_JSON).write_text(written, encoding="utf-8")
        external = config.server.opponent_cmd is not None
        self.learner = learner
        self.act = _actor(learner.policy, learner.opponent.per_game, external)
        self.sides = np.zeros(games, np.int32) if external else home_sides(games)
        self.pool = ThreadPoolExecutor(games) if config.server.threads and games > 1 else None
        with layout.episodes_csv.open("a", newline="", encoding="utf-8") as self.csv:
            if self.csv.tell() == 0:
                csv.writer(self.csv).writerow(EPISODE_FIELDS)
            try:
                for g in range(games):  # one at a time: a failed start closes those before it
                    self.envs.append(self.factory(g))
                yield self.collect
            finally:
                if self.pool is not None:
                    self.pool.shutdown(wait=True)
                for env in self.envs:
                    env.close()

    def each(self, fn: Callable[[Any, Any], Any], args: Iterable[Any]) -> list[Any]:
        """``fn(env, args[g])`` for the env of every game g, on the pool when there is one."""
        mapped = map if self.pool is None else self.pool.map
        return list(mapped(fn, self.envs, args))

    def collect(self, state: TrainState, key: jax.Array) -> tuple[Rollout, dict[str, float]]:
        """One episode of every game for ``state``'s learner, opponent and shaping, as the
        compiled ``collect``'s ``Rollout``, and the server's counts (also in episodes.csv)."""
        began, envs, sides = time.perf_counter(), self.envs, self.sides
        num_games, n = len(envs), envs[0].players_per_team
        length = self.config.learner.env.game.episode_length
        seed = self.config.run.seed * 1_000_003 + int(state.iteration) * num_games
        started = self.each(lambda env, g: env.reset(seed=seed + g), range(num_games))
        states, observations = map(list, zip(*started, strict=True))
        params = (state.params.policy, self.learner.opponent.act_params(state.opponent))
        carries = (self.learner.policy.initial_carry((num_games, n)),) * 2
        initial_carry, reset = carries[0], np.ones(num_games, bool)
        goals, counts = np.zeros((num_games, 2), np.int32), np.zeros((4, num_games), np.int64)
        times: list[list[int]] = [[] for _ in envs]  # the server's clock at every step
        records: list[StepRecord] = []
        for t, keys in enumerate(jax.random.split(key, (length, 2))):
            obs = _stack(observations)  # leading [G, 2, n]
            views = _stack([env.global_state(s) for env, s in zip(envs, states, strict=True)])
            player_reset = np.broadcast_to(reset[:, None], (num_games, n))
            carries, sample, actions, learner_obs = self.act(
                params, carries, obs, sides, player_reset, keys
            )
            results = self.each(lambda env, game: env.step(game), np.asarray(actions))
            states, observations, _, _, infos = map(list, zip(*results, strict=True))
            for g, info in enumerate(infos):
                goals[g] += np.asarray(info["goals"])[[sides[g], 1 - sides[g]]]
                counts[:, g] += [int(info.get(name, 0)) for name in _COUNTS]
                times[g] += [int(info["server_time"])] if "server_time" in info else []
            mine: dict[str, Any] = {
                name: _pick(_stack([info[name] for info in infos]), sides) for name in _TERMS
            }
            # A restart cuts the episode short and a fresh one starts next step (RoboCupEnv).
            done = np.array([bool(info.get("restarted", False)) for info in infos])
            done |= t == length - 1
            shaping = mine["ball_shaping"] + mine["approach_shaping"] + mine["possession_shaping"]
            reward = mine["goal_reward"] + (shaping if bool(state.shaping.active) else 0.0)
            mine.update(reward=reward, done=done, truncated=done, reset=reset)
            records.append(StepRecord(
                obs=learner_obs, global_state=_pick(views, sides), pre_tanh=sample.pre_tanh,
                log_prob=sample.log_prob, **mine,
            ))
            reset = done  # the policy zeroes those rows' memories itself (RecurrentCore)
        history, (goals_for, goals_against) = _stack(records), jnp.asarray(goals.T)
        rollout = collected(history, goals_for, goals_against, jnp.asarray(sides), initial_carry, n)
        played = time.perf_counter()
        writer, iteration = csv.writer(self.csv), int(state.iteration) + 1
        for g in range(num_games):
            cycles = times[g][-1] - times[g][0] + 1 if times[g] else 0
            writer.writerow((iteration, g, sides[g], *goals[g], length, cycles, *counts[:, g],
                             f"{played - self.began:.1f}"))
        self.csv.flush()
        self.episodes += num_games
        self.restarts += int(counts[0].sum())
        totals = dict(zip(("restarts", "missed", "malformed"), counts.sum(axis=1), strict=False))
        row = {f"robocup/{name}": float(total) for name, total in totals.items()}
        row["time/play_steps_per_s"] = num_games * length / max(played - began, 1e-9)
        return rollout, row


def _actor(policy: Any, per_game: bool, external: bool) -> Callable[..., Any]:
    """Both teams' actions in G games, jitted, as ``elevens.play``'s step takes them: (params,
    carries, obs [G, 2, n], side i32[G], reset bool[G, n], keys[2]) -> (carries, the learner's
    NetworkSample, actions f32[G, 2, n, A] by side, its obs). ``per_game``: a league's opponent
    params, leading [G]; ``external``: another program plays the opponent (actions left 0)."""

    @jax.jit
    def act(params: Any, carries: Any, obs: Observation, side: jax.Array, reset: jax.Array,
            keys: jax.Array) -> Any:
        learner_obs, learner = pick_side(obs, side), NetworkActor(policy, params[0])
        carry, home, sample = learner.act(carries[0], learner_obs, reset, keys[0])
        away_carry, away = carries[1], jnp.zeros_like(home)
        if not external:
            opponent = NetworkActor(policy, params[1], per_game)
            away_carry, away, _ = opponent.act(carries[1], pick_side(obs, 1 - side), reset, keys[1])
        return (carry, away_carry), sample, place_sides(home, away, side), learner_obs

    return act


def _stack(trees: Sequence[Any]) -> Any:
    return jax.tree.map(lambda *leaves: np.stack([np.asarray(x) for x in leaves]), *trees)


def _pick(tree: Any, sides: np.ndarray) -> Any:
    """Leaves [G, 2, ...] -> [G, ...]: team ``sides[g]`` of game g."""
    return jax.tree.map(lambda leaf: leaf[np.arange(len(sides)), sides], tree)
