"""Domain randomisation: draws in range, one per game, deterministic; drawn games step the same
eager, jitted and vmapped; the ball keeps its game's friction all episode; sight noise; the
handcrafted teams play on each game's field; the held-out settings are fixed and never drawn
in training."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.env.randomize import (
    HELD_OUT_SETTINGS,
    RANDOMIZED,
    Randomize,
    draw_games,
    game_axis,
    held_out_games,
    setting_rows,
    tile_games,
    training_games,
)
from elevens.play import PolicyActor, StepKeys, home_sides, unroll
from elevens.teams.scripted import Field, NaiveTeam
from tests.env.helpers import build_state, make_env

ON = Randomize(enabled=True)


def one_game(games, g):  # type: ignore[no-untyped-def]
    """Game ``g`` of per-game params, as plain scalars (an ordinary EnvParams)."""
    return jax.tree.map(lambda leaf: np.asarray(leaf)[g].item(), games)


def test_draws_lie_in_their_ranges_differ_between_games_and_repeat_for_a_key() -> None:
    _, base = make_env(2)
    games = draw_games(jax.random.key(0), base, ON, 64)
    assert game_axis(games) == 0 and game_axis(base) is None
    for name, (low, high) in ON.ranges().items():
        values = np.asarray(getattr(games, name))
        assert values.shape == (64,)
        assert np.all((values >= low) & (values <= high)), name
        assert np.unique(values).size == 64, name  # every game its own draw
        assert values.max() - values.min() > 0.5 * (high - low), name  # spread over the range
    # The rest is the base game's, in every game.
    np.testing.assert_array_equal(np.asarray(games.leg_reach), np.full(64, base.leg_reach))
    assert int(np.asarray(games.episode_length)[5]) == base.episode_length
    again = draw_games(jax.random.key(0), base, ON, 64)
    other = draw_games(jax.random.key(1), base, ON, 64)
    for name in RANDOMIZED:
        np.testing.assert_array_equal(getattr(games, name), getattr(again, name))
        assert not np.array_equal(getattr(games, name), getattr(other, name))
    # A range of one value fixes it.
    fixed = draw_games(jax.random.key(0), base, dataclasses.replace(ON, move_speed=(1.1, 1.1)), 4)
    np.testing.assert_allclose(fixed.move_speed, 1.1, rtol=1e-6)
    # Every drawn game is a valid game.
    one_game(games, 3).validate()


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("ball_friction", (0.95, 0.9), "low must not exceed high"),
        ("ball_friction", (-0.1, 0.9), "must be in [0, 1]"),
        ("kick_impulse", (-1.0, 4.0), "must be >= 0"),
        ("move_speed", (0.0, 1.0), "must be > 0"),
        ("fov_half_angle", (1.0, 3.5), "(0, pi]"),
        ("observation_noise", (-0.5, 0.0), "must be >= 0"),
        ("field_length", (90.0, float("inf")), "finite"),
        ("goal_width", (30.0, 65.0), "field_width"),
        ("turn_speed", (0.4,), "two numbers"),
    ],
)
def test_bad_ranges_are_refused_with_one_line_naming_them(field, value, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError) as error:
        dataclasses.replace(ON, **{field: value}).check()
    text = str(error.value)
    assert f"env.randomize.{field}=" in text and message in text and "\n" not in text


def test_drawn_games_step_the_same_eager_jitted_and_vmapped() -> None:
    env, base = make_env(1)
    games = draw_games(jax.random.key(3), base, ON, 2)
    reset_keys = jax.random.split(jax.random.key(4), 2)
    states, obs = jax.jit(jax.vmap(env.reset))(reset_keys, games)
    actions = jax.random.uniform(jax.random.key(5), (2, 2, 1, 2), minval=-1.0, maxval=1.0)
    step_keys = jax.random.split(jax.random.key(6), 2)
    batched = jax.jit(jax.vmap(env.step))(step_keys, states, actions, games)
    for g in range(2):
        params = one_game(games, g)
        state = jax.tree.map(lambda leaf, g=g: leaf[g], states)
        eager = env.step(step_keys[g], state, actions[g], params)  # op by op, no jit
        in_batch = jax.tree.map(lambda leaf, g=g: leaf[g], batched)
        for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(in_batch), strict=True):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-5)
    # The drawn fields matter: each game's observation normalises by its own field.
    x = obs.self_features[:, 0, 0, 1]
    half = np.asarray(games.half_length)
    np.testing.assert_allclose(np.asarray(x) * half, np.asarray(states.positions[:, 0, 0]),
                               rtol=1e-5, atol=1e-4)
    assert not np.allclose(np.asarray(x) * base.half_length, np.asarray(states.positions[:, 0, 0]))


@dataclasses.dataclass(frozen=True)
class StandStill:
    """Nobody moves: the ball rolls on alone."""

    name: str = "still"

    def init_carry(self, players_per_team: int) -> tuple[()]:
        return ()

    def act(self, params, carry, obs, key):  # type: ignore[no-untyped-def]
        return carry, jnp.zeros((obs.self_features.shape[0], 2))


def test_each_game_keeps_its_drawn_friction_for_the_whole_episode() -> None:
    env, base = make_env(1)
    games = draw_games(jax.random.key(7), base, ON, 4)
    state = build_state(base, ball_position=(0.0, 5.0), ball_velocity=(1.5, 0.0))
    states = jax.tree.map(lambda leaf: jnp.broadcast_to(leaf, (4, *leaf.shape)), state)
    steps = 12
    keys = jax.random.split(jax.random.key(8), (steps, 4))
    actor = PolicyActor(StandStill())
    _, speeds = jax.jit(
        lambda games: unroll(
            env, games, actor, actor, states, jnp.asarray(home_sides(4)),
            StepKeys(home=keys[:, 0], away=keys[:, 0], env=keys), lambda view: view.state,
        )
    )(games)
    speed = np.linalg.norm(np.asarray(speeds.ball_velocity), axis=-1)  # [T, G]
    ratios = speed[2:] / speed[1:-1]  # step 0 holds the initial velocity before friction
    friction = np.asarray(games.ball_friction)
    np.testing.assert_allclose(ratios, np.broadcast_to(friction, ratios.shape), rtol=1e-5)
    assert np.unique(np.round(friction, 4)).size == 4


def test_sight_noise_moves_what_players_see_and_nothing_else() -> None:
    env, base = make_env(2)
    state, exact = env.reset(jax.random.key(0), base)
    quiet = env.observe_noisy(state, base, jax.random.key(1))
    np.testing.assert_allclose(quiet.entities, exact.entities, atol=1e-6)  # noise 0: exact
    noisy_params = dataclasses.replace(base, observation_noise=1.0)
    seen = env.observe_noisy(state, noisy_params, jax.random.key(1))
    again = env.observe_noisy(state, noisy_params, jax.random.key(1))
    np.testing.assert_array_equal(seen.entities, again.entities)  # the key decides
    both = np.asarray(seen.entity_mask & exact.entity_mask)
    distance_error = np.abs(np.asarray(seen.entities - exact.entities)[..., 0])[both]
    field = base.field_length
    assert 0.1 / field < np.mean(distance_error) < 2.0 / field  # about a metre, not more
    # Own position, heading and clock are exact.
    np.testing.assert_array_equal(seen.self_features[..., :9], exact.self_features[..., :9])


def test_handcrafted_teams_play_each_drawn_game_on_its_own_field() -> None:
    env, base = make_env(2)
    games = draw_games(jax.random.key(9), base, ON, 2)
    states, obs = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(2), 2), games)
    team = NaiveTeam()
    carry = PolicyActor(team).init_carry(2, 2)
    keys = jax.random.split(jax.random.key(3), 2)
    team_obs = obs.team(0)
    _, drawn_actions, _ = jax.jit(PolicyActor(team, None, games).act)(
        carry, team_obs, jnp.ones((2, 2), bool), keys
    )
    for g in range(2):
        fielded = dataclasses.replace(team, field=Field.of(one_game(games, g)))
        one = jax.tree.map(lambda leaf, g=g: leaf[g], team_obs)
        _, expected = jax.jit(fielded.act)(None, team.init_carry(2), one, keys[g])
        np.testing.assert_allclose(drawn_actions[g], expected, rtol=1e-5, atol=1e-5)
    # ...which is not what the team does on SPEC.md's field.
    _, default_actions, _ = jax.jit(PolicyActor(team).act)(carry, team_obs, jnp.ones((2, 2), bool),
                                                           keys)
    assert not np.allclose(drawn_actions, default_actions)


def test_held_out_settings_are_fixed_for_a_seed_and_never_drawn_in_training() -> None:
    _, base = make_env(11)
    settings = held_out_games(0, base)
    assert len(setting_rows(settings)) == HELD_OUT_SETTINGS
    np.testing.assert_array_equal(settings.field_length, held_out_games(0, base).field_length)
    assert not np.array_equal(settings.field_length, held_out_games(1, base).field_length)
    tiled = tile_games(settings, 45)
    np.testing.assert_array_equal(tiled.kick_impulse[20:40], settings.kick_impulse)
    held = np.stack([np.asarray(getattr(settings, name)) for name in RANDOMIZED], axis=-1)
    # Training's draws: each iteration's rollout key of runs of the same seeds.
    for seed in range(3):
        key = jax.random.split(jax.random.key(seed), 3)[2]  # the run key of learner.init_state
        for _ in range(5):
            key, rollout_key, _, _ = jax.random.split(key, 4)
            drawn = training_games(rollout_key, base, ON, 32)
            train = np.stack([np.asarray(getattr(drawn, name)) for name in RANDOMIZED], axis=-1)
            assert not np.any(np.all(np.isclose(held[:, None], train[None]), axis=-1))
        # Nor does the same integer drawn plainly give them.
        plain = draw_games(jax.random.key(seed), base, ON, HELD_OUT_SETTINGS)
        assert not np.allclose(plain.field_length, held_out_games(seed, base).field_length)
