"""A scripted teacher for PPO (ppo.teacher, kickstarting): the teacher acts on the learner's own
observations, the loss pulls the policy towards its actions with a weight that falls linearly to
0; a weight of 0 changes nothing, and bad teachers are refused before anything compiles."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.runs.teams import team_on_field
from elevens.train.config import TrainConfig, make_config
from elevens.train.learner import make_learner
from elevens.train.ppo import PPOHyperparams
from tests.refusal import refused
from tests.train.test_trainer import tiny_config

# The policy loss off, so only the teacher (and the critic) move the policy.
TAUGHT = {"ppo.teacher": "naive", "ppo.teacher_weight": 2.0, "ppo.teacher_iterations": 4,
          "ppo.policy_weight": 0.0}


@pytest.fixture(scope="module")
def taught() -> list[dict[str, np.ndarray]]:
    """The metrics of 3 chunks (6 iterations) of the tiny 1v1 game taught by naive."""
    config = tiny_config(**TAUGHT)
    learner = make_learner(config.learner, config.learner.make_env(), team_on_field)
    state = learner.init(jax.random.key(0))
    chunks = []
    for _ in range(3):
        state, metrics = learner.update_chunk(state)
        chunks.append({name: np.asarray(value) for name, value in metrics.items()})
    return chunks


def test_the_policy_learns_the_teachers_actions(taught: list[dict[str, np.ndarray]]) -> None:
    log_prob = np.concatenate([chunk["train/teacher_log_prob"] for chunk in taught])
    error = np.concatenate([chunk["train/teacher_action_error"] for chunk in taught])
    # Measured: -0.60 at iteration 0, 0.78 at iteration 3 (key 1: -0.66, 0.86); the mean
    # |tanh(mean) - naive's action| falls from 0.64 to 0.59 by iteration 5 (key 1: 0.65, 0.58).
    assert log_prob[3] >= log_prob[0] + 1.0, log_prob
    assert error[-1] < error[0], error
    assert np.all(np.isfinite(log_prob))


def test_the_weight_falls_linearly_to_zero(taught: list[dict[str, np.ndarray]]) -> None:
    weights = np.concatenate([chunk["train/teacher_weight"] for chunk in taught])
    # 2 * (1 - i / 4) after i iterations, then 0.
    np.testing.assert_array_equal(weights, [2.0, 1.5, 1.0, 0.5, 0.0, 0.0])
    assert PPOHyperparams(teacher_weight=0.5).teacher_weight_at(jax.numpy.asarray(1000)) == 0.5


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"ppo.teacher_weight": -1.0}, "ppo.teacher_weight=-1.0 is invalid: it must be a finite "
                                       "number >= 0"),
        ({"ppo.teacher_weight": float("nan")}, "ppo.teacher_weight=nan is invalid"),
        ({"ppo.teacher_iterations": -2}, "ppo.teacher_iterations=-2 is invalid: it must be an "
                                         "integer >= 0"),
        ({"ppo.teacher_iterations": 1.5}, "ppo.teacher_iterations=1.5 is invalid"),
        ({"ppo.teacher": " naive"}, "ppo.teacher=' naive' is invalid"),
        ({"ppo.teacher": "self"}, "ppo.teacher='self' is invalid: the teacher is a fixed team"),
    ],
)
def test_bad_teacher_settings_are_refused(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        tiny_config(**overrides)


def test_an_unknown_teacher_or_one_outside_the_simulator_is_refused_before_compiling(
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    nobody = make_config("quickstart", **{"ppo.teacher": "nobody"}).learner
    with pytest.raises(ValueError, match="ppo.teacher team 'nobody': team spec: nobody does not"):
        make_learner(nobody, nobody.make_env(), team_on_field)
    naive = make_config("quickstart", **{"ppo.teacher": "naive"}).learner
    with pytest.raises(ValueError, match="ppo.teacher='naive' names a team: pass load_team"):
        make_learner(naive, naive.make_env())
    with pytest.raises(ValueError, match="ppo.teacher='naive' is invalid when the games are "
                                         "played outside the simulator"):
        make_learner(naive, naive.make_env(), external_games=True)
    run_dir = str(tmp_path / "run")
    error = refused(["train", "quickstart", "--ppo.teacher", "nobody", "--run.run-dir", run_dir],
                    "train", capsys)
    assert "ppo.teacher team 'nobody'" in error
    error = refused(["train", "quickstart", "--ppo.teacher-weight", "-1", "--run.run-dir",
                     run_dir], "train", capsys)
    assert "ppo.teacher_weight=-1.0 is invalid" in error
    assert not (tmp_path / "run").exists()


def test_a_config_saved_before_the_teacher_loads_without_one() -> None:
    saved = make_config("quickstart").to_dict()
    for name in ("teacher", "teacher_weight", "teacher_iterations"):
        del saved["learner"]["ppo"][name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new fields' defaults are the old behaviour
        loaded = TrainConfig.from_saved(saved, "old config.json")
    assert loaded == make_config("quickstart")
    assert loaded.learner.ppo.teacher == ""


def test_a_balanced_teacher_weighs_every_kind_alike() -> None:
    # Four entries, three of kind 0 and one of kind 2, all pointing at slot 0 in view: balanced,
    # each kind's entries weigh half of the total (3 x 2/3 and 1 x 2), the mean weight is 1.
    from elevens.nets.distributions import ParametrisedDistribution
    from elevens.train.ppo import teacher_terms

    kinds, slots = 3, 2
    distribution = ParametrisedDistribution.create(
        jnp.zeros((4, kinds)), jnp.zeros((4, kinds, slots)), jnp.ones((4, slots), bool),
        jnp.zeros((4, kinds, 2)), jnp.zeros((4, kinds, 2)),
    )
    action = jnp.array([[0, 0, 0.1, 0.2], [0, 0, -0.3, 0.0], [0, 0, 0.5, 0.5], [2, 0, 0.0, 0.1]])
    plain = teacher_terms(distribution, action)
    balanced = teacher_terms(distribution, action, balance=True)
    np.testing.assert_allclose(
        np.asarray(balanced.log_prob), np.asarray(plain.log_prob) * [2 / 3, 2 / 3, 2 / 3, 2.0],
        rtol=1e-6,
    )
    # Only the entries the policy played count: a routine's entry weighs 0 and leaves the counts.
    played = jnp.array([True, True, False, True])
    among_played = teacher_terms(distribution, action, balance=True, played=played)
    np.testing.assert_array_equal(np.asarray(among_played.mask), np.asarray(played))
    np.testing.assert_allclose(
        np.asarray(among_played.log_prob), np.asarray(plain.log_prob) * [0.75, 0.75, 0.0, 1.5],
        rtol=1e-6,
    )
    with pytest.raises(ValueError, match="ppo.teacher_balance=1 is invalid: it must be True"):
        tiny_config(**{"ppo.teacher_balance": 1})


def test_a_group_balanced_teacher_weighs_each_kind_masks_group_alike() -> None:
    # Five entries: four in the group whose mask allows kinds 0 and 1 (three of kind 0, one of
    # kind 1), one in the group that allows kind 2 alone. Each group weighs half of the total
    # (4 x 5/8, 1 x 5/2) and within a group the kinds keep their shares (unlike balance).
    from elevens.nets.distributions import ParametrisedDistribution
    from elevens.nets.policy import MASKED_LOGIT
    from elevens.train.ppo import teacher_terms

    kinds, slots = 3, 2
    logits = jnp.where(jnp.array([[1, 1, 0]] * 4 + [[0, 0, 1]], bool), 0.0, MASKED_LOGIT)
    distribution = ParametrisedDistribution.create(
        logits, jnp.zeros((5, kinds, slots)), jnp.ones((5, slots), bool),
        jnp.zeros((5, kinds, 2)), jnp.zeros((5, kinds, 2)),
    )
    action = jnp.array([[0, 0, 0.1, 0.2], [0, 0, -0.3, 0.0], [0, 0, 0.5, 0.5], [1, 0, 0.0, 0.1],
                        [2, 0, 0.2, 0.0]])
    plain = teacher_terms(distribution, action)
    grouped = teacher_terms(distribution, action, group_balance=True)
    np.testing.assert_allclose(np.asarray(grouped.log_prob), np.asarray(plain.log_prob)
                               * np.array([5 / 8, 5 / 8, 5 / 8, 5 / 8, 5 / 2]), rtol=1e-6)
    with pytest.raises(ValueError, match="teacher_group_balance=True is invalid with "
                                         "ppo.teacher_balance=True"):
        tiny_config(**{"ppo.teacher_group_balance": True, "ppo.teacher_balance": True})
