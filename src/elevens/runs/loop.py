"""The host loop of a training run: ``train(config)``.

The compiled learner (``elevens.train.learner``) runs K iterations a call; between calls this
loop, flat and in order, logs every iteration's metrics (TensorBoard and ``metrics.csv``),
updates the progress display, evaluates against ``run.eval_teams`` every ``run.eval_every``
iterations, checkpoints atomically every ``run.checkpoint_every``, and stops on the iteration
budget, the time budget (``run.max_minutes``, summed over resumed sessions) or Ctrl-C/SIGTERM,
with a checkpoint written. At the end it evaluates, draws the learning curve and a GIF.

Several processes (``--distributed``) run this same loop in step; process 0 alone writes the
run directory (checkpoints go through Orbax's multi-process path) and evaluates.

Evaluation plays the learner as a ``NetworkTeam`` that SAMPLES its actions by default
(``run.eval_deterministic``): that is the policy PPO trained and the one the opponents meet.

A run whose games cannot be compiled (another program plays them, e.g. the official server
through the wing above) passes ``HostGames``: the loop is the same, and each iteration of a chunk is
the learner's ``iteration`` with the host's ``collect`` in place of the compiled rollout.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import signal
import time
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer
from elevens.runs.errors import RunRefusedError
from elevens.runs.layout import RunLayout
from elevens.runs.memory import check_fits, rollout_bytes
from elevens.runs.resume import (
    check_resumable,
    last_good_step,
    latest_resumable_step,
    load_start_params,
    resume_line,
)
from elevens.train import parallel
from elevens.train.config import (
    LearnerConfig,
    RunConfig,
    TrainConfig,
    game_actions,
    mix_schedule,
    scenario_config,
    validate,
)
from elevens.train.learner import (
    Learner,
    TrainState,
    make_learner,
    metric_label,
    opponent_index_count,
)
from elevens.train.rollout import Rollout

Metrics = dict[str, jax.Array]
ChunkHook = Callable[[TrainState, Mapping[str, float]], None]

PROGRESS_METRICS = (
    "train/mean_score",
    "train/goals_for",
    "eval/random/outcome",
    "eval/naive/outcome",
    "eval/teamwork/outcome",
)

__all__ = [
    "Collect", "HostGames", "RunRefusedError", "TrainResult", "evaluate", "evaluation_team",
    "train",
]

Collect = Callable[[TrainState, jax.Array], tuple[Rollout, dict[str, float]]]
"""One iteration's games played on the host: ``(state, rollout key) -> (rollout, row)``, the
``Rollout`` the compiled ``collect`` would return for ``state`` (the learner's and the
opponent's params, the shaping in force) and host metrics logged with the iteration."""


@dataclasses.dataclass(frozen=True)
class HostGames:
    """Where a run plays its games when they cannot be compiled (another program plays them).
    Every iteration is then ``learner.iteration``'s order with ``collect`` on the host: the
    state's key split in four, ``collect(state, rollout key)``, the learner's jitted
    ``improve``."""

    make_learner: Callable[[LearnerConfig, Soccer], Learner]
    """Builds the run's learner from its config and game (one game size: a mix of sizes is
    the simulator's)."""
    open: Callable[[Learner], AbstractContextManager[Collect]]
    """Entered once the run directory is accepted and the untrained networks evaluated (start
    the servers there), left when the iterations end, also on an error or Ctrl-C."""


@dataclasses.dataclass
class TrainResult:
    """What ``train`` returns."""

    state: TrainState
    """The final TrainState (the one last checkpointed)."""
    iteration: int
    """Completed iterations."""
    env_steps: int
    """Game steps played (exact)."""
    interrupted: bool
    """True if Ctrl-C stopped the run (a checkpoint was still written)."""
    out_of_time: bool
    """True if ``run.max_minutes`` ended the run before ``run.iterations``."""
    run_dir: Path
    checkpoint: Path | None
    """The last checkpoint's directory."""
    evaluation: dict[str, float]
    """The last evaluation's metrics (``eval/<team>/...``); empty if none ran."""
    files: dict[str, Path]
    """What the run wrote: ``metrics_csv``, ``learning_curve``, ``gif``, ``config``."""
    wall_s: float
    """Seconds this call took."""
    train_seconds: float = 0.0
    """Training time of the whole run (``time/hours`` * 3600): compiling, chunks and
    evaluations, summed over resumed sessions; what ``run.max_minutes`` limits."""


# --------------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------------


def train(
    config: TrainConfig,
    resume: bool = False,
    progress: bool = True,
    on_chunk: ChunkHook | None = None,
    resume_from_last_good: bool = False,
    host: HostGames | None = None,
) -> TrainResult:
    """Train ``config`` from scratch (or from the latest checkpoint in its run_dir, ``resume``).

    Args:
        config: the run; validated before anything compiles.
        resume: continue from the latest checkpoint of ``run.run_dir``. Its config must match
            this one except for the fields of ``config.RESUMABLE_FIELDS`` (e.g. more iterations),
            else ``RunRefusedError`` (a ``ValueError``) lists the differences. Without a
            checkpoint the run starts fresh. Without ``resume``, a run_dir that already holds
            checkpoints is a ``RunRefusedError``; a damaged checkpoint is a ``CheckpointError``.
        progress: show the progress bar (or plain progress lines when not on a terminal).
        on_chunk: called after each chunk's logging with the new state and the last iteration's
            metrics (tests use it; raising KeyboardInterrupt there acts as a Ctrl-C).
        resume_from_last_good: when the latest checkpoint is damaged, resume from the newest
            intact one; the damaged ones after it move to ``run_dir/damaged_checkpoints``
            (kept, not deleted). Without it a damaged latest checkpoint is a
            ``CheckpointError`` that names it and the newest intact one.
        host: play the games on the host instead of in the compiled chunk (``HostGames``).
    """
    validate(config)
    _check_rollouts_fit(config)
    started = time.perf_counter()
    # The first line comes before the learner is built: that takes seconds before any compile.
    print(
        f"{'resuming' if resume else 'starting'} {config.learner.env.scenario} run in "
        f"{config.run.run_dir}: building the learner", flush=True,
    )
    run = open_run(config, resume, resume_from_last_good, progress, host)
    stop_signals = _StopSignals() if run.processes > 1 else None
    try:
        with contextlib.ExitStack() as games:
            try:
                if run.iteration == 0 and config.run.eval_every > 0 and run.lead:
                    run.evaluate_baseline()
                if host is not None:
                    run.collect = games.enter_context(host.open(run.learner))
                while run.iteration < config.run.iterations:
                    if not run.may_continue(stop_signals):
                        break
                    run.chunk(on_chunk)
            except KeyboardInterrupt:
                run.interrupted = True
        files = run.finish()
    finally:
        if stop_signals is not None:
            stop_signals.restore()
        run.close()
    return TrainResult(
        state=run.state,
        iteration=int(run.state.iteration),
        env_steps=run.env_steps,
        interrupted=run.interrupted,
        out_of_time=run.out_of_time,
        run_dir=run.layout.root,
        checkpoint=run.checkpoint_path,
        evaluation=run.evaluation,
        files=files,
        wall_s=time.perf_counter() - started,
        train_seconds=run.train_seconds,
    )


@dataclasses.dataclass
class Resumed:
    """What a run directory gives back to a resume (fresh runs: the defaults)."""

    state: TrainState
    resuming: bool = False
    env_steps: int = 0
    train_seconds: float = 0.0
    shaping_off_at: int | None = None
    fallback: str = ""
    """Set when a damaged checkpoint was skipped: what happened, for the event log."""


def _check_rollouts_fit(config: TrainConfig) -> None:
    """Each game size's rollout fits in memory (``runs.memory``): before any work."""
    for learner in game_configs(config.learner).values():
        n, count = learner.players_per_team, learner.games_per_iteration
        steps = learner.env.game.episode_length
        check_fits("games_per_iteration", count, rollout_bytes(n, count, steps),
                   f"a rollout of {count} {n}v{n} games of {steps} steps")


def open_run(
    config: TrainConfig, resume: bool, resume_from_last_good: bool, progress: bool = True,
    host: HostGames | None = None,
) -> _Run:
    """Open ``config``'s run directory: refuse a mismatched resume (or an overwrite) before
    anything compiles, build the learners (one per game size of a mixed run; ``host``'s
    one) and restore."""
    from elevens.runs.teams import team_on_field
    from elevens.train.checkpoint import Checkpointer

    layout = RunLayout.of(config.run.run_dir)
    checkpointer = Checkpointer(layout.checkpoints, max_to_keep=config.run.keep_checkpoints)
    try:
        latest = latest_resumable_step(
            checkpointer, resume, "resume=True (--resume)", "run.run_dir"
        )
        damage = _resume_damage(checkpointer, config) if latest is not None else None
        for team in config.run.eval_teams:  # a bad spec fails here, before anything compiles
            evaluation_team(team, config.learner.env.game, game_actions(config.learner))
        if host is not None and config.learner.env.mix:
            raise ValueError(
                f"env.mix={config.learner.env.mix!r} is invalid when the games are played on "
                "the host: they have one game size; leave it out"
            )
        start = None
        if config.run.init_from and latest is None:
            _, start = load_start_params(config.run.init_from, config)
        learners: dict[str, Learner] = {}
        for game, learner in game_configs(config.learner).items():
            env = learner.make_env()
            learners[game] = (
                make_learner(learner, env, team_on_field, devices=config.run.devices)
                if host is None else host.make_learner(learner, env)
            )
        init = learners[config.learner.env.scenario].init
        key = jax.random.key(config.run.seed)
        if latest is None:
            resumed = Resumed(state=init(key, start))
        else:  # shapes are all a restore needs: random networks would cost seconds, unused
            resumed = _restore(
                checkpointer, config, jax.eval_shape(init, key), latest, damage,
                resume_from_last_good, layout,
            )
    except BaseException:
        # Closed here, not left to the garbage collector with Orbax's background thread.
        checkpointer.close()
        raise
    return _Run(config, layout, checkpointer, learners, resumed, progress)


def game_configs(learner: LearnerConfig) -> dict[str, LearnerConfig]:
    """The learner of each game size a run trains on: a mixed run (env.mix) has one learner
    per size over the same TrainState; the main game's evaluates, draws and shapes."""
    if not learner.env.mix:
        return {learner.env.scenario: learner}
    games = (learner.env.scenario, *learner.env.mix)
    return {game: scenario_config(learner, game) for game in games}


def _resume_damage(checkpointer: Any, config: TrainConfig) -> Exception | None:
    """None if the latest checkpoint's config.json matches; its damage if it cannot be read
    (an earlier checkpoint may serve); a mismatch is a RunRefusedError."""
    from elevens.train.checkpoint import CheckpointError

    try:
        check_resumable(checkpointer, config)
    except CheckpointError as error:
        return error
    return None


def _restore(
    checkpointer: Any, config: TrainConfig, target: TrainState, latest: int,
    damage: Exception | None, resume_from_last_good: bool, layout: RunLayout,
) -> Resumed:
    """The latest checkpoint, or with ``resume_from_last_good`` the newest intact one."""
    from elevens.train.checkpoint import CheckpointError

    fallback = ""
    if damage is None:
        try:
            state, _, meta = checkpointer.restore(target)
        except CheckpointError as error:
            damage = error
    if damage is not None:
        step = last_good_step(
            checkpointer, target, latest, damage, resume_from_last_good, layout.root
        )
        check_resumable(checkpointer, config, step)
        state, _, meta = checkpointer.restore(target, step)
        fallback = (
            f"checkpoint {latest} is damaged ({damage}); resumed from checkpoint "
            f"{step}, the damaged ones are in {layout.damaged}"
        )
    saved_processes = int(meta.get("processes", 1))
    if saved_processes != jax.process_count():
        raise RunRefusedError(
            f"cannot resume {layout.root}: it was trained by {saved_processes} process(es) "
            f"and this run has {jax.process_count()}; resume with --num-processes "
            f"{saved_processes} (the games are split over the processes' devices)"
        )
    return Resumed(
        state=state,
        resuming=True,
        env_steps=int(
            meta.get("env_steps", int(state.iteration) * config.learner.env_steps_per_iteration)
        ),
        train_seconds=float(meta.get("train_seconds", 0.0)),
        shaping_off_at=meta.get("shaping_off_iteration"),
        fallback=fallback,
    )


class _Run:
    """An open run: its state between chunks and the hooks of the loop (log, evaluate,
    checkpoint, draw)."""

    def __init__(
        self, config: TrainConfig, layout: RunLayout, checkpointer: Any,
        learners: dict[str, Learner], resumed: Resumed, progress: bool = True,
    ) -> None:
        from elevens.runs.logging import RunLogger, TrainProgress

        self.config, self.layout, self.checkpointer = config, layout, checkpointer
        self.learners = learners
        self.configs = {game: learner.config for game, learner in learners.items()}
        self.learner = learners[config.learner.env.scenario]
        self.lead, self.processes = parallel.is_lead(), jax.process_count()
        run = config.run
        self.chunk_length = config.learner.iterations_per_chunk
        self.schedule = mix_schedule(
            config.learner, -(-run.iterations // self.chunk_length) + 1
        )
        self.env_steps, self.train_seconds = resumed.env_steps, resumed.train_seconds
        self.shaping_off_at = resumed.shaping_off_at
        if self.lead:
            layout.root.mkdir(parents=True, exist_ok=True)
            layout.config.write_text(config.to_json(), encoding="utf-8")
        self.state = parallel.replicate(resumed.state, self.learner.mesh)
        self.iteration = int(self.state.iteration)
        self.last_saved = self.iteration if resumed.resuming else None
        self.eval_key = jax.random.key(run.seed + 1)  # evaluation never touches the run's key
        self.evaluation: dict[str, float] = {}
        self.evaluated_at: int | None = None
        self.interrupted = self.out_of_time = False
        self.budget_s = run.max_minutes * 60.0 if run.max_minutes > 0 else math.inf
        self.checkpoint_path: Path | None = None
        self.compiled: set[str] = set()
        self.collect: Collect | None = None
        """Set while ``HostGames`` plays the games (``train``)."""
        resumed_at = self.iteration if resumed.resuming else None
        self.logger: Any = RunLogger(layout.root, resumed_at=resumed_at) if self.lead else _Silent()
        if resumed.fallback:
            self.logger.event(self.iteration, resumed.fallback)
        self.bar: Any = _Silent()
        if self.lead:
            self.bar = TrainProgress(
                run.iterations, metrics=PROGRESS_METRICS, start=self.iteration,
                start_env_steps=self.env_steps, plain=None if progress else True,
                plain_every=1 if progress else 10**9,
            )
        if resumed.resuming:
            self.bar.note(
                resume_line(layout.root, self.iteration, self.env_steps, self.train_seconds)
            )

    # -- the hooks ---------------------------------------------------------------------------

    def save(self) -> Path | None:
        """Checkpoint the current state (once per iteration)."""
        it = int(self.state.iteration)
        if self.last_saved == it:
            return self.checkpointer.step_directory(it)
        meta = {
            "iteration": it,
            "env_steps": self.env_steps,
            "train_seconds": self.train_seconds,
            "shaping_off_iteration": self.shaping_off_at,
            "processes": self.processes,
        }
        path = self.checkpointer.save(it, self.state, self.config.to_dict(), meta)
        self.last_saved = it
        return path

    def evaluate(self) -> dict[str, float]:
        """Evaluate the current state (its time counts as training time) and log it."""
        began = time.perf_counter()
        it = int(self.state.iteration)
        results = evaluate(
            self.learner, _local(self.state), jax.random.fold_in(self.eval_key, it), self.config.run
        )
        self.train_seconds += time.perf_counter() - began
        # The chunk before logged the time at this step; only the untrained baseline has none.
        time_rows = _time_metrics(self.env_steps, self.train_seconds) if it == 0 else {}
        self.logger.log(it, {**results, **time_rows})
        self.evaluation, self.evaluated_at = results, it
        return results

    def evaluate_baseline(self) -> None:
        """Iteration 0's evaluation: the learning curve starts at the starting networks."""
        run = self.config.run
        if run.eval_teams:
            self.bar.note(
                f"evaluating the {'starting' if run.init_from else 'untrained'} networks "
                f"against {', '.join(run.eval_teams)} ({run.eval_games} games each; the "
                "first match compiles)"
            )
        self.evaluate()

    def log_rows(
        self, before: int, rows: list[dict[str, float]], game: str, seconds: float
    ) -> None:
        """Every iteration of a chunk, with the chunk's time spread evenly over them."""
        steps_per_iteration = self.configs[game].env_steps_per_iteration
        chunk_sps = len(rows) * steps_per_iteration / max(seconds, 1e-9)
        for offset, row in enumerate(rows):
            it = before + offset + 1
            self.env_steps += steps_per_iteration
            spent = self.train_seconds + seconds * (offset + 1) / len(rows)
            row = {**row, **_time_metrics(self.env_steps, spent)}
            row["time/env_steps_per_s"] = chunk_sps
            if self.config.learner.env.mix:
                row["env/players_per_team"] = float(self.configs[game].players_per_team)
            self.logger.log(it, row)
            if row["env/shaping_switched_off"] == 1.0:
                self.shaping_off_at = it
                self.logger.event(it, "reward shaping switched off for good")
        self.train_seconds += seconds

    # -- the steps of the loop ---------------------------------------------------------------

    def may_continue(self, stop_signals: _StopSignals | None) -> bool:
        """False when the time budget is spent; KeyboardInterrupt when any process was told to
        stop (every process stops at this same iteration)."""
        if stop_signals is not None and parallel.agree_any(stop_signals.requested):
            raise KeyboardInterrupt
        if parallel.agree_any(self.train_seconds >= self.budget_s):
            self.out_of_time = True
            self.logger.event(
                self.iteration,
                f"time budget reached: {self.train_seconds / 60:.1f} of "
                f"run.max_minutes={self.config.run.max_minutes:g} min",
            )
            return False
        return True

    def chunk(self, on_chunk: ChunkHook | None) -> None:
        """One compiled chunk of K iterations (of the scheduled game size), then the hooks."""
        run = self.config.run
        count = min(self.chunk_length, run.iterations - self.iteration)
        game = self.schedule[self.iteration // self.chunk_length]
        if game not in self.compiled and self.collect is not None:
            self.bar.note(f"playing the first {game} iteration: the update compiles after it")
        elif game not in self.compiled:
            self.bar.note(
                f"compiling the {game} training chunk ({count} iteration"
                f"{'s' if count > 1 else ''}): once per run and size: about 10 s for 1 v 1 "
                "and 30 s for 11 v 11 on an idle 2-core CPU, more on a busy one"
            )
        began = time.perf_counter()
        if self.collect is None:
            new_state, metrics = self.learners[game].update(
                with_games(self.state, self.configs[game]), count
            )
            rows = _host_metrics(metrics)  # blocks until the chunk is done
        else:
            new_state, rows = self.host_iterations(self.collect, count)
        seconds = time.perf_counter() - began
        if game not in self.compiled:
            self.compiled.add(game)
            self.bar.note(f"compiled and ran the first {game} chunk in {seconds:.0f} s")
        self.state = with_games(new_state, self.configs[self.config.learner.env.scenario])
        before, self.iteration = self.iteration, int(self.state.iteration)
        self.log_rows(before, rows, game, seconds)
        shown = dict(rows[-1])
        if _due(before, self.iteration, run.eval_every) and self.lead:
            self.evaluate()
        shown.update(self.evaluation)
        self.bar.update(self.iteration, self.env_steps, shown)
        if _due(before, self.iteration, run.checkpoint_every):
            self.checkpoint_path = self.save()
        if on_chunk is not None:
            on_chunk(self.state, shown)

    def host_iterations(
        self, collect: Collect, count: int
    ) -> tuple[TrainState, list[dict[str, float]]]:
        """``count`` iterations as ``learner.iteration`` runs them, the games played by
        ``collect`` on the host: the same keys, the same ``improve``."""
        state, rows = self.state, []
        for _ in range(count):
            key, rollout_key, shuffle_key, opponent_key = jax.random.split(state.key, 4)
            data, row = collect(state, rollout_key)
            state, metrics = _improve(self.learner)(
                state.replace(key=key), data, shuffle_key, opponent_key
            )
            rows.append({**{name: float(value) for name, value in metrics.items()}, **row})
        return state, rows

    def finish(self) -> dict[str, Path]:
        """The final checkpoint (also after Ctrl-C), evaluation, learning curve and GIF."""
        from elevens.runs.pictures import write_gif, write_learning_curve

        self.checkpoint_path = self.save()
        if self.interrupted:
            self.logger.event(
                self.iteration,
                f"interrupted (Ctrl-C or SIGTERM): checkpoint {self.checkpoint_path}",
            )
        if not self.lead:
            self.logger.flush()
            return {}
        files = {"metrics_csv": self.logger.csv_path, "config": self.layout.config}
        if not self.interrupted and self.evaluated_at != self.iteration:
            self.evaluate()
        self.logger.flush()
        run = self.config.run
        if run.write_plot:
            # Also after Ctrl-C: the curve so far is what a stopped run is checked by.
            files["learning_curve"] = write_learning_curve(
                self.layout.root, self.layout.learning_curve, title=_title(self.config)
            )
        if not self.interrupted and run.write_gif:
            files["gif"] = write_gif(
                self.learner, _local(self.state), self.layout.gif, seed=run.seed,
                deterministic=run.eval_deterministic,
            )
        return files

    def close(self) -> None:
        self.bar.close()
        self.logger.close()
        self.checkpointer.close()


# --------------------------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------------------------


def evaluate(
    learner: Learner, state: TrainState, key: jax.Array, run: RunConfig | None = None,
    teams: tuple[str, ...] | None = None, num_games: int | None = None,
) -> dict[str, float]:
    """Play the learner (a NetworkTeam) against each team with ``play_match``: handcrafted
    teams by name, or any team spec (a shipped team, a run or checkpoint, an exported folder).
    ``run``'s evaluation fields (default: ``RunConfig``'s) give the teams, the games and
    whether the learner plays its mean action; ``teams`` and ``num_games`` override the first
    two.

    Returns ``eval/<team>/outcome`` (``<team>``: the spec, ``/`` made ``_``; the mean outcome
    from the learner's view: win 1, draw 0.5, loss 0), ``/win``, ``/draw``, ``/loss``,
    ``/goals_for`` and ``/goals_against``. Games use the training env's params with shaping as
    configured (shaping does not change the score); the learner plays each side in half of
    them.
    """
    from elevens.eval.match import play_match, summary
    from elevens.teams.network import NetworkTeam

    run = RunConfig() if run is None else run
    teams = run.eval_teams if teams is None else teams
    num_games = run.eval_games if num_games is None else num_games
    team = NetworkTeam(policy=learner.policy, deterministic=run.eval_deterministic, name="learner")
    results: dict[str, float] = {}
    for index, name in enumerate(teams):
        opponent, opponent_params = evaluation_team(
            name, learner.env_params, game_actions(learner.config)
        )
        result = play_match(
            learner.env, learner.env_params, team, opponent,
            jax.random.fold_in(key, index), num_games, home_params=state.params.policy,
            away_params=opponent_params,
        )
        numbers = summary(result)
        label = metric_label(name)
        results[f"eval/{label}/outcome"] = numbers["mean"]
        for field in ("win", "draw", "loss", "goals_for", "goals_against"):
            results[f"eval/{label}/{field}"] = numbers[field]
    return results


def evaluation_team(spec: str, env_params: EnvParams, actions: int = 2) -> tuple[Any, Any]:
    """(TeamPolicy, params) of an evaluation opponent: a handcrafted team told the field, or
    a trained team (figure 6.4's line against a checkpoint); one that cannot play the game
    (``actions`` action values, ``env_params``' team size) is a ValueError."""
    from elevens.runs.teams import team_on_field

    team = team_on_field(spec, env_params, "run.eval_teams")
    try:
        team.check_size(int(env_params.players_per_team), actions)
    except ValueError as error:
        raise ValueError(f"run.eval_teams team {spec!r}: {error}") from error
    return team.policy, team.params


# --------------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------------


class _Silent:
    """The logger and progress display of processes other than 0: they log nothing."""

    csv_path = None

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *args, **kwargs: None


class _StopSignals:
    """Ctrl-C and SIGTERM as a flag while several processes train: each process checks it at
    a chunk end and all stop together (an exception mid-chunk in one process would leave the
    others waiting in a collective)."""

    def __init__(self) -> None:
        self.requested = False
        self._previous = {
            number: signal.signal(number, self._request)
            for number in (signal.SIGINT, signal.SIGTERM)
        }

    def _request(self, signum: int, frame: Any) -> None:
        self.requested = True

    def restore(self) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)


def _local(state: TrainState) -> TrainState:
    """``state`` with its networks on the host: evaluation and the GIF play on this process's
    own device, whatever mesh the state is replicated on."""
    return state.replace(params=parallel.to_host(state.params))


def with_games(state: TrainState, config: LearnerConfig) -> TrainState:
    """``state`` with the per-game opponent indices of ``config``'s games per iteration (a mixed
    run's sizes differ in games; the indices are zeros for the opponents a mix allows)."""
    games = opponent_index_count(config)
    if state.opponent.indices.shape == (games,):
        return state
    return state.replace(opponent=state.opponent.replace(indices=jnp.zeros((games,), jnp.int32)))


@functools.lru_cache(maxsize=8)
def _improve(learner: Learner) -> Callable[..., tuple[TrainState, Metrics]]:
    """The learner's ``improve``, jitted once per learner (a resume in the same process reuses
    it, as ``make_learner``'s cache does the compiled chunk)."""
    return jax.jit(learner.improve)


def _host_metrics(metrics: Metrics) -> list[dict[str, float]]:
    """{name: f32[K]} -> K dicts of Python floats, one per iteration."""
    arrays = {name: np.asarray(value) for name, value in metrics.items()}
    length = len(next(iter(arrays.values())))
    return [{name: float(values[i]) for name, values in arrays.items()} for i in range(length)]


def _due(before: int, after: int, every: int) -> bool:
    """Whether a multiple of ``every`` lies in (before, after]."""
    return every > 0 and after // every > before // every


def _time_metrics(env_steps: int, seconds: float) -> dict[str, float]:
    return {"time/env_steps": float(env_steps), "time/hours": seconds / 3600.0}


def _title(config: TrainConfig) -> str:
    return (
        f"{config.learner.env.scenario} ({config.preset} preset), opponent: "
        f"{config.learner.opponent.kind}, seed {config.run.seed}"
    )
