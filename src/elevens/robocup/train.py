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
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.state import GlobalState, Observation
from elevens.play import NetworkActor, home_sides
from elevens.runs.layout import RunLayout
from elevens.train.config import TrainConfig, make_config
from elevens.train.opponents import OPPONENT_KINDS
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
class RoboCupTrainConfig:
    """A training run in rcssserver. Network and PPO numbers come from ``base`` (a TrainConfig
    preset, by default the simulator's 2v2 preset: table 6.1 and 6.2)."""

    players_per_team: int = 2
    """Players a side (1 to 11)."""
    servers: int = 2
    """Server processes = games per iteration (one episode each)."""
    episode_length: int = 200
    """Steps (server cycles) per episode."""
    iterations: int = 1000
    """Stop after this many iterations..."""
    minutes: float | None = 10.0
    """...or after this many minutes of wall-clock (None: no limit)."""
    keep_ball_in_play: bool = True
    """Put the ball back at the lines instead of kick-ins (the thesis did this while shaping)."""
    opponent: str = "polyak"
    """"polyak" (freeze rule of section 5.2.6), "self" (plain self-play) or "league" (past
    snapshots by win rate, section 5.2.7): the simulator's opponent strategies."""
    learning_rate: float = 1e-4
    """Adam's learning rate (table 6.1)."""
    init_from: str | None = None
    """A simulator checkpoint (run, checkpoints or step directory) whose policy and critic start
    the run: the thesis' transfer from the fast simulator to the server."""
    run_dir: str = "runs/robocup"
    """Where metrics.csv, episodes.csv, TensorBoard events and checkpoints go."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""
    checkpoint_every: int = 5
    """Iterations between checkpoints (and always at the end or on Ctrl-C)."""
    seed: int = 0
    """Seeds the networks and the spawns (the server's own noise is not seedable)."""
    threads: bool = True
    """Step the games' servers from a thread pool, so one server simulates while Python parses
    another's messages."""
    opponent_cmd: str | None = None
    """Learn against another team's binaries instead of a copy of the learner: its start
    command, with {host}, {port}, {coach_port} and {team} filled in (elevens.robocup.external),
    started beside every server. The learner then always plays the left side."""
    opponent_name: str = "opponent"
    """The external opponent's team name."""
    shaping: bool = True
    """Add the simulator's shaping terms (ball and approach) to the goal reward. Off: goals
    only (at 11 v 11 the approach term outweighs the goals; docs/results/table_6_3.md)."""

    def __post_init__(self) -> None:
        checks = (
            ("players_per_team", 1 <= self.players_per_team <= 11, "an int from 1 to 11"),
            ("servers", self.servers >= 1, "an int >= 1"),
            ("episode_length", self.episode_length >= 2, "an int >= 2"),
            ("iterations", self.iterations >= 1, "an int >= 1"),
            ("minutes", self.minutes is None or self.minutes > 0, "None or > 0"),
            ("opponent", self.opponent in OPPONENT_KINDS, " or ".join(map(repr, OPPONENT_KINDS))),
            ("learning_rate", self.learning_rate > 0, "> 0"),
            ("checkpoint_every", self.checkpoint_every >= 1, "an int >= 1"),
            (
                "opponent_cmd",
                self.opponent_cmd is None or bool(self.opponent_cmd.strip()),
                "None or a start command",
            ),
            (
                "opponent_name",
                self.opponent_name not in ("", "elevens_l"),
                "a team name other than elevens_l",
            ),
        )
        for name, ok, allowed in checks:
            if not ok:
                raise ValueError(f"{name}={getattr(self, name)!r} is invalid: it must be {allowed}")

    def train_config(self) -> TrainConfig:
        """The simulator TrainConfig whose networks, PPO and compiled ``learn`` this run uses."""
        n = self.players_per_team
        return make_config(
            "2v2",
            **{
                "env.scenario": f"{n}v{n}",
                "env.episode_length": self.episode_length,
                "opponent.kind": self.opponent,
                "ppo.learning_rate": self.learning_rate,
                "ppo.batch_size": self.servers * n,
                "ppo.minibatch_size": n,
                "run.games_per_iteration": self.servers,
                "run.iterations_per_chunk": 1,
                "run.run_dir": self.run_dir,
                "run.seed": self.seed,
            },
        )


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

    def make(index: int) -> Any:
        return RoboCupEnv(
            RoboCupConfig(
                players_per_team=config.players_per_team,
                # The loop ends episodes itself; the env's own limit only has to lie beyond.
                episode_length=config.episode_length + 1,
                keep_ball_in_play=config.keep_ball_in_play,
                action="sim",
                rcssserver=config.rcssserver,
                opponent_cmd=config.opponent_cmd,
                shaping=config.shaping,
                team_names=(
                    "elevens_l", config.opponent_name if config.opponent_cmd else "elevens_r"
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
    (carry, pre_tanh f32[G, n, 2], log_prob f32[G, n], action f32[G, n, 2]): the simulator's
    ``elevens.play.NetworkActor``, stepped from the host. ``per_game``: params with a leading
    [G] axis, one network per game (a league's snapshots)."""

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
                              "reset", "goal", "ball", "approach")
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
        actions = np.zeros((num_games, 2, n, 2), np.float32)
        actions[index, sides] = np.asarray(learner_action)
        if not external_opponent:
            opponent_carry, _, _, opponent_action = (opponent_act or act)(
                opponent_params, opponent_carry, opponent_obs, player_reset, step_keys[t, 1]
            )
            actions[index, others] = np.asarray(opponent_action)
        def step_game(g: int, actions: np.ndarray = actions) -> Any:
            return envs[g].step(actions[g])

        results = run(step_game)
        rewards = np.zeros((num_games, n), np.float32)
        terms = np.zeros((3, num_games, n), np.float32)
        done = np.zeros(num_games, bool)
        for g, (state, observation, _, _, info) in enumerate(results):
            side = sides[g]
            goal = np.asarray(info["goal_reward"])[side]
            ball = np.asarray(info["ball_shaping"])[side]
            approach = np.asarray(info["approach_shaping"])[side]
            terms[:, g] = goal, ball, approach
            rewards[g] = goal + (ball + approach if shaping_active else 0.0)
            goals = np.asarray(info["goals"])
            logs[g].goals_for += int(goals[side])
            logs[g].goals_against += int(goals[1 - side])
            logs[g].missed += int(info.get("missed", 0))
            logs[g].malformed += int(info.get("malformed", 0))
            logs[g].ball_returned += int(bool(info.get("ball_returned", False)))
            if "server_time" in info:
                if logs[g].first_time is None:
                    logs[g].first_time = int(info["server_time"])
                logs[g].last_time = int(info["server_time"])
            if info.get("restarted", False):
                logs[g].restarts += 1
                done[g] = True  # the episode was cut short; a fresh one starts next step
            states[g], observations[g] = state, observation
        if t == T - 1:
            done[:] = True
        for name, value in (
            ("obs", learner_obs), ("global_state", global_state),
            ("pre_tanh", np.asarray(pre_tanh)), ("log_prob", np.asarray(log_prob)),
            ("reward", rewards), ("done", done.copy()), ("reset", reset.copy()),
            ("goal", terms[0]), ("ball", terms[1]), ("approach", terms[2]),
        ):
            record[name].append(value)
        reset = done.copy()  # the policy zeroes those rows' memories itself (RecurrentCore)

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
    rollout = Rollout(
        transitions=transitions,
        learner_side=jnp.asarray(sides),
        goals_for=jnp.asarray([log.goals_for for log in logs], jnp.int32),
        goals_against=jnp.asarray([log.goals_against for log in logs], jnp.int32),
        game_global_state=game_state,
        goal_reward=jnp.asarray(goal_sum[:, 0]),
        ball_shaping=jnp.asarray(ball_sum[:, 0]),
        approach_shaping=jnp.asarray(approach_sum.mean(axis=-1)),
    )
    return rollout, logs


def _with_saved_network(checkpointer: Any, train_config: TrainConfig) -> TrainConfig:
    """``train_config`` with the network config of the latest checkpoint (unchanged when that
    config cannot be read; ``check_resumable`` then says why)."""
    try:
        saved = TrainConfig.from_dict(checkpointer.read_config(), fill_missing=True)
    except (TypeError, ValueError):
        return train_config
    return dataclasses.replace(train_config, network=saved.network).validate()


def train_robocup(
    config: RoboCupTrainConfig,
    *,
    resume: bool = False,
    env_factory: EnvFactory | None = None,
    print_fn: Callable[[str], None] = print,
) -> RoboCupTrainResult:
    """Run ``config``: iterations of G server games and the learner's ``improve`` (advantages,
    PPO epochs, opponent strategy, shaping schedule: the simulator's, compiled), until
    ``iterations`` or ``minutes``. Ctrl-C writes a checkpoint and stops cleanly; ``resume``
    continues the latest checkpoint of ``run_dir``."""
    from elevens.runs.logging import RunLogger
    from elevens.train.checkpoint import Checkpointer

    began = time.perf_counter()
    layout = RunLayout.of(config.run_dir)
    checkpointer = Checkpointer(layout.checkpoints, max_to_keep=3)
    try:
        learner, state, resumed = _open_robocup_run(config, checkpointer, resume)
    except BaseException:
        # Closed here, as train() does, not left to the garbage collector.
        checkpointer.close()
        raise
    layout.root.mkdir(parents=True, exist_ok=True)
    layout.config.write_text(learner.config.to_json(), encoding="utf-8")
    layout.robocup_config.write_text(
        json.dumps(dataclasses.asdict(config), indent=2), encoding="utf-8"
    )
    improve = jax.jit(learner.improve)
    act = make_actor(learner.policy)
    # A league plays one snapshot per game; one shared opponent acts like the learner.
    opponent_act = make_actor(learner.policy, per_game=True) if learner.opponent.per_game else act
    factory = env_factory or _default_env_factory(config)
    logger = RunLogger(layout.root, resumed_at=int(state.iteration) if resumed else None)
    new_file = not layout.episodes_csv.exists()
    episodes_file = layout.episodes_csv.open("a", newline="", encoding="utf-8")
    episodes_csv = csv.writer(episodes_file)
    if new_file:
        episodes_csv.writerow(EPISODE_FIELDS)
    deadline = None if config.minutes is None else began + 60.0 * config.minutes
    iteration = start_iteration = int(state.iteration)
    last_saved = iteration if resumed else None
    envs: list[Any] = []
    pool = ThreadPoolExecutor(config.servers) if config.threads and config.servers > 1 else None
    interrupted = False
    episodes = restarts = 0
    steps = config.servers * config.episode_length

    def save(current: Any) -> Path:
        nonlocal last_saved
        it = int(current.iteration)
        if last_saved == it:
            return checkpointer.step_directory(it)
        last_saved = it
        return checkpointer.save(
            it, current, learner.config.to_dict(),
            {"iteration": it, "env_steps": it * steps, "robocup": True},
        )

    checkpoint: Path | None = None
    try:
        envs = [factory(g) for g in range(config.servers)]
        while iteration < config.iterations:
            if deadline is not None and time.perf_counter() >= deadline:
                break
            iteration_began = time.perf_counter()
            key, rollout_key, shuffle_key, opponent_key = jax.random.split(state.key, 4)
            data, logs = play_iteration(
                envs, act, learner.policy, state.params.policy,
                learner.opponent.act_params(state.opponent), rollout_key,
                episode_length=config.episode_length,
                shaping_active=bool(state.shaping.active),
                seed=config.seed * 1_000_003 + iteration * config.servers,
                pool=pool,
                external_opponent=config.opponent_cmd is not None,
                opponent_act=opponent_act,
            )
            played = time.perf_counter()
            shaping_was_active = bool(state.shaping.active)
            state, learner_metrics = improve(
                state.replace(key=key), data, shuffle_key, opponent_key
            )
            iteration += 1
            if shaping_was_active and not bool(state.shaping.active):
                log.info("shaping switched off after iteration %d", iteration)
                print_fn(f"robocup train: reward shaping switched off at iteration {iteration}")
            now = time.perf_counter()
            for g, game in enumerate(logs):
                episodes_csv.writerow(
                    (iteration, g, int(data.learner_side[g]), game.goals_for, game.goals_against,
                     config.episode_length, game.server_cycles, game.restarts, game.missed,
                     game.malformed,
                     game.ball_returned, f"{now - began:.1f}")
                )
                restarts += game.restarts
            episodes += len(logs)
            episodes_file.flush()
            # The simulator learner's metrics, then what only this loop knows.
            metrics = {name: float(value) for name, value in learner_metrics.items()}
            metrics |= {
                "robocup/restarts": float(sum(game.restarts for game in logs)),
                "robocup/missed": float(sum(game.missed for game in logs)),
                "robocup/malformed": float(sum(game.malformed for game in logs)),
                "time/play_steps_per_s": steps / max(played - iteration_began, 1e-9),
                "time/env_steps_per_s": steps / max(now - iteration_began, 1e-9),
                "time/env_steps": float(iteration * steps),
            }
            logger.log(iteration, metrics)
            print_fn(
                f"robocup train {iteration}: score {metrics['train/mean_score']:.2f} goals "
                f"{metrics['train/goals_for']:.2f}-{metrics['train/goals_against']:.2f} | "
                f"{metrics['time/env_steps_per_s']:.0f} env steps/s "
                f"(play {metrics['time/play_steps_per_s']:.0f}) | restarts {restarts}"
            )
            if iteration % config.checkpoint_every == 0:
                checkpoint = save(state)
    except KeyboardInterrupt:
        interrupted = True
        print_fn("robocup train: interrupted, writing a checkpoint")
    finally:
        if iteration > start_iteration or not resumed:
            checkpoint = save(state)
        checkpointer.close()
        logger.close()
        episodes_file.close()
        if pool is not None:
            pool.shutdown(wait=True)
        for env in envs:
            env.close()
    return RoboCupTrainResult(
        iterations=iteration,
        env_steps=iteration * steps,
        episodes=episodes,
        restarts=restarts,
        wall_s=time.perf_counter() - began,
        interrupted=interrupted,
        checkpoint=checkpoint,
        run_dir=layout.root,
    )


def _open_robocup_run(
    config: RoboCupTrainConfig, checkpointer: Any, resume: bool
) -> tuple[Any, Any, bool]:
    """(learner, state, resumed): refuse another run's checkpoints or a mismatched resume
    before anything compiles, then build the learner and restore."""
    from elevens.runs.resume import check_resumable, latest_resumable_step
    from elevens.runs.teams import load_learner_params
    from elevens.train.learner import make_learner

    train_config = config.train_config()
    source_params = None
    if config.init_from is not None:
        # The source's networks (their sizes and switches) carry over; PPO and the rest are ours.
        source, source_params = load_learner_params(config.init_from)
        train_config = dataclasses.replace(train_config, network=source.network).validate()
    latest = latest_resumable_step(checkpointer, resume, "--resume", "--run-dir")
    if latest is not None:
        if config.init_from is None:
            # This command has no network flags: a resumed run keeps the networks it was
            # saved with (a run started with --init-from took its source's).
            train_config = _with_saved_network(checkpointer, train_config)
        # The networks, PPO and game sizes must be the checkpoint's (a list of differences,
        # not a shape error from the restore).
        check_resumable(checkpointer, train_config)
    learner = make_learner(train_config)
    state = learner.init(jax.random.key(config.seed), source_params if latest is None else None)
    if latest is not None:
        state, _, _ = checkpointer.restore(state)
    return learner, state, latest is not None
