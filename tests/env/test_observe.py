"""Observations: field of view, slot layout, frames, the critic's state, and a gather reference."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.env.observe import entity_layout, global_state, observe
from elevens.env.state import (
    ENTITY_FEATURES,
    NUM_ENTITY_FEATURES,
    NUM_SELF_FEATURES,
    SELF_FEATURES,
)
from tests.env.helpers import build_state, far_away, make_env

E = {name: i for i, name in enumerate(ENTITY_FEATURES)}
S = {name: i for i, name in enumerate(SELF_FEATURES)}


def random_state(players: int, steps: int = 30, seed: int = 0):  # type: ignore[no-untyped-def]
    env, params = make_env(players)
    state, _ = jax.jit(env.reset)(jax.random.key(seed), params)
    step = jax.jit(env.step)
    for i in range(steps):
        action_key = jax.random.fold_in(jax.random.key(seed + 1), i)
        actions = jax.random.uniform(action_key, (2, players, 2), minval=-1, maxval=1)
        state, *_ = step(jax.random.key(i), state, actions, params)
    return env, params, state


@pytest.mark.parametrize("angle_deg,visible", [(89.9, True), (90.1, False), (-89.9, True),
                                               (-90.1, False), (0.0, True), (180.0, False)])
def test_field_of_view_boundary(angle_deg, visible):
    env, params = make_env(1)
    angle = np.deg2rad(angle_deg)
    heading = 0.7
    positions = far_away(2)
    positions[0] = (0.0, 0.0)
    positions[1] = 10.0 * np.array([np.cos(heading + angle), np.sin(heading + angle)])
    state = build_state(params, positions, np.array([heading, 0.0]), (30.0, -30.0))
    obs = env.observe(state, params)
    assert bool(obs.entity_mask[0, 0, 0]) == visible
    if visible:
        features = np.asarray(obs.entities[0, 0, 0])
        assert features[E["distance"]] == pytest.approx(0.1, abs=1e-6)
        assert features[E["cos_bearing"]] == pytest.approx(np.cos(angle), abs=1e-5)
        assert features[E["sin_bearing"]] == pytest.approx(np.sin(angle), abs=1e-5)
    else:
        # Masked, not filled with fake data.
        np.testing.assert_array_equal(obs.entities[0, 0, 0], np.zeros(NUM_ENTITY_FEATURES))


def test_shapes_and_slot_layout_11v11():
    env, params, state = random_state(11)
    obs = jax.jit(env.observe)(state, params)  # (op by op: test_observe_jit_matches_eager)
    assert obs.self_features.shape == (2, 11, NUM_SELF_FEATURES)
    assert obs.entities.shape == (2, 11, 22, NUM_ENTITY_FEATURES)
    assert obs.entity_mask.shape == (2, 11, 22)
    entities = np.asarray(obs.entities)
    mask = np.asarray(obs.entity_mask)
    # Teammate flag in the first n-1 slots, ball flag in the last, where visible.
    assert np.all(entities[..., :10, E["is_teammate"]][mask[..., :10]] == 1)
    assert np.all(entities[..., 10:, E["is_teammate"]][mask[..., 10:]] == 0)
    assert np.all(entities[..., -1, E["is_ball"]][mask[..., -1]] == 1)
    assert np.all(entities[..., :-1, E["is_ball"]] == 0)
    index, _ = entity_layout(11)
    for observer in range(22):
        assert observer not in index[observer]
        assert sorted(index[observer]) == sorted(set(range(23)) - {observer})


def reference_entities(state, params):  # type: ignore[no-untyped-def]
    """A plain NumPy loop over observers and slots, straight from SPEC.md."""
    n = params.players_per_team
    index, teammate = entity_layout(n)
    pos = np.concatenate([np.asarray(state.positions), np.asarray(state.ball_position)[None]])
    vel = np.concatenate([np.asarray(state.velocities), np.asarray(state.ball_velocity)[None]])
    headings = np.asarray(state.headings)
    actions = np.asarray(state.last_actions)
    out = np.zeros((2 * n, 2 * n, NUM_ENTITY_FEATURES))
    mask = np.zeros((2 * n, 2 * n), bool)
    for k in range(2 * n):
        h = headings[k]
        for slot, j in enumerate(index[k]):
            offset = pos[j] - pos[k]
            bearing = np.arctan2(offset[1], offset[0]) - h
            if np.cos(bearing) < 0:
                continue
            mask[k, slot] = True
            rotate = np.array([[np.cos(h), np.sin(h)], [-np.sin(h), np.cos(h)]])
            is_ball = j == 2 * n
            rel = 0.0 if is_ball else headings[j] - h
            out[k, slot] = [
                np.linalg.norm(offset) / 100.0, np.cos(bearing), np.sin(bearing),
                *(rotate @ vel[j]),
                0.0 if is_ball else np.cos(rel), 0.0 if is_ball else np.sin(rel),
                *(np.zeros(2) if is_ball else actions[j]),
                teammate[k, slot], float(is_ball),
            ]
    return out.reshape(2, n, 2 * n, -1), mask.reshape(2, n, 2 * n)


@pytest.mark.parametrize("players", [1, 2, 5])
def test_entities_match_numpy_reference(players):
    env, params, state = random_state(players, steps=40, seed=players)
    obs = jax.jit(env.observe)(state, params)
    expected, mask = reference_entities(state, params)
    np.testing.assert_array_equal(obs.entity_mask, mask)
    np.testing.assert_allclose(obs.entities, expected, atol=2e-5)


def test_self_features_team_frames():
    env, params = make_env(1)
    positions = np.array([[-10.0, 5.0], [20.0, -7.0]])
    headings = np.array([0.5, -2.0])
    state = build_state(params, positions, headings, (0.0, 0.0), step=100)
    state = state.replace(last_actions=jnp.array([[0.25, -0.5], [1.0, 0.75]]))
    obs = env.observe(state, params)
    own = np.asarray(obs.self_features)
    assert own[0, 0, S["time_left"]] == pytest.approx(0.75)
    np.testing.assert_allclose(own[0, 0, [S["x"], S["y"]]], [-10 / 50, 5 / 35], atol=1e-6)
    # Team 1 sees itself point-reflected: its position negated, its heading turned by pi.
    np.testing.assert_allclose(own[1, 0, [S["x"], S["y"]]], [-20 / 50, 7 / 35], atol=1e-6)
    np.testing.assert_allclose(
        own[1, 0, [S["cos_heading"], S["sin_heading"]]],
        [np.cos(-2.0 + np.pi), np.sin(-2.0 + np.pi)], atol=1e-6,
    )
    np.testing.assert_allclose(own[1, 0, [S["last_move"], S["last_rot"]]], [1.0, 0.75])
    # Team 0 at heading 0.5 sees the ball at the centre ahead-right of it? Direction from
    # (-10, 5) to (0, 0) is atan2(-5, 10); its bearing is that minus 0.5.
    bearing = np.arctan2(-5.0, 10.0) - 0.5
    assert own[0, 0, S["ball_visible"]] == 1.0
    np.testing.assert_allclose(
        own[0, 0, [S["ball_cos_bearing"], S["ball_sin_bearing"]]],
        [np.cos(bearing), np.sin(bearing)], atol=1e-6,
    )


def test_ball_features_zero_and_flag_off_when_not_visible():
    env, params = make_env(1)
    state = build_state(params, np.array([[0.0, 0.0], [10.0, 10.0]]), np.array([0.0, 0.0]),
                        (-5.0, 0.0))
    own = np.asarray(env.observe(state, params).self_features)
    assert own[0, 0, S["ball_visible"]] == 0.0
    np.testing.assert_array_equal(own[0, 0, S["ball_visible"]:], 0.0)


def test_global_state_own_team_first_in_own_frame():
    env, params, state = random_state(3)
    critic = global_state(state, params)
    assert critic.context.shape == (2, 5)
    assert critic.players.shape == (2, 6, 11)
    players = np.asarray(critic.players)
    positions = np.asarray(state.positions)
    np.testing.assert_allclose(players[0, :, :2], positions / [50.0, 35.0], atol=1e-6)
    np.testing.assert_allclose(players[1, :3, :2], -positions[3:] / [50.0, 35.0], atol=1e-6)
    np.testing.assert_allclose(players[1, 3:, :2], -positions[:3] / [50.0, 35.0], atol=1e-6)
    np.testing.assert_array_equal(players[:, :, -1], [[1, 1, 1, 0, 0, 0]] * 2)
    ball = np.asarray(state.ball_position) / [50.0, 35.0]
    np.testing.assert_allclose(critic.context[0, 1:3], ball, atol=1e-6)
    np.testing.assert_allclose(critic.context[1, 1:3], -ball, atol=1e-6)
    np.testing.assert_allclose(critic.context[1, 3:5], -np.asarray(state.ball_velocity))
    # Each team's view of the game is the other's point reflection: the views agree on the
    # last actions (frame-free) and on the teammate split.
    np.testing.assert_allclose(players[0, :3, 6:8], players[1, 3:, 6:8])


def test_observe_jit_matches_eager_and_vmaps():
    env, params, state = random_state(4)
    eager = observe(state, params)
    jitted = jax.jit(observe)(state, params)
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    batch = jax.tree.map(lambda x: jnp.stack([x, x]), state)
    batched = jax.jit(jax.vmap(observe, in_axes=(0, None)))(batch, params)
    np.testing.assert_allclose(batched.entities[1], eager.entities, atol=1e-6)
