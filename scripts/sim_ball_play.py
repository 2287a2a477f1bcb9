"""How two 12-value teams play the ball in the simulator with rcssserver's bodies (session 21).

    python scripts/sim_ball_play.py HOME AWAY [--games 16] [--set FIELD=VALUE ...]

HOME and AWAY are team specs as `elevens tournament` takes them (rcss_naive, rcss_passer, a run
directory). `--set` changes a field of a handcrafted HOME team, e.g. `--set chasers=11`. The
games are 11 v 11, 400 cycles, the server's see timing (every third cycle), stamina and the
goalie routine, HOME always on the left. Prints the goals, each team's kicks a game (and the
player-cycles it had the ball within kicking reach), how often a
kick was next touched by a teammate or by an opponent, how many of each team's players were
within 10 m of the ball on average (how much it crowds the ball), and the share of cycles the
ball spent in HOME's half.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import jax
import numpy as np

from elevens.robocup.bodies import DEFAULT, RcssSoccer
from elevens.eval.match import play_match
from elevens.runs.teams import fit_to_field, load_team

CROWD_RADIUS = 10.0


def next_touches(kicks: np.ndarray, n: int) -> np.ndarray:
    """kicks bool[G, T, 2n] -> i64[2, 2]: [team, same team / other team] counts of who kicked
    next after a kick by one of the team's players (the same player kicking again is skipped)."""
    counts = np.zeros((2, 2), np.int64)
    for game in kicks:
        kickers = [int(np.flatnonzero(step)[0]) for step in game if step.any()]
        for first, second in zip(kickers, kickers[1:], strict=False):
            if first != second:
                counts[first // n, int(first // n != second // n)] += 1
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("home")
    parser.add_argument("away")
    parser.add_argument("--games", type=int, default=16)
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE")
    args = parser.parse_args()
    n = 11
    env = RcssSoccer(n, see_period=3, stamina=True, goalie=True)
    params = env.default_params()
    home, away = (fit_to_field(load_team(spec), params) for spec in (args.home, args.away))
    if args.set:
        changes = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
        home = dataclasses.replace(home, policy=dataclasses.replace(home.policy, **changes))
    result = play_match(
        env,
        params,
        home.policy,
        away.policy,
        jax.random.key(1),
        args.games,
        home_params=home.params,
        away_params=away.params,
        swap_sides=False,
        record=True,
        chunk_size=args.games,
    )
    record = result.record
    kicks = np.asarray(record.kicks)
    touches = next_touches(kicks, n)
    ball_x = np.asarray(record.ball_position)[..., 0]
    gaps = np.linalg.norm(
        np.asarray(record.positions) - np.asarray(record.ball_position)[:, :, None, :], axis=-1
    )
    kickable = (
        (gaps <= DEFAULT.kickable_distance).reshape(*gaps.shape[:2], 2, n).sum(axis=(0, 1, 3))
    )
    crowd = (gaps <= CROWD_RADIUS).reshape(*gaps.shape[:2], 2, n).sum(axis=-1).mean(axis=(0, 1))
    print(
        f"goals {int(np.sum(result.goals_for))} - {int(np.sum(result.goals_against))} "
        f"in {args.games} games"
    )
    for side, name in enumerate((args.home, args.away)):
        print(
            f"{name}: {kicks[..., side * n : (side + 1) * n].sum() / args.games:.1f} kicks a game "
            f"({kickable[side] / args.games:.0f} kickable player-cycles); "
            f"next touch by a teammate {touches[side, 0]}, by an opponent {touches[side, 1]}; "
            f"{crowd[side]:.1f} players within {CROWD_RADIUS:.0f} m of the ball"
        )
    print(f"ball in {args.home}'s half {np.mean(ball_x < 0):.0%} of the cycles")


if __name__ == "__main__":
    main()
