"""A team against the opponent panel: one match per panel team, the mean and the worst.

``play_panel`` plays a team against each team of a panel (``elevens.teams.registry.PANEL`` by
default in the CLI), G games a match with sides swapped at half time. Match ``k`` (the panel's
k-th team) uses ``fold_in(key(seed), k)``, so every team measured with one seed meets each
opponent in the same games. The figure of merit is the mean outcome over the panel (each
opponent weighs the same) and the worst one: a robust team has no bad opponent.

Files written by ``save_panel`` (one directory): ``panel.csv``, one line per (team, opponent)
with games, mean, std, wins, draws, losses and goals; ``panel.json``, the same with each team's
mean and worst and the settings (format ``elevens-panel`` v1).
"""

from __future__ import annotations

import csv
import dataclasses
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer
from elevens.eval.match import DEFAULT_CHUNK_SIZE, MatchResult, play_match, summary
from elevens.teams.base import Team

FORMAT = "elevens-panel"
VERSION = 1


@dataclasses.dataclass(frozen=True)
class PanelResult:
    """One team's matches against the panel, from the team's view."""

    team: str
    opponents: tuple[str, ...]
    numbers: tuple[dict[str, float], ...]
    """``elevens.eval.match.summary`` of each match, in ``opponents`` order."""

    @property
    def means(self) -> np.ndarray:
        """f64[panel]: the mean outcome against each opponent (win 1, draw 0.5, loss 0)."""
        return np.asarray([numbers["mean"] for numbers in self.numbers])

    @property
    def mean(self) -> float:
        """The mean over the panel, each opponent weighing the same."""
        return float(self.means.mean())

    @property
    def worst(self) -> tuple[str, float]:
        """(opponent, mean outcome) of the panel team it does worst against."""
        k = int(np.argmin(self.means))
        return self.opponents[k], float(self.means[k])


def play_panel(
    team: Team,
    panel: Sequence[Team],
    env: Soccer,
    params: EnvParams,
    *,
    num_games: int,
    seed: int = 0,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    on_match: Callable[[int, int, str, MatchResult], None] | None = None,
) -> PanelResult:
    """Play ``team`` (at home) against each team of ``panel``, ``num_games`` games each.

    on_match(index, total, opponent, result) is called after each match (progress).
    """
    if not panel:
        raise ValueError("the panel is empty: give at least one opponent")
    numbers = []
    for index, opponent in enumerate(panel):
        result = play_match(
            env, params, team.policy, opponent.policy, jax.random.fold_in(
                jax.random.key(seed), index), num_games, home_params=team.params,
            away_params=opponent.params, swap_sides=True, chunk_size=chunk_size,
        )
        result = jax.tree.map(np.asarray, result)
        numbers.append(summary(result))
        if on_match is not None:
            on_match(index, len(panel), opponent.name, result)
    return PanelResult(team.name, tuple(opponent.name for opponent in panel), tuple(numbers))


def panel_dict(
    results: Sequence[PanelResult], players_per_team: int, num_games: int, episode_length: int,
    seed: int,
) -> dict[str, Any]:
    """A JSON-ready description of the matches (what ``panel.json`` holds)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "players_per_team": players_per_team,
        "games_per_opponent": num_games,
        "episode_length": episode_length,
        "seed": seed,
        "outcome": "team against opponent: win 1, draw 0.5, loss 0",
        "teams": [
            {
                "team": result.team,
                "mean": result.mean,
                "worst": {"opponent": result.worst[0], "mean": result.worst[1]},
                "opponents": [
                    {"opponent": name, **numbers}
                    for name, numbers in zip(result.opponents, result.numbers, strict=True)
                ],
            }
            for result in results
        ],
    }


def save_panel(
    results: Sequence[PanelResult], out_dir: str | Path, players_per_team: int, num_games: int,
    episode_length: int, seed: int,
) -> dict[str, Path]:
    """Write ``panel.csv`` and ``panel.json`` (module docstring); returns ``{kind: path}``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "panel.csv", "json": out / "panel.json"}
    fields = ("games", "mean", "std", "win", "draw", "loss", "goals_for", "goals_against")
    with paths["csv"].open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["team", "opponent", *fields])
        for result in results:
            for name, numbers in zip(result.opponents, result.numbers, strict=True):
                writer.writerow([result.team, name, int(numbers["games"]),
                                 *(f"{numbers[field]:.6f}" for field in fields[1:])])
    document = panel_dict(results, players_per_team, num_games, episode_length, seed)
    paths["json"].write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    return paths
