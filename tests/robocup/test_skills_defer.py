"""The DEFER kind (``env.defer``): a policy's player may leave its decision to
``skills_naive``, in the simulator's skill game and in the server runtime alike."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens.robocup  # noqa: F401 - registers the skill game and its teams
from elevens.nets.policy import AttentionPolicy
from elevens.robocup.skills.game import SkillSoccer, skills_config
from elevens.robocup.skills.learned import LearnedSkills
from elevens.robocup.skills.team import DEFER, SkillsNaiveTeam, deferred
from elevens.teams.network import NetworkTeam


def test_a_team_that_always_defers_plays_skills_naives_game_exactly() -> None:
    # Two games from one state in one program: team 0 gives DEFER everywhere in the first and
    # skills_naive's own actions in the second; team 1 is skills_naive in both.
    n = 3
    env = SkillSoccer(n, defer=True)
    params = env.default_params(episode_length=100)
    naive = SkillsNaiveTeam()
    always = jnp.zeros((n, 4)).at[:, 0].set(DEFER)

    def actions(state: Any, deferring: jax.Array) -> jax.Array:
        obs = env.observe(state, params)
        own = jnp.where(deferring, always, naive.play(obs.team(0)))
        return jnp.stack([own, naive.play(obs.team(1))])

    def body(states: Any, key: jax.Array) -> tuple[Any, Any]:
        acts = jax.vmap(actions)(states, jnp.array([True, False]))
        states = jax.vmap(env.transition, in_axes=(None, 0, 0, None))(key, states, acts, params)[0]
        return states, (states.positions, states.ball_position)

    def game(key: jax.Array) -> Any:
        start = env.reset(key, params)[0]
        states = jax.tree.map(lambda leaf: jnp.stack([leaf, leaf]), start)
        return jax.lax.scan(body, states, jax.random.split(key, 80))[1]

    positions, ball = jax.jit(game)(jax.random.key(3))
    # The same decisions; the two games' arithmetic may round apart in the last bit.
    np.testing.assert_allclose(np.asarray(positions[:, 0]), np.asarray(positions[:, 1]), atol=1e-4)
    np.testing.assert_allclose(np.asarray(ball[:, 0]), np.asarray(ball[:, 1]), atol=1e-4)
    assert np.ptp(np.asarray(ball[:, 0]), axis=0).max() > 1.0  # the ball was played
    # Without the flag kind 8 is no kind of the game: it reads as TACKLE (7).
    assert np.all(np.asarray(SkillSoccer(n).applied(always))[:, 0] == 7)


def test_deferred_replaces_only_the_deferring_rows() -> None:
    env = SkillSoccer(11, defer=True)
    params = env.default_params()
    obs = jax.jit(lambda k: env.observe(env.reset(k, params)[0], params).team(0))(
        jax.random.key(0))
    own = jnp.tile(jnp.array([[5.0, 0.0, 0.3, -0.2]]), (11, 1)).at[::3, 0].set(DEFER)
    out = np.asarray(jax.jit(deferred, static_argnums=2)(own, obs, SkillsNaiveTeam()))
    naive = np.asarray(jax.jit(SkillsNaiveTeam().play)(obs))
    rows = np.arange(11) % 3 == 0
    np.testing.assert_array_equal(out[rows], naive[rows])
    np.testing.assert_array_equal(out[~rows], np.asarray(own)[~rows])


def test_the_last_kind_prior_makes_an_untrained_policy_defer_and_masks_leave_it_open() -> None:
    env = SkillSoccer(11, defer=True, reach=True)
    params = env.default_params()
    obs = jax.jit(lambda k: env.observe(env.reset(k, params)[0], params).team(0))(
        jax.random.key(1))
    policy = AttentionPolicy(features=16, num_heads=2, lstm_features=8, num_actions=4, kinds=9,
                             kind_mask="ball_first", last_kind_logit=6.0)
    carry, reset = policy.initial_carry((11,)), jnp.zeros(11, bool)
    team = NetworkTeam(policy=policy, deterministic=True)

    def untrained(key: jax.Array) -> tuple[jax.Array, jax.Array]:
        variables = policy.init(key, carry, obs, reset)
        logits = policy.apply(variables, carry, obs, reset)[1].distribution().kind_logits
        return logits, team.act(variables, carry, obs, key)[1]

    logits, actions = jax.jit(untrained)(jax.random.key(0))
    p = jax.nn.softmax(logits, axis=-1)
    assert p.shape == (11, 9)
    assert float(jnp.min(p[:, DEFER])) > 0.95
    assert np.all(np.asarray(actions)[:, 0] == DEFER)  # the mode defers


def test_the_runtime_plays_skills_naives_decision_for_a_deferring_player() -> None:
    # The server runtime's policy step on its padded 11-player view: DEFER rows become
    # skills_naive's actions there too, the others stay the policy's.
    env = SkillSoccer(11, defer=True)
    params = env.default_params()
    obs = jax.jit(lambda k: env.observe(env.reset(k, params)[0], params).team(0))(
        jax.random.key(5))

    class HalfDefer:
        def init_carry(self, n: int) -> Any:
            return jnp.zeros((n,))

        def act(self, params: Any, carry: Any, obs: Any, key: jax.Array) -> Any:
            acts = jnp.tile(jnp.array([[5.0, 0.0, 0.1, 0.1]]), (11, 1))
            return carry, acts.at[:5, 0].set(DEFER)

    decide = LearnedSkills(HalfDefer(), None, defer=True)
    _, (acts, deferring) = decide._act(None, decide.carry, obs, np.ones(11, bool),
                                      jax.random.key(0))
    naive = np.asarray(jax.jit(SkillsNaiveTeam().play)(obs))
    np.testing.assert_array_equal(np.asarray(acts)[:5], naive[:5])
    assert np.all(np.asarray(acts)[5:, 0] == 5.0)
    assert np.asarray(deferring).tolist() == [True] * 5 + [False] * 6


def test_defer_needs_the_ninth_kind_and_is_refused_in_one_line() -> None:
    with pytest.raises(ValueError, match=r"network.kinds=8 is invalid with this game: its "
                                         r"decision has 9 kinds \(set network.kinds=9\)"):
        skills_config("2v2", **{"env.defer": True})
    config = skills_config("2v2", **{"env.defer": True, "network.kinds": 9,
                                     "network.last_kind_logit": 6.0})
    assert config.learner.make_env().kinds == 9
    with pytest.raises(ValueError, match=r"network.last_kind_logit=nan is invalid"):
        skills_config("2v2", **{"network.last_kind_logit": float("nan")})


def test_server_fine_tuning_records_defer_and_plays_skills_naives_action() -> None:
    # The recorder of server fine-tuning: PPO's sample (pre_tanh, log-probability) keeps the
    # DEFER kind the policy drew; the action played is skills_naive's on the same view.
    from elevens.robocup.skills.record import Recorder

    env = SkillSoccer(11, defer=True)
    params = env.default_params()
    obs = jax.jit(lambda k: env.observe(env.reset(k, params)[0], params).team(0))(
        jax.random.key(6))
    policy = AttentionPolicy(features=16, num_heads=2, lstm_features=8, num_actions=4, kinds=9,
                             last_kind_logit=60.0)  # every draw defers
    carry = policy.initial_carry((1, 11))
    one = jax.tree.map(lambda leaf: leaf[None], obs)
    variables = jax.jit(policy.init)(jax.random.key(0), carry, one, jnp.zeros((1, 11), bool))
    recorder = Recorder(policy, defer=True)
    _, action, raw, log_prob, _ = recorder._step(variables, carry, one, np.ones((1, 11), bool),
                                              jax.random.key(1))
    assert np.all(np.asarray(raw)[0, :, 0] == DEFER)
    assert np.all(np.asarray(log_prob) > -60.0)  # finite: the kind's share is ~1
    naive = np.asarray(jax.jit(SkillsNaiveTeam().play)(obs))
    np.testing.assert_array_equal(np.asarray(action)[0], naive)


def test_a_trained_deferring_team_defers_in_the_server_runtime_and_the_tournament(
        tmp_path: Path) -> None:
    # Its config says DEFER: the runtime resolves it, and a tournament beside skills_naive plays
    # the DEFER game (else kind 8 would read as TACKLE).
    from elevens.cli.eval import _teams_and_env
    from elevens.robocup.skills import skills_policy
    from elevens.train.checkpoint import Checkpointer
    from elevens.train.learner import make_learner
    from tests.robocup.test_skills_learned import TINY

    config = skills_config("2v2", **{**TINY, "run.run_dir": str(tmp_path), "env.defer": True,
                                     "network.kinds": 9, "network.last_kind_logit": 6.0,
                                     "env.defer_to": "helios"})
    state = make_learner(config.learner, config.learner.make_env()).init(jax.random.key(3))
    with Checkpointer(tmp_path / "checkpoints") as checkpointer:
        checkpointer.save(0, state, config.to_dict(), {"iteration": 0})
    decide = skills_policy(str(tmp_path))
    assert isinstance(decide, LearnedSkills) and decide.defer and decide.defer_to == "helios"
    _, env, _ = _teams_and_env(((str(tmp_path), "skills_naive"),), 2, 4, True, 1)
    assert env.defer and env.kinds == 9
    _, env, _ = _teams_and_env((("skills_naive", "skills_random"),), 2, 4, True, 1)
    assert not env.defer


def test_deferring_to_helios_plays_helios_bases_parts_for_the_deferring_players_only() -> None:
    # env.defer_to="helios": in the server a deferring player's open-play decision goes to
    # helios-base's planner (with the ball) or basic move (without); the goalie's routine and the
    # players that did not defer keep theirs; the simulator's config refuses it without defer.
    from elevens.robocup.skills.observe import observe
    from elevens.robocup.skills.space import Kind
    from tests.robocup.fake_proxy import Scene, state

    class FirstFiveDefer:
        def init_carry(self, n: int) -> Any:
            return jnp.zeros((n,))

        def act(self, params: Any, carry: Any, obs: Any, key: jax.Array) -> Any:
            acts = jnp.tile(jnp.array([[5.0, 0.0, 0.1, 0.1]]), (11, 1))  # GO_TO
            return carry, acts.at[:5, 0].set(DEFER)

    scene = Scene(ball=(-30.0, 20.0), kickable=2, cycle=5)  # shirt 2 has the ball
    states = [state(scene, unum) for unum in range(1, 12)]
    kinds = {}
    for defer_to in ("skills_naive", "helios"):
        decide = LearnedSkills(FirstFiveDefer(), None, defer=True, defer_to=defer_to)
        kinds[defer_to] = decide.decisions(observe(states)).kind.tolist()
        assert decide.deferring.tolist() == [True] * 5 + [False] * 6
    naive, helios = kinds["skills_naive"], kinds["helios"]
    assert naive[0] == helios[0] == Kind.GOALIE
    assert helios[1] == Kind.PLANNER and naive[1] in (Kind.SHOOT, Kind.PASS, Kind.DRIBBLE,
                                                      Kind.HOLD)
    assert helios[2:5] == [Kind.HELIOS_MOVE] * 3 and Kind.HELIOS_MOVE not in naive
    assert helios[5:] == naive[5:] == [Kind.GO_TO] * 6
    # The match's report counts what was decided: 10 open-play rows (not the goalie), 4 of
    # them deferred (shirts 2 to 5), and each final kind.
    assert decide.report() == {"rows": 11, "open_play": 10, "deferred": 4,
                               "kinds": {"GO_TO": 6, "GOALIE": 1, "PLANNER": 1,
                                         "HELIOS_MOVE": 3}}
    with pytest.raises(ValueError, match=r"defer_to='helios' is invalid \(allowed: "):
        LearnedSkills(FirstFiveDefer(), None, defer=False, defer_to="helios")
    with pytest.raises(ValueError, match=r"env.defer_to='helios' is invalid without env.defer"):
        skills_config("2v2", **{"env.defer_to": "helios"})
    with pytest.raises(ValueError, match=r"env.defer_to='bob' is invalid \(allowed: "
                                         r"skills_naive, helios\)"):
        skills_config("2v2", **{"env.defer": True, "network.kinds": 9, "env.defer_to": "bob"})
