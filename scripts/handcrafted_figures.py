"""Measure the handcrafted teams' figures in 11 v 11 (500 games per match).

Bars: naive beats random with a mean outcome >= 0.95; teamwork beats naive (> 0.55); every team
against itself (no side swap, outcome of the team on side 0) scores 0.5 +- 0.05.

Usage: ``.venv/bin/python scripts/handcrafted_figures.py [--games 500] [--scenario 11v11]
[--out DIR]``: prints one line per match and writes ``DIR/handcrafted.csv`` and
``DIR/handcrafted.png`` (mean outcome of each match with its 95% interval and its bar).
Exits with status 1 if a bar is missed.
"""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax

import elevens
from elevens.eval.match import play_match, summary
from elevens.teams.base import TeamPolicy
from elevens.teams.scripted import NaiveTeam, RandomTeam, TeamworkTeam

SELF_PLAY_TOLERANCE = 0.05
NAIVE_VS_RANDOM_BAR = 0.95
TEAMWORK_VS_NAIVE_BAR = 0.55


class Fixture(NamedTuple):
    home: TeamPolicy
    away: TeamPolicy
    swap_sides: bool
    met: Callable[[float], bool]  # the bar, on the home team's mean outcome
    bar: str  # the bar in words


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--games", type=int, default=500)
    parser.add_argument("--scenario", default="11v11")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("handcrafted_figures"))
    args = parser.parse_args()

    env, params = elevens.make(args.scenario)
    random: TeamPolicy = RandomTeam()
    naive: TeamPolicy = NaiveTeam()
    teamwork: TeamPolicy = TeamworkTeam()
    fixtures = [
        Fixture(naive, random, True, lambda m: m >= NAIVE_VS_RANDOM_BAR,
                f">= {NAIVE_VS_RANDOM_BAR}"),
        Fixture(teamwork, naive, True, lambda m: m > TEAMWORK_VS_NAIVE_BAR,
                f"> {TEAMWORK_VS_NAIVE_BAR}"),
    ]
    for team in (random, naive, teamwork):
        fixtures.append(
            Fixture(team, team, False, lambda m: abs(m - 0.5) <= SELF_PLAY_TOLERANCE,
                    f"0.5 +- {SELF_PLAY_TOLERANCE}")
        )

    print(f"{args.scenario}, {args.games} games per match, {int(params.episode_length)} steps, "
          f"devices: {jax.devices()}")
    all_met = True
    start = time.perf_counter()
    rows: list[dict[str, object]] = []
    for index, fixture in enumerate(fixtures):
        match_start = time.perf_counter()
        result = play_match(
            env, params, fixture.home, fixture.away, jax.random.key(args.seed + index),
            args.games, swap_sides=fixture.swap_sides,
        )
        stats = summary(result)
        seconds = time.perf_counter() - match_start
        met = fixture.met(stats["mean"])
        all_met &= met
        sides = "sides swapped" if fixture.swap_sides else "home on side 0"
        rows.append({
            "home": fixture.home.name, "away": fixture.away.name, "sides": sides,
            "games": stats["games"], "mean": stats["mean"],
            "stderr": stats["std"] / stats["games"] ** 0.5, "win": stats["win"],
            "draw": stats["draw"], "loss": stats["loss"], "goals_for": stats["goals_for"],
            "goals_against": stats["goals_against"], "bar": fixture.bar, "met": met,
        })
        print(
            f"{fixture.home.name:>8} vs {fixture.away.name:<8} ({sides:>14}): "
            f"{stats['mean']:.3f} +- {stats['std']:.3f} "
            f"(s.e. {stats['std'] / stats['games'] ** 0.5:.3f}), "
            f"W/D/L {stats['win']:.3f}/{stats['draw']:.3f}/{stats['loss']:.3f}, "
            f"goals {stats['goals_for']:.2f}-{stats['goals_against']:.2f}, "
            f"bar {fixture.bar}: {'met' if met else 'MISSED'}  [{seconds:.1f} s incl. compile]",
            flush=True,
        )
    print(f"total wall time {time.perf_counter() - start:.1f} s; all bars met: {all_met}")
    for path in write_outputs(rows, args.out, f"{args.scenario}, {args.games} games a match"):
        print(f"wrote {path}")
    return 0 if all_met else 1


def write_outputs(rows: list[dict[str, object]], out: Path, title: str) -> list[Path]:
    """The table as CSV and a figure: each match's mean outcome with its 95% interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    table = out / "handcrafted.csv"
    with table.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    figure, axis = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
    labels = [f"{row['home']} v {row['away']}" for row in rows]
    means = [float(row["mean"]) for row in rows]  # type: ignore[arg-type]
    errors = [1.96 * float(row["stderr"]) for row in rows]  # type: ignore[arg-type]
    colours = ["#2e7d32" if row["met"] else "#c62828" for row in rows]
    axis.barh(labels, means, xerr=errors, color=colours, capsize=3)
    for index, mean in enumerate(means):
        axis.text(min(mean + 0.03, 0.97), index, f"{mean:.3f}", va="center", fontsize=8)
    axis.axvline(0.5, color="grey", linestyle=":", linewidth=1)
    axis.set_xlim(0, 1)
    axis.invert_yaxis()
    axis.set_xlabel("mean outcome of the home team (win 1, draw 0.5), 95% interval")
    axis.set_title(f"Handcrafted teams, {title} (green: bar met)", fontsize=9)
    figure_path = out / "handcrafted.png"
    figure.savefig(figure_path, dpi=110)
    plt.close(figure)
    return [table, figure_path]


if __name__ == "__main__":
    raise SystemExit(main())
