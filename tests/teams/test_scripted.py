"""The handcrafted teams: interface, frames, and their behaviour in hand-built situations."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env import Observation, State
from elevens.env.state import SELF_FEATURES
from elevens.teams import NaiveTeam, RandomTeam, TeamPolicy, TeamworkTeam

Team = RandomTeam | NaiveTeam | TeamworkTeam
TEAMS: list[Team] = [RandomTeam(), NaiveTeam(), TeamworkTeam()]
SIZES = [1, 2, 5, 11]


@functools.cache
def reset_fn(n: int) -> tuple[elevens.Soccer, elevens.EnvParams, Any]:
    """Jitted reset of an n v n game (eager JAX dispatches every small op: seconds per call)."""
    env, params = elevens.make(f"{n}v{n}")
    return env, params, jax.jit(env.reset)


@functools.cache
def jitted_act(team: Any) -> Any:
    return jax.jit(team.act)


def hand_state(
    n: int,
    positions: dict[int, tuple[float, float]],
    headings: dict[int, float],
    ball: tuple[float, float],
) -> tuple[elevens.Soccer, elevens.EnvParams, State]:
    """An n v n state, world frame. Players not named stand at the far ends of the field (team 0
    on its own goal line at y = 30, team 1 on its goal line at y = -30), facing the side lines."""
    env, params, reset = reset_fn(n)
    state, _ = reset(jax.random.key(0), params)
    pos = np.zeros((2 * n, 2), np.float32)
    pos[:n] = (-49.0, 30.0)
    pos[n:] = (49.0, -30.0)
    head = np.full(2 * n, math.pi / 2, np.float32)
    head[n:] = -math.pi / 2
    for k, p in positions.items():
        pos[k] = p
    for k, h in headings.items():
        head[k] = h
    state = dataclasses.replace(
        state,
        positions=jnp.asarray(pos),
        headings=jnp.asarray(head),
        start_positions=jnp.asarray(pos),
        ball_position=jnp.asarray(ball, jnp.float32),
        ball_velocity=jnp.zeros(2),
    )
    return env, params, state


def reflect(state: State, n: int) -> State:
    """The same situation with the teams' roles exchanged: point-reflect and swap the teams."""

    def swap(x: jax.Array) -> jax.Array:
        return jnp.concatenate([x[n:], x[:n]], axis=0)

    headings = jnp.mod(swap(state.headings) + 2 * jnp.pi, 2 * jnp.pi) - jnp.pi
    return dataclasses.replace(
        state,
        positions=-swap(state.positions),
        headings=headings,
        velocities=-swap(state.velocities),
        last_actions=swap(state.last_actions),
        start_positions=-swap(state.start_positions),
        ball_position=-state.ball_position,
        ball_velocity=-state.ball_velocity,
    )


def team_actions(
    team: Team, env: elevens.Soccer, params: elevens.EnvParams, state: State, side: int = 0
) -> np.ndarray:
    obs = jax.jit(env.observe)(state, params)
    _, actions = jitted_act(team)(
        None, team.init_carry(env.players_per_team), obs.team(side), jax.random.key(1)
    )
    return np.asarray(actions)


class Playing(NamedTuple):
    state: State
    team_carry: Any


def simulate(
    env: elevens.Soccer,
    params: elevens.EnvParams,
    state: State,
    team: Team,
    steps: int,
    side: int = 0,
    active: np.ndarray | None = None,
) -> State:
    """Play ``steps`` steps: ``team`` on ``side`` (only the ``active`` players move), the other
    side stands still."""
    n = env.players_per_team
    mask = jnp.ones(n) if active is None else jnp.asarray(active, jnp.float32)

    def body(playing: Playing, key: jax.Array) -> tuple[Playing, None]:
        obs = env.observe(playing.state, params)
        team_carry, actions = team.act(None, playing.team_carry, obs.team(side), key)
        both = jnp.zeros((2, n, 2)).at[side].set(actions * mask[:, None])
        state, _, _, _ = env.transition(key, playing.state, both, params)
        return Playing(state, team_carry), None

    def run(state: State) -> State:
        keys = jax.random.split(jax.random.key(2), steps)
        final, _ = jax.lax.scan(body, Playing(state, team.init_carry(n)), keys)
        return final.state

    return jax.jit(run)(state)


# ----------------------------------------------------------------------------- interface


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("team", TEAMS, ids=lambda t: t.name)
def test_actions_have_shape_n_by_2_and_lie_in_range(team: Team, n: int) -> None:
    _, params, reset = reset_fn(n)
    _, obs = reset(jax.random.key(n), params)
    act = jitted_act(team)
    for side in (0, 1):
        carry, actions = act(None, team.init_carry(n), obs.team(side), jax.random.key(3))
        assert actions.shape == (n, 2)
        assert bool(jnp.all(jnp.isfinite(actions)))
        assert bool(jnp.all(jnp.abs(actions) <= 1.0))
    # Garbage observations (no real game looks like this) still give valid actions.
    noise_key, mask_key = jax.random.split(jax.random.key(4))
    garbage = Observation(
        self_features=3 * jax.random.normal(noise_key, obs.self_features[0].shape),
        entities=jnp.zeros(obs.entities[0].shape),
        entity_mask=jax.random.bernoulli(mask_key, 0.5, obs.entity_mask[0].shape),
    )
    _, actions = act(None, team.init_carry(n), garbage, jax.random.key(5))
    assert actions.shape == (n, 2)
    assert bool(jnp.all(jnp.isfinite(actions) & (jnp.abs(actions) <= 1.0)))


@pytest.mark.parametrize("team", TEAMS, ids=lambda t: t.name)
def test_teams_are_hashable_team_policies(team: Team) -> None:
    # play_match compiles per policy: policies are static arguments, so they must hash.
    assert isinstance(team, TeamPolicy)
    assert hash(team) == hash(dataclasses.replace(team))


@pytest.mark.parametrize("team", TEAMS, ids=lambda t: t.name)
def test_jit_equals_eager(team: Team) -> None:
    _, params, reset = reset_fn(5)
    _, obs = reset(jax.random.key(6), params)
    key = jax.random.key(7)
    carry: Any = team.init_carry(5)
    _, eager = team.act(None, carry, obs.team(1), key)
    _, jitted = jax.jit(team.act)(None, carry, obs.team(1), key)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), atol=1e-5)


@pytest.mark.parametrize("team", TEAMS, ids=lambda t: t.name)
def test_a_team_reads_only_its_own_observations(team: Team) -> None:
    _, params, reset = reset_fn(5)
    _, obs = reset(jax.random.key(8), params)
    key = jax.random.key(9)
    act = jitted_act(team)
    _, before = act(None, team.init_carry(5), obs.team(0), key)
    changed = Observation(
        self_features=obs.self_features.at[1].set(7.0),
        entities=obs.entities.at[1].set(-3.0),
        entity_mask=obs.entity_mask.at[1].set(~obs.entity_mask[1]),
    )
    _, after = act(None, team.init_carry(5), changed.team(0), key)
    np.testing.assert_array_equal(np.asarray(after), np.asarray(before))
    _, other_side = act(None, team.init_carry(5), changed.team(1), key)
    if not isinstance(team, RandomTeam):  # the deterministic teams do read what they get
        assert not np.array_equal(np.asarray(other_side), np.asarray(before))


def test_random_team_is_uniform_and_keyed() -> None:
    _, params, reset = reset_fn(11)
    obs = reset(jax.random.key(0), params)[1]
    team = RandomTeam()
    keys = jax.random.split(jax.random.key(11), 40)
    draws = jax.vmap(lambda key: team.act(None, (), obs.team(0), key)[1])(keys)
    assert abs(float(draws.mean())) < 0.1
    assert float(draws.min()) < -0.9 and float(draws.max()) > 0.9
    assert not np.array_equal(np.asarray(draws[0]), np.asarray(draws[1]))


# ------------------------------------------------------------------------------- frames


@pytest.mark.parametrize("team", [NaiveTeam(), TeamworkTeam()], ids=lambda t: t.name)
def test_teams_play_the_same_on_either_side(team: Team) -> None:
    env, params, reset = reset_fn(5)
    state, _ = reset(jax.random.key(10), params)
    as_side_0 = team_actions(team, env, params, state, side=0)
    as_side_1 = team_actions(team, env, params, reflect(state, 5), side=1)
    np.testing.assert_allclose(as_side_1, as_side_0, atol=1e-4)


# ------------------------------------------------------------------------- naive behaviour


def test_naive_player_facing_the_ball_runs_forward() -> None:
    env, params, state = hand_state(1, {0: (-20.0, 0.0), 1: (40.0, 30.0)}, {0: 0.0}, (-10.0, 0))
    move, rot = team_actions(NaiveTeam(), env, params, state)[0]
    assert move == pytest.approx(1.0)
    assert abs(rot) < 1.0  # only a correction to pass the ball beside the legs


@pytest.mark.parametrize("ball_y, turn_sign", [(7.0, -1.0), (-7.0, 1.0)])
def test_naive_player_turns_towards_a_ball_to_its_side(ball_y: float, turn_sign: float) -> None:
    # rot > 0 turns clockwise: a ball on the left (+y when facing +x) needs rot < 0.
    env, params, state = hand_state(1, {0: (-20.0, 0.0), 1: (40.0, 30.0)}, {0: 0.0},
                                    (-13.0, ball_y))
    _, rot = team_actions(NaiveTeam(), env, params, state)[0]
    assert np.sign(rot) == turn_sign
    assert abs(rot) > 0.5


def test_naive_player_that_sees_no_ball_turns_on_the_spot() -> None:
    env, params, state = hand_state(1, {0: (0.0, 0.0), 1: (40.0, 30.0)}, {0: 0.0}, (-10.0, 0.0))
    visible = env.observe(state, params).self_features[0, 0, SELF_FEATURES.index("ball_visible")]
    assert not bool(visible)
    move, rot = team_actions(NaiveTeam(), env, params, state)[0]
    assert move == 0.0
    assert rot == NaiveTeam().search_turn != 0.0


def test_naive_player_uses_a_teammates_sighting() -> None:
    # Player 1 sees the ball behind player 0, on player 0's left: player 0 turns left (rot < 0),
    # against its default search turn (clockwise), the short way to the ball.
    env, params, state = hand_state(
        2, {0: (0.0, 0.0), 1: (-20.0, 10.0)}, {0: 0.0, 1: 0.0}, (-8.0, 6.0)
    )
    move, rot = team_actions(NaiveTeam(), env, params, state)[0]
    assert rot < 0.0
    _, lone_rot = team_actions(NaiveTeam(share_sightings=False), env, params, state)[0]
    assert lone_rot == NaiveTeam().search_turn


@pytest.mark.parametrize("side", [0, 1])
def test_naive_player_scores_from_midfield(side: int) -> None:
    # The ball lies off-centre in the attacking half; the player starts beside it, facing away.
    env, params, state = hand_state(1, {0: (5.0, -10.0), 1: (40.0, 30.0)}, {0: 2.5}, (12.0, 8.0))
    if side == 1:
        state = reflect(state, 1)
    final = simulate(env, params, state, NaiveTeam(), steps=80, side=side)
    assert int(final.score[side]) == 1
    assert int(final.score[1 - side]) == 0


# ---------------------------------------------------------------------- teamwork behaviour


def arc_spots(team: TeamworkTeam, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(is_defender, spot f[n, 2], facing angle f[n]) in the team's frame."""
    is_defender, angle = team.roles(n)
    spot = np.stack([-50.0 + team.arc_radius * np.cos(angle), team.arc_radius * np.sin(angle)], -1)
    return is_defender, spot, angle


@pytest.mark.parametrize("n", [1, 2, 5, 11])
def test_teamwork_roles_follow_the_formation(n: int) -> None:
    is_defender, _, angle = arc_spots(TeamworkTeam(), n)
    expected = {1: 0, 2: 1, 5: 3, 11: 5}[n]
    assert int(is_defender.sum()) == expected
    if expected > 1:  # distinct spots spread over the arc
        assert len(set(np.round(angle[is_defender], 4))) == expected
        assert np.max(np.abs(angle)) == pytest.approx(TeamworkTeam().arc_half_angle)


def test_teamwork_defender_on_its_spot_stays_when_the_ball_is_far() -> None:
    team = TeamworkTeam()
    _, spot, angle = arc_spots(team, 5)
    env, params, state = hand_state(
        5, {0: tuple(spot[0]), 5: (40.0, 30.0)}, {0: float(angle[0])}, (30.0, 0.0)
    )
    move, rot = team_actions(team, env, params, state)[0]
    assert abs(move) < 0.05 and abs(rot) < 0.05


@pytest.mark.parametrize("side", [0, 1])
def test_teamwork_defender_returns_to_its_arc_spot(side: int) -> None:
    team = TeamworkTeam()
    is_defender, spot, angle = arc_spots(team, 11)
    k = 1  # the back-line player on the right, spot at the end of the arc beside the post
    # Player 10 (standing still) sees the far ball, so the team knows where it is.
    env, params, state = hand_state(
        11, {k: (-38.0, 2.0), 10: (0.0, 0.0)}, {k: 2.0, 10: 0.0}, (30.0, 25.0)
    )
    if side == 1:
        state = reflect(state, 11)
    active = np.zeros(11, bool)
    active[k] = True
    final = simulate(env, params, state, team, steps=40, side=side, active=active)
    sign = 1.0 if side == 0 else -1.0
    row = side * 11 + k
    position = sign * np.asarray(final.positions[row])
    heading = float(final.headings[row]) + (0.0 if side == 0 else math.pi)
    assert np.linalg.norm(position - spot[k]) < 1.5
    assert abs(math.remainder(heading - angle[k], 2 * math.pi)) < 0.3


def test_teamwork_defender_clears_a_ball_near_its_spot_towards_the_side_line() -> None:
    team = TeamworkTeam()
    is_defender, spot, angle = arc_spots(team, 5)
    k = int(np.argmax(np.where(is_defender, angle, -np.inf)))  # the spot at (-50, +14)
    start = (-44.0, 12.0)
    positions = {j: tuple(spot[j]) for j in range(5) if is_defender[j]}
    env, params, state = hand_state(5, positions, {j: float(angle[j]) for j in positions}, start)
    # Only the defenders play: the attackers would chase the ball too.
    final = simulate(env, params, state, team, steps=40, active=is_defender)
    ball = np.asarray(final.ball_position)
    assert int(final.score[1]) == 0
    assert ball[1] > 25.0  # sent to the near (left, +y) side line
    assert ball[0] > start[0]  # and away from the goal line
    assert np.linalg.norm(np.asarray(final.positions[k]) - spot[k]) < 25.0
