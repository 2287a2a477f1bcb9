"""Round-robin tournaments (thesis table 6.3 and figure 6.7) and ratings over their games.

Every pair of teams plays one match of G games with sides swapped at half time, and every team
plays itself. A match between ``i`` and ``j`` (``i < j``, ``i`` at home) fills two cells of the
table: row ``i`` against column ``j`` is the home team's view, and row ``j`` against column ``i``
the same games from the away team's view (outcome ``1 - o``, wins and losses exchanged, same
std). The diagonal is a team against itself, from the home side's view (about 0.5 by symmetry).

Files written by ``save_tournament`` (all in one directory):

* ``table.csv``: the table of table 6.3, row team against column team, cells ``mean±std``;
* ``pairs.csv``: one line per (row, column): games, mean, std, win/draw/loss counts, goals;
* ``ratings.csv``: Bradley-Terry ratings (``elevens.eval.ratings``), best first;
* ``tournament.json``: everything above plus the settings (format ``elevens-tournament`` v1);
* ``outcomes.png``: figure 6.7, games won, drawn and lost by each team against each opponent;
* ``ratings.png``: the ratings with their bootstrap intervals.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from elevens.env.params import EnvParams
from elevens.env.randomize import held_out_games, setting_rows, tile_games
from elevens.env.soccer import Soccer
from elevens.eval.match import DEFAULT_CHUNK_SIZE, MatchResult, play_match
from elevens.eval.ratings import GameCounts, Ratings, fit_bradley_terry
from elevens.teams.base import Team

FORMAT = "elevens-tournament"
VERSION = 1
WIN_COLOUR, DRAW_COLOUR, LOSS_COLOUR = "#2e7d32", "#f9a825", "#c62828"


@dataclasses.dataclass(frozen=True)
class TournamentTable:
    """Row team against column team. Arrays are ``[N, N]`` in ``names`` order."""

    names: tuple[str, ...]
    games: np.ndarray  # i64[N, N] games between row and column
    mean: np.ndarray  # f64[N, N] mean outcome of the row team (win 1, draw 0.5, loss 0)
    std: np.ndarray  # f64[N, N] std of the row team's outcome over the games
    wins: np.ndarray  # i64[N, N] games the row team won
    draws: np.ndarray  # i64[N, N]
    losses: np.ndarray  # i64[N, N] games the row team lost
    goals_for: np.ndarray  # f64[N, N] mean goals of the row team per game
    goals_against: np.ndarray  # f64[N, N] mean goals of the column team per game

    def counts(self) -> GameCounts:
        """The games for a rating fit: each match counted once (the upper triangle)."""
        upper = np.triu(np.ones(self.mean.shape, bool), k=1)
        return GameCounts(
            names=self.names,
            wins=np.where(upper, self.wins, 0),
            draws=np.where(upper, self.draws, 0),
            losses=np.where(upper, self.losses, 0),
        )

    def cell(self, row: int, column: int) -> str:
        """``'0.64±0.41'``, as in table 6.3."""
        return f"{self.mean[row, column]:.2f}±{self.std[row, column]:.2f}"


@dataclasses.dataclass(frozen=True)
class Tournament:
    """A played round robin: the table, the ratings and the settings."""

    table: TournamentTable
    ratings: Ratings
    players_per_team: int
    games_per_pair: int
    episode_length: int
    seed: int
    specs: tuple[str, ...]
    wall_s: float
    randomize: int | None = None
    """Seed of the held-out randomised settings the games were played on (None: ``params``'s
    game, the same for every game)."""
    settings: tuple[dict[str, Any], ...] = ()
    """Those settings' drawn constants (game g of every match played setting g % count)."""


def table_from_results(
    names: Sequence[str], results: Mapping[tuple[int, int], MatchResult]
) -> TournamentTable:
    """The tournament table from its matches.

    results: ``{(i, j): MatchResult}`` for ``i <= j``, team ``i`` at home (the result's view).
    Each pair fills ``[i, j]`` from the home view and ``[j, i]`` from the away view.
    """
    n = len(names)
    games = np.zeros((n, n), np.int64)
    mean = np.full((n, n), np.nan)
    std = np.full((n, n), np.nan)
    wins = np.zeros((n, n), np.int64)
    draws = np.zeros((n, n), np.int64)
    losses = np.zeros((n, n), np.int64)
    goals_for = np.full((n, n), np.nan)
    goals_against = np.full((n, n), np.nan)
    for (i, j), result in results.items():
        if not (0 <= i <= j < n):
            raise ValueError(f"result key {(i, j)} is invalid: expected 0 <= i <= j < {n}")
        outcome = np.asarray(result.outcome, np.float64)
        scored = np.asarray(result.goals_for, np.float64)
        conceded = np.asarray(result.goals_against, np.float64)
        won, drawn, lost = (int(np.sum(outcome == v)) for v in (1.0, 0.5, 0.0))
        if won + drawn + lost != outcome.size:
            raise ValueError(f"match {(i, j)} has outcomes other than 0, 0.5 and 1")
        games[i, j] = games[j, i] = outcome.size
        mean[i, j], std[i, j] = outcome.mean(), outcome.std()
        wins[i, j], draws[i, j], losses[i, j] = won, drawn, lost
        goals_for[i, j], goals_against[i, j] = scored.mean(), conceded.mean()
        if i != j:
            # The away team's view of the same games.
            mean[j, i], std[j, i] = 1.0 - outcome.mean(), outcome.std()
            wins[j, i], draws[j, i], losses[j, i] = lost, drawn, won
            goals_for[j, i], goals_against[j, i] = conceded.mean(), scored.mean()
    return TournamentTable(
        names=tuple(names), games=games, mean=mean, std=std, wins=wins, draws=draws,
        losses=losses, goals_for=goals_for, goals_against=goals_against,
    )


def schedule(num_teams: int) -> list[tuple[int, int]]:
    """The matches of a round robin with self-play: ``(i, j)`` for ``i <= j``, row by row."""
    return [(i, j) for i in range(num_teams) for j in range(i, num_teams)]


PlayFn = Callable[..., MatchResult]
ProgressFn = Callable[[int, int, str, str, MatchResult], None]


def play_round_robin(
    teams: Sequence[Team],
    env: Soccer,
    params: EnvParams,
    key: jax.Array,
    num_games: int,
    *,
    names: Sequence[str] | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    on_match: ProgressFn | None = None,
    play: PlayFn = play_match,
) -> dict[tuple[int, int], MatchResult]:
    """Play every match of ``schedule(len(teams))``; match ``m`` uses ``fold_in(key, m)``.

    on_match(index, total, home, away, result) is called after each match (progress).
    Returns ``{(i, j): MatchResult}`` (team ``i`` at home, sides swapped at half time).
    """
    labels = list(names) if names is not None else [team.name for team in teams]
    matches = schedule(len(teams))
    results: dict[tuple[int, int], MatchResult] = {}
    for index, (i, j) in enumerate(matches):
        home, away = teams[i], teams[j]
        result = play(
            env, params, home.policy, away.policy, jax.random.fold_in(key, index), num_games,
            home_params=home.params, away_params=away.params, swap_sides=True,
            chunk_size=chunk_size,
        )
        # Only the per-game numbers are kept: a tournament never records trajectories.
        results[(i, j)] = jax.tree.map(np.asarray, result)
        if on_match is not None:
            on_match(index, len(matches), labels[i], labels[j], results[(i, j)])
    return results


def run_tournament(
    teams: Sequence[Team],
    env: Soccer,
    params: EnvParams,
    *,
    num_games: int = 500,
    seed: int = 0,
    names: Sequence[str] | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    on_match: ProgressFn | None = None,
    anchor: str | None = None,
    bootstrap_samples: int = 1000,
    randomize: int | None = None,
) -> Tournament:
    """Play a round robin and fit ratings (see ``play_round_robin`` and ``fit_bradley_terry``).

    ``randomize``: a seed; every match then plays its games on the held-out randomised
    settings of that seed drawn on ``params`` (``elevens.env.randomize.held_out_games``, game
    ``g`` on setting ``g % 20``), which no training run draws."""
    if len(teams) < 1:
        raise ValueError("a tournament needs at least one team")
    labels = tuple(names) if names is not None else tuple(team.name for team in teams)
    if len(set(labels)) != len(labels):
        raise ValueError(f"team names must be distinct, got {labels}")
    settings: tuple[dict[str, Any], ...] = ()
    games_params = params
    if randomize is not None:
        held_out = held_out_games(randomize, params)
        settings = tuple(setting_rows(held_out))
        games_params = tile_games(held_out, num_games)
    began = time.perf_counter()
    results = play_round_robin(
        teams, env, games_params, jax.random.key(seed), num_games, names=labels,
        chunk_size=chunk_size, on_match=on_match,
    )
    table = table_from_results(labels, results)
    ratings = fit_bradley_terry(
        table.counts(), anchor=anchor, bootstrap_samples=bootstrap_samples, seed=seed
    )
    return Tournament(
        table=table,
        ratings=ratings,
        players_per_team=env.players_per_team,
        games_per_pair=num_games,
        episode_length=int(params.episode_length),
        seed=seed,
        specs=tuple(team.spec or team.name for team in teams),
        wall_s=time.perf_counter() - began,
        randomize=randomize,
        settings=settings,
    )


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------


def _scenario(tournament: Tournament) -> str:
    n = tournament.players_per_team
    return f"{n} v {n}"


def print_tournament(tournament: Tournament, console: Any = None) -> None:
    """The table (row against column, mean ± std) and the ratings, as rich tables."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console if console is not None else Console()
    table = tournament.table
    grid = Table(
        title="Mean outcome ± std, row team against column team",
        caption=(
            f"{_scenario(tournament)}, {tournament.games_per_pair} games a pair, sides swapped; "
            "win 1, draw 0.5, loss 0"
            + (
                f"; on the {len(tournament.settings)} held-out randomised settings of seed "
                f"{tournament.randomize}" if tournament.randomize is not None else ""
            )
        ),
        title_justify="left",
        caption_justify="left",
    )
    grid.add_column("team", style="bold")
    for name in table.names:
        grid.add_column(escape(name), justify="right")
    for i, name in enumerate(table.names):
        grid.add_row(escape(name), *(table.cell(i, j) for j in range(len(table.names))))
    console.print(grid)

    ratings = tournament.ratings
    level = f"{100 * ratings.confidence:g}%"
    where = f"{ratings.anchor} = 0" if ratings.anchor else "mean 0"
    rated = Table(
        title="Bradley-Terry ratings",
        caption=f"Elo points, {where}; a draw counts half a win",
        title_justify="left",
        caption_justify="left",
    )
    for column in ("rank", "team", "rating", f"{level} interval", "± s.e.", "games", "score"):
        rated.add_column(column, justify="left" if column == "team" else "right")
    for row in ratings.as_rows():
        interval = (
            escape(f"[{row['ci_low']:.0f}, {row['ci_high']:.0f}]")
            if np.isfinite(float(row["ci_low"])) else "-"
        )
        rated.add_row(
            str(row["rank"]), escape(str(row["team"])), f"{row['rating']:.0f}", interval,
            f"{row['stderr']:.0f}", str(row["games"]), f"{row['score']:.3f}",
        )
    console.print(rated)


def tournament_dict(tournament: Tournament) -> dict[str, Any]:
    """A JSON-ready description of the tournament (what ``tournament.json`` holds)."""
    table = tournament.table

    def matrix(values: np.ndarray) -> list[list[float | int | None]]:
        return [
            [None if isinstance(v, float) and not np.isfinite(v) else v for v in row]
            for row in values.tolist()
        ]

    ratings = tournament.ratings
    return {
        "format": FORMAT,
        "version": VERSION,
        "teams": list(table.names),
        "specs": list(tournament.specs),
        "players_per_team": tournament.players_per_team,
        "games_per_pair": tournament.games_per_pair,
        "episode_length": tournament.episode_length,
        "seed": tournament.seed,
        "wall_s": tournament.wall_s,
        "randomize": tournament.randomize,
        "settings": list(tournament.settings),
        "outcome": "row team against column team: win 1, draw 0.5, loss 0",
        "games": matrix(table.games),
        "mean": matrix(table.mean),
        "std": matrix(table.std),
        "wins": matrix(table.wins),
        "draws": matrix(table.draws),
        "losses": matrix(table.losses),
        "goals_for": matrix(table.goals_for),
        "goals_against": matrix(table.goals_against),
        "ratings": {
            "model": "Bradley-Terry, draws as half wins, Gaussian prior on ratings (MAP)",
            "scale": "Elo points (400 = 10:1 odds)",
            "anchor": ratings.anchor,
            "prior_std_nats": ratings.prior_std,
            "confidence": ratings.confidence,
            "bootstrap_samples": ratings.bootstrap_samples,
            "teams": ratings.as_rows(),
        },
    }


def save_tournament(tournament: Tournament, out_dir: str | Path) -> dict[str, Path]:
    """Write the files listed in the module docstring; returns ``{kind: path}``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = tournament.table
    names = table.names
    paths = {
        "table": out / "table.csv",
        "pairs": out / "pairs.csv",
        "ratings": out / "ratings.csv",
        "json": out / "tournament.json",
    }
    with paths["table"].open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["team", *names])
        for i, name in enumerate(names):
            writer.writerow([name, *(table.cell(i, j) for j in range(len(names)))])
    with paths["pairs"].open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["row", "column", "games", "mean", "std", "wins", "draws", "losses",
                         "goals_for", "goals_against"])
        for i, row in enumerate(names):
            for j, column in enumerate(names):
                writer.writerow([
                    row, column, int(table.games[i, j]), f"{table.mean[i, j]:.6f}",
                    f"{table.std[i, j]:.6f}", int(table.wins[i, j]), int(table.draws[i, j]),
                    int(table.losses[i, j]), f"{table.goals_for[i, j]:.6f}",
                    f"{table.goals_against[i, j]:.6f}",
                ])
    rows = tournament.ratings.as_rows()
    with paths["ratings"].open("w", newline="", encoding="utf-8") as handle:
        dict_writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        dict_writer.writeheader()
        dict_writer.writerows(rows)
    paths["json"].write_text(
        json.dumps(tournament_dict(tournament), indent=2) + "\n", encoding="utf-8"
    )
    paths["table_png"] = plot_table(tournament, out / "table.png")
    paths["outcomes_png"] = plot_outcomes(tournament, out / "outcomes.png")
    paths["ratings_png"] = plot_ratings(tournament, out / "ratings.png")
    return paths


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_outcomes(tournament: Tournament, path: str | Path) -> Path:
    """Figure 6.7: for each team, stacked bars of games won, drawn and lost per opponent."""
    plt = _pyplot()
    table = tournament.table
    names = table.names
    n = len(names)
    columns = min(n, 4)
    rows = -(-n // columns)
    figure, axes = plt.subplots(
        rows, columns, figsize=(max(4.2, 0.55 * n + 2.2) * columns, 3.6 * rows + 0.6),
        sharey=True, squeeze=False,
    )
    x = np.arange(n)
    games = tournament.games_per_pair
    for i, name in enumerate(names):
        axis = axes[i // columns][i % columns]
        won, drawn, lost = table.wins[i], table.draws[i], table.losses[i]
        axis.bar(x, won, color=WIN_COLOUR, label="won")
        axis.bar(x, drawn, bottom=won, color=DRAW_COLOUR, label="drawn")
        axis.bar(x, lost, bottom=won + drawn, color=LOSS_COLOUR, label="lost")
        axis.set_title(f"{name} against ...")
        axis.set_xticks(x, names, rotation=30 if n > 3 else 0, ha="right" if n > 3 else "center")
        axis.set_xlabel("opponent")
        axis.set_ylim(0, games * 1.02)
        axis.grid(axis="y", alpha=0.3)
        if i % columns == 0:
            axis.set_ylabel(f"games (of {games})")
    for k in range(n, rows * columns):
        axes[k // columns][k % columns].set_visible(False)
    handles, labels = axes[0][0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="upper right", ncol=3, frameon=False)
    figure.suptitle(
        f"Games won, drawn and lost ({_scenario(tournament)}, {games} games a pair, "
        "sides swapped)", x=0.02, ha="left",
    )
    figure.tight_layout(rect=(0, 0, 1, 0.93))
    path = Path(path)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def plot_table(tournament: Tournament, path: str | Path) -> Path:
    """Table 6.3 as a figure: the row team's mean outcome against each column team, written in
    each cell (win 1, draw 0.5, loss 0), green above 0.5 and red below."""
    plt = _pyplot()
    table = tournament.table
    names = list(table.names)
    n = len(names)
    games = np.asarray(table.wins) + np.asarray(table.draws) + np.asarray(table.losses)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (np.asarray(table.wins) + 0.5 * np.asarray(table.draws)) / games
    figure, axis = plt.subplots(figsize=(1.1 * n + 2.4, 0.8 * n + 1.6), layout="constrained")
    image = axis.imshow(mean, cmap="RdYlGn", vmin=0.0, vmax=1.0)
    for i in range(n):
        for j in range(n):
            if np.isfinite(mean[i, j]):
                axis.text(j, i, f"{mean[i, j]:.2f}", ha="center", va="center", fontsize=10,
                          color="black")
    axis.set_xticks(range(n), names, rotation=30 if n > 3 else 0, ha="right" if n > 3 else "center")
    axis.set_yticks(range(n), names)
    axis.set_xlabel("opponent")
    axis.set_ylabel("team")
    bar = figure.colorbar(image, ax=axis, shrink=0.8)
    bar.set_label("mean outcome of the row team")
    axis.set_title(
        f"Mean outcome ({_scenario(tournament)}, {tournament.games_per_pair} games a pair, "
        "sides swapped)", fontsize=9,
    )
    path = Path(path)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def plot_ratings(tournament: Tournament, path: str | Path) -> Path:
    """Ratings (Elo points) with bootstrap intervals, best at the top."""
    plt = _pyplot()
    ratings = tournament.ratings
    order = ratings.order()
    n = len(order)
    figure, axis = plt.subplots(figsize=(7.0, 1.6 + 0.45 * n))
    y = np.arange(n)[::-1]
    values = ratings.rating[order]
    if ratings.bootstrap_samples > 0:
        low, high = ratings.ci_low[order], ratings.ci_high[order]
        what = f"{100 * ratings.confidence:g}% bootstrap interval"
    else:
        low, high = values - 1.96 * ratings.stderr[order], values + 1.96 * ratings.stderr[order]
        what = "±1.96 s.e. (Fisher information)"
    errors = np.stack([values - low, high - values])
    axis.errorbar(values, y, xerr=np.clip(errors, 0, None), fmt="o", color="#1f4e9c",
                  ecolor="#7a9cd6", capsize=4, label=f"rating, {what}")
    axis.set_yticks(y, [ratings.names[i] for i in order])
    where = f"{ratings.anchor} = 0" if ratings.anchor else "mean 0"
    axis.set_xlabel(f"Bradley-Terry rating (Elo points, {where})")
    axis.set_ylim(-0.7, n - 0.3)
    axis.grid(axis="x", alpha=0.3)
    # Below the axes, so it never hides a team's interval.
    axis.legend(loc="upper center", bbox_to_anchor=(0.5, -0.25), fontsize=8, frameon=False)
    axis.set_title(
        f"Ratings from the round robin ({_scenario(tournament)}, "
        f"{tournament.games_per_pair} games a pair)"
    )
    figure.tight_layout()
    path = Path(path)
    figure.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(figure)
    return path
