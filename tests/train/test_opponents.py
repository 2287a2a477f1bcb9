"""Opponents by hand: Polyak step and freezing, league win rates, sampling, eviction, gathering."""

from __future__ import annotations

from collections import deque

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.train.opponents import (
    game_outcome,
    league_add,
    league_eviction_slot,
    league_init,
    league_maybe_add,
    league_params,
    league_probabilities,
    league_record,
    league_sample,
    league_win_rates,
    polyak_init,
    polyak_step,
    polyak_update,
    ring_record,
    self_play_opponent,
    single_opponent_step,
)

OPPONENT = {"a": jnp.array([1.0, 2.0]), "b": jnp.array(3.0)}
LEARNER = {"a": jnp.array([3.0, 0.0]), "b": jnp.array(5.0)}


def test_game_outcome() -> None:
    got = game_outcome(jnp.array([2, 1, 0]), jnp.array([1, 1, 3]))
    np.testing.assert_array_equal(got, [1.0, 0.5, 0.0])


def test_self_play_opponent_is_the_learner() -> None:
    opponent = self_play_opponent(LEARNER)
    np.testing.assert_array_equal(opponent["a"], LEARNER["a"])
    grad = jax.grad(lambda p: jnp.sum(self_play_opponent(p)["a"]))(LEARNER)
    np.testing.assert_array_equal(grad["a"], [0.0, 0.0])  # no gradient reaches the learner


# ------------------------------------------------------------------------------------------
# Polyak
# ------------------------------------------------------------------------------------------


def test_polyak_update_by_hand() -> None:
    # tau = .25: a = [.25*3 + .75*1, .25*0 + .75*2] = [1.5, 1.5]; b = .25*5 + .75*3 = 3.5
    got = polyak_update(OPPONENT, LEARNER, 0.25)
    np.testing.assert_allclose(got["a"], [1.5, 1.5])
    np.testing.assert_allclose(got["b"], 3.5)
    # default tau = alpha_s = .01: b = .01*5 + .99*3 = 3.02
    np.testing.assert_allclose(polyak_update(OPPONENT, LEARNER)["b"], 3.02, rtol=1e-6)


@pytest.mark.parametrize(
    ("score", "moves"), [(0.3, False), (0.55, False), (0.551, True), (0.9, True)]
)
def test_polyak_step_freezes_unless_the_learner_scores_above_0_55(score, moves) -> None:
    state = polyak_init(OPPONENT)
    stepped = jax.jit(polyak_step)(state, LEARNER, jnp.float32(score), 0.25)
    want_a = [1.5, 1.5] if moves else [1.0, 2.0]
    np.testing.assert_allclose(stepped.params["a"], want_a)
    np.testing.assert_allclose(stepped.params["b"], 3.5 if moves else 3.0)
    assert bool(stepped.frozen) is (not moves)
    assert int(stepped.num_updates) == int(moves) and int(stepped.num_steps) == 1


def test_polyak_step_score_from_outcomes() -> None:
    # 11 wins in 20 games is exactly .55: frozen. 11 wins, 1 draw, 8 losses is .575: moves.
    state = polyak_init(OPPONENT)
    exact = jnp.mean(game_outcome(jnp.array([1] * 11 + [0] * 9), jnp.array([0] * 11 + [1] * 9)))
    np.testing.assert_allclose(exact, 0.55)
    assert bool(polyak_step(state, LEARNER, exact).frozen)
    learner_goals = jnp.array([1] * 11 + [0] * 9)
    opponent_goals = jnp.array([0] * 11 + [0] + [1] * 8)
    above = jnp.mean(game_outcome(learner_goals, opponent_goals))
    np.testing.assert_allclose(above, 0.575)
    assert not bool(polyak_step(state, LEARNER, above).frozen)


# ------------------------------------------------------------------------------------------
# Ring buffers
# ------------------------------------------------------------------------------------------


def test_ring_record_matches_deques() -> None:
    rng = np.random.default_rng(0)
    num_rings, length = 3, 5
    buffers, write_index = jnp.zeros((num_rings, length)), jnp.zeros(num_rings, jnp.int32)
    reference: list[deque[float]] = [deque(maxlen=length) for _ in range(num_rings)]
    record = jax.jit(ring_record)
    for batch_size in (4, 1, 13, 7, 2):  # 13 exceeds the ring length for some rings
        rows = rng.integers(-1, num_rings + 1, size=batch_size)  # includes out-of-range rows
        values = rng.normal(size=batch_size).astype(np.float32)
        valid = rng.random(batch_size) < 0.8
        out = record(buffers, write_index, rows, values, valid)
        for row, value, ok in zip(rows, values, valid, strict=True):
            if ok and 0 <= row < num_rings:
                reference[row].append(value)
        buffers, write_index = out.buffers, out.write_index
        for ring in range(num_rings):
            # the last min(n, K) values written, read back in write order
            n = len(reference[ring])
            order = (np.asarray(write_index[ring]) - n + np.arange(n)) % length
            np.testing.assert_allclose(np.asarray(buffers[ring])[order], list(reference[ring]))


# ------------------------------------------------------------------------------------------
# League
# ------------------------------------------------------------------------------------------


def snapshot(value: float) -> dict[str, jax.Array]:
    return {"w": jnp.full((2,), value), "b": jnp.asarray(value)}


def four_slot_league():
    """Capacity 4, snapshots 0., 1., 2. in slots 0..2, slot 3 empty."""
    league = league_init(snapshot(0.0), capacity=4, iteration=0)
    league = league_add(league, snapshot(1.0), iteration=10)
    return league_add(league, snapshot(2.0), iteration=20)


def games(index: int, wins: int, draws: int, losses: int):
    """Indices and opponent-view outcomes for a block of games against one snapshot."""
    outcomes = np.array([1.0] * wins + [0.5] * draws + [0.0] * losses, np.float32)
    return np.full(outcomes.shape, index, np.int32), outcomes


def record(league, *blocks):
    indices = np.concatenate([b[0] for b in blocks])
    outcomes = np.concatenate([b[1] for b in blocks])
    return jax.jit(league_record)(league, indices, outcomes)


def hand_league():
    """w = [.5 (99 games: held), .8 (200 games), .2 (100 games with draws)], slot 3 empty."""
    league = four_slot_league()
    return record(
        league,
        games(0, 99, 0, 0),
        games(1, 160, 0, 40),  # 160 / 200 = .8
        games(2, 10, 20, 70),  # (10 + 20 * .5) / 100 = .2
    )


def test_league_init_and_add_fill_slots_in_order() -> None:
    league = four_slot_league()
    assert int(league.size) == 3 and league.capacity == 4 and league.window == 1000
    np.testing.assert_array_equal(league.params["b"], [0.0, 1.0, 2.0, 0.0])
    np.testing.assert_array_equal(league.serial, [0, 1, 2, -1])
    np.testing.assert_array_equal(league.iteration, [0, 10, 20, -1])


def test_win_rates_with_draws_and_the_100_game_rule() -> None:
    league = hand_league()
    np.testing.assert_allclose(league_win_rates(league), [0.5, 0.8, 0.2, 0.0], rtol=1e-6)
    np.testing.assert_array_equal(league.result_count, [99, 200, 100, 0])
    # the 100th game (a win) ends the hold: 100 wins of 100
    league = record(league, games(0, 1, 0, 0))
    np.testing.assert_allclose(league_win_rates(league)[0], 1.0)


def test_probabilities_proportional_to_win_rate_squared() -> None:
    # w^2 = [.25, .64, .04] -> sum .93 -> p = [.25/.93, .64/.93, .04/.93, 0]
    got = jax.jit(league_probabilities)(hand_league())
    np.testing.assert_allclose(got, [0.25 / 0.93, 0.64 / 0.93, 0.04 / 0.93, 0.0], rtol=1e-5)
    # psi = 0 samples the live snapshots uniformly
    np.testing.assert_allclose(league_probabilities(hand_league(), psi=0.0), [1 / 3] * 3 + [0.0])


def test_probabilities_fall_back_to_uniform_when_every_win_rate_is_zero() -> None:
    league = four_slot_league()
    league = record(league, games(0, 0, 0, 100), games(1, 0, 0, 100), games(2, 0, 0, 100))
    np.testing.assert_allclose(league_probabilities(league), [1 / 3, 1 / 3, 1 / 3, 0.0])


def test_results_ring_keeps_only_the_last_1000_games() -> None:
    league = four_slot_league()
    # 500 wins then 1000 losses in one batch: only the losses remain
    league = record(league, games(1, 500, 0, 1000))
    np.testing.assert_allclose(league_win_rates(league)[1], 0.0)
    assert int(league.result_count[1]) == 1500
    # one more win pushes out the oldest loss: 1 / 1000
    league = record(league, games(1, 1, 0, 0))
    np.testing.assert_allclose(league_win_rates(league)[1], 0.001, rtol=1e-5)
    # the same history fed game by game in small batches gives the same rates
    step_by_step = four_slot_league()
    outcomes = np.array([1.0] * 500 + [0.0] * 1000 + [1.0], np.float32)
    for chunk in np.array_split(outcomes, 7):
        step_by_step = record(step_by_step, (np.ones(chunk.shape, np.int32), chunk))
    np.testing.assert_allclose(league_win_rates(step_by_step), league_win_rates(league))


def test_league_record_mask_ignores_non_league_games() -> None:
    league = four_slot_league()
    indices, outcomes = games(1, 100, 0, 0)
    mask = np.arange(100) < 40
    league = league_record(league, indices, outcomes, mask)
    np.testing.assert_array_equal(league.result_count, [0, 40, 0, 0])


def test_sampling_frequencies_match_probabilities() -> None:
    league = hand_league()
    num = 20_000
    samples = np.asarray(jax.jit(league_sample, static_argnums=2)(league, jax.random.key(7), num))
    counts = np.bincount(samples, minlength=4)
    assert counts[3] == 0  # the empty slot is never drawn
    expected = np.asarray(league_probabilities(league))[:3] * num
    chi_square = float(np.sum((counts[:3] - expected) ** 2 / expected))
    assert chi_square < 13.8  # 2 degrees of freedom, p = 0.001


def test_eviction_replaces_the_weakest_evaluated_snapshot() -> None:
    league = league_add(hand_league(), snapshot(3.0), iteration=30)  # fills slot 3
    assert int(league.size) == 4
    # slot 0 has 99 games (held at .5, not a candidate), slot 3 none: of the evaluated, slot 2
    # (w = .2) is the weakest
    assert int(league_eviction_slot(league)) == 2
    league = league_add(league, snapshot(4.0), iteration=40)
    assert int(league.size) == 4
    np.testing.assert_array_equal(league.params["b"], [0.0, 1.0, 4.0, 3.0])
    np.testing.assert_array_equal(league.serial, [0, 1, 4, 3])
    np.testing.assert_array_equal(league.iteration, [0, 10, 40, 30])
    assert int(league.result_count[2]) == 0 and float(jnp.sum(league.results[2])) == 0.0
    np.testing.assert_allclose(league_win_rates(league), [0.5, 0.8, 0.5, 0.5])
    # now only slot 1 is evaluated, so it goes next even though it is strong
    assert int(league_eviction_slot(league)) == 1


def test_eviction_picks_the_oldest_when_none_is_evaluated_or_on_ties() -> None:
    league = league_init(snapshot(0.0), capacity=2)
    league = league_add(league, snapshot(1.0))
    league = league_add(league, snapshot(2.0))  # nobody has 100 games: the oldest (slot 0) goes
    np.testing.assert_array_equal(league.params["b"], [2.0, 1.0])
    np.testing.assert_array_equal(league.serial, [2, 1])
    # equal win rates: slot 1 (serial 1) is older than slot 0 (serial 2)
    league = record(league, games(0, 50, 0, 50), games(1, 50, 0, 50))
    assert int(league_eviction_slot(league)) == 1


def test_league_params_gathers_snapshots() -> None:
    league = four_slot_league()
    one = jax.jit(league_params)(league, 2)
    np.testing.assert_array_equal(one["w"], [2.0, 2.0])
    assert one["b"].shape == ()
    many = league_params(league, jnp.array([1, 0, 2, 1]))
    np.testing.assert_array_equal(many["b"], [1.0, 0.0, 2.0, 1.0])
    assert many["w"].shape == (4, 2)


def test_league_maybe_add_every_10_iterations() -> None:
    maybe_add = jax.jit(league_maybe_add, static_argnames="every")
    league = league_init(snapshot(0.0), capacity=4)
    for iteration in range(0, 31):
        league = maybe_add(league, snapshot(float(iteration)), iteration)
    np.testing.assert_array_equal(league.iteration, [0, 10, 20, 30])
    np.testing.assert_array_equal(league.params["b"], [0.0, 10.0, 20.0, 30.0])
    assert int(league.num_added) == 4


def test_league_functions_compile_together() -> None:
    @jax.jit
    def iteration_step(league, learner, key, iteration):
        indices = league_sample(league, key, 64)
        opponents = league_params(league, indices)
        outcomes = jnp.where(opponents["b"] > 0.5, 1.0, 0.0)  # a stand-in for playing games
        league = league_record(league, indices, outcomes)
        return league_maybe_add(league, learner, iteration), league_probabilities(league)

    league = four_slot_league()
    for i in range(1, 4):
        league, probs = iteration_step(league, snapshot(9.0), jax.random.key(i), i * 10)
    assert int(league.size) == 4 and np.isclose(float(jnp.sum(probs)), 1.0)
    assert iteration_step._cache_size() == 1  # type: ignore[attr-defined]  # compiled once


def test_single_opponent_step_by_kind() -> None:
    start = polyak_init({"w": jnp.zeros(3)})
    learner = {"w": jnp.ones(3)}
    moved = single_opponent_step(start, "polyak", learner, 0.9, tau=0.5)
    np.testing.assert_allclose(moved.params["w"], 0.5)
    held = single_opponent_step(start, "polyak", learner, 0.5, tau=0.5)
    np.testing.assert_allclose(held.params["w"], 0.0)
    assert bool(held.frozen) and int(held.num_steps) == 1 and int(held.num_updates) == 0
    latest = single_opponent_step(start, "self", learner, 0.0)
    np.testing.assert_allclose(latest.params["w"], 1.0)
    assert int(latest.num_updates) == 1 and int(latest.num_steps) == 1
    with pytest.raises(ValueError, match="kind='league'"):
        single_opponent_step(start, "league", learner, 0.5)
