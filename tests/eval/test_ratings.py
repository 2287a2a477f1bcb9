"""Bradley-Terry ratings: hand-worked values, known orders, draws, separation, intervals."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pytest

from elevens.eval.ratings import (
    ELO_PER_NAT,
    GameCounts,
    counts_from_outcomes,
    fit_bradley_terry,
)


def _two_teams(wins: int, draws: int, losses: int) -> GameCounts:
    zero = np.zeros((2, 2), np.int64)
    w, d, l_ = zero.copy(), zero.copy(), zero.copy()
    w[0, 1], d[0, 1], l_[0, 1] = wins, draws, losses
    return GameCounts(names=("a", "b"), wins=w, draws=d, losses=l_)


def _simulate(true_nats: np.ndarray, games_per_pair: int, seed: int) -> GameCounts:
    """Every pair plays ``games_per_pair`` games drawn from the Bradley-Terry model itself."""
    rng = np.random.default_rng(seed)
    rows, columns, outcomes = [], [], []
    for i in range(true_nats.size):
        for j in range(i + 1, true_nats.size):
            p = 1.0 / (1.0 + math.exp(-(true_nats[i] - true_nats[j])))
            won = rng.random(games_per_pair) < p
            rows += [i] * games_per_pair
            columns += [j] * games_per_pair
            outcomes += list(won.astype(float))
    names = tuple(f"t{i}" for i in range(true_nats.size))
    return counts_from_outcomes(names, rows, columns, outcomes)


def test_two_teams_by_hand() -> None:
    # 75 wins in 100 games: the maximum-likelihood gap is log(75 / 25) = log 3 nats, and its
    # Fisher standard error 1 / sqrt(N p (1 - p)) = 1 / sqrt(100 * 0.75 * 0.25); each centred
    # rating is half the gap away from the mean. A huge prior std makes MAP = ML.
    ratings = fit_bradley_terry(_two_teams(75, 0, 25), prior_std=1e4, bootstrap_samples=0)
    gap = math.log(3.0) * ELO_PER_NAT
    assert ratings.rating[0] - ratings.rating[1] == pytest.approx(gap, rel=1e-6)
    assert ratings.rating.sum() == pytest.approx(0.0, abs=1e-9)
    stderr_gap = ELO_PER_NAT / math.sqrt(100 * 0.75 * 0.25)
    np.testing.assert_allclose(ratings.stderr, [stderr_gap / 2] * 2, rtol=1e-6)
    assert ratings.win_probability(0, 1) == pytest.approx(0.75, rel=1e-6)
    assert list(ratings.games) == [100, 100]
    np.testing.assert_allclose(ratings.score, [0.75, 0.25])
    assert np.all(np.isnan(ratings.ci_low))  # no bootstrap asked for


def test_a_draw_counts_as_half_a_win() -> None:
    all_draws = fit_bradley_terry(_two_teams(0, 40, 0), bootstrap_samples=0)
    assert all_draws.rating[0] == pytest.approx(all_draws.rating[1], abs=1e-9)
    # 30 wins and 20 draws in 50 games score 40 of 50, like 40 wins and 10 losses.
    with_draws = fit_bradley_terry(_two_teams(30, 20, 0), bootstrap_samples=0)
    without = fit_bradley_terry(_two_teams(40, 0, 10), bootstrap_samples=0)
    np.testing.assert_allclose(with_draws.rating, without.rating, rtol=1e-9)
    assert with_draws.rating[0] > with_draws.rating[1]


def test_recovers_a_known_order_and_scale() -> None:
    true_nats = np.array([0.0, 1.0, -1.5, 2.5, 0.4])
    counts = _simulate(true_nats, games_per_pair=1500, seed=0)
    ratings = fit_bradley_terry(counts, bootstrap_samples=200, seed=1)
    assert ratings.order() == list(np.argsort(-true_nats))
    centred = (true_nats - true_nats.mean()) * ELO_PER_NAT
    # Within four standard errors (and the errors are small: ~10 Elo at 1500 games a pair).
    assert np.all(np.abs(ratings.rating - centred) < 4 * ratings.stderr)
    assert np.all(ratings.stderr < 15)
    assert np.all(ratings.ci_low < ratings.rating) and np.all(ratings.rating < ratings.ci_high)


def test_intervals_shrink_with_more_games() -> None:
    true_nats = np.array([0.0, 0.8, -0.6, 1.5])
    few = fit_bradley_terry(_simulate(true_nats, 100, seed=2), bootstrap_samples=300, seed=3)
    many = fit_bradley_terry(_simulate(true_nats, 1600, seed=4), bootstrap_samples=300, seed=5)
    width_few = few.ci_high - few.ci_low
    width_many = many.ci_high - many.ci_low
    # 16 times the games: intervals about 4 times narrower.
    assert np.all(width_many < 0.4 * width_few)
    assert np.all(many.stderr < 0.4 * few.stderr)
    # The bootstrap and the Fisher information agree on the size (95% ~ +-1.96 s.e.).
    np.testing.assert_allclose(width_many, 2 * 1.96 * many.stderr, rtol=0.3)


def test_perfect_separation_stays_finite_and_last() -> None:
    # A team that loses every game has no finite ML rating; the prior keeps it finite.
    names = ("random", "naive", "teamwork")
    wins = np.array([[0, 0, 0], [0, 0, 150], [0, 0, 0]])
    draws = np.array([[0, 0, 0], [0, 0, 100], [0, 0, 0]])
    losses = np.array([[0, 500, 500], [0, 0, 250], [0, 0, 0]])
    ratings = fit_bradley_terry(
        GameCounts(names, wins, draws, losses), bootstrap_samples=100, anchor="naive"
    )
    assert np.all(np.isfinite(ratings.rating)) and np.all(np.isfinite(ratings.ci_low))
    assert [ratings.names[i] for i in ratings.order()] == ["teamwork", "naive", "random"]
    assert ratings.rating[1] == 0.0  # the anchor
    assert ratings.rating[0] < -500


def test_an_undefeated_team_gets_an_interval_its_standard_error_implies() -> None:
    # 64 wins of 64: a plain bootstrap resamples 64 wins every time (an interval a few Elo
    # wide against an s.e. of hundreds); Jeffreys' half games and the Wald floor prevent it.
    ratings = fit_bradley_terry(
        GameCounts(("naive", "random"), np.array([[0, 64], [0, 0]]), np.zeros((2, 2), int),
                   np.zeros((2, 2), int)),
        bootstrap_samples=200,
    )
    width = ratings.ci_high - ratings.ci_low
    z = statistics.NormalDist().inv_cdf(0.975)
    assert np.all(width >= 2 * z * ratings.stderr - 1e-9)
    assert np.all(ratings.ci_low <= ratings.rating) and np.all(ratings.rating <= ratings.ci_high)
    assert ratings.stderr[0] > 100  # the s.e. is wide, so the interval is too


def test_anchor_shifts_without_changing_gaps() -> None:
    counts = _simulate(np.array([0.0, 1.0, 2.0]), 200, seed=6)
    centred = fit_bradley_terry(counts, bootstrap_samples=0)
    anchored = fit_bradley_terry(counts, bootstrap_samples=0, anchor="t0")
    assert anchored.rating[0] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(np.diff(anchored.rating), np.diff(centred.rating), atol=1e-9)
    with pytest.raises(ValueError, match="anchor='nobody'"):
        fit_bradley_terry(counts, anchor="nobody")


def test_games_filed_in_either_direction_add_up() -> None:
    # (i, j) and (j, i) hold different games of the same pair: a won 60 and b won 20, filed
    # all under (a, b) from a's view, or b's wins under (b, a) from b's view: the same data.
    forward = counts_from_outcomes(("a", "b"), [0] * 80, [1] * 80, [1.0] * 60 + [0.0] * 20)
    split = counts_from_outcomes(
        ("a", "b"), [0] * 60 + [1] * 20, [1] * 60 + [0] * 20, [1.0] * 60 + [1.0] * 20
    )
    a = fit_bradley_terry(forward, bootstrap_samples=0)
    b = fit_bradley_terry(split, bootstrap_samples=0)
    np.testing.assert_allclose(a.rating, b.rating, rtol=1e-9)


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="outcomes must be"):
        counts_from_outcomes(("a", "b"), [0], [1], [0.7])
    with pytest.raises(ValueError, match="shape"):
        GameCounts(("a", "b"), np.zeros((3, 3)), np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="prior_std"):
        fit_bradley_terry(_two_teams(1, 0, 1), prior_std=0.0)
