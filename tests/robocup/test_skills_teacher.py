"""skills_naive teaches the learned skills team in the simulator's skill game (ppo.teacher):
its (kind, pointer, x, y) are scored by the parametrised head, pointer slot for pointer slot."""

from __future__ import annotations

import jax
import numpy as np

import elevens.robocup  # noqa: F401 - registers the skill game and its teams
from elevens.robocup.skills.game import skills_config
from elevens.runs.teams import team_on_field
from elevens.train.learner import make_learner
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
    # The recorded actions are the team's own on the learner's observations.
    data = jax.jit(lambda key: rollout(
        env, learner.policy, learner.env_params, state.params.policy, state.params.policy, key,
        num_games=2, num_steps=8, teacher=teacher,
    ))(jax.random.key(1))
    recorded = np.asarray(data.transitions.teacher_action)  # [G * n, T, 4]
    obs = jax.tree.map(lambda leaf: leaf[0:2, 3], data.transitions.obs)  # game 0, step 3
    _, expected = teacher.policy.act(None, (), obs, jax.random.key(2))
    np.testing.assert_array_equal(recorded[0:2, 3], np.asarray(expected))
    assert recorded.shape == (4, 8, 4)
    _, metrics = learner.update_chunk(state)
    log_prob = float(np.asarray(metrics["train/teacher_log_prob"])[0])
    agreement = float(np.asarray(metrics["train/teacher_agreement"])[0])
    assert np.isfinite(log_prob) and -60.0 < log_prob < 0.0, log_prob
    assert 0.0 <= agreement <= 1.0
