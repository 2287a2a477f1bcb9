"""Exact events on hand-built states: kicks, pushes, friction, cap, bounces, goals, clamping."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.env.helpers import build_state, far_away, make_env, zero_actions

KEY = jax.random.key(0)


def step_once(env, params, state, actions=None):  # type: ignore[no-untyped-def]
    n = params.players_per_team
    actions = zero_actions(n) if actions is None else jnp.asarray(actions, jnp.float32)
    return env.step(KEY, state, actions, params)


def positions_with(params, **placed):  # type: ignore[no-untyped-def]
    positions = far_away(params.num_players)
    for index, xy in placed.items():
        positions[int(index[1:])] = xy
    return positions


def test_leg_kick_gives_4_along_heading():
    env, params = make_env(1)
    # Player 0 faces +x; the ball sits beside its legs (2.5 to its left, on the leg line).
    headings = np.array([0.0, np.pi / 2])
    state = build_state(params, positions_with(params, p0=(0.0, 0.0)), headings, (0.0, 2.5))
    state, _, _, _, info = step_once(env, params, state)
    np.testing.assert_allclose(state.ball_position, [4.0, 2.5], atol=1e-6)
    np.testing.assert_allclose(state.ball_velocity, [4.0 * 0.9, 0.0], atol=1e-6)
    assert info.kicks.tolist() == [True, False]
    assert info.pushes.tolist() == [False, False]


def test_kick_follows_heading_not_offset():
    env, params = make_env(1)
    heading = 0.3
    # Ball on the leg line of a player facing 0.3 rad, 3 to its right.
    offset = 3.0 * np.array([np.sin(heading), -np.cos(heading)])
    state = build_state(
        params, positions_with(params, p0=(0.0, 0.0)), np.array([heading, 0.0]), tuple(offset)
    )
    state, *_ = step_once(env, params, state)
    velocity = np.asarray(state.ball_velocity) / 0.9
    np.testing.assert_allclose(velocity, 4.0 * np.array([np.cos(heading), np.sin(heading)]),
                               atol=1e-5)


def test_no_kick_outside_band_or_reach():
    env, params = make_env(1)
    for ball in [(1.2, 2.5), (0.0, 4.2)]:  # 1.2 ahead of the leg line; 4.2 away on it
        state = build_state(
            params, positions_with(params, p0=(0.0, 0.0)), np.array([0.0, 0.0]), ball
        )
        state, _, _, _, info = step_once(env, params, state)
        assert not bool(info.kicks[0]), ball
        np.testing.assert_allclose(state.ball_velocity, [0.0, 0.0])


def test_body_push_gives_0_6_away_from_player():
    env, params = make_env(1)
    # Facing +y, ball 1.5 ahead: inside the body (d < 2) but off the leg line (1.5 > 1).
    state = build_state(
        params, positions_with(params, p0=(0.0, 0.0)), np.array([np.pi / 2, 0.0]), (0.0, 1.5)
    )
    state, _, _, _, info = step_once(env, params, state)
    np.testing.assert_allclose(state.ball_position, [0.0, 2.1], atol=1e-6)
    np.testing.assert_allclose(state.ball_velocity, [0.0, 0.6 * 0.9], atol=1e-6)
    assert info.pushes.tolist() == [True, False]
    assert info.kicks.tolist() == [False, False]


def test_friction_and_stop_speed():
    env, params = make_env(1)
    state = build_state(params, ball_position=(0.0, 0.0), ball_velocity=(2.0, 0.0))
    state, *_ = step_once(env, params, state)
    np.testing.assert_allclose(state.ball_position, [2.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(state.ball_velocity, [1.8, 0.0], atol=1e-6)
    slow = build_state(params, ball_position=(0.0, 0.0), ball_velocity=(0.011, 0.0))
    slow, *_ = step_once(env, params, slow)
    np.testing.assert_allclose(slow.ball_position, [0.011, 0.0], atol=1e-7)
    np.testing.assert_array_equal(slow.ball_velocity, [0.0, 0.0])


def test_speed_cap_at_5():
    env, params = make_env(1)
    # Both players face +x with the ball on their leg lines: two kicks of 4 make 8, capped at 5.
    positions = positions_with(params, p0=(0.0, 2.5), p1=(0.0, -2.5))
    state = build_state(params, positions, np.array([0.0, 0.0]), (0.0, 0.0))
    state, _, _, _, info = step_once(env, params, state)
    assert info.kicks.tolist() == [True, True]
    np.testing.assert_allclose(state.ball_position, [5.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(state.ball_velocity, [4.5, 0.0], atol=1e-5)


def test_bounce_on_side_line():
    env, params = make_env(1)
    state = build_state(params, ball_position=(0.0, 33.0), ball_velocity=(1.0, 3.0))
    state, _, rewards, _, info = step_once(env, params, state)
    np.testing.assert_allclose(state.ball_position, [1.0, 35.0], atol=1e-6)
    np.testing.assert_allclose(state.ball_velocity, [0.9 * 0.6, -2.7 * 0.6], atol=1e-6)
    assert info.goals.tolist() == [0, 0]


@pytest.mark.parametrize("y", [25.0, -21.0])
def test_bounce_on_goal_line_outside_mouth(y):
    env, params = make_env(1)
    state = build_state(params, ball_position=(48.0, y), ball_velocity=(3.0, 0.0))
    state, _, _, _, info = step_once(env, params, state)
    np.testing.assert_allclose(state.ball_position, [50.0, y], atol=1e-6)
    np.testing.assert_allclose(state.ball_velocity, [-2.7 * 0.6, 0.0], atol=1e-6)
    assert info.goals.tolist() == [0, 0]
    np.testing.assert_array_equal(state.score, [0, 0])


@pytest.mark.parametrize("side,scorer", [(1.0, 0), (-1.0, 1)])
def test_goal_inside_mouth_scores_rewards_and_respawns(side, scorer):
    env, params = make_env(2, ball_spawn="centre")
    state = build_state(
        params, ball_position=(side * 48.0, 19.0), ball_velocity=(side * 3.0, 0.5)
    )
    state = state.replace(score=jnp.array([2, 3], jnp.int32))
    new_state, obs, rewards, done, info = step_once(env, params, state)
    expected_goals = [1, 0] if scorer == 0 else [0, 1]
    assert info.goals.tolist() == expected_goals
    np.testing.assert_array_equal(new_state.score, np.array([2, 3]) + np.array(expected_goals))
    sign = np.array([1.0, -1.0]) if scorer == 0 else np.array([-1.0, 1.0])
    np.testing.assert_allclose(info.goal_reward, np.repeat(sign[:, None], 2, axis=1))
    # Everyone respawned: ball at the centre at rest, players in their own halves near their
    # slots, everything at rest, and the observation is the post-respawn one.
    np.testing.assert_array_equal(new_state.ball_position, [0.0, 0.0])
    np.testing.assert_array_equal(new_state.ball_velocity, [0.0, 0.0])
    np.testing.assert_array_equal(new_state.velocities, np.zeros((4, 2)))
    positions = np.asarray(new_state.positions)
    assert np.all(positions[:2, 0] <= 0.0) and np.all(positions[2:, 0] >= 0.0)
    slots = np.array([[-49.5, 0.0], [-11.0, 0.0]])
    assert np.all(np.abs(positions[:2] - slots) <= 5.5 + 1e-5)
    assert np.all(np.abs(positions[2:] + slots) <= 5.5 + 1e-5)
    np.testing.assert_array_equal(new_state.start_positions, new_state.positions)
    np.testing.assert_allclose(obs.self_features[0, :, 1], positions[:2, 0] / 50.0, atol=1e-6)


def test_goal_at_post_edge_counts():
    env, params = make_env(1)
    state = build_state(params, ball_position=(49.0, 20.0), ball_velocity=(3.0, 0.0))
    *_, info = step_once(env, params, state)
    assert info.goals.tolist() == [1, 0]


def test_goal_judged_where_ball_crosses_the_line():
    env, params = make_env(1)
    # The centre crosses x = 50 at y = 19.5 (inside) and ends at y = 22 (outside the mouth).
    state = build_state(params, ball_position=(47.0, 18.0), ball_velocity=(5.0, 2.5))
    *_, info = step_once(env, params, state)
    assert info.goals.tolist() == [1, 0]


def test_player_clamped_at_edge():
    env, params = make_env(1)
    positions = positions_with(params, p0=(49.5, 0.0), p1=(-10.0, -34.8))
    state = build_state(params, positions, np.array([0.0, -np.pi / 2]), (0.0, 20.0))
    state, *_ = step_once(env, params, state, [[[1.0, 0.0]], [[1.0, 0.0]]])
    np.testing.assert_allclose(state.positions, [[50.0, 0.0], [-10.0, -35.0]], atol=1e-5)
    np.testing.assert_allclose(state.velocities, [[0.5, 0.0], [0.0, -0.2]], atol=1e-5)


def test_turn_then_move_clockwise_positive():
    env, params = make_env(1)
    positions = positions_with(params, p0=(0.0, 0.0))
    state = build_state(params, positions, np.array([0.0, 0.0]), (20.0, 20.0))
    state, *_ = step_once(env, params, state, [[[1.0, 1.0]], [[0.0, 0.0]]])
    assert float(state.headings[0]) == pytest.approx(-0.4)
    np.testing.assert_allclose(state.positions[0], [np.cos(-0.4), np.sin(-0.4)], atol=1e-6)
    np.testing.assert_allclose(state.last_actions[0], [1.0, 1.0])


def test_heading_wraps_to_minus_pi_pi():
    env, params = make_env(1)
    state = build_state(params, headings=np.array([-np.pi + 0.1, np.pi - 0.1]))
    state, *_ = step_once(env, params, state, [[[0.0, 1.0]], [[0.0, -1.0]]])
    np.testing.assert_allclose(state.headings, [np.pi - 0.3, -np.pi + 0.3], atol=1e-5)


def test_out_of_range_and_nan_actions_are_clipped():
    env, params = make_env(1)
    state = build_state(params, ball_position=(20.0, 20.0))
    clipped, *_ = step_once(env, params, state, [[[5.0, -7.0]], [[jnp.nan, 0.5]]])
    reference, *_ = step_once(env, params, state, [[[1.0, -1.0]], [[0.0, 0.5]]])
    np.testing.assert_array_equal(clipped.positions, reference.positions)
    np.testing.assert_array_equal(clipped.headings, reference.headings)
    assert np.all(np.isfinite(np.asarray(clipped.positions)))
