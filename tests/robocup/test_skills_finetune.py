"""Fine-tuning a skills team in rcssserver: the recorder samples the learner's policy for the
fake proxy's players, its cycles pack into the compiled unroll's Rollout (masks where the
policy did not play, the goal reward), ``improve`` runs on it, and the host loop trains on
matches (a fake match here, helios-base in the real-server test)."""

from __future__ import annotations

import csv
import threading
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens.robocup  # noqa: F401 - registers the skill game
from elevens.cli import main
from elevens.robocup.skills import finetune
from elevens.robocup.skills.finetune import (
    SkillGames,
    make_skills_train_config,
    train_skills,
)
from elevens.robocup.skills.observe import observe
from elevens.robocup.skills.record import Recorder, pack, routine_played, teacher_actions
from elevens.robocup.skills.runtime import DecisionServer
from elevens.robocup.skills.team import SkillsNaiveTeam
from elevens.train.learner import make_learner
from elevens.train.rollout import Teacher
from tests.robocup.conftest import needs_rcssserver
from tests.robocup.fake_proxy import FakeTeam, Scene, state
from tests.robocup.test_match import HELIOS, needs_helios, needs_proxy

STEPS = 6
TINY = {
    "env.episode_length": STEPS, "network.features": 16, "network.num_heads": 2,
    "network.lstm_features": 8, "network.lstm_layers": 1, "ppo.epochs": 1,
    "run.iterations": 1, "run.write_plot": False,
    "server.opponent_cmd": "unused {port}",
}


def _config(tmp_path: Path, **overrides: Any) -> Any:
    return make_skills_train_config(**{**TINY, "run.run_dir": str(tmp_path / "run"),
                                       **overrides})


def _recording(config: Any) -> tuple[Any, Any, Recorder]:
    """A fresh learner, its state from key 0, and a warmed-up recorder of its policy."""
    learner = make_learner(config.learner, config.learner.make_env(), devices=1,
                           external_games=True)
    state = learner.init(jax.random.key(0))
    recorder = Recorder(learner.policy, seed=1)
    recorder.set_params(state.params.policy)
    recorder.warm_up()
    return learner, state, recorder


def _ball(c: int) -> tuple[float, float]:
    return (-20.0 + 3.0 * c, 4.0)


def _metric(run: Path, name: str) -> list[float]:
    """Every logged value of ``name`` in the run's metrics.csv (step, name, value rows)."""
    with open(run / "metrics.csv", encoding="utf-8") as f:
        return [float(row["value"]) for row in csv.DictReader(f) if row["name"] == name]


class _SlowOnce:
    """The recorder, with the decision of one cycle held past the deadline."""

    def __init__(self, recorder: Recorder, cycle: int, seconds: float) -> None:
        self.recorder, self.cycle, self.seconds = recorder, cycle, seconds

    def __call__(self, states: Any) -> Any:
        if int(states[0].world_model.cycle) == self.cycle:
            time.sleep(self.seconds)
        return self.recorder(states)


def test_server_cycles_pack_into_the_learners_rollout(tmp_path: Path) -> None:
    """(The learner's improve on such rollouts: the host-loop test below.)"""
    config = _config(tmp_path)
    learner, state, recorder = _recording(config)
    games = SkillGames(config)
    # Cycle 1 is played before recording starts (the match goes on between iterations);
    # recorded: 2 before the kick-off (everyone placed: a routine), 3..8 in play, our goal
    # announced at 5 (scored in step 4->5), theirs at 7; at 6 the decision misses its
    # deadline (the default plays); at 8 player 9 does not ask.
    # Deadlines of seconds: a busy machine's decisions must not miss them but at cycle 6.
    slow = _SlowOnce(recorder, cycle=6, seconds=5.0)
    with DecisionServer(slow, deadline_s=4.0, gather_s=2.0,
                        on_default=recorder.defaulted) as server:
        team = FakeTeam(server.port, timeout_ms=120_000)
        try:
            team.cycle(Scene(ball=_ball(1), cycle=1))
            carry_before = jax.tree.map(np.asarray, recorder.carry)
            recorder.start()
            for c in range(2, 9):
                score = (1, 0) if 5 <= c < 7 else (1, 1) if c >= 7 else (0, 0)
                scene = Scene(ball=_ball(c), cycle=c, mode=0 if c == 2 else 2, score=score)
                answers, _ = team.cycle(scene, skip=(9,) if c == 8 else ())
                assert len(answers) == (10 if c == 8 else 11)
            segment = recorder.stop()
            team.cycle(Scene(ball=_ball(9), cycle=9))  # no longer recorded
        finally:
            team.close()
        stats = server.stats()
    assert stats.defaults == 11 and segment.cycles == STEPS + 1
    assert segment.defaulted == {(0, 6, shirt) for shirt in range(1, 12)}

    rollout, counts = pack([segment], STEPS, learner.policy, games.params, shaping=False)
    t = rollout.transitions
    assert t.obs.self_features.shape == (11, STEPS, 15)
    assert t.obs.entities.shape == (11, STEPS, 22, 11)
    assert t.obs.entity_mask.shape == (11, STEPS, 22)
    assert t.pre_tanh.shape == (11, STEPS, 4) and t.log_prob.shape == (11, STEPS)
    assert rollout.game_global_state.players.shape == (1, STEPS, 22, 11)
    assert rollout.game_global_state.context.shape == (1, STEPS, 5)
    assert jax.tree.leaves(t.initial_carry)[0].shape == (11, 8)
    # Masks, steps 0..5 = cycles 2..7: the kick-off placing, the goalie always, the
    # defaulted cycle 6 (step 4) for everyone; cycle 8 is the last one's next (reward only).
    scripted = np.asarray(rollout.scripted)
    expected = np.zeros((11, STEPS), bool)
    expected[:, 0] = True
    expected[0, :] = True
    expected[:, 4] = True
    np.testing.assert_array_equal(scripted, expected)
    assert counts[0]["defaulted"] == 11 and counts[0]["filled"] == 0
    # The goal reward, every player's: +1 for the step before ours was announced, -1 for
    # the step before theirs; the shaping is off.
    reward = np.asarray(t.reward)
    np.testing.assert_array_equal(reward, np.broadcast_to([0, 0, 1, 0, -1, 0], (11, STEPS)))
    assert int(rollout.goals_for[0]) == 1 and int(rollout.goals_against[0]) == 1
    assert np.asarray(t.done)[:, -1].all() and not np.asarray(t.done)[:, :-1].any()
    assert not np.asarray(t.reset).any()  # the memory goes on from the match before
    np.testing.assert_allclose(
        np.asarray(jax.tree.leaves(t.initial_carry)[0]),
        jax.tree.leaves(carry_before)[0][0], atol=1e-6)
    # What was recorded is what PPO evaluates: the policy replayed from the initial memory
    # over the recorded observations gives the recorded log-probabilities.
    @jax.jit
    def replay(carry: Any, obs: Any, pre_tanh: jax.Array) -> tuple[Any, jax.Array]:
        carry, output = learner.policy.apply(state.params.policy, carry, obs,
                                             jnp.zeros((1, 11), bool))
        return carry, output.distribution().log_prob(pre_tanh)

    # With a teacher (ppo.teacher): its action on every recorded observation, as it plays
    # each cycle's observations itself; the rest of the rollout is unchanged.
    teacher = SkillsNaiveTeam()
    play = jax.jit(teacher.play)  # compiled once: op by op it is 350 compiles
    taught, _ = pack([segment], STEPS, learner.policy, games.params, shaping=False,
                     teacher=teacher_actions(Teacher(teacher, None)), key=jax.random.key(3))
    action = np.asarray(taught.transitions.teacher_action)
    assert action.shape == (11, STEPS, 4)
    for step in range(STEPS):
        played = play(jax.tree.map(lambda leaf, step=step: leaf[:, step], t.obs))
        np.testing.assert_allclose(action[:, step], np.asarray(played), atol=1e-6)
    assert len(np.unique(action[..., 0].round(3))) > 1  # not one kind for everyone
    np.testing.assert_array_equal(np.asarray(taught.transitions.reward), reward)
    np.testing.assert_array_equal(np.asarray(taught.scripted), scripted)
    assert t.teacher_action is None

    carry = jax.tree.map(lambda leaf: leaf[None], t.initial_carry)
    for step in range(STEPS):
        obs = jax.tree.map(lambda leaf, step=step: leaf[None, :, step], t.obs)
        carry, log_prob = replay(carry, obs, t.pre_tanh[None, :, step])
        np.testing.assert_allclose(np.asarray(log_prob)[0], np.asarray(t.log_prob[:, step]),
                                   atol=1e-4)


def test_a_player_that_does_not_ask_is_filled_in_and_a_new_match_starts_an_episode(
    tmp_path: Path,
) -> None:
    config = _config(tmp_path)
    policy, _, recorder = _recording(config)
    with DecisionServer(recorder, deadline_s=60.0, gather_s=3.0) as server:
        team = FakeTeam(server.port, timeout_ms=120_000)
        try:
            recorder.start()
            for c in range(1, 5):  # a match at 1 - 0 ends after cycle 4
                team.cycle(Scene(ball=_ball(c), cycle=c, score=(1, 0)),
                           skip=(9,) if c == 3 else ())
            recorder.new_match()
            for c in (0, 0, 1):  # a fresh one at 0 - 0: the clock stands before its kick-off
                team.cycle(Scene(ball=_ball(c), cycle=c, mode=0 if c == 0 else 2))
            segment = recorder.stop()
        finally:
            team.close()
    rollout, counts = pack([segment], STEPS, policy.policy, SkillGames(config).params,
                           shaping=True)
    assert sorted(segment.rows)[3:] == [(0, 4, 0), (1, 0, 0), (1, 0, 1), (1, 1, 0)]
    scripted = np.asarray(rollout.scripted)
    assert counts[0]["filled"] == 1 and counts[0]["matches"] == 2
    expected = np.zeros((11, STEPS), bool)
    expected[0] = True  # the goalie
    expected[8, 2] = True  # the player that did not ask
    expected[:, 4:] = True  # the placing before the kick-off
    np.testing.assert_array_equal(scripted, expected)
    # Its stand-in is its step before, and the shaping of a still ball and players is 0.
    obs = np.asarray(rollout.transitions.obs.self_features)
    np.testing.assert_array_equal(obs[8, 2], obs[8, 1])
    # The score going back to 0 - 0 is a new match, not a goal; the first match's last step
    # ends an episode and the next one starts with a fresh memory.
    t = rollout.transitions
    assert not np.asarray(t.reward).any() and int(rollout.goals_against[0]) == 0
    np.testing.assert_array_equal(np.asarray(t.done)[0], [0, 0, 0, 1, 0, 1])
    np.testing.assert_array_equal(np.asarray(t.reset)[0], [0, 0, 0, 0, 1, 0])
    # Several servers: their games side by side, games outermost (unit g * 11 + k).
    both, _ = pack([segment, segment], STEPS, policy.policy, SkillGames(config).params,
                   shaping=False)
    assert both.transitions.reward.shape == (22, STEPS) and both.goals_for.shape == (2,)
    assert jax.tree.leaves(both.transitions.initial_carry)[0].shape == (22, 8)
    np.testing.assert_array_equal(np.asarray(both.scripted)[11:], scripted)
    with pytest.raises(ValueError, match="a segment of 7 cycles cannot give 7 steps"):
        pack([segment], STEPS + 1, policy.policy, SkillGames(config).params, shaping=False)


class _FakeMatch:
    """A match played by the fake proxy: a thread plays cycles against the decision server
    until stopped; it ends after ``cycles`` (a new match is then started)."""

    started: list[_FakeMatch] = []

    def __init__(self, config: Any, decision: DecisionServer, folder: Path,
                 cycles: int = 10) -> None:
        self.decision, self.cycles = decision, cycles
        self.server: Any = None
        self.thread: threading.Thread | None = None
        self.running = False

    def start(self) -> None:
        self.server, self.running = object(), True
        _FakeMatch.started.append(self)
        self.thread = threading.Thread(target=self._play, daemon=True)
        self.thread.start()

    def _play(self) -> None:
        team = FakeTeam(self.decision.port, timeout_ms=120_000)
        try:
            for c in range(1, self.cycles + 1):
                if not self.running:
                    break
                team.cycle(Scene(ball=_ball(c % 10), cycle=c, score=(c // 7, 0)))
        finally:
            team.close()
            self.running = False

    @property
    def alive(self) -> bool:
        return self.running

    def missed_cycles(self) -> int:
        return 0

    def stop(self) -> None:
        self.running = False
        if self.thread is not None:
            self.thread.join(30)


def test_the_host_loop_trains_on_matches_and_starts_a_fresh_one_when_one_ends(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(finetune, "ServerMatch", _FakeMatch)
    monkeypatch.setattr(finetune, "find_proxy", lambda folder: tmp_path)
    _FakeMatch.started = []
    # Taught by skills_naive (ppo.teacher): its actions recorded on the server's states.
    config = _config(tmp_path, **{"run.iterations": 2, "server.hold_ms": 0.0,
                                  "ppo.teacher": "skills_naive", "ppo.teacher_balance": True})
    result = train_skills(config, progress=False)
    assert result.iteration == 2 and result.env_steps == 2 * STEPS
    # 2 x 7 cycles recorded from matches of 10 cycles: the first ended while the learner
    # updated (its last cycles unrecorded), and a fresh one was started for the second.
    assert result.matches == 2 and len(_FakeMatch.started) == 2
    with open(tmp_path / "run" / "episodes.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["iteration"] for r in rows] == ["1", "2"]
    assert rows[0]["goals_for"] == "1" and rows[0]["matches"] == "1"
    assert rows[1]["restarts"] == "1" and rows[1]["matches"] == "1"
    assert rows[1]["missed"] == "0"
    # The learner's improve ran on both packed rollouts.
    losses = _metric(tmp_path / "run", "train/loss")
    assert len(losses) == 2 and np.isfinite(losses).all()
    assert _metric(tmp_path / "run", "train/teacher_weight") == [1.0, 1.0]
    agreement = _metric(tmp_path / "run", "train/teacher_agreement")
    assert len(agreement) == 2 and all(0 <= a <= 1 for a in agreement)
    assert np.isfinite(_metric(tmp_path / "run", "train/teacher_log_prob")).all()
    assert result.checkpoint is not None and result.checkpoint.exists()


def test_a_team_deciding_its_set_plays_learns_from_ours_and_not_from_theirs() -> None:
    shirts = (1, 5, 10)
    ours = observe([state(Scene(mode=5, our_set_play=True, kickable=10), u) for u in shirts])
    theirs = observe([state(Scene(mode=5), u) for u in shirts])
    assert routine_played(ours).tolist() == [True] * 3
    assert routine_played(ours, "decided").tolist() == [True, False, False]  # the goalie's
    assert routine_played(theirs, "decided").tolist() == [True] * 3


def test_bad_fine_tuning_commands_are_refused_in_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
) -> None:
    for argv, message in (
        (["robocup", "train", "skills-2v2"], "preset 'skills-2v2' is invalid in elevens "
         "robocup train: the skills proxy plays 11 a side; use skills-11v11"),
        (["robocup", "train", "skills-11v11", "--run.run-dir", str(tmp_path)],
         "server.opponent_cmd=None is invalid"),
        (["robocup", "train", "skills-11v11", "--server.hold-ms", "2000",
          "--server.opponent-cmd", "x"], "server.hold_ms=2000.0 is invalid"),
        (["robocup", "train", "skills-11v11", "--server.set-plays", "own",
          "--server.opponent-cmd", "x"],
         "server.set_plays 'own' is invalid (allowed: routine, decided)"),
        (["robocup", "train", "skills-11v11", "--opponent.mix", "skills_naive=0.25",
          "--server.opponent-cmd", "x"], "opponent.mix=('skills_naive=0.25',) is invalid"),
        (["robocup", "train", "skills-11v11", "--ppo.teacher", "nobody", "--run.run-dir",
          str(tmp_path / "run"), "--server.opponent-cmd", "x"], "ppo.teacher team 'nobody'"),
    ):
        with pytest.raises(SystemExit) as stop:
            main(argv)
        assert stop.value.code == 2
        error = capsys.readouterr().err.strip()
        assert "\n" not in error and error.startswith("elevens robocup train"), error
        assert message in error, error
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="env.players_per_team=2 is invalid"):
        _config(tmp_path, **{"env.players_per_team": 2, "ppo.minibatch_size": 2})


@needs_rcssserver
@needs_proxy
@needs_helios
def test_fine_tuning_plays_helios_base_in_the_server(tmp_path: Path) -> None:
    """One iteration of 40 cycles against helios-base: the real proxy, server and opponent."""
    config = _config(tmp_path, **{
        "env.episode_length": 40,
        "server.opponent_cmd": f"{HELIOS} -p {{port}} -P {{coach_port}} -t {{team}}",
        "server.opponent_name": "HELIOS_base",
    })
    result = train_skills(config, progress=False)
    assert result.iteration == 1 and result.env_steps == 40 and result.matches == 1
    losses = _metric(tmp_path / "run", "train/loss")
    assert len(losses) == 1 and np.isfinite(losses).all()
    with open(tmp_path / "run" / "episodes.csv", encoding="utf-8") as f:
        (row,) = list(csv.DictReader(f))
    assert row["steps"] == "40" and row["matches"] == "1" and int(row["missed"]) >= 0
