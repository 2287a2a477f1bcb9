"""skills_naive teaches the learned skills team in the simulator's skill game (ppo.teacher):
its (kind, pointer, x, y) are scored by the parametrised head, pointer slot for pointer slot."""

from __future__ import annotations

from typing import Any

import jax
import numpy as np

import elevens.robocup  # noqa: F401 - registers the skill game and its teams
from elevens.nets.policy import AttentionPolicy
from elevens.robocup.skills.game import skills_config
from elevens.runs.teams import team_on_field
from elevens.train.learner import make_learner
from elevens.train.ppo import teacher_terms
from elevens.train.rollout import Teacher, rollout

TINY = {
    "env.episode_length": 8, "games_per_iteration": 2, "network.features": 16,
    "network.num_heads": 2, "network.lstm_features": 8, "network.lstm_layers": 1,
    "ppo.minibatch_size": 4, "iterations_per_chunk": 1, "ppo.epochs": 1,
    "ppo.teacher": "skills_naive",
}


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
