"""skills_naive teaches the learned skills team in the simulator's skill game (ppo.teacher):
its (kind, pointer, x, y) are scored by the parametrised head, pointer slot for pointer slot;
with the kind mask (network.kind_mask='ball') a player chooses the ball kinds exactly when the
ball is at its feet."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens.robocup  # noqa: F401 - registers the skill game and its teams
from elevens.env.state import ENTITY_FEATURES, SELF_FEATURES, Observation
from elevens.nets.policy import AttentionPolicy
from elevens.robocup.skills.game import skills_config
from elevens.robocup.skills.team import (
    SKILLS_FIELD,
    SkillsNaiveTeam,
    ball_kind_mask,
    first_kind_mask,
    nearest_kind_mask,
    skill_observation,
)
from elevens.runs.errors import RunRefusedError
from elevens.runs.resume import load_start_params
from elevens.runs.teams import team_on_field
from elevens.train.checkpoint import Checkpointer
from elevens.train.learner import make_learner
from elevens.train.ppo import teacher_terms
from elevens.train.rollout import Teacher, rollout

DISTANCE = ENTITY_FEATURES.index("distance")
TINY = {
    "env.episode_length": 8, "games_per_iteration": 2, "network.features": 16,
    "network.num_heads": 2, "network.lstm_features": 8, "network.lstm_layers": 1,
    "ppo.minibatch_size": 4, "iterations_per_chunk": 1, "ppo.epochs": 1,
    "ppo.teacher": "skills_naive",
}


@pytest.mark.slow
def test_skills_naive_teaches_in_the_skill_game() -> None:
    config = skills_config("2v2", **TINY)
    env = config.learner.make_env()
    learner = make_learner(config.learner, env, team_on_field)
    state = learner.init(jax.random.key(0))
    teacher = learner.setup.teacher
    assert isinstance(teacher, Teacher)

    # One compile (the learner's update would be a second): the rollout, then the policy's
    # distribution over the recorded steps scored on the teacher's actions, as the loss does.
    @jax.jit
    def taught(key: jax.Array) -> tuple[Any, Any]:
        data = rollout(
            env, learner.policy, learner.env_params, state.params.policy, state.params.policy,
            key, num_games=2, num_steps=8, teacher=teacher,
        )
        t = data.transitions
        _, output = learner.policy.apply(
            state.params.policy, t.initial_carry, t.obs, t.reset, 1,
            method=AttentionPolicy.unroll,
        )
        return data, teacher_terms(output.distribution(), t.teacher_action)

    data, terms = taught(jax.random.key(1))
    recorded = np.asarray(data.transitions.teacher_action)  # [G * n, T, 4]
    assert recorded.shape == (4, 8, 4)
    # The recorded actions are the team's own on the learner's observations.
    obs = jax.tree.map(lambda leaf: leaf[0:2, 3], data.transitions.obs)  # game 0, step 3
    _, expected = teacher.policy.act(None, (), obs, jax.random.key(2))
    np.testing.assert_array_equal(recorded[0:2, 3], np.asarray(expected))
    # Every pointer names a slot in view (players see all around): every entry counts.
    assert np.all(np.asarray(terms.mask))
    log_prob = np.asarray(terms.log_prob)
    assert np.all(np.isfinite(log_prob)) and -60.0 < log_prob.mean() < 0.0, log_prob.mean()
    agreement = np.asarray(terms.agreement)
    assert set(np.unique(agreement)) <= {0.0, 1.0}

    # The same policy with the skill game's kind mask (network.kind_mask='ball'; no parameter
    # of its own): player 0 of game 0 gets the ball at its feet at step 5 and loses sight of it
    # at step 6. With the ball only the ball kinds have probability, without it only the
    # others; the teacher's term leaves out exactly the entries whose kind is ruled out.
    masked = dataclasses.replace(config.learner.network, kind_mask="ball").policy()
    t = data.transitions
    reach = 0.5 / (2.0 * SKILLS_FIELD.half_length)
    obs = t.obs.replace(
        entities=t.obs.entities.at[0, 5, -1, DISTANCE].set(reach),
        entity_mask=t.obs.entity_mask.at[0, 5, -1].set(True).at[0, 6, -1].set(False),
    )
    _, output = jax.jit(functools.partial(masked.apply, time_axis=1,
                                          method=AttentionPolicy.unroll))(
        state.params.policy, t.initial_carry, obs, t.reset)
    distribution = output.distribution()
    allowed = np.asarray(ball_kind_mask(obs))  # [G * n, T, K]
    assert allowed[0, 5].tolist() == [True] * 4 + [False] * 4
    assert allowed[0, 6].tolist() == [False] * 4 + [True] * 4
    assert allowed.any(-1).all() and (allowed[..., :4] != allowed[..., 4:]).all()
    # Where the ball is seen, the mask's reach is the teacher's view's (skill_observation).
    view, _ = skill_observation(jax.tree.map(lambda leaf: leaf[0:2, 5], obs), SKILLS_FIELD)
    assert np.asarray(view.kickable).tolist() == allowed[0:2, 5, 0].tolist()
    p = np.exp(np.asarray(jax.nn.log_softmax(distribution.kind_logits, axis=-1)))
    assert np.all(p[~allowed] == 0.0) and np.allclose(p.sum(-1), 1.0)
    assert allowed[np.arange(4)[:, None], np.arange(8), np.asarray(distribution.mode())[..., 0]
                   .astype(int)].all()
    terms = teacher_terms(distribution, t.teacher_action)
    kind = recorded[..., 0].astype(int)
    ruled_in = np.take_along_axis(allowed, kind[..., None], axis=-1)[..., 0]
    np.testing.assert_array_equal(np.asarray(terms.mask), ruled_in)
    assert np.all(np.isfinite(np.asarray(terms.log_prob)[ruled_in]))
    # Unmasked, the same params give every kind some probability.
    unmasked = np.exp(np.asarray(jax.nn.log_softmax(
        learner.policy.apply(state.params.policy, t.initial_carry, obs, t.reset, 1,
                             method=AttentionPolicy.unroll)[1].kind_logits, axis=-1)))
    assert np.all(unmasked > 0.0)


NET = {name: value for name, value in TINY.items() if name.startswith("network.")}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """(a skills-2v2 run directory with the tiny networks at their init as checkpoint 0, its
    TrainState)."""
    source = skills_config("2v2", **NET)
    state = make_learner(source.learner, source.learner.make_env()).init(jax.random.key(3))
    tmp_path = tmp_path_factory.mktemp("tiny")
    with Checkpointer(tmp_path / "source" / "checkpoints") as checkpointer:
        checkpointer.save(0, state, source.to_dict(), {"iteration": 0})
    return tmp_path, state


def test_a_run_with_the_kind_mask_starts_from_networks_without_it(
        tiny_run: tuple[Path, Any]) -> None:
    tmp_path, state = tiny_run
    net = NET
    masked = skills_config("2v2", **net, **{"network.kind_mask": "ball"})
    _, params = load_start_params(str(tmp_path / "source"), masked)
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(state.params), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    wider = skills_config("2v2", **{**net, "network.features": 24, "network.kind_mask": "ball"})
    with pytest.raises(RunRefusedError, match=r"other networks.*--network.features 16 "
                                              r"\(this run: 24\)$"):
        load_start_params(str(tmp_path / "source"), wider)


def test_a_run_with_reach_features_starts_from_networks_without_them(
        tiny_run: tuple[Path, Any]) -> None:
    tmp_path, state = tiny_run
    source = skills_config("2v2", **NET)
    env = source.learner.make_env()
    reach = skills_config("2v2", **NET, **{"env.reach_features": True})
    _, params = load_start_params(str(tmp_path / "source"), reach)
    kernel = params.policy["params"]["encode_ff"]["hidden"]["kernel"]
    before = state.params.policy["params"]["encode_ff"]["hidden"]["kernel"]
    assert kernel.shape == (len(SELF_FEATURES) + 3, before.shape[1])
    # The new inputs' weights start at zero: the policy decides what it decided.
    reach_env = reach.learner.make_env()
    game = reach_env.default_params(episode_length=50)
    policy = source.learner.network.policy()
    carry, reset = policy.initial_carry((2,)), jnp.zeros(2, bool)

    @jax.jit
    def both(key: jax.Array) -> tuple[jax.Array, ...]:
        def body(start: Any, k: jax.Array) -> tuple[Any, None]:
            actions = reach_env.sample_actions(jax.random.fold_in(k, 1))
            return reach_env.step(k, start, actions, game)[0], None

        # The ball rolling, the players moved: the table is not all zeros.
        start = jax.lax.scan(body, reach_env.reset(key, game)[0], jax.random.split(key, 20))[0]
        grown = reach_env.observe(start, game).team(0)
        plain = env.observe(start, game).team(0)
        a = policy.apply(params.policy, carry, grown, reset)[1].kind_logits
        b = policy.apply(state.params.policy, carry, plain, reset)[1].kind_logits
        return grown.self_features[:, -3:], a, b

    table, a, b = both(jax.random.key(1))
    assert np.asarray(table).any()
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-5)


def test_the_first_mask_allows_skills_naives_kind_where_the_nearest_mask_does_not() -> None:
    # skills_naive sends the player who reaches the ball first by the intercept table, which
    # the first mask reads (env.reach_features); the nearest one by distance is another player
    # whenever the ball rolls or a player faces away.
    from elevens.robocup.skills.game import SkillSoccer
    from elevens.robocup.skills.naive import naive_choices

    env = SkillSoccer(11, reach=True)
    params = env.default_params(episode_length=200)
    team = SkillsNaiveTeam()

    @jax.jit
    def kinds(key: jax.Array) -> tuple[jax.Array, ...]:
        def body(state: Any, k: jax.Array) -> tuple[Any, tuple[jax.Array, ...]]:
            obs = env.observe(state, params)
            actions = jnp.stack([team.play(obs.team(0)), team.play(obs.team(1))])
            view, _ = skill_observation(obs.team(0), team.field)
            kind = naive_choices(view, jnp)[0]
            return env.step(k, state, actions, params)[0], (
                kind, first_kind_mask(obs.team(0)), nearest_kind_mask(obs.team(0)))

        return jax.lax.scan(body, env.reset(key, params)[0], jax.random.split(key, 100))[1]

    kind, first, nearest = (np.asarray(a) for a in kinds(jax.random.key(4)))
    rows = (kind[..., None] == np.arange(8))[:, 1:]  # outfield: the goalie plays its routine
    first, nearest = first[:, 1:], nearest[:, 1:]
    runs = rows[..., 4].sum()
    assert runs > 40  # intercepts in play
    allowed_first = (first & rows).any(-1).mean()
    allowed_nearest = (nearest & rows).any(-1).mean()
    assert allowed_first > 0.995 and allowed_first > allowed_nearest
    assert (first & rows)[..., 4].sum() / runs > 0.99
    without_reach = jax.jit(lambda k: SkillSoccer(11).observe(env.reset(k, params)[0], params))
    with pytest.raises(ValueError, match=r"ball_first.*needs --env.reach-features"):
        first_kind_mask(without_reach(jax.random.key(0)).team(0))


def test_the_nearest_mask_sends_the_player_nearest_the_ball_and_places_the_rest() -> None:
    # Five 2 v 2 observers (slots: the teammate, two opponents, the ball), distances in metres
    # and bearings from each one's heading.
    scale = 2.0 * SKILLS_FIELD.half_length

    def observer(ball: tuple[float, float] | None, mate: tuple[float, float],
                 mate_seen: bool = True) -> Any:
        entities = np.zeros((4, len(ENTITY_FEATURES)), np.float32)
        seen = np.array([mate_seen, False, False, ball is not None])
        for slot, (d, angle) in ((0, mate), (3, ball or (0.0, 0.0))):
            entities[slot, DISTANCE] = d / scale
            entities[slot, ENTITY_FEATURES.index("cos_bearing")] = np.cos(angle)
            entities[slot, ENTITY_FEATURES.index("sin_bearing")] = np.sin(angle)
        return entities, seen

    cases = [
        observer((3.0, 0.0), (10.0, np.pi / 2)),  # its mate 10.4 m from the ball: it runs
        observer((0.5, 0.0), (10.0, 0.0)),  # the ball at its feet: the ball kinds
        observer((3.0, 0.0), (2.5, 0.0)),  # its mate 0.5 m from the ball: it takes a place
        observer((3.0, 0.0), (3.0, 0.1), mate_seen=False),  # a mate out of view does not count
        observer(None, (10.0, 0.0)),  # no ball in view: a place
    ]
    obs = Observation(
        self_features=jnp.zeros((5, len(SELF_FEATURES))),
        entities=jnp.asarray(np.stack([c[0] for c in cases])),
        entity_mask=jnp.asarray(np.stack([c[1] for c in cases])),
    )
    ball, run, place = [True] * 4 + [False] * 4, [False] * 4 + [True, False, False, True], (
        [False] * 5 + [True, True, False])
    assert np.asarray(nearest_kind_mask(obs)).tolist() == [run, ball, place, run, place]
    assert np.asarray(ball_kind_mask(obs))[:, 0].tolist() == [False, True, False, False, False]
