"""Each team's stamina, speed, commands and ball contacts over one match, from its .rcg log.

    python scripts/rcg_team_stats.py LOG.rcg

Reads rcssserver's text game log (version 6, as `elevens robocup match --log-dir` keeps it):
every `(show ...)` line gives each player's position, velocity, stamina and command counters.
Prints, per side: mean speed (m/cycle), kicks, dashes, turns and tackles over the match,
player-cycles within kickable distance of the ball (1.085 m), and the mean stamina in each
600-cycle block (the server's maximum is 8000). docs/results/robocup.md, session 15.
"""

from __future__ import annotations

import collections
import math
import re
import sys

KICKABLE = 1.085  # player_size + ball_size + kickable_margin, default player type
BLOCK = 600
PLAYER = re.compile(
    r"\(\((l|r) (\d+)\) \d+ 0x[0-9a-f]+ (-?[\d.]+) (-?[\d.]+) (-?[\d.]+) (-?[\d.]+)"
    r"[^()]*\(v [^)]*\) \(fp [^)]*\) \(s ([\d.]+) [\d.]+ [\d.]+ [\d.]+\)"
    r"(?: \(f [^)]*\))? \(c ([\d ]+)\)\)"
)
BALL = re.compile(r"\(\(b\) (-?[\d.]+) (-?[\d.]+) -?[\d.]+ -?[\d.]+\)")
COUNTERS = {"kicks": 0, "dashes": 1, "turns": 2, "tackles": 9}


def main(path: str) -> None:
    speeds: dict[str, list[float]] = collections.defaultdict(list)
    stamina: dict[str, dict[int, list[float]]] = collections.defaultdict(
        lambda: collections.defaultdict(list)
    )
    near: collections.Counter[str] = collections.Counter()
    counters: dict[tuple[str, int], list[int]] = {}
    cycles = ball_in_left_half = 0
    with open(path, encoding="utf-8", errors="replace") as log:
        for line in log:
            if not line.startswith("(show "):
                continue
            time = int(line.split()[1])
            ball = BALL.search(line)
            if ball is None:
                continue
            cycles += 1
            ball_x, ball_y = float(ball.group(1)), float(ball.group(2))
            ball_in_left_half += ball_x < 0
            for match in PLAYER.finditer(line):
                side, unum = match.group(1), int(match.group(2))
                x, y, vx, vy = (float(match.group(i)) for i in range(3, 7))
                speeds[side].append(math.hypot(vx, vy))
                stamina[side][time // BLOCK].append(float(match.group(7)))
                near[side] += math.hypot(x - ball_x, y - ball_y) < KICKABLE
                counters[(side, unum)] = [int(c) for c in match.group(8).split()]
    print(f"{cycles} shows; the ball was in the left half in {ball_in_left_half / cycles:.0%}")
    for side, name in (("l", "left"), ("r", "right")):
        totals = {
            label: sum(c[index] for (s, _), c in counters.items() if s == side)
            for label, index in COUNTERS.items()
        }
        blocks = [round(sum(v) / len(v)) for _, v in sorted(stamina[side].items())]
        print(
            f"{name}: mean speed {sum(speeds[side]) / len(speeds[side]):.3f} m/cycle, "
            + ", ".join(f"{label} {count}" for label, count in totals.items())
            + f", player-cycles within kickable distance {near[side]}"
        )
        print(f"  mean stamina per {BLOCK}-cycle block: {blocks}")


if __name__ == "__main__":
    main(sys.argv[1])
