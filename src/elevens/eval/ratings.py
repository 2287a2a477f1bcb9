"""Bradley-Terry ratings with confidence intervals, so many teams sit on one scale.

The model: team ``i`` beats team ``j`` with probability ``sigmoid(r_i - r_j)`` (ratings in nats).
A draw counts as half a win and half a loss: a game scores ``s = 1, 0.5, 0`` for the row team,
and the log-likelihood of a pair's games is ``S log p + (N - S) log(1 - p)`` with ``S`` the summed
score and ``N`` the games (the "draws as half wins" convention of Elo; it keeps the model at one
parameter per team).

A team that wins or loses every game (random against anything) has no finite maximum-likelihood
rating, so the fit is a MAP estimate with a Gaussian prior ``N(0, prior_std^2)`` on every rating:
with hundreds of games a pair the prior moves nothing that the data pins down, and it keeps the
ratings of perfectly separated teams finite (their distance then grows only with the log of the
number of games). Ratings are reported in Elo points (``ELO_PER_NAT = 400 / ln 10``: a 400 point
gap is 10:1 odds), shifted so that their mean is 0, or so that an ``anchor`` team sits at 0.

Uncertainty, two ways:

* ``stderr``: from the Fisher information (the inverse of the penalised log-likelihood's negative
  Hessian at the fit), propagated to the reported (centred or anchored) ratings.
* ``ci_low`` / ``ci_high``: a bootstrap over games. Each pair's games are resampled
  (multinomially over its wins, draws and losses, so the schedule is kept), the ratings are
  refitted, and the percentile interval of each reported rating is taken. The resampling
  probabilities carry Jeffreys' half a game of each result (``(wins + 1/2) / (games + 3/2)``
  and so on): a plain bootstrap of a perfect record (64 wins of 64) resamples 64 wins every
  time and gives an interval a few Elo wide. The interval is then widened, where needed, to
  hold ``rating +- z * stderr`` (z of the normal for ``confidence``), so it is never narrower
  than the Fisher standard error implies.

Both shrink like ``1 / sqrt(games)``.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Sequence

import numpy as np

ELO_PER_NAT = 400.0 / math.log(10.0)
"""Elo points per nat of rating difference (400 points = 10:1 odds)."""
PRIOR_STD = 5.0
"""Prior std of a rating in nats (about 870 Elo): weak for any pair with mixed results, yet
it keeps perfectly separated teams finite."""
JEFFREYS = 0.5
"""Pseudo-games of each result (win, draw, loss) in the bootstrap's resampling probabilities."""
_NEWTON_TOL = 1e-10
_NEWTON_MAX_STEPS = 100


@dataclasses.dataclass(frozen=True)
class GameCounts:
    """Game results between N teams, each game counted once, from the row team's view.

    ``wins[i, j]`` is the games team ``i`` won against team ``j`` in the games filed under
    ``(i, j)``; a round robin fills only one triangle (the home team's row). Games filed under
    ``(j, i)`` are other games, added to the same pair. The diagonal (a team against itself) is
    ignored by the fit.
    """

    names: tuple[str, ...]
    wins: np.ndarray  # i64[N, N]
    draws: np.ndarray  # i64[N, N]
    losses: np.ndarray  # i64[N, N]

    def __post_init__(self) -> None:
        n = len(self.names)
        for field in ("wins", "draws", "losses"):
            value = np.asarray(getattr(self, field))
            if value.shape != (n, n):
                raise ValueError(f"GameCounts.{field} has shape {value.shape}, expected {(n, n)}")
            if np.any(value < 0):
                raise ValueError(f"GameCounts.{field} has negative counts")

    @property
    def games(self) -> np.ndarray:
        """i64[N, N]: games filed under each (row, column)."""
        return np.asarray(self.wins) + np.asarray(self.draws) + np.asarray(self.losses)

    @property
    def score(self) -> np.ndarray:
        """f64[N, N]: the row team's summed outcome (win 1, draw 0.5) over those games."""
        return np.asarray(self.wins, np.float64) + 0.5 * np.asarray(self.draws, np.float64)


@dataclasses.dataclass(frozen=True)
class Ratings:
    """A fitted Bradley-Terry model, in Elo points. Arrays are ``[N]`` in ``names`` order."""

    names: tuple[str, ...]
    rating: np.ndarray  # f64[N] Elo points, mean 0 (or the anchor at 0)
    stderr: np.ndarray  # f64[N] Fisher-information standard error, Elo points
    ci_low: np.ndarray  # f64[N] bootstrap interval, at least +- z stderr, Elo (NaN: no bootstrap)
    ci_high: np.ndarray  # f64[N]
    games: np.ndarray  # i64[N] games each team played against others
    score: np.ndarray  # f64[N] each team's mean outcome in those games
    confidence: float  # of the interval, e.g. 0.95
    bootstrap_samples: int  # 0: no bootstrap
    prior_std: float  # nats
    anchor: str | None  # the team at 0, or None (mean 0)

    def order(self) -> list[int]:
        """Team indices from the highest rating down."""
        return [int(i) for i in np.argsort(-self.rating, kind="stable")]

    def win_probability(self, i: int, j: int) -> float:
        """The model's expected outcome of team i against team j (draws as half wins)."""
        return float(1.0 / (1.0 + math.exp(-(self.rating[i] - self.rating[j]) / ELO_PER_NAT)))

    def as_rows(self) -> list[dict[str, float | int | str]]:
        """One dict per team, best first (for CSV and JSON)."""
        rows: list[dict[str, float | int | str]] = []
        for rank, i in enumerate(self.order(), start=1):
            rows.append(
                {
                    "rank": rank,
                    "team": self.names[i],
                    "rating": float(self.rating[i]),
                    "stderr": float(self.stderr[i]),
                    "ci_low": float(self.ci_low[i]),
                    "ci_high": float(self.ci_high[i]),
                    "games": int(self.games[i]),
                    "score": float(self.score[i]),
                }
            )
        return rows


def _pair_arrays(games: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, ...]:
    """Off-diagonal pairs with games: (row i64[P], column i64[P], N f64[P], S f64[P])."""
    rows, columns = np.nonzero((games > 0) & ~np.eye(games.shape[0], dtype=bool))
    return rows, columns, games[rows, columns].astype(np.float64), score[rows, columns]


def _fit_nats(
    num_teams: int,
    rows: np.ndarray,
    columns: np.ndarray,
    games: np.ndarray,
    score: np.ndarray,
    prior_std: float,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """MAP ratings in nats (f64[N]) and the penalised negative Hessian there (f64[N, N]).

    Newton's method on a concave objective (the prior makes it strictly concave), with step
    halving as a guard; converges in a handful of steps.
    """
    precision = 1.0 / prior_std**2
    r = np.zeros(num_teams) if start is None else start.astype(np.float64).copy()

    def objective(r: np.ndarray) -> float:
        d = r[rows] - r[columns]
        # log sigmoid(d) = -logaddexp(0, -d): stable for large |d|.
        log_p, log_q = -np.logaddexp(0.0, -d), -np.logaddexp(0.0, d)
        return float(np.sum(score * log_p + (games - score) * log_q) - 0.5 * precision * r @ r)

    def gradient_and_hessian(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = r[rows] - r[columns]
        p = 0.5 * (1.0 + np.tanh(0.5 * d))  # sigmoid, stable
        residual = score - games * p
        gradient = -precision * r
        np.add.at(gradient, rows, residual)
        np.add.at(gradient, columns, -residual)
        weight = games * p * (1.0 - p)
        information = precision * np.eye(num_teams)
        np.add.at(information, (rows, rows), weight)
        np.add.at(information, (columns, columns), weight)
        np.add.at(information, (rows, columns), -weight)
        np.add.at(information, (columns, rows), -weight)
        return gradient, information

    value = objective(r)
    for _ in range(_NEWTON_MAX_STEPS):
        gradient, information = gradient_and_hessian(r)
        step = np.linalg.solve(information, gradient)
        size = 1.0
        while True:
            candidate = r + size * step
            new_value = objective(candidate)
            if new_value >= value - 1e-12 or size < 1e-6:
                break
            size *= 0.5
        r, value = candidate, new_value
        if np.max(np.abs(size * step)) < _NEWTON_TOL:
            break
    _, information = gradient_and_hessian(r)
    return r, information


def _report_matrix(num_teams: int, anchor_index: int | None) -> np.ndarray:
    """f64[N, N]: the linear map from fitted ratings to reported ones (centred or anchored)."""
    if anchor_index is None:
        return np.eye(num_teams) - np.full((num_teams, num_teams), 1.0 / num_teams)
    transform = np.eye(num_teams)
    transform[:, anchor_index] -= 1.0
    return transform


def fit_bradley_terry(
    counts: GameCounts,
    *,
    prior_std: float = PRIOR_STD,
    anchor: str | None = None,
    bootstrap_samples: int = 1000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Ratings:
    """Fit Bradley-Terry ratings (draws as half wins) with Fisher and bootstrap uncertainty.

    counts: the games (see ``GameCounts``). anchor: a team name to put at 0 (default: mean 0).
    bootstrap_samples: refits on games resampled within each pair (0 skips the bootstrap; the
    intervals are then NaN). Returns ``Ratings`` in Elo points.
    """
    names = tuple(counts.names)
    num_teams = len(names)
    if num_teams < 1:
        raise ValueError("cannot rate an empty set of teams")
    if not prior_std > 0:
        raise ValueError(f"prior_std={prior_std!r} is invalid: it must be > 0 (nats)")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence={confidence!r} is invalid: it must be in (0, 1)")
    if bootstrap_samples < 0:
        raise ValueError(f"bootstrap_samples={bootstrap_samples!r} is invalid: it must be >= 0")
    anchor_index = None
    if anchor is not None:
        if anchor not in names:
            raise ValueError(f"anchor={anchor!r} is not one of the teams: {', '.join(names)}")
        anchor_index = names.index(anchor)

    games = counts.games.astype(np.float64)
    score = counts.score
    rows, columns, pair_games, pair_score = _pair_arrays(games, score)
    ratings_nats, information = _fit_nats(
        num_teams, rows, columns, pair_games, pair_score, prior_std
    )
    report = _report_matrix(num_teams, anchor_index)
    covariance = report @ np.linalg.inv(information) @ report.T
    stderr = np.sqrt(np.clip(np.diag(covariance), 0.0, None)) * ELO_PER_NAT
    rating = report @ ratings_nats * ELO_PER_NAT

    ci_low = np.full(num_teams, np.nan)
    ci_high = np.full(num_teams, np.nan)
    if bootstrap_samples > 0 and rows.size > 0:
        rng = np.random.default_rng(seed)
        wins = np.asarray(counts.wins)[rows, columns]
        draws = np.asarray(counts.draws)[rows, columns]
        losses = np.asarray(counts.losses)[rows, columns]
        probabilities = (np.stack([wins, draws, losses], axis=-1) + JEFFREYS) / (
            pair_games[:, None] + 3 * JEFFREYS
        )
        # All resamples at once: drawn[b, p] = (wins, draws, losses) of pair p in sample b.
        drawn = rng.multinomial(
            pair_games.astype(np.int64), probabilities, size=(bootstrap_samples, rows.size)
        )
        samples = np.empty((bootstrap_samples, num_teams))
        for b in range(bootstrap_samples):
            resampled_score = drawn[b, :, 0] + 0.5 * drawn[b, :, 1]
            refit, _ = _fit_nats(
                num_teams, rows, columns, pair_games, resampled_score, prior_std,
                start=ratings_nats,
            )
            samples[b] = report @ refit * ELO_PER_NAT
        tail = 100.0 * (1.0 - confidence) / 2.0
        ci_low, ci_high = np.percentile(samples, [tail, 100.0 - tail], axis=0)
        z = statistics.NormalDist().inv_cdf(0.5 + confidence / 2.0)
        ci_low = np.minimum(ci_low, rating - z * stderr)
        ci_high = np.maximum(ci_high, rating + z * stderr)

    off_diagonal = ~np.eye(num_teams, dtype=bool)
    played = np.where(off_diagonal, games, 0.0)
    scored = np.where(off_diagonal, score, 0.0)
    team_games = played.sum(axis=1) + played.sum(axis=0)
    team_score = scored.sum(axis=1) + (played - scored).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_score = np.where(team_games > 0, team_score / np.maximum(team_games, 1), np.nan)
    return Ratings(
        names=names,
        rating=rating,
        stderr=stderr,
        ci_low=np.asarray(ci_low, np.float64),
        ci_high=np.asarray(ci_high, np.float64),
        games=team_games.astype(np.int64),
        score=mean_score,
        confidence=float(confidence),
        bootstrap_samples=int(bootstrap_samples) if rows.size > 0 else 0,
        prior_std=float(prior_std),
        anchor=anchor,
    )


def counts_from_outcomes(
    names: Sequence[str], row: Sequence[int], column: Sequence[int], outcome: Sequence[float]
) -> GameCounts:
    """GameCounts from a list of games: ``outcome[g]`` (1, 0.5, 0) of team ``row[g]`` against
    ``column[g]``. Any other outcome value is a ``ValueError``."""
    num_teams = len(names)
    row_index, column_index = np.asarray(row, np.int64), np.asarray(column, np.int64)
    values = np.asarray(outcome, np.float64)
    if not (row_index.shape == column_index.shape == values.shape):
        raise ValueError("row, column and outcome must have the same length")
    if np.any(~np.isin(values, (0.0, 0.5, 1.0))):
        raise ValueError("outcomes must be 1 (win), 0.5 (draw) or 0 (loss)")
    counts = {}
    for name, value in (("wins", 1.0), ("draws", 0.5), ("losses", 0.0)):
        table = np.zeros((num_teams, num_teams), np.int64)
        mask = values == value
        np.add.at(table, (row_index[mask], column_index[mask]), 1)
        counts[name] = table
    return GameCounts(names=tuple(names), **counts)
