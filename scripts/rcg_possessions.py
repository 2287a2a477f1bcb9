"""How a match's goals came about, read from its .rcg/.rcl (docs/results/robocup.md, session 17).

    python scripts/rcg_possessions.py MATCH_DIR [MATCH_DIR ...]

MATCH_DIR is one match folder of `elevens robocup match --log-dir` (one .rcg and its .rcl).
For the left team it prints: the game cycles each play mode took (stopped time left out), the
goals it conceded, the cycles from each of its kick-offs to the next goal against it, where the
opponents first reached the ball after that kick-off (cycles and ball x), and how far the nearest
left outfield player was from the ball over the 50 cycles before each goal.
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path

import numpy as np

from elevens.robocup.imitate import read_game_log

KICKABLE = 1.085


def summarize(match_dir: Path) -> None:
    rcg = next(match_dir.glob("*.rcg"))
    game = read_game_log(rcg, rcg.with_suffix(".rcl"))
    modes = game.play_mode
    advancing = collections.Counter(
        modes[t] for t in range(1, len(modes)) if game.time[t] > game.time[t - 1]
    )
    print(f"== {match_dir}: {game.team_names[0]} (left) v {game.team_names[1]}")
    print("  game cycles by play mode:", dict(advancing.most_common(8)))
    ball = game.ball[:, :2]
    gap = np.hypot(*(game.positions - ball[:, None, None, :]).transpose(3, 0, 1, 2))
    to_goal, lost_at, lost_x, marking = [], [], [], []
    kick_off = None
    for t in range(1, len(modes)):
        if modes[t] == modes[t - 1]:
            continue
        if modes[t] == "kick_off_l":
            kick_off = t
        if modes[t] == "goal_r":
            marking.append(np.median(np.nanmin(gap[max(0, t - 50) : t, 0, 1:], axis=1)))
            if kick_off is not None:
                to_goal.append(t - kick_off)
                reached = np.flatnonzero(np.nanmin(gap[kick_off:t, 1], axis=1) <= KICKABLE)
                if len(reached):
                    lost_at.append(reached[0])
                    lost_x.append(ball[kick_off + reached[0], 0])
            kick_off = None
    print(f"  goals against: {sum(m == 'goal_r' for m in _starts(modes))}")
    if to_goal:
        print(f"  shows from our kick-off to the goal: median {np.median(to_goal):.0f}, "
              f"quartiles {np.percentile(to_goal, 25):.0f}-{np.percentile(to_goal, 75):.0f}")
    if lost_at:
        print(f"  opponents first at the ball after our kick-off: median {np.median(lost_at):.0f} "
              f"shows, at ball x median {np.median(lost_x):.1f} m")
    if marking:
        print(f"  nearest left outfield player to the ball, 50 shows before each goal: median "
              f"{np.median(marking):.1f} m")
    play_on = np.array([m == "play_on" for m in modes])
    print(f"  ball in the left half during play_on: {np.mean(ball[play_on, 0] < 0):.0%}")


def _starts(modes: list[str]) -> list[str]:
    return [modes[t] for t in range(1, len(modes)) if modes[t] != modes[t - 1]]


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for folder in sys.argv[1:]:
        summarize(Path(folder))
