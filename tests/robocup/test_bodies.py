"""elevens.robocup.bodies: the server's body model, against hand-worked cases and a running
rcssserver with its noise switched off."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.robocup import bodies as rcss
from elevens.robocup.protocol import Dash, Kick, Turn
from tests.robocup.conftest import needs_rcssserver

P = rcss.RcssParams()
NO_NOISE = {"server::player_rand": "0", "server::ball_rand": "0", "server::kick_rand": "0",
            "server::wind_none": "true"}


def test_a_dash_straight_ahead_pushes_by_power_times_the_dash_rate() -> None:
    accel = rcss.dash_acceleration(jnp.float32(100.0), jnp.float32(0.0), jnp.float32(0.5))
    np.testing.assert_allclose(accel, 0.6 * np.array([math.cos(0.5), math.sin(0.5)]), rtol=1e-6)
    # Sideways (+90: clockwise, to the right) at side_dash_rate, backwards at back_dash_rate.
    right = rcss.dash_acceleration(jnp.float32(100.0), jnp.float32(90.0), jnp.float32(0.0))
    np.testing.assert_allclose(right, [0.0, -0.6 * 0.4], atol=1e-7)
    back = rcss.dash_acceleration(jnp.float32(50.0), jnp.float32(180.0), jnp.float32(0.0))
    np.testing.assert_allclose(back, [-0.3 * 0.7, 0.0], atol=1e-7)
    # Negative power is clamped to 0 (protocol v17+).
    np.testing.assert_allclose(rcss.dash_acceleration(jnp.float32(-50.0), 0.0, 0.0), [0, 0])


def test_a_turn_is_slower_the_faster_the_player_moves() -> None:
    at_rest = rcss.turn(jnp.float32(0.0), jnp.float32(60.0), jnp.zeros(2))
    assert float(at_rest) == pytest.approx(-math.radians(60.0))  # clockwise
    moving = rcss.turn(jnp.float32(0.0), jnp.float32(60.0), jnp.array([0.6, 0.0]))
    assert float(moving) == pytest.approx(-math.radians(60.0) / (1.0 + 5.0 * 0.6))


def test_a_kick_loses_power_with_the_balls_distance_and_angle() -> None:
    player, body = jnp.zeros(2), jnp.float32(0.0)
    touching = jnp.array([P.player_size + P.ball_size, 0.0])  # right in front, no gap
    accel = rcss.kick_acceleration(jnp.float32(100.0), jnp.float32(0.0), body, player, touching)
    np.testing.assert_allclose(accel, [2.7, 0.0], rtol=1e-6)  # the full 100 * 0.027
    # At the edge of reach, 90 degrees off the body: 1 - 0.125 - 0.25 of the power.
    edge = jnp.array([0.0, P.kickable_distance])
    accel = rcss.kick_acceleration(jnp.float32(100.0), jnp.float32(-90.0), body, player, edge)
    np.testing.assert_allclose(accel, [0.0, 2.7 * 0.625], atol=1e-6)
    far = jnp.array([P.kickable_distance + 0.01, 0.0])
    assert not bool(rcss.kickable(player, far))
    np.testing.assert_allclose(rcss.kick_acceleration(100.0, 0.0, body, player, far), [0, 0])


def test_advance_caps_the_acceleration_and_speed_then_decays() -> None:
    position, velocity = rcss.advance(
        jnp.zeros(2), jnp.array([2.0, 0.0]), jnp.array([2.7, 0.0]), P.ball_accel_max,
        P.ball_speed_max, P.ball_decay,
    )
    np.testing.assert_allclose(position, [3.0, 0.0], rtol=1e-6)  # capped at 3 m a cycle
    np.testing.assert_allclose(velocity, [3.0 * 0.94, 0.0], rtol=1e-6)
    # No push: a fast object keeps its speed above the cap (the server caps only on a push).
    position, velocity = rcss.advance(
        jnp.zeros(2), jnp.array([1.2, 0.0]), jnp.zeros(2), 1.0, 1.05, 0.4
    )
    np.testing.assert_allclose(position, [1.2, 0.0]) and np.testing.assert_allclose(
        velocity, [0.48, 0.0], rtol=1e-6
    )


def test_atan2_is_jnp_arctan2_to_a_few_ulps() -> None:
    rng = np.random.default_rng(0)
    scale = rng.choice([1e-3, 1.0, 1e3], (2, 100_000))
    y, x = (rng.normal(size=(2, 100_000)) * scale).astype(np.float32)
    edges = np.array([0.0, -0.0, 1.0, -1.0, 2.5, -2.5], np.float32)
    y = np.concatenate([y, np.repeat(edges, len(edges))])
    x = np.concatenate([x, np.tile(edges, len(edges))])
    ours = np.asarray(jax.jit(rcss.atan2)(y, x))
    np.testing.assert_allclose(ours, np.arctan2(y, x), rtol=0, atol=3e-7)
    # Signed zeros and the axes as arctan2 gives them (atan2(-0, -1) = -pi).
    np.testing.assert_array_equal(np.signbit(ours), np.signbit(np.arctan2(y, x)))


def test_jit_vmap_and_eager_agree() -> None:
    rng = np.random.default_rng(0)
    power = rng.uniform(0, 100, 16).astype(np.float32)
    direction = rng.uniform(-180, 180, 16).astype(np.float32)
    body = rng.uniform(-3, 3, 16).astype(np.float32)
    player = rng.uniform(-5, 5, (16, 2)).astype(np.float32)
    ball = player + rng.uniform(-1, 1, (16, 2)).astype(np.float32)
    batched = rcss.kick_acceleration(power, direction, body, player, ball)
    mapped = jax.vmap(rcss.kick_acceleration)(power, direction, body, player, ball)
    jitted = jax.jit(rcss.kick_acceleration)(power, direction, body, player, ball)
    single = np.stack([rcss.kick_acceleration(*a) for a in zip(power, direction, body, player,
                                                                ball, strict=True)])
    for other in (mapped, jitted, single):
        np.testing.assert_allclose(batched, other, rtol=1e-5, atol=1e-6)
    dashes = jax.jit(rcss.dash_acceleration)(power, direction, body)
    np.testing.assert_allclose(dashes, rcss.dash_acceleration(power, direction, body), rtol=1e-6)


# ---------------------------------------------------------------- against rcssserver
def _world(x: float, y: float) -> np.ndarray:
    return np.array([x, -y])  # the server's y points down


def _body(deg: float) -> float:
    return -math.radians(deg)


@needs_rcssserver
def test_the_model_predicts_the_servers_next_cycle() -> None:
    from elevens.robocup.env import RoboCupConfig, RoboCupEnv

    config = RoboCupConfig(players_per_team=1, server_options=NO_NOISE)
    with RoboCupEnv(config) as env:
        env.reset(seed=0)
        client: Any = env._client

        def place(player: tuple[float, float], body: float, ball: tuple[float, float],
                  ball_vel: tuple[float, float] = (0.0, 0.0)) -> Any:
            positions = np.array([[player], [[-40.0, 30.0]]])
            client.reset(positions, np.array([[body], [0.0]]), ball, ball_vel)
            # The reset's own cycle may still show the old state: one more, then it is placed.
            return client.step([None, None])

        def after(command: Any) -> Any:
            world = client.step([command, None]).world
            me = next(p for p in world.players if p.team == config.team_names[0])
            return world.ball, me

        # Kicks: ball ahead-left, behind, at rest and rolling; directions both ways. A rolling
        # ball has moved on when placed: the kick starts from what the server reports.
        for ball_at, ball_vel, power, direction in [
            ((10.6, 0.3), (0.0, 0.0), 100.0, 0.0),
            ((10.3, -0.6), (0.0, 0.0), 60.0, 45.0),
            ((9.3, 0.4), (0.0, 0.0), 80.0, -120.0),
            ((10.0, 1.3), (0.0, -0.35), 40.0, 90.0),
        ]:
            start = place((10.0, 0.0), 20.0, ball_at, ball_vel).world.ball
            ball, _ = after(Kick(power, direction))
            origin, rolling = _world(start.x, start.y), _world(start.vx, start.vy)
            assert bool(rcss.kickable(jnp.asarray(_world(10.0, 0.0)), jnp.asarray(origin)))
            accel = rcss.kick_acceleration(
                jnp.float32(power), jnp.float32(direction), jnp.float32(_body(20.0)),
                jnp.asarray(_world(10.0, 0.0)), jnp.asarray(origin),
            )
            position, velocity = rcss.advance(
                jnp.asarray(origin), jnp.asarray(rolling), accel,
                P.ball_accel_max, P.ball_speed_max, P.ball_decay,
            )
            np.testing.assert_allclose(_world(ball.x, ball.y), position, atol=1e-3)
            np.testing.assert_allclose(_world(ball.vx, ball.vy), velocity, atol=1e-3)
        # Dashes: forward, sideways and backwards, then a second dash on the carried velocity.
        for power, direction in [(100.0, 0.0), (100.0, 90.0), (70.0, -150.0)]:
            place((0.0, 10.0), -30.0, (30.0, 30.0))
            position, velocity = jnp.asarray(_world(0.0, 10.0)), jnp.zeros(2)
            for _ in range(2):
                _, me = after(Dash(power, direction))
                accel = rcss.dash_acceleration(
                    jnp.float32(power), jnp.float32(direction), jnp.float32(_body(-30.0))
                )
                position, velocity = rcss.advance(
                    position, velocity, accel, P.player_accel_max, P.player_speed_max,
                    P.player_decay,
                )
                np.testing.assert_allclose(_world(me.x, me.y), position, atol=1e-3)
                np.testing.assert_allclose(_world(me.vx, me.vy), velocity, atol=1e-3)
        # A turn while moving: the dash's velocity slows it.
        place((0.0, 10.0), 0.0, (30.0, 30.0))
        _, me = after(Dash(100.0, 0.0))
        speed_then = np.array(_world(me.vx, me.vy))
        _, me = after(Turn(90.0))
        body = rcss.turn(jnp.float32(_body(0.0)), jnp.float32(90.0), jnp.asarray(speed_then))
        assert _body(me.body) == pytest.approx(float(body), abs=math.radians(1.0))
        assert abs(me.body) < 45.0  # less than half the 90 asked for


# ---------------------------------------------------------------- the 12-value game
def _action(kind: int, **values: float) -> np.ndarray:
    a = np.full(12, -1.0, np.float32)
    a[5:] = 0.0
    a[kind] = 1.0
    for index, value in values.items():
        a[int(index[1:])] = value
    return a


def test_decoding_agrees_with_the_servers_action_mapping() -> None:
    from elevens.robocup.actions import ActionScaling, actions_to_commands
    from elevens.robocup.env import command_summary
    from elevens.robocup.protocol import NoOp, Tackle

    rng = np.random.default_rng(3)
    actions = rng.uniform(-1.2, 1.2, (400, 12)).astype(np.float32)
    decoded = rcss.decode_thesis12(jnp.asarray(actions))
    summary = np.asarray(rcss.command_summary(decoded))
    kinds = {Dash: rcss.DASH, Kick: rcss.KICK, Turn: rcss.TURN, Tackle: rcss.TACKLE,
             NoOp: rcss.NOOP}
    for i, command in enumerate(actions_to_commands(actions)):
        assert int(decoded.kind[i]) == kinds[type(command)]
        if isinstance(command, Dash):
            assert float(decoded.dash_power[i]) == pytest.approx(command.power, abs=1e-3)
            assert float(decoded.dash_direction[i]) == pytest.approx(command.direction, abs=1e-3)
        if isinstance(command, Kick):
            assert float(decoded.kick_power[i]) == pytest.approx(command.power, abs=1e-3)
            assert float(decoded.kick_direction[i]) == pytest.approx(command.direction, abs=1e-3)
        if isinstance(command, Turn):
            assert float(decoded.turn_moment[i]) == pytest.approx(command.moment, abs=1e-3)
        np.testing.assert_allclose(summary[i], command_summary(command, ActionScaling()),
                                   atol=1e-5)


def test_rcss_soccer_moves_bodies_and_ball_by_the_servers_rules() -> None:
    from tests.env.helpers import build_state

    env = rcss.RcssSoccer(1)
    params = env.default_params()
    # Player 0 at (0, 0) facing +x with the ball 0.6 m ahead; player 1 far away, facing -x.
    state = build_state(params, positions=np.array([[0.0, 0.0], [30.0, 20.0]]),
                        headings=np.array([0.0, math.pi]), ball_position=(0.6, 0.0))
    kick = _action(rcss.KICK, a7=1.0, a8=-0.25)  # full power, 45 degrees to the left
    dash = _action(rcss.DASH, a5=1.0)
    actions = jnp.asarray(np.stack([[kick], [dash]]))
    after, *_ = env.step(jax.random.key(0), state, actions, params)
    rate = 1.0 - 0.25 * (0.6 - 0.385) / 0.7
    expected_ball = 2.7 * rate * np.array([math.cos(math.pi / 4), math.sin(math.pi / 4)])
    np.testing.assert_allclose(after.ball_position, [0.6, 0.0] + expected_ball, atol=1e-5)
    np.testing.assert_allclose(after.ball_velocity, expected_ball * 0.94, atol=1e-5)
    # Player 1 dashed along its heading (-x) at 0.6 a cycle, then its velocity decayed.
    np.testing.assert_allclose(after.positions[1], [29.4, 20.0], atol=1e-5)
    np.testing.assert_allclose(after.velocities[1], [-0.24, 0.0], atol=1e-6)
    np.testing.assert_allclose(after.last_actions, [[0.0, 0.0], [1.0, 0.0]], atol=1e-6)
    assert float(jnp.abs(after.velocities[0]).sum()) == 0.0
    np.testing.assert_array_equal(after.headings, state.headings)
    # Out of reach, a kick does nothing; a turn turns (clockwise +), slower when moving.
    far_ball = build_state(params, positions=np.array([[0.0, 0.0], [30.0, 20.0]]),
                           headings=np.array([0.0, math.pi]), ball_position=(2.0, 0.0))
    turn_right = _action(rcss.TURN, a9=0.5)
    out, *_ = env.step(jax.random.key(0), far_ball,
                       jnp.asarray(np.stack([[kick], [turn_right]])), params)
    np.testing.assert_allclose(out.ball_position, [2.0, 0.0])
    assert float(out.headings[1]) == pytest.approx(math.pi - math.radians(90.0))  # at rest
    with pytest.raises(ValueError, match=r"expected \(2, 1, 12\)"):
        env.step(jax.random.key(0), state, jnp.zeros((2, 1, 2)), params)


def test_rcss_soccer_jit_vmap_and_eager_agree_and_a_seed_repeats() -> None:
    env = rcss.RcssSoccer(2)
    params = env.default_params(episode_length=40)
    keys = jax.random.split(jax.random.key(5), 3)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    actions = jax.random.uniform(jax.random.key(6), (3, 2, 2, 12), minval=-1.0, maxval=1.0)
    step = jax.jit(jax.vmap(env.transition, in_axes=(0, 0, 0, None)))
    batched, rewards, _, _ = step(keys, states, actions, params)
    for g in (0, 2):  # eager runs op by op (seconds a step): two games of the three
        state = jax.tree.map(lambda leaf, g=g: leaf[g], states)
        one, one_rewards, _, _ = env.transition(keys[g], state, actions[g], params)
        for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(batched), strict=True):
            np.testing.assert_allclose(a, b[g], rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(one_rewards, rewards[g], rtol=1e-5, atol=1e-6)
    again, *_ = step(keys, states, actions, params)
    for a, b in zip(jax.tree.leaves(again), jax.tree.leaves(batched), strict=True):
        np.testing.assert_array_equal(a, b)


def test_with_a_see_period_players_act_on_their_last_see_and_jit_agrees() -> None:
    from elevens.env.state import SELF_FEATURES

    env = rcss.RcssSoccer(2, see_period=3)
    params = env.default_params(episode_length=40)
    state, obs = env.reset(jax.random.key(1), params)
    fresh_observe = jax.jit(rcss.Soccer.observe, static_argnums=0)
    fresh = fresh_observe(env, state, params)
    np.testing.assert_allclose(obs.self_features, fresh.self_features, atol=1e-6)
    dash = jnp.zeros((2, 2, 12)).at[..., 0].set(1.0).at[..., 5].set(1.0)  # everyone dashes
    step = jax.jit(env.step)
    x = SELF_FEATURES.index("x")
    clock = SELF_FEATURES.index("time_left")
    seen_x = np.array(obs.self_features[..., x])
    for t in range(1, 7):
        before = obs
        state, obs, *_ = step(jax.random.key(t), state, dash, params)
        fresh = fresh_observe(env, state, params)
        assert int(state.step) == t
        for player in range(2):
            sees = (t + player) % 3 == 0
            if sees:
                seen_x[:, player] = fresh.self_features[:, player, x]
            np.testing.assert_array_equal(obs.self_features[:, player, x], seen_x[:, player])
            np.testing.assert_array_equal(
                obs.entity_mask[:, player],
                fresh.entity_mask[:, player] if sees else before.entity_mask[:, player],
            )
        # The clock is current between sees; the position moved on but the view did not.
        np.testing.assert_array_equal(
            obs.self_features[..., clock], fresh.self_features[..., clock]
        )
        assert not np.allclose(fresh.self_features[..., x], seen_x)
    eager_state, eager_obs, *_ = env.step(jax.random.key(9), state, dash, params)
    jit_state, jit_obs, *_ = step(jax.random.key(9), state, dash, params)
    eager, jitted = jax.tree.leaves((eager_state, eager_obs)), jax.tree.leaves((jit_state, jit_obs))
    for a, b in zip(eager, jitted, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="see_period=0 is invalid"):
        rcss.RcssSoccer(2, see_period=0)


def _server_stamina(cycles: int, power: float) -> list[tuple[float, float, float]]:
    """rcssserver's Player::dash and updateStamina, step by step, with the elevens pacing
    rule in front: (stamina, effort, power paid) after each cycle of full dashes."""
    p = rcss.DEFAULT
    stamina, effort, recovery, capacity = 8000.0, 1.0, 1.0, 130600.0
    out = []
    for cycle in range(cycles):
        spare = max(stamina - 3000.0, 0.0) + capacity / (3000 - cycle % 3000)
        need = min(min(power, spare), stamina + p.extra_stamina)
        paid_effort = effort
        stamina = max(0.0, stamina - need)
        if stamina <= 0.3 * 8000:
            recovery = max(recovery - 0.002, 0.5)
            effort = max(effort - 0.005, 0.6)
        if stamina >= 0.6 * 8000:
            effort = min(effort + 0.01, 1.0)
        gain = min(recovery * 45.0, 8000.0 - stamina, capacity)
        stamina, capacity = stamina + gain, capacity - gain
        out.append((stamina, paid_effort, need))
    return out


def test_with_stamina_full_dashes_tire_the_players_as_in_the_server() -> None:
    env = rcss.RcssSoccer(1, stamina=True)
    params = env.default_params(episode_length=200)
    state, _ = env.reset(jax.random.key(0), params)
    assert float(state.stamina.stamina[0]) == 8000.0
    dash = jnp.zeros((2, 1, 12)).at[0, :, 0].set(1.0).at[0, :, 5].set(1.0)  # team 0 dashes
    dash = dash.at[1, :, 4].set(1.0)  # team 1 does nothing
    step = jax.jit(env.transition)
    expected = _server_stamina(150, 100.0)
    speeds = []
    for t in range(150):
        state, *_ = step(jax.random.key(t), state, dash, params)
        np.testing.assert_allclose(state.stamina.stamina[0], expected[t][0], rtol=1e-5)
        speeds.append(float(jnp.linalg.norm(state.velocities[0])))
    # 55 a cycle net: the reserve (3000) is reached after about 90 cycles; then the rule
    # allows what recovery brings back (about 45), so the stamina stays above the 2400 where
    # effort would fall for good. (Velocities as the server reports them: after the decay.)
    assert expected[80][2] == 100.0 and expected[120][2] < 50.0
    assert min(stamina for stamina, _, _ in expected) > 2400.0
    assert float(state.stamina.effort[0]) == 1.0
    assert speeds[60] == pytest.approx(0.4, abs=0.03)
    # The paced dash is slower: from rest, 10 cycles at the paced power cover less ground.
    tired = dataclasses.replace(state, velocities=jnp.zeros_like(state.velocities),
                                positions=jnp.zeros_like(state.positions))
    rested = dataclasses.replace(tired, stamina=rcss.Stamina.full(2))
    for t in range(10):
        tired, *_ = step(jax.random.key(t), tired, dash, params)
        rested, *_ = step(jax.random.key(t), rested, dash, params)
    assert float(tired.positions[0, 0]) < 0.6 * float(rested.positions[0, 0])
    # The other team stood still: it kept its stamina. A new episode starts fresh.
    assert float(state.stamina.stamina[1]) == 8000.0
    fresh, _ = env.reset(jax.random.key(1), params)
    assert float(fresh.stamina.stamina[0]) == 8000.0
    without = rcss.RcssSoccer(1)
    plain, _ = without.reset(jax.random.key(0), params)
    assert plain.stamina is None


def test_with_the_goalie_routine_a_goalie_holds_a_shot_and_clears_it_up_the_wing() -> None:
    env = rcss.RcssSoccer(2, goalie=True)
    params = env.default_params(episode_length=50)
    state, _ = env.reset(jax.random.key(0), params)
    # Team 1's goalie (player 2) on its goal line at (50, 0) facing the field (-x); a shot
    # from team 0 arrives 1 m in front of it at 2 m a cycle, heading for the goal.
    positions = np.array(state.positions)
    positions[2] = (50.0, 0.0)
    headings = np.array(state.headings)
    headings[2] = math.pi
    shot = dataclasses.replace(
        state, positions=jnp.asarray(positions), headings=jnp.asarray(headings),
        ball_position=jnp.asarray([49.0, -0.5]), ball_velocity=jnp.asarray([2.0, 0.0]),
    )
    nothing = jnp.zeros((2, 2, 12)).at[..., 4].set(1.0)
    step = jax.jit(env.transition)
    caught, *_ = step(jax.random.key(1), shot, nothing, params)
    assert caught.score.tolist() == [0, 0]
    # Cleared at full kick speed (2.7 m a cycle, then decayed) towards team 1's attacking half
    # and the wing on the ball's side (y -0.5 in world is +0.5 in team 1's frame: y = -24).
    velocity = np.asarray(caught.ball_velocity)
    assert np.linalg.norm(velocity) == pytest.approx(2.7 * 0.94, rel=1e-3)
    assert velocity[0] < 0 and velocity[1] < 0
    def goals_after(game: rcss.RcssSoccer, start: Any, cycles: int = 6) -> list[int]:
        move = jax.jit(game.transition)
        for t in range(cycles):
            start, *_ = move(jax.random.key(t), start, nothing, params)
        return start.score.tolist()

    assert goals_after(env, caught) == [0, 0]
    # Without hands the same shot goes in; with hands, one 2 m wide of the goalie too.
    assert goals_after(rcss.RcssSoccer(2), shot) == [1, 0]
    wide = dataclasses.replace(shot, ball_position=jnp.asarray([49.0, -2.0]))
    assert goals_after(env, wide) == [1, 0]
    # Outside its penalty area the goalie cannot catch.
    away = positions.copy()
    away[2] = (30.0, 0.0)
    far = dataclasses.replace(shot, positions=jnp.asarray(away),
                              ball_position=jnp.asarray([29.0, -0.5]))
    loose, *_ = step(jax.random.key(1), far, nothing, params)
    assert np.asarray(loose.ball_velocity)[0] > 0  # rolls on towards the goal


def test_the_goalie_routine_keeps_the_goalie_between_the_ball_and_its_goal() -> None:
    env = rcss.RcssSoccer(1, goalie=True)
    params = env.default_params(episode_length=80)
    state, _ = env.reset(jax.random.key(0), params)
    # Team 0's goalie starts off its line, facing away; the ball waits at (-20, 15), outside
    # the penalty area. Whatever its policy asks (a full dash ahead), it turns to the ball and
    # takes its guard point: a quarter of the ball's distance (8 m at most) along the line from
    # its goal's centre to the ball.
    state = dataclasses.replace(
        state,
        positions=jnp.asarray([[-40.0, -10.0], [40.0, 0.0]]),
        headings=jnp.asarray([math.pi, 0.0]),
        ball_position=jnp.asarray([-20.0, 15.0]),
        ball_velocity=jnp.zeros(2),
    )
    run = jnp.zeros((2, 1, 12)).at[..., 0].set(1.0).at[..., 5].set(1.0)
    step = jax.jit(env.transition)
    for t in range(40):
        state, *_ = step(jax.random.key(t), state, run, params)
    goal = np.array([-52.5, 0.0])
    to_ball = np.array([-20.0, 15.0]) - goal
    guard = goal + to_ball / np.linalg.norm(to_ball) * 8.0
    np.testing.assert_allclose(state.positions[0], guard, atol=1.0)
    facing = np.array([math.cos(float(state.headings[0])), math.sin(float(state.headings[0]))])
    toward = (np.array([-20.0, 15.0]) - np.asarray(state.positions[0]))
    assert facing @ toward / np.linalg.norm(toward) > math.cos(math.radians(26.0))


def test_a_kick_into_the_goal_scores_and_respawns() -> None:
    from tests.env.helpers import build_state

    env = rcss.RcssSoccer(1)
    params = env.default_params(ball_shaping_weight=0.0, approach_shaping_weight=0.0)
    state = build_state(params, positions=np.array([[50.0, 0.0], [-30.0, 20.0]]),
                        headings=np.array([0.0, math.pi]), ball_position=(50.5, 0.0))
    shot = _action(rcss.KICK, a7=1.0)
    after, _, rewards, _, info = env.step(
        jax.random.key(1), state, jnp.asarray(np.stack([[shot], [_action(rcss.NOOP)]])), params
    )
    assert info.goals.tolist() == [1, 0] and after.score.tolist() == [1, 0]
    np.testing.assert_allclose(rewards, [[1.0], [-1.0]])
    assert abs(float(after.ball_position[0])) < 52.5 and float(after.positions[0, 0]) < 0.0


def _beside_the_server(
    script: list[np.ndarray], player: np.ndarray, heading: float, ball: np.ndarray
) -> Iterator[tuple[int, Any, Any, Any]]:
    """One player's 12-value actions played in rcssserver (noise off) and in RcssSoccer from
    the same start (the player at ``player`` facing ``heading``, the ball at rest at ``ball``,
    world frame); yields (cycle, the server's see_global, its view of the player, RcssSoccer's
    state) after each action."""
    from elevens.robocup.actions import actions_to_commands
    from elevens.robocup.env import RoboCupConfig, RoboCupEnv
    from tests.env.helpers import build_state

    env = rcss.RcssSoccer(1)
    params = env.default_params()
    state = build_state(params, positions=np.array([player, [-40.0, -30.0]]),
                        headings=np.array([heading, 0.0]), ball_position=tuple(ball))
    config = RoboCupConfig(players_per_team=1, server_options=NO_NOISE)
    with RoboCupEnv(config) as server_env:
        server_env.reset(seed=0)
        client: Any = server_env._client
        client.reset(np.array([[_world(*player)], [[40.0, 30.0]]]),
                     np.array([[-math.degrees(heading)], [180.0]]), tuple(_world(*ball)))
        placed = client.step([None, None]).world  # the reset's own cycle may show the old state
        assert _world(placed.ball.x, placed.ball.y) == pytest.approx(ball, abs=1e-3)
        for cycle, action in enumerate(script):
            (command,) = actions_to_commands(action[None])
            world = client.step([command, None]).world
            state, *_ = env.step(jax.random.key(cycle), state,
                                 jnp.asarray(np.stack([[action], [_action(rcss.NOOP)]])), params)
            me = next(p for p in world.players if p.team == config.team_names[0])
            yield cycle, world, me, state


@needs_rcssserver
def test_rcss_soccer_follows_the_server_for_a_sequence_of_commands() -> None:
    """Ten cycles of one player's dashes, turns and kicks, played in the server (noise off)
    and in RcssSoccer from the same start: the same path for the player and the ball."""
    script = [
        _action(rcss.DASH, a5=1.0), _action(rcss.DASH, a5=1.0, a6=0.5),
        _action(rcss.TURN, a9=-0.3), _action(rcss.DASH, a5=0.8),
        _action(rcss.KICK, a7=0.4, a8=0.1), _action(rcss.DASH, a5=-0.6),
        _action(rcss.NOOP), _action(rcss.KICK, a7=1.0, a8=-0.5),
        _action(rcss.TURN, a9=0.8), _action(rcss.DASH, a5=1.0, a6=-1.0),
    ]
    # The ball passes within reach but never touches the player (collisions have their own
    # test): the kicks are what is compared.
    for _, world, me, state in _beside_the_server(
        script, np.array([0.0, -10.0]), 0.3, np.array([2.2, -8.8])
    ):
        np.testing.assert_allclose(_world(me.x, me.y), state.positions[0], atol=2e-3)
        np.testing.assert_allclose(_world(world.ball.x, world.ball.y), state.ball_position,
                                   atol=2e-3)
        assert _body(me.body) == pytest.approx(float(state.headings[0]), abs=0.02)


def test_collisions_push_overlapping_bodies_apart_and_bounce_them() -> None:
    positions = jnp.array([[0.0, 0.0], [0.5, 0.0], [10.0, 0.0]])
    velocities = jnp.array([[0.5, 0.0], [-0.2, 0.0], [0.3, 0.0]])
    ball, ball_velocity = jnp.array([10.2, 0.0]), jnp.array([-1.0, 0.0])
    moved, bounced, ball_at, ball_bounced = rcss.collide(positions, velocities, ball,
                                                         ball_velocity)
    # Players 0 and 1 (0.5 m apart, 0.6 needed) move apart about their midpoint.
    np.testing.assert_allclose(moved[0], [0.25 - 0.3, 0.0], atol=1e-4)
    np.testing.assert_allclose(moved[1], [0.25 + 0.3, 0.0], atol=1e-4)
    # Player 2 and the ball (0.2 m apart, 0.385 needed) likewise.
    np.testing.assert_allclose(moved[2], [10.1 - 0.1925, 0.0], atol=1e-4)
    np.testing.assert_allclose(ball_at, [10.1 + 0.1925, 0.0], atol=1e-4)
    np.testing.assert_allclose(bounced, -0.1 * velocities, atol=1e-7)
    np.testing.assert_allclose(ball_bounced, [0.1, 0.0], atol=1e-7)
    # Nobody overlapping: nothing changes.
    apart = positions.at[1].set([5.0, 5.0]).at[2].set([20.0, 0.0])
    out = rcss.collide(apart, velocities, ball, ball_velocity)
    for got, before in zip(out, (apart, velocities, ball, ball_velocity), strict=True):
        np.testing.assert_array_equal(got, before)


@needs_rcssserver
def test_a_player_that_runs_into_the_ball_bounces_as_in_the_server() -> None:
    dash = _action(rcss.DASH, a5=1.0)
    for cycle, world, me, state in _beside_the_server(
        [dash] * 3, np.array([0.0, -10.0]), 0.0, np.array([0.8, -10.05])
    ):
        np.testing.assert_allclose(_world(me.x, me.y), state.positions[0], atol=2e-3)
        np.testing.assert_allclose(_world(me.vx, me.vy), state.velocities[0], atol=2e-3)
        np.testing.assert_allclose(_world(world.ball.x, world.ball.y), state.ball_position,
                                   atol=2e-3)
        if cycle == 0:
            # A free dash would have carried the player 0.6 m, onto the ball (0.8 m ahead):
            # it stopped touching it, and bounced back.
            gap = float(jnp.linalg.norm(state.ball_position - state.positions[0]))
            assert gap == pytest.approx(P.ball_size + P.player_size, abs=1e-3)
            assert float(state.velocities[0, 0]) < 0.0
