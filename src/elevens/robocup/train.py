"""Training in rcssserver: the same PPO as in the simulator, fed by games on server processes.

The thesis (sections 4.5 and 6.7) trains its algorithm unchanged in the official server. Here
``G`` RoboCupEnv games, each on its own rcssserver process, play one episode each per iteration
on the host (the server is a separate process, so this part cannot be compiled); both teams'
networks act in one jitted call per step for all games. The episodes are packed into the same
``Rollout`` container the compiled rollout makes, and the trainer's compiled ``learn`` (advantages
and the PPO epochs) does the update. The opponent is the Polyak-averaged copy with the freeze rule
(or plain self-play), and the shaping schedule switches shaping off as in the simulator.

Episode boundaries are the loop's own: every game is reset at the start of an iteration and ends
after ``episode_length`` steps. If a server dies mid-episode, RoboCupEnv restarts it and starts a
fresh episode; that step is marked as an episode end and the next one as a start (the LSTM memory
is zeroed there), so the advantages never run across it.

Games alternate sides as in the simulator (``elevens.play.home_sides``): the learner plays the
left side in the first half of the games and the right side in the others.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.state import GlobalState, Observation
from elevens.play import NetworkActor, home_sides
from elevens.robocup.actions import action_mode
from elevens.runs.layout import RunLayout
from elevens.train.config import (
    LearnerConfig,
    RunConfig,
    TrainConfig,
    apply_overrides,
    make_config,
    validate,
)
from elevens.train.rollout import Rollout, Transition

log = logging.getLogger(__name__)

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
class RoboCupTrainResult:
    iterations: int
    env_steps: int
    episodes: int
    restarts: int
    wall_s: float
    interrupted: bool
    checkpoint: Path | None
    run_dir: Path


EnvFactory = Callable[[int], Any]
"""game index -> a RoboCupEnv-like object (reset(seed), step(actions), global_state(state))."""


def _default_env_factory(config: RoboCupTrainConfig) -> EnvFactory:
    from elevens.robocup.env import RoboCupConfig, RoboCupEnv

    game, server = config.learner.env.game, config.server

    def make(index: int) -> Any:
        return RoboCupEnv(
            RoboCupConfig(
                players_per_team=game.players_per_team,
                # The loop ends episodes itself; the env's own limit only has to lie beyond.
                episode_length=game.episode_length + 1,
                spawn=game.spawn,
                ball_spawn=game.ball_spawn,
                episodes=server.episodes,
                keep_ball_in_play=server.keep_ball_in_play and server.episodes == "drill",
                goal_reward=game.goal_reward,
                ball_shaping_weight=game.ball_shaping_weight,
                approach_shaping_weight=game.approach_shaping_weight,
                possession_shaping_weight=game.possession_shaping_weight,
                possession_radius=game.possession_radius,
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
    num_games = len(envs)
    sides = np.zeros(num_games, np.int32) if external_opponent else home_sides(num_games)
    others = 1 - sides
    index = np.arange(num_games)
    n = envs[0].players_per_team
    T = episode_length

    def run(fn: Callable[[int], Any]) -> list[Any]:
        if pool is None:
            return [fn(g) for g in range(num_games)]
        return list(pool.map(fn, range(num_games)))

    started = run(lambda g: envs[g].reset(seed=seed + g))
    states = [s for s, _ in started]
    observations = [o for _, o in started]
    learner_carry = policy.initial_carry((num_games, n))
    opponent_carry = learner_carry
    initial_carry = learner_carry
    reset = np.ones(num_games, bool)
    logs = [_GameLog() for _ in range(num_games)]
    record: dict[str, list[Any]] = {
        name: [] for name in ("obs", "global_state", "pre_tanh", "log_prob", "reward", "done",
                              "reset", "goal", "ball", "approach", "possession", "holder",
                              "scripted")
    }
    step_keys = jax.random.split(key, (T, 2))
    for t in range(T):
        obs = _stack(observations)  # leading [G, 2, n]
        views = [env.global_state(s) for env, s in zip(envs, states, strict=True)]
        global_state = _pick(_stack(views), sides)
        learner_obs, opponent_obs = _pick(obs, sides), _pick(obs, others)
        player_reset = np.broadcast_to(reset[:, None], (num_games, n))
        learner_carry, pre_tanh, log_prob, learner_action = act(
            learner_params, learner_carry, learner_obs, player_reset, step_keys[t, 0]
        )
        learner_action = np.asarray(learner_action)  # [G, n, 2 or 12]
        actions = np.zeros((num_games, 2, n, learner_action.shape[-1]), np.float32)
        actions[index, sides] = learner_action
        if not external_opponent:
            opponent_carry, _, _, opponent_action = (opponent_act or act)(
                opponent_params, opponent_carry, opponent_obs, player_reset, step_keys[t, 1]
            )
            actions[index, others] = np.asarray(opponent_action)
        def step_game(g: int, actions: np.ndarray = actions) -> Any:
            return envs[g].step(actions[g])

        results = run(step_game)
        rewards = np.zeros((num_games, n), np.float32)
        terms = np.zeros((4, num_games, n), np.float32)
        holder = np.zeros(num_games, np.float32)
        scripted = np.zeros((num_games, n), bool)
        done = np.zeros(num_games, bool)
        for g, (state, observation, _, _, info) in enumerate(results):
            side = sides[g]
            goal = np.asarray(info["goal_reward"])[side]
            ball = np.asarray(info["ball_shaping"])[side]
            approach = np.asarray(info["approach_shaping"])[side]
            possession = np.asarray(info["possession_shaping"])[side]
            terms[:, g] = goal, ball, approach, possession
            holder[g] = np.asarray(info["holder"])[side]
            scripted[g] = np.asarray(info["scripted"])[side]
            rewards[g] = goal + (ball + approach + possession if shaping_active else 0.0)
            # A restart cuts the episode short; a fresh one starts next step.
            done[g] = logs[g].add(info, side)
            states[g], observations[g] = state, observation
        if t == T - 1:
            done[:] = True
        for name, value in (
            ("obs", learner_obs), ("global_state", global_state),
            ("pre_tanh", np.asarray(pre_tanh)), ("log_prob", np.asarray(log_prob)),
            ("reward", rewards), ("done", done.copy()), ("reset", reset.copy()),
            ("goal", terms[0]), ("ball", terms[1]), ("approach", terms[2]),
            ("possession", terms[3]), ("holder", holder), ("scripted", scripted),
        ):
            record[name].append(value)
        reset = done.copy()  # the policy zeroes those rows' memories itself (RecurrentCore)

    return _packed_rollout(record, sides, logs, initial_carry, n), logs


def _packed_rollout(
    record: dict[str, list[Any]], sides: np.ndarray, logs: Sequence[_GameLog],
    initial_carry: Any, n: int,
) -> Rollout:
    """The steps ``play_iteration`` recorded (T x [G, ...]) as the ``Rollout`` the compiled
    rollout makes: player sequences [G * n, T, ...], the game's global state [G, T, ...]."""
    num_games, T = len(sides), len(record["done"])

    def per_player(steps: list[Any]) -> Any:  # T x [G, n, ...] -> [G * n, T, ...]
        stacked = _stack(steps)  # [T, G, n, ...]
        return jax.tree.map(
            lambda x: jnp.asarray(np.moveaxis(x, 0, 2).reshape(num_games * n, T, *x.shape[3:])),
            stacked,
        )

    def per_game(steps: list[Any]) -> Any:  # T x [G, ...] -> [G, T, ...]
        return jax.tree.map(lambda x: jnp.asarray(np.moveaxis(x, 0, 1)), _stack(steps))

    def games_to_players(x: Any) -> Any:
        return jax.tree.map(lambda leaf: jnp.repeat(leaf, n, axis=0), x)

    game_state: GlobalState = per_game(record["global_state"])
    done_games = per_game(record["done"])
    transitions = Transition(
        obs=per_player(record["obs"]),
        global_state=games_to_players(game_state),
        pre_tanh=per_player(record["pre_tanh"]),
        log_prob=per_player(record["log_prob"]),
        reward=per_player(record["reward"]),
        done=games_to_players(done_games),
        truncated=games_to_players(done_games),
        reset=games_to_players(per_game(record["reset"])),
        initial_carry=jax.tree.map(
            lambda leaf: leaf.reshape(num_games * n, *leaf.shape[2:]), initial_carry
        ),
    )
    goal_sum = np.sum(np.stack(record["goal"]), axis=0)  # [G, n]
    ball_sum = np.sum(np.stack(record["ball"]), axis=0)
    approach_sum = np.sum(np.stack(record["approach"]), axis=0)
    possession_sum = np.sum(np.stack(record["possession"]), axis=0)
    rollout = Rollout(
        transitions=transitions,
        learner_side=jnp.asarray(sides),
        goals_for=jnp.asarray([log.goals_for for log in logs], jnp.int32),
        goals_against=jnp.asarray([log.goals_against for log in logs], jnp.int32),
        game_global_state=game_state,
        goal_reward=jnp.asarray(goal_sum[:, 0]),
        ball_shaping=jnp.asarray(ball_sum[:, 0]),
        approach_shaping=jnp.asarray(approach_sum.mean(axis=-1)),
        possession_shaping=jnp.asarray(possession_sum[:, 0]),
        possession=jnp.asarray(np.mean(np.stack(record["holder"]), axis=0)),
        scripted=per_player(record["scripted"]),
    )
    return rollout


def train_robocup(
    config: RoboCupTrainConfig,
    *,
    resume: bool = False,
    env_factory: EnvFactory | None = None,
    print_fn: Callable[[str], None] = print,
) -> RoboCupTrainResult:
    """Run ``config``: iterations of G server games and the learner's ``improve`` (advantages,
    PPO epochs, opponent strategy, shaping schedule: the simulator's, compiled), until
    ``run.iterations`` or ``run.max_minutes``. Ctrl-C writes a checkpoint and stops cleanly;
    ``resume`` continues the latest checkpoint of ``run.run_dir``. With ``run.eval_teams`` the
    policy is also evaluated in the simulator (every ``run.eval_every`` iterations and at the
    end) and the learning curve drawn, as ``elevens train`` does."""
    from elevens.train.checkpoint import Checkpointer

    began = time.perf_counter()
    config.validate()
    layout = RunLayout.of(config.run.run_dir)
    checkpointer = Checkpointer(layout.checkpoints, max_to_keep=config.run.keep_checkpoints)
    try:
        learner, state, resumed = _open_robocup_run(config, checkpointer, resume)
    except BaseException:
        # Closed here, as train() does, not left to the garbage collector.
        checkpointer.close()
        raise
    layout.root.mkdir(parents=True, exist_ok=True)
    layout.config.write_text(config.train_config().to_json(), encoding="utf-8")
    layout.robocup_config.write_text(
        json.dumps(dataclasses.asdict(config), indent=2), encoding="utf-8"
    )
    loop = _RoboCupLoop(config, layout, checkpointer, learner, state, resumed, print_fn, began)
    try:
        loop.run(env_factory or _default_env_factory(config))
    finally:
        loop.close()
    return RoboCupTrainResult(
        iterations=loop.iteration,
        env_steps=loop.iteration * loop.steps,
        episodes=loop.episodes,
        restarts=loop.restarts,
        wall_s=time.perf_counter() - began,
        interrupted=loop.interrupted,
        checkpoint=loop.checkpoint,
        run_dir=layout.root,
    )


class _RoboCupLoop:
    """An open server run: the iterations (play on the servers, improve, log, checkpoint,
    evaluate), then the final checkpoint and pictures."""

    def __init__(
        self, config: RoboCupTrainConfig, layout: RunLayout, checkpointer: Any, learner: Any,
        state: Any, resumed: bool, print_fn: Callable[[str], None], began: float,
    ) -> None:
        from elevens.runs.logging import RunLogger
        from elevens.runs.resume import resume_line

        self.config, self.layout, self.checkpointer = config, layout, checkpointer
        self.saved_config = config.train_config()  # what every checkpoint saves
        self.learner, self.state, self.resumed = learner, state, resumed
        self.print_fn, self.began = print_fn, began
        self.improve = jax.jit(learner.improve)
        self.act = make_actor(learner.policy)
        # A league plays one snapshot per game; one shared opponent acts like the learner.
        self.opponent_act = (
            make_actor(learner.policy, per_game=True) if learner.opponent.per_game else self.act
        )
        self.logger = RunLogger(layout.root, resumed_at=int(state.iteration) if resumed else None)
        self.episodes_csv = _EpisodesCsv(layout.episodes_csv)
        self.evaluations = _SimulatorEvaluation(learner, config.run, self.logger)
        self.games = config.learner.games_per_iteration
        self.steps = self.games * config.learner.env.game.episode_length
        self.iteration = self.start_iteration = int(state.iteration)
        if resumed:  # this loop does not count training time across sessions
            print_fn(resume_line(layout.root, self.iteration, self.iteration * self.steps, None))
        self.last_saved = self.iteration if resumed else None
        self.episodes = self.restarts = 0
        self.interrupted = False
        self.checkpoint: Path | None = None

    def run(self, factory: EnvFactory) -> None:
        run = self.config.run
        deadline = self.began + 60.0 * run.max_minutes if run.max_minutes > 0 else None
        threads = self.config.server.threads and self.games > 1
        pool = ThreadPoolExecutor(self.games) if threads else None
        envs: list[Any] = []
        try:
            envs = [factory(g) for g in range(self.games)]
            while self.iteration < run.iterations:
                if deadline is not None and time.perf_counter() >= deadline:
                    break
                self.step(envs, pool)
                if run.checkpoint_every and self.iteration % run.checkpoint_every == 0:
                    self.checkpoint = self.save()
                if run.eval_every and self.iteration % run.eval_every == 0:
                    self.evaluations.evaluate(self.state)
        except KeyboardInterrupt:
            self.interrupted = True
            self.print_fn("robocup train: interrupted, writing a checkpoint")
        finally:
            if self.iteration > self.start_iteration or not self.resumed:
                self.checkpoint = self.save()
            self.checkpointer.close()
            if pool is not None:
                pool.shutdown(wait=True)
            for env in envs:
                env.close()
        if not self.interrupted:
            self.evaluations.finish(self.state, self.layout, self.saved_config)

    def step(self, envs: list[Any], pool: ThreadPoolExecutor | None) -> None:
        """One iteration: an episode on every server, then ``improve``, then its logs."""
        learner, state, game = self.learner, self.state, self.config.learner.env.game
        began = time.perf_counter()
        key, rollout_key, shuffle_key, opponent_key = jax.random.split(state.key, 4)
        data, logs = play_iteration(
            envs, self.act, learner.policy, state.params.policy,
            learner.opponent.act_params(state.opponent), rollout_key,
            episode_length=game.episode_length,
            shaping_active=bool(state.shaping.active),
            seed=self.config.run.seed * 1_000_003 + self.iteration * self.games,
            pool=pool,
            external_opponent=self.config.server.opponent_cmd is not None,
            opponent_act=self.opponent_act,
        )
        played = time.perf_counter()
        self.state, learner_metrics = self.improve(
            state.replace(key=key), data, shuffle_key, opponent_key
        )
        self.iteration += 1
        if bool(state.shaping.active) and not bool(self.state.shaping.active):
            log.info("shaping switched off after iteration %d", self.iteration)
            self.print_fn(
                f"robocup train: reward shaping switched off at iteration {self.iteration}"
            )
        now = time.perf_counter()
        self.episodes_csv.write(
            self.iteration, data.learner_side, logs, game.episode_length, now - self.began
        )
        self.restarts += sum(game_log.restarts for game_log in logs)
        self.episodes += len(logs)
        # The simulator learner's metrics, then what only this loop knows.
        metrics = {name: float(value) for name, value in learner_metrics.items()}
        metrics |= {
            "robocup/restarts": float(sum(game_log.restarts for game_log in logs)),
            "robocup/missed": float(sum(game_log.missed for game_log in logs)),
            "robocup/malformed": float(sum(game_log.malformed for game_log in logs)),
            "time/play_steps_per_s": self.steps / max(played - began, 1e-9),
            "time/env_steps_per_s": self.steps / max(now - began, 1e-9),
            "time/env_steps": float(self.iteration * self.steps),
        }
        self.logger.log(self.iteration, metrics)
        self.print_fn(
            f"robocup train {self.iteration}: score {metrics['train/mean_score']:.2f} goals "
            f"{metrics['train/goals_for']:.2f}-{metrics['train/goals_against']:.2f} | "
            f"{metrics['time/env_steps_per_s']:.0f} env steps/s "
            f"(play {metrics['time/play_steps_per_s']:.0f}) | restarts {self.restarts}"
        )

    def save(self) -> Path:
        it = int(self.state.iteration)
        if self.last_saved == it:
            return cast(Path, self.checkpointer.step_directory(it))
        self.last_saved = it
        return cast(Path, self.checkpointer.save(
            it, self.state, self.saved_config.to_dict(),
            {"iteration": it, "env_steps": it * self.steps, "robocup": True},
        ))

    def close(self) -> None:
        self.logger.close()
        self.episodes_csv.close()


class _EpisodesCsv:
    """episodes.csv (``EPISODE_FIELDS``): one row per server game, appended across resumes."""

    def __init__(self, path: Path) -> None:
        new_file = not path.exists()
        self.file = path.open("a", newline="", encoding="utf-8")
        self.writer = csv.writer(self.file)
        if new_file:
            self.writer.writerow(EPISODE_FIELDS)

    def write(
        self, iteration: int, learner_sides: Any, logs: Sequence[Any], episode_length: int,
        wall_s: float,
    ) -> None:
        for g, game in enumerate(logs):
            self.writer.writerow(
                (iteration, g, int(learner_sides[g]), game.goals_for, game.goals_against,
                 episode_length, game.server_cycles, game.restarts, game.missed, game.malformed,
                 game.ball_returned, f"{wall_s:.1f}")
            )
        self.file.flush()

    def close(self) -> None:
        self.file.close()


class _SimulatorEvaluation:
    """``run.eval_teams`` games in the simulator (``elevens.runs.loop.evaluate``), logged like
    ``elevens train``'s, and the pictures at the end (curve with an evaluation, GIF)."""

    def __init__(self, learner: Any, run: RunConfig, logger: Any) -> None:
        self.learner, self.run, self.logger = learner, run, logger
        self.key = jax.random.key(run.seed + 1)
        self.evaluated_at: int | None = None

    def evaluate(self, state: Any) -> None:
        from elevens.runs.loop import evaluate

        if not self.run.eval_teams:
            return
        it = int(state.iteration)
        results = evaluate(self.learner, state, jax.random.fold_in(self.key, it), self.run)
        self.logger.log(it, results)
        self.evaluated_at = it

    def finish(self, state: Any, layout: RunLayout, config: TrainConfig) -> None:
        from elevens.runs.pictures import write_gif, write_learning_curve

        if self.evaluated_at != int(state.iteration):
            self.evaluate(state)
        self.logger.flush()
        if self.run.write_plot and self.run.eval_teams:
            title = f"{config.learner.env.scenario} in rcssserver, seed {self.run.seed}"
            write_learning_curve(layout.root, layout.learning_curve, title=title)
        if self.run.write_gif:
            write_gif(
                self.learner, state, layout.gif, seed=self.run.seed,
                deterministic=self.run.eval_deterministic,
            )


def _open_robocup_run(
    config: RoboCupTrainConfig, checkpointer: Any, resume: bool
) -> tuple[Any, Any, bool]:
    """(learner, state, resumed): refuse another run's checkpoints or a mismatched resume
    before anything compiles, then build the learner and restore (or start from
    ``run.init_from``, whose networks must be this run's, as in ``elevens train``)."""
    from elevens.runs.loop import evaluation_team
    from elevens.runs.resume import check_resumable, latest_resumable_step, load_start_params
    from elevens.train.learner import make_learner

    train_config = config.train_config()
    latest = latest_resumable_step(checkpointer, resume, "--resume", "--run.run-dir")
    source_params = None
    if latest is not None:
        # The networks, PPO and game sizes must be the checkpoint's (a list of differences,
        # not a shape error from the restore).
        check_resumable(checkpointer, train_config)
    elif config.run.init_from:
        _, source_params = load_start_params(config.run.init_from, train_config)
    for team in config.run.eval_teams:  # a bad spec fails here, before anything compiles
        evaluation_team(team, config.learner.env.game)
    learner = make_learner(config.learner, devices=1, plays_rcssserver=True)
    state = learner.init(jax.random.key(config.run.seed), source_params)
    if latest is not None:
        state, _, _ = checkpointer.restore(state)
    return learner, state, latest is not None
