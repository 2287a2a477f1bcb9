"""Training in rcssserver: the same PPO as in the simulator, fed by games on server processes.

The thesis (sections 4.5 and 6.7) trains its algorithm unchanged in the official server. Here
``G`` RoboCupEnv games, each on its own rcssserver process, play one episode each per iteration
on the host (the server is a separate process, so this part cannot be compiled); both teams'
networks act in one jitted call per step for all games. The steps are recorded and packed as
the compiled rollout's are (``elevens.train.rollout.StepRecord``, ``collected``), and the run
is ``elevens.runs.loop.train``'s with these games in place of the compiled ones
(``HostGames``): the learner's ``improve``, logging, checkpoints, resume, the time budget and
the evaluation in the simulator are the simulator's.

Episode boundaries are the loop's own: every game is reset at the start of an iteration and ends
after ``episode_length`` steps. If a server dies mid-episode, RoboCupEnv restarts it and starts a
fresh episode; that step is marked as an episode end and the next one as a start (the LSTM memory
is zeroed there), so the advantages never run across it. Games alternate sides as in the
simulator (``elevens.play.home_sides``).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.state import Observation
from elevens.play import NetworkActor, home_sides
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
from elevens.train.learner import make_learner
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


# The EnvConfig fields that only the simulator's game reads (EnvConfig.game and the shaping
# schedule's are honoured); robocup train refuses them rather than ignore them.
SERVER_ENV_FIELDS = ("mix", "mix_shares", "physics", "stamina", "goalie", "see_period")


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
    iterations=1000,
    max_minutes=10.0,
    eval_teams=(),
    checkpoint_every=5,
    run_dir="runs/robocup",
    write_plot=True,
    write_gif=False,
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
    """``elevens.runs.loop.train``'s result and this call's server games."""

    episodes: int = 0
    restarts: int = 0
    """Servers restarted in this call."""

    @property
    def iterations(self) -> int:
        return self.iteration


EnvFactory = Callable[[int], Any]
"""game index -> a RoboCupEnv-like object (reset(seed), step(actions), global_state(state))."""


def _default_env_factory(config: RoboCupTrainConfig) -> EnvFactory:
    from elevens.robocup.env import RoboCupConfig, RoboCupEnv

    game, server = config.learner.env.game, config.server

    def make(index: int) -> Any:
        return RoboCupEnv(
            RoboCupConfig(
                # The loop ends episodes itself; the env's own limit only has to lie beyond.
                episode_length=game.episode_length + 1,
                **{name: getattr(game, name) for name in SERVER_GAME_FIELDS
                   if name not in ("episode_length", "possession_by")},  # "near", the env's
                episodes=server.episodes,
                keep_ball_in_play=server.keep_ball_in_play and server.episodes == "drill",
                action=action_mode(config.learner.network.actions),
                rcssserver=server.rcssserver,
                opponent_cmd=server.opponent_cmd,
                team_names=(
                    "elevens_l", server.opponent_name if server.opponent_cmd else "elevens_r"
                ),
            )
        )

    return make


def _stack(trees: Sequence[Any]) -> Any:
    return jax.tree.map(lambda *leaves: np.stack([np.asarray(x) for x in leaves]), *trees)


def _pick(tree: Any, sides: np.ndarray) -> Any:
    """Leaves [G, 2, ...] -> [G, ...]: team ``sides[g]`` of game g."""
    index = np.arange(len(sides))
    return jax.tree.map(lambda leaf: leaf[index, sides], tree)


def make_actor(policy: Any, per_game: bool = False) -> Callable[..., Any]:
    """Jitted: (params, carry, obs [G, n], reset bool[G, n], key) ->
    (carry, pre_tanh f32[G, n, A], log_prob f32[G, n], action f32[G, n, A]), A the policy's
    2 or 12 actions: the simulator's ``elevens.play.NetworkActor``, stepped from the host.
    ``per_game``: params with a leading [G] axis, one network per game (a league's
    snapshots)."""

    @jax.jit
    def act(params: Any, carry: Any, obs: Observation, reset: jax.Array, key: jax.Array) -> Any:
        actor = NetworkActor(policy, params, per_game=per_game)
        carry, action, sample = actor.act(carry, obs, reset, key)
        return carry, sample.pre_tanh, sample.log_prob, action

    return act


@dataclasses.dataclass
class _GameLog:
    goals_for: int = 0
    goals_against: int = 0
    restarts: int = 0
    missed: int = 0
    malformed: int = 0
    ball_returned: int = 0
    first_time: int | None = None
    last_time: int | None = None

    @property
    def server_cycles(self) -> int:
        if self.first_time is None or self.last_time is None:
            return 0
        return self.last_time - self.first_time + 1

    def add(self, info: Mapping[str, Any], side: int) -> bool:
        """Count one step's ``info`` for the learner on ``side``; True if the server restarted
        (the episode was cut short)."""
        goals = np.asarray(info["goals"])
        self.goals_for += int(goals[side])
        self.goals_against += int(goals[1 - side])
        self.missed += int(info.get("missed", 0))
        self.malformed += int(info.get("malformed", 0))
        self.ball_returned += int(bool(info.get("ball_returned", False)))
        if "server_time" in info:
            if self.first_time is None:
                self.first_time = int(info["server_time"])
            self.last_time = int(info["server_time"])
        restarted = bool(info.get("restarted", False))
        self.restarts += int(restarted)
        return restarted


def play_iteration(
    envs: Sequence[Any],
    act: Callable[..., Any],
    policy: Any,
    learner_params: Any,
    opponent_params: Any,
    key: jax.Array,
    *,
    episode_length: int,
    shaping_active: bool,
    seed: int,
    pool: ThreadPoolExecutor | None = None,
    external_opponent: bool = False,
    opponent_act: Callable[..., Any] | None = None,
) -> tuple[Rollout, list[_GameLog]]:
    """One episode of every game (learner against opponent) packed as a ``Rollout``. With an
    ``external_opponent`` the learner plays the left side of every game and the opponent's
    actions are not computed (the other program plays them). ``opponent_act``: how the
    opponent acts when it differs from ``act`` (one network per game: a league's)."""
    num_games, n = len(envs), envs[0].players_per_team
    sides = np.zeros(num_games, np.int32) if external_opponent else home_sides(num_games)
    index = np.arange(num_games)

    def run(fn: Callable[[int], Any]) -> list[Any]:
        return [fn(g) for g in range(num_games)] if pool is None else list(pool.map(fn, index))

    states, observations = map(list, zip(*run(lambda g: envs[g].reset(seed=seed + g)), strict=True))
    initial_carry = learner_carry = opponent_carry = policy.initial_carry((num_games, n))
    reset = np.ones(num_games, bool)
    logs = [_GameLog() for _ in range(num_games)]
    records: list[StepRecord] = []
    step_keys = jax.random.split(key, (episode_length, 2))
    for t in range(episode_length):
        obs = _stack(observations)  # leading [G, 2, n]
        views = _stack([env.global_state(s) for env, s in zip(envs, states, strict=True)])
        learner_obs = _pick(obs, sides)
        player_reset = np.broadcast_to(reset[:, None], (num_games, n))
        learner_carry, pre_tanh, log_prob, learner_action = act(
            learner_params, learner_carry, learner_obs, player_reset, step_keys[t, 0]
        )
        learner_action = np.asarray(learner_action)  # [G, n, 2 or 12]
        actions = np.zeros((num_games, 2, n, learner_action.shape[-1]), np.float32)
        actions[index, sides] = learner_action
        if not external_opponent:
            opponent_carry, _, _, opponent_action = (opponent_act or act)(
                opponent_params, opponent_carry, _pick(obs, 1 - sides), player_reset,
                step_keys[t, 1],
            )
            actions[index, 1 - sides] = np.asarray(opponent_action)
        results = run(lambda g, actions=actions: envs[g].step(actions[g]))
        infos = [info for *_, info in results]
        by_game = list(zip(infos, sides, strict=True))
        states, observations = [r[0] for r in results], [r[1] for r in results]
        # The learner's side of each game's info, stacked over games.
        mine = {
            name: np.stack([np.asarray(info[name])[side] for info, side in by_game])
            for name in ("goal_reward", "ball_shaping", "approach_shaping",
                         "possession_shaping", "holder", "scripted")
        }
        shaping = mine["ball_shaping"] + mine["approach_shaping"] + mine["possession_shaping"]
        # A restart cuts the episode short; a fresh one starts next step.
        done = np.array(
            [log.add(info, side) for log, (info, side) in zip(logs, by_game, strict=True)], bool
        )
        done |= t == episode_length - 1
        records.append(StepRecord(
            obs=learner_obs, global_state=_pick(views, sides), pre_tanh=np.asarray(pre_tanh),
            log_prob=np.asarray(log_prob),
            reward=(mine["goal_reward"] + (shaping if shaping_active else 0.0)).astype(
                np.float32),
            done=done, truncated=done, reset=reset, goal_reward=mine["goal_reward"],
            ball_shaping=mine["ball_shaping"], approach_shaping=mine["approach_shaping"],
            possession_shaping=mine["possession_shaping"],
            holder=mine["holder"].astype(np.float32), scripted=mine["scripted"].astype(bool),
        ))
        reset = done  # the policy zeroes those rows' memories itself (RecurrentCore)
    goals = [np.asarray([getattr(log, name) for log in logs], np.int32)
             for name in ("goals_for", "goals_against")]
    rollout = collected(_stack(records), *goals, jnp.asarray(sides), initial_carry, n)
    return rollout, logs


def train_robocup(
    config: RoboCupTrainConfig,
    *,
    resume: bool = False,
    env_factory: EnvFactory | None = None,
    progress: bool = True,
) -> RoboCupTrainResult:
    """Run ``config`` with ``elevens.runs.loop.train``, the games of every iteration played on
    G servers (``env_factory``: how to start game g's, by default a RoboCupEnv), then the
    learner's ``improve``; logging, evaluation in the simulator (``run.eval_teams``),
    checkpoints, ``resume``, ``run.max_minutes`` (summed over sessions), Ctrl-C and the
    learning curve are the loop's, as in ``elevens train``."""
    config.validate()
    servers = _Servers(config, env_factory or _default_env_factory(config))
    host = HostGames(
        make_learner=lambda learner: make_learner(learner, devices=1, plays_rcssserver=True),
        open=servers.open,
    )
    result = train(config.train_config(), resume=resume, progress=progress, host=host)
    fields = {field.name: getattr(result, field.name) for field in dataclasses.fields(result)}
    return RoboCupTrainResult(**fields, episodes=servers.episodes, restarts=servers.restarts)


class _Servers:
    """A run's G servers, one game each: started when the loop opens them, they play every
    iteration's games (``Collect``) and write episodes.csv."""

    def __init__(self, config: RoboCupTrainConfig, factory: EnvFactory) -> None:
        self.config, self.factory = config, factory
        self.episodes = self.restarts = 0
        self.began = time.perf_counter()

    @contextlib.contextmanager
    def open(self, learner: Any) -> Iterator[Collect]:
        config, games = self.config, self.config.learner.games_per_iteration
        length = config.learner.env.game.episode_length
        layout = RunLayout.of(config.run.run_dir)
        layout.robocup_config.write_text(
            json.dumps(dataclasses.asdict(config), indent=2), encoding="utf-8"
        )
        act = make_actor(learner.policy)
        # A league plays one snapshot per game; one shared opponent acts like the learner.
        opponent_act = make_actor(learner.policy, True) if learner.opponent.per_game else act
        pool = ThreadPoolExecutor(games) if config.server.threads and games > 1 else None
        envs: list[Any] = []
        with layout.episodes_csv.open("a", newline="", encoding="utf-8") as file:
            writer = csv.writer(file)
            if file.tell() == 0:
                writer.writerow(EPISODE_FIELDS)

            def collect(state: Any, key: jax.Array) -> tuple[Rollout, dict[str, float]]:
                began, iteration = time.perf_counter(), int(state.iteration)
                data, logs = play_iteration(
                    envs, act, learner.policy, state.params.policy,
                    learner.opponent.act_params(state.opponent), key, episode_length=length,
                    shaping_active=bool(state.shaping.active),
                    seed=config.run.seed * 1_000_003 + iteration * games, pool=pool,
                    external_opponent=config.server.opponent_cmd is not None,
                    opponent_act=opponent_act,
                )
                played = time.perf_counter()
                for g, (side, log) in enumerate(zip(data.learner_side, logs, strict=True)):
                    writer.writerow(
                        (iteration + 1, g, int(side), log.goals_for, log.goals_against, length,
                         log.server_cycles, log.restarts, log.missed, log.malformed,
                         log.ball_returned, f"{played - self.began:.1f}")
                    )
                file.flush()
                self.episodes += len(logs)
                self.restarts += sum(log.restarts for log in logs)
                return data, {
                    **{f"robocup/{name}": float(sum(getattr(log, name) for log in logs))
                       for name in ("restarts", "missed", "malformed")},
                    "time/play_steps_per_s": games * length / max(played - began, 1e-9),
                }

            try:
                for g in range(games):  # one at a time: a failed start closes those before it
                    envs.append(self.factory(g))
                yield collect
            finally:
                if pool is not None:
                    pool.shutdown(wait=True)
                for env in envs:
                    env.close()
