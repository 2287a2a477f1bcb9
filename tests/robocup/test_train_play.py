"""Training and matches in the server's host loop (elevens.robocup.train / play).

Without a server, the loop runs on ``SimEnv``: the simulator behind RoboCupEnv's host-side
contract (numpy in and out, the same info keys), which can also fake a server restart. The tests
at the end use a real rcssserver when there is one.
"""

from __future__ import annotations

import csv
import functools
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pytest

from elevens.cli import main
from elevens.env.soccer import Soccer
from elevens.robocup.actions import ActionIndex
from elevens.robocup.external import TeamCommandNotFound
from elevens.robocup.play import load_robocup_team, play_robocup
from elevens.robocup.train import (
    RoboCupTrainConfig,
    ServerGames,
    make_robocup_config,
    train_robocup,
)
from elevens.runs.errors import RunRefusedError
from elevens.runs.layout import EPISODES_CSV
from elevens.runs.logging import read_metrics_csv
from elevens.train.checkpoint import Checkpointer
from elevens.train.config import NetworkConfig, make_config
from elevens.train.learner import make_learner
from tests.robocup.conftest import needs_rcssserver, wait_stopped


@functools.cache
def _sim_game(players_per_team: int) -> tuple[Soccer, Any, Any, Any, Any]:
    """The simulator and its jitted reset, step and global state, shared by every SimEnv of a
    size (a fresh jit of each for every game would trace them again)."""
    env = Soccer(players_per_team)
    return (env, env.default_params(), jax.jit(env.reset), jax.jit(env.step),
            jax.jit(env.global_state))


class SimEnv:
    """RoboCupEnv's host contract on the simulator. ``restart_at``: the step whose result is a
    faked server restart (a fresh episode, done, info["restarted"])."""

    def __init__(self, players_per_team: int, restart_at: int | None = None) -> None:
        self.players_per_team = players_per_team
        self.restart_at = restart_at
        self.env, self.params, self._reset, self._step, self._global = _sim_game(players_per_team)
        self.key = jax.random.key(0)
        self.steps = 0
        self.closed = False
        self.actions_seen: list[np.ndarray] = []

    def reset(self, seed: int | None = None) -> tuple[Any, Any]:
        self.key = jax.random.key(0 if seed is None else seed)
        self.state, obs = self._reset(self.key, self.params)
        self.steps = 0
        return self.state, jax.tree.map(np.asarray, obs)

    def step(self, actions: np.ndarray) -> tuple[Any, Any, np.ndarray, bool, dict[str, Any]]:
        assert actions.shape == (2, self.players_per_team, 2) and np.isfinite(actions).all()
        self.actions_seen.append(actions)
        self.steps += 1
        self.key, key = jax.random.split(self.key)
        if self.restart_at is not None and self.steps == self.restart_at:
            self.restart_at = None  # once
            state, obs = self.reset(seed=99)
            zeros = np.zeros((2, self.players_per_team), np.float32)
            info = {"restarted": True, "goals": np.zeros(2, np.int32), "goal_reward": zeros,
                    "ball_shaping": zeros, "approach_shaping": zeros,
                    "possession_shaping": zeros, "holder": np.zeros(2, np.float32),
                    "scripted": np.zeros((2, self.players_per_team), bool), "missed": 0}
            return state, obs, zeros, True, info
        self.state, obs, rewards, done, step_info = self._step(
            key, self.state, actions, self.params
        )
        info = {
            "restarted": False,
            "goals": np.asarray(step_info.goals),
            "goal_reward": np.asarray(step_info.goal_reward),
            "ball_shaping": np.asarray(step_info.ball_shaping),
            "approach_shaping": np.asarray(step_info.approach_shaping),
            "possession_shaping": np.asarray(step_info.possession_shaping),
            "holder": np.asarray(step_info.holder),
            "scripted": np.zeros((2, self.players_per_team), bool),  # drills: no routines
            "missed": 0,
            "malformed": 0,
        }
        return self.state, jax.tree.map(np.asarray, obs), np.asarray(rewards), bool(done), info

    def global_state(self, state: Any) -> Any:
        return jax.tree.map(np.asarray, self._global(state, self.params))

    def close(self) -> None:
        self.closed = True


SMALL_NETWORKS = {"network.features": 16, "network.num_heads": 2, "network.lstm_features": 8,
                  "network.lstm_layers": 1}
"""The loop's tests train small networks (shorter compiles): none of them depends on the size."""
DEFAULT_NETWORKS = {
    f"network.{name}": getattr(NetworkConfig(), name)
    for name in ("features", "num_heads", "lstm_features", "lstm_layers")
}


def small_config(tmp_path: Path, **overrides: Any) -> RoboCupTrainConfig:
    players = overrides.pop("env.players_per_team", 1)
    values: dict[str, Any] = {
        "env.players_per_team": players, "ppo.minibatch_size": players,
        "games_per_iteration": 2, "env.episode_length": 12, "run.iterations": 2,
        "run.max_minutes": 0.0, "run.run_dir": str(tmp_path / "run"),
        "run.checkpoint_every": 1, "server.threads": False, **SMALL_NETWORKS,
    }
    values.update(overrides)
    return make_robocup_config(**values)


def test_config_rejects_bad_values_by_name() -> None:
    with pytest.raises(ValueError, match="games_per_iteration=0"):
        make_robocup_config(games_per_iteration=0)
    with pytest.raises(ValueError, match="opponent.kind='neighbours' is invalid"):
        make_robocup_config(**{"opponent.kind": "neighbours"})
    with pytest.raises(ValueError, match="learning_rate=-0.1"):
        make_robocup_config(**{"ppo.learning_rate": -0.1})
    with pytest.raises(ValueError, match="run.devices=2 is invalid in elevens robocup train"):
        make_robocup_config(**{"run.devices": 2})
    with pytest.raises(ValueError, match="env.episode_length=1 is invalid"):
        make_robocup_config(**{"env.episode_length": 1})
    # 11 a side needs whole games in a minibatch: the error says what fits.
    with pytest.raises(ValueError, match="multiple of 11 that divides the batch of 22"):
        make_robocup_config(**{"env.players_per_team": 11})
    with pytest.raises(ValueError, match="'server.port': unknown field.*server.threads"):
        make_robocup_config(**{"server.port": 1})


def test_the_robocup_config_is_the_simulators_learner_and_run() -> None:
    config = RoboCupTrainConfig()
    assert config.validate() is config
    learner = config.learner
    # Table 6.1's learning rate, the server's formation spawns, 200-cycle drills, one game per
    # server and minibatch, one iteration per host step.
    assert learner.ppo.learning_rate == 1e-4 and learner.env.game.spawn == "formation"
    assert (learner.env.game.episode_length, learner.games_per_iteration) == (200, 2)
    assert (learner.num_minibatches, learner.iterations_per_chunk) == (2, 1)
    assert config.run.max_minutes == 10.0 and config.run.eval_teams == ()
    saved = config.train_config()
    assert (saved.preset, saved.learner, saved.run) == ("robocup", learner, config.run)


def test_server_games_pack_a_rollout_like_the_compiled_one(tmp_path: Path) -> None:
    config = small_config(tmp_path, **{"env.players_per_team": 2, "env.episode_length": 6})
    trainer = make_learner(config.learner, config.learner.make_env())
    state = trainer.init(jax.random.key(0))
    envs = [SimEnv(2), SimEnv(2, restart_at=3)]
    games = ServerGames(config, lambda g: envs[g])
    with games.open(trainer) as collect:
        data, row = collect(state, jax.random.key(1))
    assert all(env.closed for env in envs)
    t = data.transitions
    assert t.obs.self_features.shape == (4, 6, 15)
    assert t.obs.entities.shape == (4, 6, 4, 11)
    assert t.pre_tanh.shape == (4, 6, 2) and t.log_prob.shape == (4, 6)
    assert data.game_global_state.players.shape == (2, 6, 4, 11)
    assert data.scripted is not None and data.scripted.shape == (4, 6)
    assert np.asarray(data.learner_side).tolist() == [0, 1]
    done, reset = np.asarray(t.done), np.asarray(t.reset)
    # Episode ends: the last step everywhere, and the faked restart in game 1 (players 2, 3).
    assert done[:, 5].all() and not done[:2, :5].any()
    assert done[2:, 2].all() and not done[2:, [0, 1, 3, 4]].any()
    # Starts: step 0 everywhere, and the step after the restart in game 1.
    assert reset[:, 0].all() and reset[2:, 3].all() and not reset[:2, 1:].any()
    assert games.restarts == 1 and row["robocup/restarts"] == 1.0
    with (tmp_path / "run" / EPISODES_CSV).open() as f:
        assert [r["restarts"] for r in csv.DictReader(f)] == ["0", "1"]
    # The learner acted on side 1 in game 1: the actions there are its samples, squashed.
    acted = np.stack(envs[1].actions_seen)[:, 1]  # [T, n, 2]
    np.testing.assert_allclose(acted, np.tanh(np.asarray(t.pre_tanh[2:])).swapaxes(0, 1),
                               atol=1e-5)
    # The compiled learn accepts it.
    learned = jax.jit(trainer.learn)(state.params, state.opt_state, data, jax.random.key(2))
    assert np.isfinite(float(learned.update.metrics.total))


def test_an_external_opponent_leaves_the_learner_on_the_left_and_its_side_unplayed(
    tmp_path: Path,
) -> None:
    config = small_config(tmp_path, **{"env.players_per_team": 2, "env.episode_length": 4,
                                       "server.opponent_cmd": "start.sh"})
    trainer = make_learner(config.learner, config.learner.make_env())
    state = trainer.init(jax.random.key(0))
    envs = [SimEnv(2), SimEnv(2)]
    with ServerGames(config, lambda g: envs[g]).open(trainer) as collect:
        data, _ = collect(state, jax.random.key(1))
    assert np.asarray(data.learner_side).tolist() == [0, 0]
    for env in envs:
        acted = np.stack(env.actions_seen)  # [T, 2, n, 2]
        assert np.abs(acted[:, 0]).sum() > 0 and not acted[:, 1].any()  # nobody acts for 1


def test_config_checks_the_external_opponent() -> None:
    with pytest.raises(ValueError, match="server.opponent_cmd=' '"):
        make_robocup_config(**{"server.opponent_cmd": " "})
    with pytest.raises(ValueError, match="server.opponent_name='elevens_l'"):
        make_robocup_config(**{"server.opponent_cmd": "x", "server.opponent_name": "elevens_l"})


def test_train_writes_episodes_checkpoints_and_resumes(tmp_path: Path) -> None:
    envs: list[SimEnv] = []

    def factory(index: int) -> SimEnv:
        envs.append(SimEnv(1))
        return envs[-1]

    config = small_config(tmp_path)
    result = train_robocup(config, env_factory=factory, progress=False)
    assert result.iteration == 2 and result.episodes == 4 and not result.interrupted
    assert result.env_steps == 2 * 2 * 12
    assert all(env.closed for env in envs)
    run = tmp_path / "run"
    with (run / EPISODES_CSV).open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["iteration"], r["game"]) for r in rows] == [
        ("1", "0"), ("1", "1"), ("2", "0"), ("2", "1")
    ]
    assert {r["steps"] for r in rows} == {"12"}
    assert (run / "checkpoints" / "2").is_dir() and (run / "metrics.csv").exists()
    # The simulator trainer's metrics, under the same names, then the server's own.
    logged = read_metrics_csv(run)
    for name in ("train/policy_loss", "train/grad_norm", "train/explained_variance",
                 "train/visible_share", "env/shaping_active", "opponent/updates",
                 "robocup/restarts", "time/env_steps_per_s"):
        assert name in logged and logged[name].steps.tolist() == [1, 2], name
    robocup_config = json.loads((run / "robocup_config.json").read_text())
    assert robocup_config["learner"]["games_per_iteration"] == 2
    assert robocup_config["server"]["threads"] is False
    assert json.loads((run / "config.json").read_text())["config_version"] == 2
    assert logged["time/env_steps"].values[-1] == 48
    # A second run into the same directory needs --resume, and then continues.
    with pytest.raises(ValueError, match="resume"):
        train_robocup(config, env_factory=factory)
    # A resume whose networks, PPO or game sizes differ is refused with the list of differences,
    # before any server starts.
    other = small_config(
        tmp_path, **{"run.iterations": 3, "env.episode_length": 13, "ppo.learning_rate": 3e-4}
    )
    started = len(envs)
    with pytest.raises(RunRefusedError) as refused:
        train_robocup(other, resume=True, env_factory=factory)
    assert "env.episode_length: 12 -> 13" in str(refused.value)
    assert "ppo.learning_rate: 0.0001 -> 0.0003" in str(refused.value)
    assert len(envs) == started
    more = small_config(tmp_path, **{"run.iterations": 3})
    resumed = train_robocup(more, resume=True, env_factory=factory, progress=False)
    assert resumed.iteration == 3 and resumed.episodes == 2
    assert (run / "checkpoints" / "3").is_dir()
    # The checkpoint is a normal one: it loads as a team for the simulator and the server.
    team = load_robocup_team(str(run), "sim")
    assert team.name


# Self-play's opponent plays the server games as polyak's does (the default, in the episodes
# test above: one network for every game); its copy of the learner is the learner's own,
# tested in tests/train/test_opponents.py. --slow: a compile of its own.
@pytest.mark.parametrize("kind", [pytest.param("self", marks=pytest.mark.slow), "league"])
def test_every_opponent_kind_trains_in_the_server_loop(tmp_path: Path, kind: str) -> None:
    # The server loop improves through the learner's own opponent strategies: a league's
    # snapshots play their games one network per game, and its metrics are logged.
    config = small_config(tmp_path, **{"opponent.kind": kind})
    result = train_robocup(config, env_factory=lambda i: SimEnv(1), progress=False)
    assert result.iteration == 2
    logged = read_metrics_csv(tmp_path / "run")
    name, expected = (
        ("opponent/league_size", [1.0, 1.0]) if kind == "league"
        else ("opponent/updates", [1.0, 2.0])  # self-play: a copy of the learner every time
    )
    assert logged[name].values.tolist() == expected
    team = load_robocup_team(str(tmp_path / "run"), "sim")
    assert team.name


class KickScoreEnv(SimEnv):
    """RoboCupEnv's host contract for 12-value actions (``action="thesis12"``): the game is
    the simulator's, moved by each action's dash power and turn moment, and a team's reward
    each step is its players' kick selection score (thesis table 4.1), so a learner that
    learns raises it."""

    def step(self, actions: np.ndarray) -> tuple[Any, Any, np.ndarray, bool, dict[str, Any]]:
        assert actions.shape == (2, self.players_per_team, 12) and np.isfinite(actions).all()
        moves = actions[..., [ActionIndex.DASH_POWER, ActionIndex.TURN_MOMENT]]
        state, obs, rewards, done, info = super().step(np.ascontiguousarray(moves))
        self.actions_seen[-1] = actions
        info["goal_reward"] = actions[..., ActionIndex.KICK_SCORE].astype(np.float32)
        return state, obs, rewards, done, info


@pytest.mark.slow
def test_a_12_value_policy_learns_in_the_server_loop(tmp_path: Path) -> None:
    # network.actions=12: the policy gives the thesis's 12 values, the servers play them
    # ("thesis12"), PPO improves them and the run is a team that elevens robocup match plays.
    envs: list[KickScoreEnv] = []

    def factory(index: int) -> KickScoreEnv:
        envs.append(KickScoreEnv(1))
        return envs[-1]

    # The default networks: the run this learning check was tuned with.
    config = small_config(
        tmp_path, **{"network.actions": 12, "games_per_iteration": 8, "run.iterations": 12,
                     "ppo.learning_rate": 3e-3, "env.ball_shaping_weight": 0.0,
                     "env.approach_shaping_weight": 0.0, **DEFAULT_NETWORKS}
    )
    result = train_robocup(config, env_factory=factory, progress=False)
    assert result.iteration == 12
    assert all(a.shape == (2, 1, 12) for env in envs for a in env.actions_seen)
    logged = read_metrics_csv(tmp_path / "run")
    reward = logged["env/goal_reward"].values  # the learner's kick scores summed over a game
    assert reward[-3:].mean() > reward[:3].mean() + 2.0, reward
    team = load_robocup_team(str(tmp_path / "run"), "thesis12")
    assert team.actions == 12
    with pytest.raises(ValueError, match="plays the simulator"):
        small_config(tmp_path, **{"network.actions": 12, "run.eval_teams": ("naive",)})
    with pytest.raises(ValueError, match="run.write_gif"):
        small_config(tmp_path, **{"network.actions": 12, "run.write_gif": True})


def test_server_training_can_evaluate_in_the_simulator(tmp_path: Path) -> None:
    # run.eval_teams: the policy also plays the simulator's teams (every run.eval_every
    # iterations and at the end) and the learning curve is drawn, as in elevens train.
    config = small_config(
        tmp_path, **{"run.eval_teams": ("random",), "run.eval_games": 4, "run.eval_every": 1}
    )
    train_robocup(config, env_factory=lambda i: SimEnv(1), progress=False)
    logged = read_metrics_csv(tmp_path / "run")
    # The curve starts at the untrained networks, as in elevens train.
    assert logged["eval/random/outcome"].steps.tolist() == [0, 1, 2]
    assert (tmp_path / "run" / "learning_curve.png").stat().st_size > 0


def test_ctrl_c_writes_a_checkpoint(tmp_path: Path) -> None:
    class Interrupting(SimEnv):
        def step(self, actions: np.ndarray) -> Any:
            if self.steps == 4:
                raise KeyboardInterrupt
            return super().step(actions)

    config = small_config(tmp_path, **{"run.iterations": 5})
    result = train_robocup(config, env_factory=lambda i: Interrupting(1), progress=False)
    assert result.interrupted and result.iteration == 0
    assert result.checkpoint is not None and result.checkpoint.is_dir()


def test_ctrl_c_in_a_server_game_still_draws_the_learning_curve(tmp_path: Path) -> None:
    # Ctrl-C while the servers play iteration 2: the run keeps iteration 1 (its checkpoint and
    # metrics) and draws the curve so far, as elevens train does; the servers are closed.
    envs: list[SimEnv] = []

    class Interrupting(SimEnv):
        def step(self, actions: np.ndarray) -> Any:
            if len(self.actions_seen) == 12 + 4:  # step 4 of the second episode
                raise KeyboardInterrupt
            return super().step(actions)

    def factory(index: int) -> SimEnv:
        envs.append(Interrupting(1))
        return envs[-1]

    config = small_config(tmp_path, **{"run.iterations": 5, "run.checkpoint_every": 5})
    result = train_robocup(config, env_factory=factory, progress=False)
    assert result.interrupted and result.iteration == 1 and result.episodes == 2
    assert result.checkpoint == tmp_path / "run" / "checkpoints" / "1"
    assert (tmp_path / "run" / "learning_curve.png").stat().st_size > 0
    assert all(env.closed for env in envs)
    assert read_metrics_csv(tmp_path / "run")["train/policy_loss"].steps.tolist() == [1]


def test_max_minutes_add_up_over_resumed_server_runs(tmp_path: Path) -> None:
    # run.max_minutes bounds the run's training time summed over its sessions, as in elevens
    # train: a resume starts from the time already spent, not from zero.
    iteration_s = 2.4  # at least, from the sleeps of an iteration's 2 games x 12 steps

    class Slow(SimEnv):
        def step(self, actions: np.ndarray) -> Any:
            time.sleep(iteration_s / 24)
            return super().step(actions)

    envs: list[Slow] = []

    def factory(index: int) -> Slow:
        envs.append(Slow(1))
        return envs[-1]

    config = small_config(tmp_path, **{"run.iterations": 5, "run.max_minutes": iteration_s / 60})
    first = train_robocup(config, env_factory=factory, progress=False)
    assert first.iteration == 1 and first.out_of_time and first.train_seconds >= iteration_s
    # The same budget again: already spent, so not one more game is played.
    played = sum(len(env.actions_seen) for env in envs)
    again = train_robocup(config, resume=True, env_factory=factory, progress=False)
    assert again.iteration == 1 and again.out_of_time and again.episodes == 0
    assert sum(len(env.actions_seen) for env in envs) == played
    # A second more than the first session spent: one more iteration, then the sum is over.
    budget = (first.train_seconds + 1.0) / 60.0
    more = small_config(tmp_path, **{"run.iterations": 5, "run.max_minutes": budget})
    last = train_robocup(more, resume=True, env_factory=factory, progress=False)
    assert last.iteration == 2 and last.out_of_time
    hours = read_metrics_csv(tmp_path / "run")["time/hours"]
    spent = dict(zip(hours.steps.tolist(), (hours.values * 3600.0).tolist(), strict=True))
    # The second counts from the first.
    assert spent[1] >= iteration_s and spent[2] >= spent[1] + iteration_s
    assert last.train_seconds >= spent[2] > budget * 60.0


def test_the_host_loop_refuses_a_mix_of_game_sizes_before_anything_starts(
    tmp_path: Path,
) -> None:
    from elevens.runs.loop import HostGames, train

    def refuse(*args: Any) -> Any:
        raise AssertionError("nothing is built or started for a refused run")

    config = make_config(
        "2v2", **{"env.players_per_team": 1, "env.mix": ("2v2",), "env.mix_shares": (0.5,),
                  "run.run_dir": str(tmp_path / "run")}
    )
    with pytest.raises(ValueError, match=r"env.mix=\('2v2',\) is invalid when the games"):
        train(config, progress=False, host=HostGames(make_learner=refuse, open=refuse))


def test_play_handcrafted_teams_on_a_stand_in_env() -> None:
    env = SimEnv(2)
    lines: list[str] = []
    results = play_robocup(
        "naive", "random", episodes=1, action="sim", env=_Episode(env, 20), print_fn=lines.append
    )
    assert len(results) == 1 and results[0].steps == 20
    assert lines[0].startswith("episode 0: naive")
    with pytest.raises(ValueError, match="plays \\(move, rot\\) actions.*must be 'sim'"):
        load_robocup_team("elevens-2v2", "thesis12")
    with pytest.raises(ValueError, match="episodes=0"):
        play_robocup("naive", "random", episodes=0, env=_Episode(env, 5))


class _Episode:
    """Ends a SimEnv episode after ``length`` steps (RoboCupEnv's episode_length)."""

    def __init__(self, env: SimEnv, length: int) -> None:
        self.env, self.length, self.players_per_team = env, length, env.players_per_team

    def reset(self, seed: int | None = None) -> Any:
        return self.env.reset(seed)

    def step(self, actions: np.ndarray) -> Any:
        state, obs, rewards, _, info = self.env.step(actions)
        return state, obs, rewards, self.env.steps >= self.length, info

    def close(self) -> None:
        self.env.close()


def test_cli_says_how_to_install_a_missing_server(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("ELEVENS_RCSSSERVER", raising=False)
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "bench", "--cycles", "10"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "rcssserver was not found" in err and "github.com/rcsoccersim/rcssserver" in err


def test_cli_train_refuses_another_runs_directory_without_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with Checkpointer(tmp_path / "checkpoints") as checkpointer:
        checkpointer.save(3, {"x": np.zeros(2)}, config={})
    before = sorted(p.name for p in (tmp_path / "checkpoints").iterdir())
    # Any executable passes the binary check; the refusal comes before a server starts.
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "train", "--run.run-dir", str(tmp_path),
              "--server.rcssserver", sys.executable])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("elevens robocup train: error: ") and "already holds checkpoints" in err
    assert "Traceback" not in err
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == before


@needs_rcssserver
def test_server_bench_reports_cycles_per_second(capsys: pytest.CaptureFixture[str]) -> None:
    main(["robocup", "bench", "--players", "2", "--cycles", "200", "--json"])
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["cycles_per_s"] > 0 and result["missed"] == 0 and result["players"] == 4


@pytest.mark.slow
@needs_rcssserver
@pytest.mark.parametrize("actions", [2, 12])
def test_server_short_training_run(tmp_path: Path, actions: int) -> None:
    config = small_config(
        tmp_path, **{"env.episode_length": 20, "server.threads": True,
                     "server.rcssserver": os.environ.get("ELEVENS_RCSSSERVER"),
                     "network.actions": actions}
    )
    result = train_robocup(config, progress=False)
    assert result.iteration == 2 and result.restarts == 0
    with (tmp_path / "run" / EPISODES_CSV).open() as f:
        assert len(list(csv.DictReader(f))) == 4


@pytest.mark.slow
@needs_rcssserver
def test_server_training_against_an_external_team(tmp_path: Path) -> None:
    fake = Path(__file__).with_name("fake_team.py")
    config = small_config(
        tmp_path,
        **{"env.players_per_team": 2, "games_per_iteration": 1, "env.episode_length": 20,
           "server.rcssserver": os.environ.get("ELEVENS_RCSSSERVER"),
           "server.opponent_cmd":
               f"{sys.executable} {fake} --port {{port}} --team {{team}} --players 2",
           "server.opponent_name": "fake"},
    )
    result = train_robocup(config, progress=False)
    assert result.iteration == 2 and result.restarts == 0
    with (tmp_path / "run" / EPISODES_CSV).open() as f:
        rows = list(csv.DictReader(f))
    assert [r["learner_side"] for r in rows] == ["0", "0"]
    assert all(r["missed"] == "0" and int(r["server_cycles"]) >= 1 for r in rows)


@needs_rcssserver
def test_server_training_names_an_opponent_command_that_does_not_exist_at_once(
    tmp_path: Path,
) -> None:
    # Not retried: a restarted server would not make the command exist.
    config = small_config(
        tmp_path,
        **{"env.players_per_team": 1, "games_per_iteration": 1, "env.episode_length": 20,
           "server.rcssserver": os.environ.get("ELEVENS_RCSSSERVER"),
           "server.opponent_cmd": f"{tmp_path / 'start.sh'} -p {{port}}",
           "server.opponent_name": "fake"},
    )
    # At once: the shell's status (TeamCommandNotFound), not a timeout's error or a restart.
    with pytest.raises(TeamCommandNotFound, match="start command failed .status 127."):
        train_robocup(config, progress=False)


@needs_rcssserver
def test_server_naive_plays_random() -> None:
    results = play_robocup(
        "naive", "random", players_per_team=1, episodes=1, episode_length=60,
        action="thesis12", rcssserver=os.environ.get("ELEVENS_RCSSSERVER"),
        print_fn=lambda _: None,
    )
    assert results[0].steps == 60 and results[0].restarts == 0


def test_init_from_a_checkpoint_starts_from_its_networks_and_resumes_with_them(
    tmp_path: Path,
) -> None:
    from elevens.runs.teams import load_learner_params

    # A source with small_config's networks, written by hand (an init, no training): the run
    # from it compiles what the tests above compiled.
    source_config = make_config("2v2", **{"env.players_per_team": 1, **SMALL_NETWORKS})
    source_state = make_learner(
        source_config.learner, source_config.learner.make_env()
    ).init(jax.random.key(3))
    with Checkpointer(tmp_path / "source" / "checkpoints") as checkpointer:
        checkpointer.save(0, source_state, source_config.to_dict(), {"iteration": 0})
    # Its networks must be this run's: a clear refusal names the flags to pass.
    with pytest.raises(RunRefusedError, match="other networks.*--network.features 16"):
        train_robocup(small_config(tmp_path, **{"run.init_from": str(tmp_path / "source"),
                                                "network.features": 24}),
                      env_factory=lambda i: SimEnv(1), progress=False)
    # No time to play: the run saves its starting point, which must be the source's networks.
    target = small_config(
        tmp_path, **{"run.init_from": str(tmp_path / "source"), "run.max_minutes": 1e-9}
    )
    result = train_robocup(target, env_factory=lambda i: SimEnv(1), progress=False)
    assert result.iteration == 0
    _, expected = load_learner_params(str(tmp_path / "source"))
    _, started = load_learner_params(str(tmp_path / "run"))
    for a, b in zip(jax.tree.leaves(expected), jax.tree.leaves(started), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(FileNotFoundError, match="nothing-here does not exist"):
        load_learner_params(str(tmp_path / "run" / "nothing-here"))
    # A resume keeps the networks (a resume ignores init_from, as elevens train does).
    resumed = train_robocup(
        small_config(tmp_path, **{"run.max_minutes": 1e-9}), resume=True,
        env_factory=lambda i: SimEnv(1), progress=False,
    )
    assert resumed.iteration == 0 and not resumed.interrupted
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved["learner"]["network"]["features"] == 16
    assert saved["learner"]["network"]["lstm_features"] == 8


@needs_rcssserver
def test_sigterm_stops_the_servers_a_command_started(tmp_path: Path) -> None:
    command = [sys.executable, "-c", "from elevens.cli import main; main()"]
    process = subprocess.Popen(
        [*command, "robocup", "serve", "--servers", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()  # "rcssserver pid N: ..." once it is ready
        match = re.match(r"rcssserver pid (\d+):", line)
        assert match, line
        server_pid = int(match.group(1))
        os.kill(server_pid, 0)  # running
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=600) == 0
        assert wait_stopped(server_pid)
    finally:
        process.kill()
        process.wait()
        if process.stdout is not None:
            process.stdout.close()


