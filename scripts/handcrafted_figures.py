"""Measure the handcrafted teams' figures in 11 v 11 (500 games per match).

Bars: naive beats random with a mean outcome >= 0.95; teamwork beats naive (> 0.55); every team
against itself (no side swap, outcome of the team on side 0) scores 0.5 +- 0.05.

Usage: ``.venv/bin/python scripts/handcrafted_figures.py [--games 500] [--scenario 11v11]``.
Exits with status 1 if a bar is missed.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
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
    return 0 if all_met else 1


if __name__ == "__main__":
    raise SystemExit(main())
