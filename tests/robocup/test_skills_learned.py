"""A trained skills policy plays the server runtime unchanged: the world model's arrays back
into the skill game's observations, and the runtime's decide over a tiny trained checkpoint."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import numpy as np
import pytest

import elevens.robocup  # noqa: F401 - registers the skill game and its teams
from elevens.env.state import ENTITY_FEATURES, SELF_FEATURES
from elevens.robocup.skills import SKILLS, check_skills_policy, skills_policy
from elevens.robocup.skills.decode import GO_TO, HOLD, MARK, PASS, SKILL_ACTION_SIZE
from elevens.robocup.skills.game import SkillSoccer, skills_config
from elevens.robocup.skills.learned import (
    APPROXIMATED,
    LearnedSkills,
    sim_observation,
    skill_decisions,
)
from elevens.robocup.skills.naive import kick_off_points
from elevens.robocup.skills.observe import Observation as SkillObservation
from elevens.robocup.skills.observe import observe
from elevens.robocup.skills.space import Kind
from elevens.robocup.skills.team import SKILLS_FIELD, skill_observation
from elevens.train.checkpoint import Checkpointer
from elevens.train.learner import make_learner
from tests.refusal import refused
from tests.robocup.conftest import needs_rcssserver
from tests.robocup.fake_proxy import FakeTeam, Scene, state
from tests.robocup.test_match import _fake_team, needs_proxy


def _moving(players: int) -> tuple[Any, Any, Any]:
    """(env params, state, observation) of a skill game at step 7 with everyone moving, turned
    any way and having given a command (a reset then drawn velocities and command summaries:
    no step; the reset and the observation compiled, as eagerly each of their ops compiles
    alone)."""
    env = SkillSoccer(players)
    p = env.default_params(episode_length=400)
    start, _ = jax.jit(env.reset)(jax.random.key(1), p)
    k = jax.random.split(jax.random.key(2), 3)
    m = 2 * players
    current = start.replace(
        velocities=jax.random.uniform(k[0], (m, 2), minval=-0.8, maxval=0.8),
        headings=jax.random.uniform(k[1], (m,), minval=-np.pi, maxval=np.pi),
        last_actions=jax.random.uniform(k[2], (m, 2), minval=-1.0, maxval=1.0),
        ball_velocity=jax.numpy.asarray([1.2, -0.7]), step=jax.numpy.asarray(7),
    )
    return p, current, jax.jit(env.observe)(current, p)


# ------------------------------------------------------------------ the converter
def test_the_world_models_arrays_give_back_the_skill_games_observation() -> None:
    """skill_observation then sim_observation is the identity on every feature the world
    model has, for both teams (each in its own frame); the rest is what APPROXIMATED says."""
    params, current, obs = _moving(11)
    approximated_self = [SELF_FEATURES.index(f) for f in APPROXIMATED["self"]]
    approximated_entity = [ENTITY_FEATURES.index(f) for f in APPROXIMATED["entity"]]
    exact_self = [i for i in range(len(SELF_FEATURES)) if i not in approximated_self]
    exact_entity = [i for i in range(len(ENTITY_FEATURES)) if i not in approximated_entity]
    # One compile for both teams (eagerly, each op of the intercept tables compiles alone).
    to_arrays = jax.jit(lambda o: vars(skill_observation(o, SKILLS_FIELD)[0]))
    for team in (0, 1):
        leaves = {k: np.asarray(v) for k, v in to_arrays(obs.team(team)).items()}
        # The server's cycle stands for the game's step (the time left counts from it).
        arrays = SkillObservation(**{**leaves, "cycle": np.full(11, int(current.step))})
        back = sim_observation(arrays, episode_length=params.episode_length)
        sim = obs.team(team)
        assert back.self_features.shape == sim.self_features.shape
        assert back.entities.shape == sim.entities.shape
        np.testing.assert_array_equal(back.entity_mask, np.asarray(sim.entity_mask))
        np.testing.assert_allclose(back.self_features[:, exact_self],
                                   np.asarray(sim.self_features)[:, exact_self], atol=2e-5)
        np.testing.assert_allclose(back.entities[..., exact_entity],
                                   np.asarray(sim.entities)[..., exact_entity], atol=2e-5)
        # The time left agrees once the cycle is the step; the commands' summaries are unknown
        # (0) while the players have moved, and the start is the kick-off point.
        time_left = SELF_FEATURES.index("time_left")
        assert back.self_features[0, time_left] == pytest.approx(
            float(sim.self_features[0, time_left]), abs=1e-6)
        moves = [SELF_FEATURES.index("last_move"), SELF_FEATURES.index("last_rot")]
        assert not np.any(back.self_features[:, moves])
        assert np.any(np.asarray(sim.self_features)[:, moves])
        assert not np.any(back.entities[..., approximated_entity])


def test_a_team_trained_with_reach_features_reads_librcscs_intercept_table(
        tmp_path: Path, trained: Path) -> None:
    # In the server the table is librcsc's; here the skill game's own (the view skills_naive
    # reads), so the converted features equal the game's.
    params, current, _ = _moving(11)
    to_arrays = jax.jit(lambda o: vars(skill_observation(o, SKILLS_FIELD)[0]))
    observe = jax.jit(SkillSoccer(11, reach=True).observe)  # op by op: 120 compiles
    for team in (0, 1):
        sim = observe(current, params).team(team)
        leaves = {k: np.asarray(v) for k, v in to_arrays(sim).items()}
        arrays = SkillObservation(**{**leaves, "cycle": np.full(11, int(current.step))})
        back = sim_observation(arrays, episode_length=params.episode_length, reach=True)
        assert back.self_features.shape == sim.self_features.shape == (11, len(SELF_FEATURES) + 3)
        np.testing.assert_allclose(back.self_features[:, :-3],
                                   sim_observation(arrays, episode_length=params.episode_length)
                                   .self_features, atol=1e-6)
        np.testing.assert_allclose(back.self_features[:, -3:],
                                   np.asarray(sim.self_features)[:, -3:], atol=1e-6)
        assert len(np.unique(back.self_features[:, -3:])) > 2
    # A checkpoint trained so decides the proxy's cycle with the table (one per metre here).
    config = skills_config("2v2", **{**TINY, "run.run_dir": str(tmp_path),
                                     "env.reach_features": True})
    state0 = make_learner(config.learner, config.learner.make_env()).init(jax.random.key(3))
    with Checkpointer(tmp_path / "checkpoints") as checkpointer:
        checkpointer.save(0, state0, config.to_dict(), {"iteration": 0})
    decide = skills_policy(str(tmp_path))
    assert isinstance(decide, LearnedSkills) and decide.reach
    assert len(decide(_states())) == 11
    # In the simulator's tournament it plays a team trained without the table: the game gives
    # the table, and that team reads the features before it.
    from elevens.cli.eval import _teams_and_env

    (teams,), env, game = _teams_and_env(((str(tmp_path), str(trained)),), 2, 4, True, 1)
    assert env.reach and [t.policy.self_features for t in teams] == [18, 15]
    _, obs = jax.jit(env.reset)(jax.random.key(0), game)
    plain = teams[1]
    _, actions = jax.jit(plain.policy.act)(plain.params, plain.policy.init_carry(2), obs.team(1),
                                           jax.random.key(1))
    assert np.asarray(actions).shape == (2, SKILL_ACTION_SIZE)


def test_slots_the_world_model_does_not_place_are_masked_and_zero() -> None:
    obs = observe([state(Scene(ball=(10.0, 5.0)), u) for u in (1, 7)])
    opps_valid = obs.opps_valid.copy()
    opps_valid[:, 3] = False  # opponent 4 unseen
    mates_valid = obs.mates_valid.copy()
    mates_valid[1, 9] = False  # player 7 has lost teammate 10
    stale = obs.ball_pos_count.copy()
    stale[1] = 11  # and the ball, 11 cycles unseen
    arrays = SkillObservation(**{**vars(obs), "opps_valid": opps_valid,
                                 "mates_valid": mates_valid, "ball_pos_count": stale})
    back = sim_observation(arrays)
    # Observer 7's teammate slots: shirts 1..6, 8..11 -> slot of shirt 10 is 8; opponent 4
    # is slot 10 + 3; the ball the last.
    assert not back.entity_mask[:, 13].any() and not back.entities[:, 13].any()
    assert not back.entity_mask[1, 8] and not back.entities[1, 8].any()
    assert back.entity_mask[0, 8]  # player 1 sees teammate 10 (its slot 8 is shirt 10 too)
    assert back.entity_mask[0, -1] and not back.entity_mask[1, -1]
    ball = SELF_FEATURES.index("ball_visible")
    assert back.self_features[0, ball] == 1.0 and not back.self_features[1, ball:].any()
    assert back.entity_mask.sum(1).tolist() == [21, 19]


def test_an_unset_own_position_stands_at_its_kick_off_point_and_nothing_is_nan() -> None:
    # Before its first see, librcsc's own position is unset (inf): in a real match every shirt's
    # first request had it, and the NaN features it gave kept a recurrent policy's memory NaN
    # for the whole match (every decision then decoded as INTERCEPT or SHOOT).
    obs = observe([state(Scene(ball=(10.0, 5.0)), u) for u in (1, 7)])
    pos = obs.pos.copy()
    pos[1] = np.inf
    mates = obs.mates.copy()
    mates[0, 9] = np.nan  # player 1's estimate of teammate 10 is not a number
    back = sim_observation(SkillObservation(**{**vars(obs), "pos": pos, "mates": mates}))
    assert np.isfinite(back.self_features).all() and np.isfinite(back.entities).all()
    kick_off = kick_off_points(np.array([7]))[0] / [SKILLS_FIELD.half_length,
                                                     SKILLS_FIELD.half_width]
    x, y = SELF_FEATURES.index("x"), SELF_FEATURES.index("y")
    np.testing.assert_allclose(back.self_features[1, [x, y]], kick_off, rtol=1e-6)
    assert not back.entity_mask[0, 8] and not back.entities[0, 8].any()  # shirt 10's slot
    # The other player's view is the one it had before.
    before = sim_observation(obs)
    np.testing.assert_array_equal(back.self_features[0], before.self_features[0])


def test_a_pass_or_mark_through_an_unplaced_slot_falls_back() -> None:
    obs = observe([state(Scene(ball=(-20.0, 0.0), kickable=7), 7)])
    seen = np.ones((1, 22), bool)
    # Pointer 6 of observer 7 is teammate shirt 8, pointer 12 opponent shirt 3.
    pass_8 = np.array([[PASS, 6, 0.0, 0.0]], np.float32)
    mark_3 = np.array([[MARK, 12, 0.0, 0.0]], np.float32)
    assert skill_decisions(obs, pass_8, seen).index.tolist() == [8]
    assert skill_decisions(obs, mark_3, seen).index.tolist() == [3]
    seen[0, [6, 12]] = False
    assert skill_decisions(obs, pass_8, seen).kind.tolist() == [HOLD]
    assert skill_decisions(obs, mark_3, seen).kind.tolist() == [GO_TO]


def test_a_team_deciding_its_set_plays_plays_its_decoded_kinds_in_ours_only() -> None:
    ours = Scene(ball=(-20.0, 0.0), kickable=7, mode=5, our_set_play=True)  # our free kick
    theirs = Scene(ball=(-20.0, 0.0), mode=5)
    seen = np.ones((1, 22), bool)
    pass_8 = np.array([[PASS, 6, 0.0, 0.0]], np.float32)
    for scene, decided in ((ours, [Kind.PASS]), (theirs, [Kind.SET_PLAY])):
        obs = observe([state(scene, 7)])
        assert skill_decisions(obs, pass_8, seen).kind.tolist() == [Kind.SET_PLAY]
        assert skill_decisions(obs, pass_8, seen, set_plays="decided").kind.tolist() == decided


# ------------------------------------------------------------------ a trained team decides
TINY = {
    "env.episode_length": 8, "games_per_iteration": 2, "network.features": 16,
    "network.num_heads": 2, "network.lstm_features": 8, "network.lstm_layers": 1,
    "ppo.minibatch_size": 4, "iterations_per_chunk": 1, "run.iterations": 1,
    "run.eval_games": 2, "run.eval_teams": (), "run.write_plot": False,
}


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A skills-2v2 run directory with one checkpoint: the tiny networks at their init (what
    is tested is loading and deciding, not what was learned; no update compiles)."""
    from elevens.train.checkpoint import Checkpointer
    from elevens.train.learner import make_learner

    run_dir = tmp_path_factory.mktemp("skills-run")
    config = skills_config("2v2", **{**TINY, "run.run_dir": str(run_dir)})
    state = make_learner(config.learner, config.learner.make_env()).init(jax.random.key(3))
    with Checkpointer(run_dir / "checkpoints") as checkpointer:
        checkpointer.save(0, state, config.to_dict(), {"iteration": 0})
    return run_dir


@pytest.fixture(scope="module")
def decide(trained: Path) -> LearnedSkills:
    policy = skills_policy(str(trained))
    assert isinstance(policy, LearnedSkills)
    return policy


SCENE = Scene(ball=(-12.0, 4.0), kickable=7, cycle=30)


def _states(scene: Scene = SCENE, shirts: Any = range(1, 12)) -> list[Any]:
    return [state(scene, u) for u in shirts]


def _carry(decide: LearnedSkills) -> np.ndarray:
    return np.concatenate([np.asarray(leaf).reshape(11, -1)
                           for leaf in jax.tree.leaves(decide.carry)], axis=1)


def test_a_trained_checkpoint_decides_a_cycle_in_one_policy_call(decide: LearnedSkills) -> None:
    decide.reset()
    before = decide.policy_calls
    states = _states()
    answers = decide(states)
    assert decide.policy_calls == before + 1 and len(answers) == 11
    decisions = decide.decisions(observe(states))
    decisions.check(11)  # kinds, shirt numbers and directions within their ranges
    kinds = decisions.kind.tolist()
    assert kinds[0] == Kind.GOALIE  # the goalie plays the proxy's, as skills_naive's does
    assert all(k <= Kind.TACKLE for k in kinds[1:])  # play on: open-play kinds only
    with_ball = {Kind.SHOOT, Kind.PASS, Kind.DRIBBLE, Kind.HOLD}
    assert all(k not in with_ball for i, k in enumerate(kinds[1:], 2) if i != 7)
    # Before a kick-off everyone moves to its slot, whatever the policy says.
    placing = decide.decisions(observe(_states(Scene(mode=0))))
    assert set(placing.kind.tolist()) == {Kind.KICKOFF_MOVE}
    assert (placing.point[:, 0] <= -1.0).all()


def test_a_trained_team_deciding_its_set_plays_keeps_the_free_kick_rule(trained: Path) -> None:
    with pytest.raises(ValueError, match=r"--set-plays 'own' is invalid"):
        skills_policy(str(trained), set_plays="own")
    deciding = skills_policy(str(trained), set_plays="decided")
    assert isinstance(deciding, LearnedSkills) and deciding.set_plays == "decided"
    kick_off = Scene(ball=(0.0, 0.0), kickable=10, mode=3, our_set_play=True, cycle=1)
    kinds = deciding.decisions(observe(_states(kick_off))).kind
    assert kinds[0] == Kind.GOALIE and Kind.SET_PLAY not in kinds.tolist()
    # Player 10 had the ball in our set play: in play on, while it is the last kicker, it
    # neither dribbles nor runs at the ball; reset (a new match) forgets it.
    after = observe([state(Scene(ball=(8.0, 0.0), mode=2, last_kicker=10, cycle=2), 10)])
    assert deciding.guard.takers(after).tolist() == [True]
    deciding.reset()
    assert deciding.guard.takers(after).tolist() == [False]


def test_the_memory_is_kept_per_shirt_and_the_mode_is_deterministic(
    decide: LearnedSkills,
) -> None:
    decide.reset()
    fresh = _carry(decide)
    first, _ = decide.actions(observe(_states()))
    after_one = _carry(decide)
    assert not np.allclose(after_one, fresh)  # every asking player's memory moved
    second, _ = decide.actions(observe(_states()))
    # The same States with a cycle of memory decide otherwise than from a fresh memory
    # (the continuous part of the mode reads the LSTM's state).
    assert not np.allclose(second[:, 2:], first[:, 2:])
    # Only the players that ask change their memory.
    held = _carry(decide)
    decide.actions(observe(_states(shirts=(3, 9))))
    moved = ~np.isclose(_carry(decide), held).all(axis=1)
    assert np.flatnonzero(moved).tolist() == [2, 8]
    # The mode: the same States from the same memory, the same actions.
    decide.reset()
    again, _ = decide.actions(observe(_states()))
    np.testing.assert_array_equal(again, first)
    assert again.shape == (11, SKILL_ACTION_SIZE)


def test_a_batch_holding_a_player_twice_decides_in_order(decide: LearnedSkills) -> None:
    decide.reset()
    late, now = Scene(ball=(0.0, 0.0), cycle=5), Scene(ball=(3.0, 0.0), cycle=6)
    calls = decide.policy_calls
    both, _ = decide.actions(observe([state(late, 4), state(now, 4), state(now, 5)]))
    assert decide.policy_calls == calls + 2
    decide.reset()
    one, _ = decide.actions(observe([state(late, 4)]))
    two, _ = decide.actions(observe([state(now, 4), state(now, 5)]))
    np.testing.assert_allclose(both, np.concatenate([one, two]), atol=1e-6)


def test_the_decision_server_plays_a_trained_team_with_one_call_a_cycle(
    decide: LearnedSkills,
) -> None:
    from elevens.robocup.skills.runtime import DecisionServer

    decide.reset()
    with DecisionServer(decide, deadline_s=20.0, gather_s=10.0) as server:
        team = FakeTeam(server.port)
        calls = decide.policy_calls
        try:
            for c in range(3):
                answers, _ = team.cycle(Scene(ball=(-10.0 + 5 * c, 2.0), cycle=c + 1))
                assert sorted(answers) == list(range(1, 12))
        finally:
            team.close()
        stats = server.stats()
    assert stats.batches == 3 and stats.defaults == 0 and stats.errors == 0
    assert decide.policy_calls == calls + 3


def _ball_at_seven() -> Scene:
    """Shirt 7 has the ball at its feet (in reach by the geometry too), play on."""
    ours = Scene().ours.copy()
    ours[6] = (-12.5, 4.0)
    return Scene(ours=ours, ball=(-12.0, 4.0), kickable=7, cycle=30)


def test_the_simulators_skills_naive_decides_as_the_runtimes_through_the_converter() -> None:
    """skills_naive_sim (the simulator's team: the world model turned into its observation,
    its action decoded as the game decodes it) plays what skills_naive plays on the world
    model: the converter's path, both ways."""
    from elevens.robocup.skills.naive import skills_naive_decisions

    assert {"skills_naive", "skills_random", "skills_naive_sim"} <= set(SKILLS)
    obs = observe(_states(_ball_at_seven()))
    runtime = skills_naive_decisions(obs)
    simulator = skills_policy("skills_naive_sim").decisions(obs)
    assert simulator.kind.tolist() == runtime.kind.tolist()
    assert simulator.index.tolist() == runtime.index.tolist()
    assert runtime.kind[6] == Kind.PASS and runtime.kind[0] == Kind.GOALIE
    going = runtime.kind == Kind.GO_TO
    assert going.sum() >= 8
    np.testing.assert_allclose(simulator.point[going], runtime.point[going], atol=1e-3)


def test_skills_random_plays_every_open_play_kind_in_the_runtime() -> None:
    """skills_random in the server runtime: uniform skill actions decoded as the game decodes
    them; the goalie plays the proxy's, the others every open-play kind over a few cycles."""
    decide = skills_policy("skills_random")
    obs = observe(_states(_ball_at_seven()))
    kinds: set[int] = set()
    for _ in range(6):
        decisions = decide.decisions(obs)
        decisions.check(11)
        assert decisions.kind[0] == Kind.GOALIE
        kinds |= set(decisions.kind[1:].tolist())
    # Without the ball the with-ball kinds intercept; shirt 7 has it and plays them.
    assert kinds >= {Kind.INTERCEPT, Kind.GO_TO, Kind.MARK}
    assert len(decide(_states(_ball_at_seven()))) == 11


def test_the_simulators_teams_play_matches_through_the_proxy() -> None:
    from elevens.robocup.match import SkillsTeam, parse_team

    for name in ("skills_random", "skills_naive_sim"):
        team = parse_team(name, None, "sim")
        assert team == SkillsTeam(name, "sim")
        command = team.command("127.0.0.1", 6000, 11, synch=True)
        assert command[command.index("--skills") + 1] == name
    check_skills_policy("skills_random")


# ------------------------------------------------------------------ the commands
def test_a_team_that_is_not_a_skills_policy_is_refused_in_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
) -> None:
    error = refused(["robocup", "skills-team", "--skills", "elevens-2v2", "--proxy",
                     str(tmp_path)], "robocup skills-team", capsys)
    assert "team 'elevens-2v2' is not a skills team: it is a team of 2-value actions" in error
    error = refused(["robocup", "skills-team", "--skills", "naive"], "robocup skills-team",
                    capsys)
    assert "'naive' is not a skills team: it is a handcrafted team" in error
    with pytest.raises(ValueError, match=r"skills team '.*nowhere' is unknown .* does not exist"):
        check_skills_policy(str(tmp_path / "nowhere"))


def test_a_trained_skills_team_plays_matches_through_the_proxy(trained: Path) -> None:
    from elevens.robocup.match import SkillsTeam, parse_team

    team = parse_team(str(trained), None, "skills", sample=True)
    assert team == SkillsTeam(str(trained), "skills", sample=True)
    command = team.command("127.0.0.1", 6000, 11, synch=True)
    assert command[command.index("--skills") + 1] == str(trained) and "--sample" in command
    # A checkpoint of another action is an elevens team, as before.
    assert not isinstance(parse_team("elevens-2v2", None, "other"), SkillsTeam)


@needs_rcssserver
@needs_proxy
def test_a_trained_skills_team_plays_a_short_match_through_the_proxy(
    trained: Path, tmp_path: Path,
) -> None:
    """The real proxy's eleven players ask a tiny trained checkpoint every cycle of a
    synch-mode match of 60 cycles: every cycle played, no decision failed."""
    from elevens.robocup.match import SkillsTeam, play_match

    result = play_match(SkillsTeam(str(trained), "skills"), _fake_team(), half_time=3,
                        log_dir=tmp_path)
    assert result.names == ("skills", "fake") and result.lost_cycles == 0
    report = result.teams[0]
    assert report is not None and report["ended"] == "players left"
    stats = report["stats"]
    assert stats["errors"] == 0 and stats["requests"] >= 11 * 60
    assert stats["requests"] / stats["batches"] > 1.0
