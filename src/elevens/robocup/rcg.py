"""rcssserver's game logs (.rcg, the text format of version 5 and 6 that rcssserver 19 writes)
read into arrays, and what they say about a match from one team's side: where the goals came
from, who touched the ball, the free-kick faults it gave away, and when the players' stamina ran
out.

A game is read from its ``(team ...)``, ``(playmode ...)`` and ``(show ...)`` lines; a show
line gives the ball and every player's position, stamina and command counters. A **touch** is
a kick or tackle command that the server counted (its counter went up) while the ball was
within :data:`TOUCH_REACH` of the player at the show before: the server counts a kick command
whether or not the ball was in reach, and a team that kicks at the air must not look as if it
touched the ball. The side of view is a team's: its own goal at -x, whichever side it played.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "FaultStory",
    "GoalStory",
    "MatchLog",
    "TeamSummary",
    "find_logs",
    "read_rcg",
    "summarize_team",
]

TOUCH_REACH = 2.5
"""Metres: a counted kick or tackle with the ball farther than this at the show before was
not a touch (kickable area 1.085 m for the default player, a tackle reaches 2 m ahead)."""
# The play modes (less their side) whose taker may not touch the ball twice: rules.SET_PIECES,
# not imported (rules brings in the simulator's bodies, and this module only reads text).
_SET_PIECES = ("kick_off", "free_kick", "indirect_free_kick", "kick_in", "corner_kick",
               "goal_kick")
THIRDS = (-52.5, -17.5, 17.5, 52.5)
"""Our third, the middle, their third (x from our side)."""

_SHOW = re.compile(r"^\(show (\d+) ")
_BALL = re.compile(r"\(\(b\) (\S+) (\S+) ")
# ((side unum) type state x y ... (s stamina effort recovery capacity) ... (c counts))
_PLAYER = re.compile(
    r"\(\((l|r) (\d+)\) \S+ \S+ (\S+) (\S+) .*?\(s (\S+) \S+ \S+ (\S+)\).*?\(c ([^)]*)\)"
)
_PLAYMODE = re.compile(r"^\(playmode (\d+) (\S+)\)")
_TEAM = re.compile(r"^\(team (\d+) (\S+) (\S+) (\d+) (\d+)\)")
_KICK, _TACKLE = 0, 8  # indexes of the kick and tackle counts in "(c ...)"


@dataclasses.dataclass(frozen=True)
class MatchLog:
    """One game log as arrays over its ``T`` shows (a stopped clock repeats a cycle)."""

    path: str
    names: tuple[str, str]  # the left and the right team
    score: tuple[int, int]  # at the end
    cycle: np.ndarray  # int [T]
    ball: np.ndarray  # float [T, 2], the server's frame (left team attacks +x)
    pos: np.ndarray  # float [T, 2, 11, 2], side, shirt number - 1 (NaN: not on the field)
    stamina: np.ndarray  # float [T, 2, 11]
    capacity: np.ndarray  # float [T, 2, 11]
    touches: np.ndarray  # int [K, 3]: show index, side (0 left), shirt number
    playmodes: tuple[tuple[int, str], ...]  # (cycle, mode) as they changed
    # Per playmode, the shows before it: a stopped clock repeats a cycle, so only this orders
    # a mode against the shows (and so against the touches).
    playmode_shows: tuple[int, ...]

    def side_of(self, team: str | None) -> int:
        """0 or 1 for the team named ``team`` (None: the left team)."""
        if team is None:
            return 0
        if team not in self.names:
            raise ValueError(
                f"--team {team!r} did not play in {self.path} (its teams: "
                f"{self.names[0]!r} and {self.names[1]!r})"
            )
        return self.names.index(team)


def find_logs(paths: Sequence[str]) -> list[Path]:
    """The .rcg files among ``paths`` (files, or folders searched through), sorted; a path
    that does not exist, or that holds no .rcg, is a ValueError naming it."""
    found: list[Path] = []
    for text in paths:
        path = Path(text)
        if path.is_dir():
            logs = sorted(path.rglob("*.rcg"))
            if not logs:
                raise ValueError(f"{text!r} holds no .rcg game log (searched its subfolders)")
            found += logs
        elif path.is_file():
            if path.suffix != ".rcg":
                raise ValueError(f"{text!r} is not a .rcg game log (allowed: .rcg files, folders)")
            found.append(path)
        else:
            raise ValueError(f"{text!r} does not exist (allowed: .rcg files, folders)")
    return found


def read_rcg(path: str | Path) -> MatchLog:
    """Read a text .rcg of rcssserver 19; a file that is not one is a ValueError naming it."""
    path = Path(path)
    names: tuple[str, str] | None = None
    score = (0, 0)
    cycles: list[int] = []
    balls: list[tuple[float, float]] = []
    rows: list[np.ndarray] = []  # per show: [2, 11, 6] x, y, stamina, capacity, kicks, tackles
    modes: list[tuple[int, str]] = []
    mode_shows: list[int] = []
    with open(path, encoding="ascii", errors="replace") as f:
        header = f.readline()
        if not header.startswith("ULG"):
            raise ValueError(f"{str(path)!r} is not a text .rcg game log (its first line is "
                             f"{header.strip()[:20]!r}; allowed: ULG5 or ULG6)")
        for line in f:
            if line.startswith("(show "):
                show = _SHOW.match(line)
                ball = _BALL.search(line)
                if show is None or ball is None:
                    continue
                row = np.full((2, 11, 6), np.nan)
                for m in _PLAYER.finditer(line):
                    side, unum = int(m.group(1) == "r"), int(m.group(2)) - 1
                    counts = m.group(7).split()
                    row[side, unum] = (float(m.group(3)), float(m.group(4)), float(m.group(5)),
                                       float(m.group(6)), float(counts[_KICK]),
                                       float(counts[_TACKLE]))
                cycles.append(int(show.group(1)))
                balls.append((float(ball.group(1)), float(ball.group(2))))
                rows.append(row)
            elif line.startswith("(playmode "):
                mode = _PLAYMODE.match(line)
                if mode:
                    modes.append((int(mode.group(1)), mode.group(2)))
                    mode_shows.append(len(rows))
            elif line.startswith("(team "):
                team = _TEAM.match(line)
                if team:
                    names = (team.group(2), team.group(3))
                    score = (int(team.group(4)), int(team.group(5)))
    if names is None or not rows:
        raise ValueError(f"{str(path)!r} has no teams or no shows: not a game log of a match")
    table = np.stack(rows)
    ball_xy = np.asarray(balls)
    return MatchLog(
        path=str(path), names=names, score=score, cycle=np.asarray(cycles), ball=ball_xy,
        pos=table[..., :2], stamina=table[..., 2], capacity=table[..., 3],
        touches=_touches(ball_xy, table[..., :2], table[..., 4:6]), playmodes=tuple(modes),
        playmode_shows=tuple(mode_shows),
    )


def _touches(ball: np.ndarray, pos: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """[K, 3] (show index, side, shirt number): a counted kick or tackle with the ball in reach
    at the show before."""
    went_up = np.any(np.diff(counts, axis=0) > 0, axis=-1)  # [T-1, 2, 11]
    reach = np.linalg.norm(pos[:-1] - ball[:-1, None, None, :], axis=-1) <= TOUCH_REACH
    show, side, unum = np.nonzero(went_up & reach)
    order = np.lexsort((unum, side, show))
    return np.stack([show[order] + 1, side[order], unum[order] + 1], axis=1).astype(np.int64)


@dataclasses.dataclass(frozen=True)
class GoalStory:
    """A goal conceded by the team of view, told from its side (its goal at -x)."""

    cycle: int
    since_kick_off: int  # cycles since the team's own last kick-off (after a goal or a half)
    last_touch_cycle: int | None  # the team's last touch before the goal (None: none in the half)
    last_touch_x: float | None
    regained_x: float | None  # where the scorers' move began: their first touch after ours


@dataclasses.dataclass(frozen=True)
class FaultStory:
    """A free-kick fault given away by the team of view (``free_kick_fault_l/_r``: its set
    piece's taker touched the ball a second time before anyone else did)."""

    cycle: int
    set_piece: str  # the team's set piece before it: kick_off, free_kick, kick_in, ...
    conceded_cycle: int | None  # the goal it conceded before its next touch (None: none)


@dataclasses.dataclass(frozen=True)
class TeamSummary:
    """One team's matches (means a match where it says so)."""

    team: str
    matches: int
    goals_for: int
    goals_against: int
    touches_for: float  # a match
    touches_against: float
    ball_in_own_half: float  # share of the shows
    conceded: tuple[GoalStory, ...]
    faults: tuple[FaultStory, ...]
    capacity_empty_cycle: tuple[float, float]  # median over matches, per half (inf: never)

    def as_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out["capacity_empty_cycle"] = [None if math.isinf(c) else c
                                       for c in self.capacity_empty_cycle]
        return out

    def lines(self) -> list[str]:
        """The summary as text lines."""
        n = max(self.matches, 1)
        goals = self.conceded
        out = [
            f"{self.team}: {self.matches} matches, goals {self.goals_for} - "
            f"{self.goals_against} ({(self.goals_for - self.goals_against) / n:+.1f} a match), "
            f"touches {self.touches_for:.0f} - {self.touches_against:.0f} a match, the ball in "
            f"its own half {100 * self.ball_in_own_half:.0f}% of the time",
        ]
        if goals:
            regained = [g.regained_x for g in goals if g.regained_x is not None]
            counts = np.histogram(regained, bins=THIRDS)[0] if regained else np.zeros(3, int)
            last = [g.cycle - g.last_touch_cycle for g in goals if g.last_touch_cycle is not None]
            since = np.array([g.since_kick_off for g in goals])
            out += [
                f"  conceded {len(goals)}; where the scorers won the ball (after its last "
                f"touch): its own third {counts[0]}, the middle {counts[1]}, the far third "
                f"{counts[2]}, not at all (an own touch went in) {len(goals) - len(regained)}",
                f"  cycles from its last touch to the goal: median "
                f"{np.median(last) if last else float('nan'):.0f}; within 100 cycles of its "
                f"own kick-off: {int(np.sum(since < 100))} of {len(goals)}",
            ]
        faults = self.faults
        kinds = Counter(f.set_piece for f in faults)
        after = ", ".join(f"{kind} {count}" for kind, count in kinds.most_common())
        goals_after = sum(f.conceded_cycle is not None for f in faults)
        out.append(f"  free-kick faults given away: {len(faults)}" + (
            f" (after its {after}), {goals_after} followed by a goal conceded before its next "
            f"touch" if faults else ""))
        empty = [("never" if math.isinf(c) else f"cycle {c:.0f}")
                 for c in self.capacity_empty_cycle]
        out.append(f"  stamina capacity of its outfield players spent (mean, median match): "
                   f"first half {empty[0]}, second half {empty[1]}")
        return out


def _story(game: MatchLog, side: int, cycle: int, show: int) -> GoalStory:
    """The goal at ``show`` (its playmode's cycle ``cycle``) conceded by ``side``."""
    flip = 1.0 if side == 0 else -1.0
    kick_off = f"kick_off_{'lr'[side]}"
    kick_offs = [c for c, mode in game.playmodes if mode == kick_off and c <= cycle]
    half_start = 0 if cycle <= game.cycle.max() // 2 else int(game.cycle.max() // 2)
    touches = game.touches[game.touches[:, 0] < show]
    touches = touches[game.cycle[touches[:, 0]] >= half_start]
    ours = touches[touches[:, 1] == side]
    last_cycle = last_x = regained = None
    if len(ours):
        last = ours[-1]
        last_cycle = int(game.cycle[last[0]])
        last_x = float(flip * game.ball[last[0], 0])
        theirs = touches[(touches[:, 1] != side) & (touches[:, 0] > last[0])]
        if len(theirs):
            regained = float(flip * game.ball[theirs[0, 0], 0])
    elif len(touches):
        regained = float(flip * game.ball[touches[0, 0], 0])
    return GoalStory(
        cycle=cycle, since_kick_off=cycle - (kick_offs[-1] if kick_offs else 0),
        last_touch_cycle=last_cycle, last_touch_x=last_x, regained_x=regained,
    )


def _faults(game: MatchLog, side: int) -> list[FaultStory]:
    """The free-kick faults ``side`` gave away, each with the goal it conceded before its next
    touch (its next set piece begins with one) and in the same half."""
    letter = "lr"[side]
    half = int(game.cycle.max() // 2)
    ours = game.touches[game.touches[:, 1] == side, 0]
    modes = list(zip(game.playmodes, game.playmode_shows, strict=True))
    out = []
    set_piece = "play"
    for i, ((cycle, mode), shows) in enumerate(modes):
        if mode[:-2] in _SET_PIECES and mode.endswith(f"_{letter}"):
            set_piece = mode[:-2]
        if mode != f"free_kick_fault_{letter}":
            continue
        # A fault by a kick has its count in the first show after the mode: not a next touch.
        next_touch = ours[ours > shows]
        until = int(next_touch[0]) if len(next_touch) else len(game.cycle)
        conceded = None
        for (later, later_mode), later_shows in modes[i + 1:]:
            if later_shows >= until or (cycle <= half < later):
                break
            if later_mode == f"goal_{'rl'[side]}":
                conceded = later
                break
        out.append(FaultStory(cycle=cycle, set_piece=set_piece, conceded_cycle=conceded))
    return out


def _capacity_empty(game: MatchLog, side: int) -> tuple[float, float]:
    """The first cycle of each half at which the outfield players' mean capacity is spent."""
    mean = np.nanmean(game.capacity[:, side, 1:], axis=-1)  # the goalie (shirt 1) aside
    half = game.cycle.max() // 2
    out = []
    for first in (game.cycle <= half, game.cycle > half):
        empty = np.nonzero(first & (mean <= 1.0))[0]
        out.append(float(game.cycle[empty[0]]) if len(empty) else math.inf)
    return out[0], out[1]


def summarize_team(games: Iterable[MatchLog], team: str | None = None) -> TeamSummary:
    """The matches of ``team`` (None: the left team of each game), from its side."""
    stories: list[GoalStory] = []
    faults: list[FaultStory] = []
    goals_for = goals_against = 0
    touches_for = touches_against = 0
    own_half: list[float] = []
    empty: list[tuple[float, float]] = []
    name = team
    count = 0
    for game in games:
        side = game.side_of(team)
        name = game.names[side]
        count += 1
        goals_for += game.score[side]
        goals_against += game.score[1 - side]
        touches_for += int(np.sum(game.touches[:, 1] == side))
        touches_against += int(np.sum(game.touches[:, 1] != side))
        flip = 1.0 if side == 0 else -1.0
        own_half.append(float(np.mean(flip * game.ball[:, 0] < 0)))
        empty.append(_capacity_empty(game, side))
        faults += _faults(game, side)
        conceded = f"goal_{'rl'[side]}"
        for cycle, mode in game.playmodes:
            if mode == conceded:
                shows = np.nonzero(game.cycle <= cycle)[0]
                stories.append(_story(game, side, cycle, int(shows[-1]) + 1 if len(shows) else 0))
    if count == 0:
        raise ValueError("no game logs to summarise")
    halves = np.asarray(empty)
    return TeamSummary(
        team=name or "", matches=count, goals_for=goals_for, goals_against=goals_against,
        touches_for=touches_for / count, touches_against=touches_against / count,
        ball_in_own_half=float(np.mean(own_half)), conceded=tuple(stories), faults=tuple(faults),
        capacity_empty_cycle=(float(np.median(halves[:, 0])), float(np.median(halves[:, 1]))),
    )
