"""The PettingZoo front: API conformance, seeding, spaces, bad actions, truncation, rewards."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import warnings
from typing import Any

import numpy as np
import pytest

pytest.importorskip(
    "pettingzoo", reason="PettingZoo is an optional extra: pip install 'elevens[pettingzoo]'"
)

import jax  # noqa: E402
from gymnasium import spaces  # noqa: E402
from pettingzoo.test import parallel_api_test, parallel_seed_test  # noqa: E402

import elevens  # noqa: E402
from elevens.adapters import pettingzoo as adapter  # noqa: E402
from elevens.adapters.pettingzoo import SoccerParallelEnv, observation_bounds  # noqa: E402
from elevens.env.state import SELF_FEATURES  # noqa: E402

BALL_VISIBLE = SELF_FEATURES.index("ball_visible")
BALL_SIN = SELF_FEATURES.index("ball_sin_bearing")
# A small pitch where chasing players score often, so goals (and respawn keys) get exercised.
SMALL_PITCH: dict[str, Any] = {"field_length": 30.0, "field_width": 20.0, "goal_width": 16.0}


def chase_ball(observations: dict) -> dict:
    """Run at the ball if it is in view (turn towards it), else turn on the spot to find it."""
    actions = {}
    for agent, obs in observations.items():
        if obs["self"][BALL_VISIBLE]:
            # rot > 0 turns clockwise; a ball to the left (sin > 0) needs rot < 0.
            actions[agent] = np.array([1.0, -np.sign(obs["self"][BALL_SIN])], np.float32)
        else:
            actions[agent] = np.array([0.0, 1.0], np.float32)
    return actions


def random_actions(env: SoccerParallelEnv, rng: np.random.Generator) -> dict:
    return {agent: rng.uniform(-1, 1, 2).astype(np.float32) for agent in env.agents}


def assert_same(tree_a: object, tree_b: object) -> None:
    leaves_a, def_a = jax.tree_util.tree_flatten(tree_a)
    leaves_b, def_b = jax.tree_util.tree_flatten(tree_b)
    assert str(def_a) == str(def_b)
    for a, b in zip(leaves_a, leaves_b, strict=True):
        np.testing.assert_array_equal(a, b)


# ----------------------------------------------------------------------- API conformance
@pytest.mark.parametrize("scenario", ["1v1", "2v2", "11v11"])
def test_parallel_api_test_passes_without_warnings(scenario: str) -> None:
    # episode_length < num_cycles, so the test also walks through a truncation and a reset.
    env = SoccerParallelEnv(scenario, episode_length=25)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the API test reports most problems as warnings
        parallel_api_test(env, num_cycles=30)


def test_pettingzoo_seed_test_passes() -> None:
    parallel_seed_test(lambda: SoccerParallelEnv("2v2", episode_length=30), num_cycles=30)


def test_names_spaces_and_metadata() -> None:
    env = SoccerParallelEnv("2v2")
    assert env.possible_agents == ["team0_0", "team0_1", "team1_0", "team1_1"]
    assert env.metadata["name"] == "elevens_soccer_v0"
    assert env.metadata["render_modes"] == ["rgb_array"]
    assert env.metadata["is_parallelizable"] is True
    action_space = env.action_space("team1_0")
    assert action_space == spaces.Box(-1.0, 1.0, (2,), np.float32)
    obs_space = env.observation_space("team0_1")
    assert isinstance(obs_space, spaces.Dict)
    assert isinstance(obs_space["self"], spaces.Box)
    assert isinstance(obs_space["entities"], spaces.Box)
    assert obs_space["self"].shape == (15,)
    assert obs_space["entities"].shape == (4, 11)
    assert obs_space["entity_mask"] == spaces.MultiBinary(4)
    # distances reach the field diagonal / length; velocities the ball's speed cap
    assert obs_space["entities"].high[0, 0] == pytest.approx(np.hypot(100, 70) / 100, rel=1e-6)
    assert obs_space["self"].high[SELF_FEATURES.index("ball_vel_forward")] == 5.0
    # each agent owns its space objects (seeding one does not reseed another)
    assert env.action_space("team0_0") is not env.action_space("team0_1")


def test_import_of_adapters_package_does_not_import_pettingzoo() -> None:
    code = (
        "import sys, elevens.adapters; "
        "assert 'pettingzoo' not in sys.modules and 'gymnasium' not in sys.modules; "
        "from elevens.adapters import SoccerParallelEnv; assert 'pettingzoo' in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_bad_constructor_arguments_are_clear_errors() -> None:
    with pytest.raises(ValueError, match="render_mode='human'"):
        SoccerParallelEnv("2v2", render_mode="human")
    with pytest.raises(ValueError, match="scenario='2v3'"):
        SoccerParallelEnv("2v3")
    with pytest.raises(ValueError, match="episode_length"):
        SoccerParallelEnv("2v2", episode_length=0)


# --------------------------------------------------------------------------- seeding
def rollout(env: SoccerParallelEnv, seed: int | None, steps: int) -> list[Any]:
    """(observations, rewards, infos) per step under a fixed action sequence."""
    history: list[Any] = [env.reset(seed=seed)[0]]
    rng = np.random.default_rng(123)
    for _ in range(steps):
        observations, rewards, _, _, infos = env.step(random_actions(env, rng))
        history.append((observations, rewards, infos))
    return history


def test_same_seed_same_rollout_and_different_seed_differs() -> None:
    first = rollout(SoccerParallelEnv("1v1", **SMALL_PITCH), seed=7, steps=60)
    second = rollout(SoccerParallelEnv("1v1", **SMALL_PITCH), seed=7, steps=60)
    assert_same(first, second)
    other = rollout(SoccerParallelEnv("1v1", **SMALL_PITCH), seed=8, steps=1)
    assert not np.array_equal(first[0]["team0_0"]["self"], other[0]["team0_0"]["self"])


def test_reset_without_seed_continues_the_key_sequence() -> None:
    env_a, env_b = SoccerParallelEnv("2v2"), SoccerParallelEnv("2v2")
    seeded_a, _ = env_a.reset(seed=3)
    again_a, _ = env_a.reset()
    seeded_b, _ = env_b.reset(seed=3)
    again_b, _ = env_b.reset()
    assert_same(again_a, again_b)  # the continuation is reproducible
    assert not np.array_equal(seeded_a["team0_0"]["self"], again_a["team0_0"]["self"])
    reseeded, _ = env_a.reset(seed=3)
    assert_same(reseeded, seeded_a)


def test_seed_must_be_an_integer() -> None:
    env = SoccerParallelEnv("1v1")
    with pytest.raises(ValueError, match="seed=1.5"):
        env.reset(seed=1.5)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- spaces
def test_observations_and_state_lie_in_their_spaces_and_bounds_are_honest() -> None:
    """Hundreds of steps of random and ball-chasing play, goals included.

    The adapter clips to the declared bounds, so the raw JAX observations are checked too: they
    must lie within the bounds up to float rounding, or the bounds are wrong.
    """
    env = SoccerParallelEnv("2v2", spawn="random", episode_length=60, **SMALL_PITCH)
    bounds = observation_bounds(env.params)
    raw_observe = jax.jit(env.soccer.observe)
    tolerance = 1e-5
    rng = np.random.default_rng(0)
    observations, _ = env.reset(seed=0)
    goals = touches = 0
    ball_speed = 0.0
    for step in range(300):
        if not env.agents:
            observations, _ = env.reset()
        for agent, obs in observations.items():
            assert env.observation_space(agent).contains(obs), (step, agent, obs)
        assert env.state_space.contains(env.state())
        raw = jax.device_get(raw_observe(env.game_state, env.params))
        assert np.all(raw.self_features >= bounds.self_low - tolerance)
        assert np.all(raw.self_features <= bounds.self_high + tolerance)
        assert np.all(raw.entities >= bounds.entity_low - tolerance)
        assert np.all(raw.entities <= bounds.entity_high + tolerance)
        actions = chase_ball(observations) if step % 3 else random_actions(env, rng)
        observations, _, _, _, infos = env.step(actions)
        goals += infos["team0_0"]["goal_reward"] != 0
        touches += sum(info["touched"] for info in infos.values())
        ball_speed = max(ball_speed, float(np.hypot(*env.game_state.ball_velocity)))
    # The run must reach the interesting corners of the space, or it proves little.
    assert goals >= 1 and touches >= 10 and ball_speed > 3.0


def test_state_is_both_critic_views_flattened() -> None:
    env = SoccerParallelEnv("2v2")
    env.reset(seed=1)
    env.step({agent: np.array([1.0, 0.2], np.float32) for agent in env.agents})
    state = env.state()
    assert state.shape == env.state_space.shape == (2 * (5 + 4 * 11),)
    critic = jax.device_get(env.soccer.global_state(env.game_state, env.params))
    for team in range(2):
        expected = np.concatenate([critic.context[team], critic.players[team].reshape(-1)])
        np.testing.assert_allclose(state.reshape(2, -1)[team], expected, atol=1e-6)


# ------------------------------------------------------------------------- bad actions
def good_actions(env: SoccerParallelEnv) -> dict:
    return {agent: np.zeros(2, np.float32) for agent in env.agents}


@pytest.mark.parametrize(
    ("agent", "value", "message"),
    [
        ("team0_1", np.zeros(3), r"'team0_1' has shape \(3,\).*expected shape \(2,\)"),
        ("team0_1", 0.5, r"'team0_1' has shape \(\).*0\.5.*expected shape \(2,\)"),
        ("team1_0", np.zeros((1, 2)), r"'team1_0' has shape \(1, 2\)"),
        ("team1_0", ["up", "left"], r"'team1_0' is not numeric: \['up', 'left'\].*\[-1, 1\]"),
        ("team1_0", None, r"'team1_0' is not numeric: None"),
        ("team0_0", [True, False], r"'team0_0' is not numeric: \[True, False\]"),
        ("team0_0", [0.1, [0.2, 0.3]], r"'team0_0' is not numeric"),
        ("team0_0", np.array([np.nan, 0.0]), r"'team0_0' contains NaN or Inf: .*nan.*\[-1, 1\]"),
        ("team1_1", [0.0, float("inf")], r"'team1_1' contains NaN or Inf: \[0\.0, inf\]"),
    ],
)
def test_bad_action_values_raise_clear_errors(agent: str, value: object, message: str) -> None:
    env = SoccerParallelEnv("2v2")
    env.reset(seed=0)
    actions = good_actions(env)
    actions[agent] = value
    with pytest.raises(ValueError, match=message):
        env.step(actions)
    # Nothing happened: the game did not advance, and a good step still works.
    assert int(env.game_state.step) == 0
    env.step(good_actions(env))
    assert int(env.game_state.step) == 1


def test_unknown_and_missing_agents_raise_clear_errors() -> None:
    env = SoccerParallelEnv("2v2")
    env.reset(seed=0)
    actions = good_actions(env) | {"team2_0": np.zeros(2)}
    with pytest.raises(ValueError, match=r"unknown or finished agent\(s\) \['team2_0'\].*team0_0"):
        env.step(actions)
    actions = good_actions(env)
    del actions["team1_1"]
    with pytest.raises(ValueError, match=r"missing for live agent\(s\) \['team1_1'\]"):
        env.step(actions)
    with pytest.raises(ValueError, match="must be a dict"):
        env.step([np.zeros(2)] * 4)  # type: ignore[arg-type]


def test_out_of_range_actions_are_clipped() -> None:
    big, clipped = SoccerParallelEnv("1v1"), SoccerParallelEnv("1v1")
    big.reset(seed=4)
    clipped.reset(seed=4)
    out_big = big.step({"team0_0": [7.0, -3.0], "team1_0": np.array([-2, 9])})
    out_clipped = clipped.step({"team0_0": [1.0, -1.0], "team1_0": [-1.0, 1.0]})
    assert_same(out_big, out_clipped)


def test_step_before_reset_is_an_error() -> None:
    with pytest.raises(RuntimeError, match="reset"):
        SoccerParallelEnv("1v1").step({"team0_0": [0, 0], "team1_0": [0, 0]})


# ------------------------------------------------------------------------- truncation
def test_truncation_at_episode_length_empties_agents() -> None:
    env = SoccerParallelEnv("2v2", episode_length=20)
    env.reset(seed=0)
    for _ in range(19):
        _, rewards, terminations, truncations, _ = env.step(good_actions(env))
        assert not any(terminations.values()) and not any(truncations.values())
        assert env.agents == env.possible_agents
        assert all(type(reward) is float for reward in rewards.values())
    observations, rewards, terminations, truncations, infos = env.step(good_actions(env))
    every = set(env.possible_agents)
    assert set(observations) == set(rewards) == set(terminations) == set(infos) == every
    assert truncations == dict.fromkeys(env.possible_agents, True)
    assert terminations == dict.fromkeys(env.possible_agents, False)
    assert env.agents == []
    with pytest.raises(RuntimeError, match="episode ended"):
        env.step({})
    env.reset()
    assert env.agents == env.possible_agents


# ----------------------------------------------------------------- agreement with JAX
def test_rewards_and_observations_agree_with_the_jax_env() -> None:
    """Replay the adapter's documented key schedule on the JAX env; goals must happen."""
    seed, steps = 11, 240
    env = SoccerParallelEnv("1v1", **SMALL_PITCH)
    soccer, params = elevens.make("1v1", **SMALL_PITCH)
    jax_step = jax.jit(soccer.step)
    observations, _ = env.reset(seed=seed)

    key = jax.random.key(seed)
    key, reset_key = jax.random.split(key)
    state, _ = soccer.reset(reset_key, params)
    goals = 0
    for _ in range(steps):
        actions = chase_ball(observations)
        observations, rewards, _, _, infos = env.step(actions)
        array = np.stack([actions[agent] for agent in env.possible_agents]).reshape(2, 1, 2)
        key, step_key = jax.random.split(key)
        state, obs, jax_rewards, _, info = jax_step(step_key, state, array, params)
        jax_rewards = np.asarray(jax_rewards).reshape(-1)
        for i, agent in enumerate(env.possible_agents):
            assert rewards[agent] == pytest.approx(float(jax_rewards[i]), abs=1e-6)
            assert infos[agent]["goal_reward"] == float(np.asarray(info.goal_reward).reshape(-1)[i])
            assert infos[agent]["score"] == tuple(int(s) for s in state.score)
        np.testing.assert_allclose(
            observations["team1_0"]["entities"], np.asarray(obs.entities)[1, 0], atol=1e-5
        )
        goals += int(np.sum(np.asarray(info.goals)))
    assert goals >= 2  # respawns happened, so the step keys were checked too


def test_one_compiled_step_shared_by_envs_of_the_same_size() -> None:
    _, step_fn, _ = adapter._compiled(2)
    first = SoccerParallelEnv("2v2", episode_length=50)
    first.reset(seed=0)
    first.step(good_actions(first))
    compiled = step_fn._cache_size()
    second = SoccerParallelEnv("2v2", episode_length=80, kick_impulse=3.0)
    second.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(5):
        second.step(random_actions(second, rng))
        second.step({a: [2, -2] for a in second.agents})  # ints, out of range: same trace
    assert step_fn._cache_size() == compiled


# --------------------------------------------------------------------------- render
def test_render_without_mode_warns_and_returns_none() -> None:
    env = SoccerParallelEnv("1v1")
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    env.close()
    assert env.agents == []


def test_render_rgb_array() -> None:
    env = SoccerParallelEnv("1v1", render_mode="rgb_array")
    env.reset(seed=0)
    if importlib.util.find_spec("elevens.env.render") is None:
        with pytest.raises(NotImplementedError, match="render_frame"):
            env.render()
        return
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    assert frame.ndim == 3 and frame.shape[-1] == 3 and frame.dtype == np.uint8
