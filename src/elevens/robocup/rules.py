"""Playing by the rules in a real match: kick-off formation, set pieces, the goalie's catch.

A policy trained in elevens knows play_on only: the simulator has no referee stoppages, and its
keeper has no hands. In rcssserver the referee stops play for kick-offs, kick-ins, corners, free
kicks and goal kicks, and the server ignores a kick by the team that does not have the set
piece. :func:`apply_rules` takes the policy's commands for one team and one cycle and replaces
some of them with short scripted routines, then hands back to the policy when play resumes:

* **before_kick_off, after a goal, at half time**: every player ``(move)``-s to its formation
  slot in its own half (the simulator's formation, scaled to 105 x 68); the kick-off taker
  stands at the ball when its side kicks off.
* **our set piece** (kick_off, kick_in, corner_kick, free_kick, goal_kick, indirect_free_kick):
  the player nearest the ball (the goalie only when it holds the ball after a catch, or for a
  goal kick) turns to it,
  runs to it and kicks: at the goal from within ``SHOOT_RANGE`` of it, a pass back to a
  midfield slot at kick-off, else a long ball up the wing. Everybody else plays the policy
  (but the goalie, which guards its goal) less its kicks, tackles and catches: the first
  kick makes the server's taker, which must be the one the second-touch ban follows.
* **the goalie catches** in play_on: the ball fresh in its latest see, within the catchable
  area (1.2 m along the catch direction) and the goalie inside its penalty area: ``(catch)``;
  not while the ball's last kick was a teammate's (:class:`LastKick`: a back pass).
* **the goalie guards the goal** in play and in set pieces it does not take (:func:`guard_goal`):
  it faces the ball and keeps to the line from the goal's centre to the ball, closer to the
  ball as it comes; a ball inside the penalty area it goes for, so that it can catch it.
* **no second touch** (:class:`SecondTouch`, :func:`no_second_touch`): rcssserver gives the
  opponents a free kick (``free_kick_fault``) when the player that put the ball in play from a
  set piece touches it again (a kick, a tackle, a catch, or running into it) after a dash of
  its own, before another player has touched it. So after its kick the taker sends no kick,
  tackle or catch once it has dashed, and no dash while the ball is near enough to run into;
  the ban lasts until the server shows another touch (a teammate's kick count or its collision
  with the ball in its sense_body, an opponent seen kicking with the ball in its reach) or the
  play mode leaves play_on.

Frames as elevens.robocup.observe: each team's own frame (x towards the opponent goal, y up,
radians, + = to the left); server commands in degrees with + = clockwise.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from elevens.env.params import formation
from elevens.robocup.bodies import (
    GUARD_DEPTH,
    GUARD_FACE_BALL,
    GUARD_SLACK,
    HALF_CYCLES,
    STAMINA_RESERVE,
)
from elevens.robocup.bodies import PENALTY_AREA as RCSS_PENALTY_AREA
from elevens.robocup.observe import FIELD_LENGTH, FIELD_WIDTH, PerceptMemory
from elevens.robocup.protocol import Catch, Command, Dash, Kick, Move, Tackle, Turn

__all__ = [
    "CATCH_REACH",
    "LastKick",
    "MATCH_CLOCK",
    "MatchRoutines",
    "SHOOT_RANGE",
    "TeamView",
    "apply_rules",
    "kick_off_positions",
    "kicks_off_next",
    "near_ball",
    "touched_by_another",
    "guard_goal",
    "mode_kind",
    "no_second_touch",
    "SecondTouch",
]

CATCH_REACH = 1.15  # metres: server::catchable_area_l = 1.2, less the see's quantisation
SEARCH_TURN = 90.0  # degrees a player turns a cycle in our set piece while nobody sees the ball
SHOOT_RANGE = 30.0  # metres to the opponent goal within which a set piece is a shot
KICKABLE = 1.085  # player_size + ball_size + kickable_margin of the default player type
# |x| from, |y| up to (the penalty box flags): 36.0, 20.16
PENALTY_AREA = (FIELD_LENGTH / 2 - RCSS_PENALTY_AREA[0], RCSS_PENALTY_AREA[1])
_HALF = np.array([FIELD_LENGTH / 2, FIELD_WIDTH / 2])
_SIM_FIELD = np.array([50.0, 35.0])  # the simulator's default half extents (formation slots)
_TURN_FIRST = math.radians(12.0)  # a taker further off its line to the ball turns first
_TOUCHES = (Kick, Tackle, Catch)  # the commands that touch the ball
_BALL_DECAY = 0.94  # server::ball_decay
_KICK_POWER_RATE = 0.027  # server::kick_power_rate
# Set pieces that the side named by the suffix takes.
SET_PIECES = (
    "kick_off",
    "kick_in",
    "corner_kick",
    "free_kick",
    "goal_kick",
    "indirect_free_kick",
)
MOVE_MODES = ("before_kick_off", "goal_l", "goal_r")
# Faults, named by the side that committed them (before SET_PIECES: "free_kick_fault_l" is
# the left team's fault, not its free kick).
FAULTS = (
    "free_kick_fault",
    "catch_fault",
    "back_pass",
    "foul_charge",
    "foul_push",
    "foul_multiple_attack",
    "offside",
)


# STAMINA_RESERVE: stamina a player keeps for itself (server::stamina_max 8000; below
# effort_dec_thr x max = 2400 its effort falls for good); above it a player dashes as the policy
# asks. HALF_CYCLES: each half restores the capacity. Shared with the simulator's copy of this
# rule (elevens.robocup.bodies.paced_power).
RECOVERING_DASH = 30.0
"""The dash power at or below the reserve when the stamina capacity is unknown: less than the
stamina a player recovers a cycle (server::stamina_inc_max 45), so it walks while its stamina
comes back."""


def pace_dashes(
    commands: Sequence[Command | None],
    stamina: Sequence[float | None],
    capacity: Sequence[float | None] | None = None,
    server_time: int | None = None,
) -> list[Command | None]:
    """Each player's dash capped to what its stamina allows; the same for every elevens team,
    like the set pieces and the catch. A player spends the stamina above
    ``STAMINA_RESERVE`` freely and, beyond it, its stamina capacity (what recovery can still
    refill this half) evenly over the cycles left in the half. Without it a team that dashes
    at full power every cycle (the "sim" rule's ``|move| * 100``) has no stamina left after
    600 cycles of each half (docs/results/robocup.md, session 15). ``stamina[i]`` and
    ``capacity[i]``: player i's latest sense_body (None: unknown; an unknown stamina leaves the
    dash as it is, an unknown capacity allows ``RECOVERING_DASH`` beyond the reserve)."""
    cycles_left = HALF_CYCLES - (server_time or 0) % HALF_CYCLES
    capacities = capacity if capacity is not None else [None] * len(commands)
    paced: list[Command | None] = []
    for command, left, tank in zip(commands, stamina, capacities, strict=True):
        if isinstance(command, Dash) and left is not None:
            steady = RECOVERING_DASH if tank is None else tank / cycles_left
            spare = max(left - STAMINA_RESERVE, 0.0) + steady
            if abs(command.power) > spare:
                command = dataclasses.replace(
                    command, power=math.copysign(spare, command.power)
                )
        paced.append(command)
    return paced


def mode_kind(play_mode: str, side: int) -> str:
    """What a play mode asks of ``side`` (0 left, 1 right): "move" (go to the kick-off
    formation), "ours" (our set piece), "theirs" (theirs: the policy plays, the server keeps us
    away from the ball), "play" (play_on and the rest), "over" (time_over)."""
    if play_mode == "time_over":
        return "over"
    if play_mode in MOVE_MODES:
        return "move"
    for fault in FAULTS:  # the side named committed it: the other side's free kick follows
        if play_mode.startswith(fault + "_") and play_mode[-1] in "lr":
            return "theirs" if play_mode[-1] == "lr"[side] else "play"
    for piece in SET_PIECES:
        if play_mode.startswith(piece + "_") and play_mode[-1] in "lr":
            return "ours" if play_mode[-1] == "lr"[side] else "theirs"
    return "play"


def kicks_off_next(play_mode: str, side: int, halves_played: int) -> bool:
    """Whether ``side`` takes the next kick-off, judged in a "move" mode: the side that
    conceded after a goal; else left in the first half (``halves_played`` = 1), right in the
    second, and so on (rcssserver alternates)."""
    if play_mode in ("goal_l", "goal_r"):
        return play_mode[-1] != "lr"[side]
    return (halves_played - 1) % 2 == side


def kick_off_positions(players_per_team: int, *, taker: bool) -> np.ndarray:
    """The kick-off formation f64[n, 2] in the team's own frame, all in the own half; with
    ``taker`` the player whose slot is nearest the centre stands at the ball."""
    slots = formation(players_per_team) * (_HALF / _SIM_FIELD)
    slots[:, 0] = np.minimum(slots[:, 0], -1.0)
    if taker:
        slots[kick_off_taker(players_per_team)] = (-0.4, 0.0)
    return slots


def kick_off_taker(players_per_team: int) -> int:
    """The player (index) whose formation slot is nearest the centre spot."""
    slots = formation(players_per_team)
    return int(np.argmin(np.hypot(slots[:, 0], slots[:, 1])))


@dataclasses.dataclass(frozen=True)
class TeamView:
    """What one team knows in one cycle, from its players' percepts (own frame, metres).

    ``ball_seen`` bool[n]: the ball is in the player's latest see; ``ball_distance`` f[n] and
    ``ball_bearing`` f[n] (radians, + = left of the body) from it; ``stale`` i[n]: cycles since
    that see (0: this cycle).
    """

    position: np.ndarray
    heading: np.ndarray
    ball_seen: np.ndarray
    ball_distance: np.ndarray
    ball_bearing: np.ndarray
    stale: np.ndarray

    def ball_position(self, player: int) -> np.ndarray:
        """Where ``player`` saw the ball, in the team frame."""
        angle = self.heading[player] + self.ball_bearing[player]
        d = self.ball_distance[player]
        return self.position[player] + d * np.array([math.cos(angle), math.sin(angle)])


def _degrees_clockwise(bearing: float) -> float:
    """A bearing (radians, + = left) as a server direction (degrees, + = clockwise)."""
    return -math.degrees(math.atan2(math.sin(bearing), math.cos(bearing)))


def _kick_to(view: TeamView, player: int, target: np.ndarray, power: float) -> Kick:
    delta = target - view.position[player]
    bearing = math.atan2(delta[1], delta[0]) - view.heading[player]
    return Kick(float(power), _degrees_clockwise(bearing))


def _pass_power(distance: float) -> float:
    """Kick power that rolls the ball about ``distance`` metres (it decays by 0.94 a cycle)."""
    return float(np.clip(distance * (1 - _BALL_DECAY) / _KICK_POWER_RATE + 15.0, 20.0, 100.0))


def _set_piece_kick(view: TeamView, player: int, play_mode: str, n: int) -> Kick:
    goal = np.array([_HALF[0], 0.0])
    ball = view.ball_position(player)
    if np.linalg.norm(goal - ball) < SHOOT_RANGE:
        aim = goal + np.array([0.0, -3.5 if ball[1] > 0 else 3.5])  # the far post's side
        return _kick_to(view, player, aim, 100.0)
    if play_mode.startswith("kick_off") and n > 1:
        target = np.array([-12.0, 8.0 if view.position[player][1] <= 0 else -8.0])
        return _kick_to(view, player, target, _pass_power(float(np.linalg.norm(target - ball))))
    wing = np.array([min(ball[0] + 30.0, 40.0), 24.0 if ball[1] >= 0 else -24.0])
    return _kick_to(view, player, wing, 100.0)


def _go_to_ball(view: TeamView, player: int) -> Command | None:
    bearing = float(view.ball_bearing[player])
    if abs(bearing) > _TURN_FIRST:
        # A see's bearing is from before the turns made since: turning again on it overshoots
        # (a taker spun in place for 100 cycles), so turn on a fresh see only.
        return Turn(_degrees_clockwise(bearing)) if view.stale[player] == 0 else None
    return Dash(100.0 if view.ball_distance[player] > 3.0 else 50.0)


def set_piece_taker(
    view: TeamView, exclude: int | None = None, keep: int | None = None
) -> int | None:
    """The player nearest the ball among those who see it (but ``exclude``); None when nobody
    does. ``keep``: the taker so far, who stays the taker while it sees the ball (nearest by
    each see, the takers took turns and nobody reached the ball)."""
    if keep is not None and keep != exclude and view.ball_seen[keep]:
        return keep
    seen = np.flatnonzero(view.ball_seen)
    if exclude is not None:
        seen = seen[seen != exclude]
    if len(seen) == 0:
        return None
    return int(seen[np.argmin(view.ball_distance[seen])])


def our_set_piece_taker(
    view: TeamView, play_mode: str, goalie: int | None = 0, keep: int | None = None
) -> int | None:
    """Who takes our set piece in ``play_mode`` (see :func:`set_piece_taker`; ``keep``: the
    taker so far)."""
    holder = goalie is not None and view.ball_seen[goalie] and (
        view.ball_distance[goalie] <= KICKABLE and play_mode.startswith("free_kick")
    )
    if holder:
        return goalie
    # The goalie leaves its goal for a goal kick or a ball it holds only: it once ran 30 m
    # to a kick-in and helios-base scored into the empty goal.
    stays = None if play_mode.startswith("goal_kick") else goalie
    return set_piece_taker(view, exclude=stays, keep=keep)


def _in_own_penalty_area(position: np.ndarray) -> bool:
    return bool(position[0] <= -PENALTY_AREA[0] and abs(position[1]) <= PENALTY_AREA[1])


def apply_rules(
    commands: Sequence[Command | None],
    view: TeamView,
    play_mode: str,
    side: int,
    *,
    halves_played: int = 1,
    goalie: int | None = 0,
    catch_allowed: bool = True,
    taker: int | None = None,
) -> tuple[list[Command | None], str]:
    """The policy's ``commands`` (one per player) with the routines of the module docstring
    applied for ``side`` in ``play_mode``. Returns (commands, what: "move", "set_piece",
    "catch" or "policy"). ``goalie``: the goalie's index (None: no goalie); ``catch_allowed``:
    False during the server's catch ban (5 cycles after an attempt); ``taker``: who took our
    set piece last cycle (:func:`our_set_piece_taker`)."""
    n = len(commands)
    out = list(commands)
    kind = mode_kind(play_mode, side)
    if kind == "over":
        return [None] * n, "move"
    if kind == "move":
        ours = kicks_off_next(play_mode, side, halves_played)
        for i, (x, y) in enumerate(kick_off_positions(n, taker=ours)):
            out[i] = Move(float(x), float(-y))  # the server's own frame has y down
        return out, "move"
    if kind == "ours":
        taker = our_set_piece_taker(view, play_mode, goalie, keep=taker)
        # Only the taker touches the ball: the server's taker is whoever kicks first, and a
        # policy's kick (the kick-off slot stands at the ball) made a player the taker that
        # the ban (SecondTouch) did not follow: it ran into its own kick, a free kick against.
        out = [None if i != taker and isinstance(c, _TOUCHES) else c for i, c in enumerate(out)]
        if taker is None:
            # Nobody sees the ball: the outfield players look for it (the set piece would
            # otherwise wait for ever; a quarter turn at a time covers the field in a few sees).
            for i in range(n):
                if i != goalie:
                    out[i] = Turn(SEARCH_TURN)
            return out, "set_piece"
        if view.ball_distance[taker] <= KICKABLE:
            # Aimed from the see's heading: on a stale see the taker may have turned since.
            fresh = view.stale[taker] == 0
            out[taker] = _set_piece_kick(view, taker, play_mode, n) if fresh else None
        else:
            out[taker] = _go_to_ball(view, taker)
        return out, "set_piece"
    if (
        kind == "play"
        and play_mode == "play_on"
        and goalie is not None
        and catch_allowed
        and view.ball_seen[goalie]
        and view.stale[goalie] == 0
        and view.ball_distance[goalie] <= CATCH_REACH
        and abs(view.ball_bearing[goalie]) <= math.pi / 2  # the server's catch range: +-90
        and _in_own_penalty_area(view.position[goalie])
    ):
        # Clipped: a float32 bearing that passes the check above as pi/2 is 90.0000025 degrees
        # in float64, which the server's range refuses.
        direction = _degrees_clockwise(float(view.ball_bearing[goalie]))
        out[goalie] = Catch(min(max(direction, -90.0), 90.0))
        return out, "catch"
    return out, "policy"


KINDS_GUARDED = ("play", "theirs", "ours")  # mode kinds in which the goalie guards its goal
_FACE_BALL = math.radians(GUARD_FACE_BALL)


def _ball_estimate(view: TeamView) -> np.ndarray | None:
    """The ball where the nearest player that sees it saw it (team frame); None if nobody
    does."""
    taker = set_piece_taker(view)
    return None if taker is None else view.ball_position(taker)


def guard_goal(
    commands: Sequence[Command | None],
    view: TeamView,
    play_mode: str,
    side: int,
    *,
    goalie: int | None = 0,
    goalie_busy: bool = False,
) -> tuple[list[Command | None], bool]:
    """The goalie's routine in play and in every set piece (module docstring): ``commands``
    with the goalie's replaced, and whether it was. Left alone when nobody sees the ball, when
    ``goalie_busy`` (a routine of :func:`apply_rules` gave the goalie its command: it takes
    the set piece or catches), and in the moves before a kick-off."""
    out = list(commands)
    kind = mode_kind(play_mode, side)
    if goalie is None or goalie_busy or kind not in KINDS_GUARDED:
        return out, False
    ball = _ball_estimate(view)
    if ball is None:
        return out, False
    position, heading = view.position[goalie], float(view.heading[goalie])
    to_ball = ball - position
    bearing = math.atan2(to_ball[1], to_ball[0]) - heading
    bearing = math.atan2(math.sin(bearing), math.cos(bearing))
    goal = np.array([-_HALF[0], 0.0])
    if _in_own_penalty_area(ball) and kind == "play":
        target = ball  # go for it: the catch rule takes it in reach
    else:
        from_goal = ball - goal
        distance = float(np.linalg.norm(from_goal))
        depth = float(np.clip(0.25 * distance, *GUARD_DEPTH))
        target = goal + from_goal / max(distance, 1e-6) * depth
    offset = target - position
    gap = float(np.linalg.norm(offset))
    # Pose and bearing are the latest see's: after a turn they are out of date until the next
    # see, so it turns on a fresh see only (turning on each stale one spun it round).
    fresh = view.stale[goalie] == 0
    if abs(bearing) > _FACE_BALL:
        out[goalie] = Turn(_degrees_clockwise(bearing)) if fresh else None
    elif gap > GUARD_SLACK:
        # Facing the ball, it steps to its point in any direction (the server's omni-dash).
        direction = math.atan2(offset[1], offset[0]) - heading
        out[goalie] = Dash(float(min(100.0, 30.0 * gap + 20.0)), _degrees_clockwise(direction))
    else:
        out[goalie] = Turn(_degrees_clockwise(bearing)) if fresh else None
    return out, True


# rcssserver 19 (FreeKickRef): once the set piece's kick is taken, a touch by the same player
# (kick, tackle, catch or a collision with the ball) is a free_kick_fault if that player has
# dashed since the kick; a touch by anyone else, or any play mode but play_on, ends it. The
# server counts a kick only when the ball was in reach (sense_body's kick count), so a
# teammate's rising count is a touch; its sense_body's collision with the ball is one too.
_COLLIDE = 0.385  # player_size + ball_size: closer than this, the player runs into the ball
_PLAYER_SPEED_MAX = 1.05  # metres a cycle (player_speed_max of the default player type)


@dataclasses.dataclass
class SecondTouch:
    """The server's ban on a set piece's taker (module docstring), as one team can follow it.

    ``taker``: the player that took our last set piece (None: no ban); ``mode``: the set piece's
    play mode; ``in_play``: play_on was seen since the kick; ``dashed``: a dash went out to the
    taker since its kick (after that, any touch is a fault); ``kicks``: each player's kick
    count at its latest sense_body."""

    taker: int | None = None
    mode: str = ""
    in_play: bool = False
    dashed: bool = False
    kicks: dict[int, int] = dataclasses.field(default_factory=dict)

    def start(self, taker: int, mode: str) -> None:
        """``taker`` kicked in our set piece ``mode``: the ban begins (again, after a kick that
        may not have reached the ball)."""
        self.taker, self.mode, self.in_play, self.dashed = taker, mode, False, False

    def observe(self, mode: str, touched: bool) -> None:
        """This cycle's play mode and whether another player touched the ball (see
        :func:`touched_by_another`): the ban ends as the server's does."""
        if self.taker is None:
            return
        if touched:
            self.taker = None
        elif mode == "play_on":
            self.in_play = True
        elif self.in_play or mode != self.mode:
            # Any stoppage after the kick clears the server's ban; before play_on was seen,
            # only the set piece's own mode (the kick may not have reached the ball) keeps it.
            self.taker = None

    def sent(self, commands: Sequence[Command | None]) -> None:
        """The commands that went out this cycle: note the taker's dash."""
        if self.taker is not None and isinstance(commands[self.taker], Dash):
            self.dashed = True


def _relative(obj: Any) -> np.ndarray | None:
    """A see object's position relative to the seer's head (metres; frame irrelevant)."""
    if obj.distance is None:
        return None
    angle = math.radians(obj.direction)
    return obj.distance * np.array([math.cos(angle), math.sin(angle)])


def touched_by_another(
    cycle: Any,
    side: int,
    n: int,
    touch: SecondTouch,
    team_names: tuple[str, str],
    *,
    kickable: float = KICKABLE,
) -> bool:
    """Whether this cycle's percepts show a player other than ``touch.taker`` touching the
    ball in the step that just passed: a teammate's sense_body kick count rose (the server
    counts only kicks that reached the ball) or it reports a collision with the ball; or one
    of our players sees an opponent kicking (the ``k`` mark) with the ball, in the same see,
    within ``kickable`` of it. ``touch.kicks`` is updated. Team mates seen kicking do not count:
    their own sense_body says for sure."""
    touched = False
    ours = team_names[side]
    for player in cycle.players:
        i = player.unum - 1
        if player.side != side or not 0 <= i < n:
            continue
        body = player.sense_body
        other = i != touch.taker
        if body is not None and body.counts.kick is not None:
            before = touch.kicks.get(i)
            touched |= other and before is not None and body.counts.kick > before
            touch.kicks[i] = body.counts.kick
        if body is not None and other and body.collisions and "ball" in body.collisions:
            touched = True
        if player.see is None or touch.taker is None or touched:
            continue  # the sees matter only to a ban that is on and not over yet
        balls = [o for o in player.see.objects if o.kind == "ball" and o.distance is not None]
        if not balls:
            continue
        ball = _relative(min(balls, key=lambda o: o.distance))
        for obj in player.see.objects:
            if obj.kind != "player" or not obj.kicking or obj.team in (None, ours):
                continue
            where = _relative(obj)
            if where is not None and ball is not None:
                touched |= bool(np.linalg.norm(where - ball) <= kickable)
    return touched


@dataclasses.dataclass
class LastKick:
    """Whether the ball's last kick was ours, as one team can tell: rcssserver (CatchRef) calls
    a back pass, an indirect free kick to the opponents where the goalie stood, when the goalie
    catches a ball whose last kick or tackle was a teammate's (a collision does not count), and
    forgets the kicker at any play mode but play_on. ``kicks``: each player's kick and tackle
    count at its latest sense_body."""

    ours: bool = False
    kicks: dict[int, int] = dataclasses.field(default_factory=dict)

    def observe(self, cycle: Any, mode: str, side: int, n: int, team_names: tuple[str, str],
                *, goalie: int | None = 0, kickable: float = KICKABLE) -> None:
        """This cycle's percepts and play mode: a teammate's rising count makes the last kick
        ours (the goalie's own kick leaves it as it was: after an opponent's kick the server
        lets it catch); an opponent seen kicking, or seen with the ball in its reach (a see shows a
        kick one time in three), makes it theirs; a stoppage clears it."""
        teammate = False
        for player in cycle.players:
            i = player.unum - 1
            body = player.sense_body
            if player.side != side or not 0 <= i < n or body is None or body.counts.kick is None:
                continue
            count = body.counts.kick + (body.tackle_count or 0)
            before = self.kicks.get(i)
            teammate |= i != goalie and before is not None and count > before
            self.kicks[i] = count
        if teammate:
            self.ours = True
        elif self.ours and _opponent_at_ball(cycle, side, team_names[side], kickable):
            self.ours = False
        if mode != "play_on":
            self.ours = False


def _opponent_at_ball(cycle: Any, side: int, ours: str, kickable: float) -> bool:
    """Whether one of our players' sees this cycle shows an opponent kicking or tackling, or
    within ``kickable`` of the ball."""
    for player in cycle.players:
        if player.side != side or player.see is None:
            continue
        balls = [o for o in player.see.objects if o.kind == "ball" and o.distance is not None]
        if not balls:
            continue
        ball = _relative(min(balls, key=lambda o: o.distance))
        for obj in player.see.objects:
            if obj.kind != "player" or obj.team in (None, ours):
                continue
            where = _relative(obj)
            near = where is not None and ball is not None and (
                np.linalg.norm(where - ball) <= kickable)
            if near or obj.kicking or obj.tackling:
                return True
    return False


def _ball_gap(view: TeamView, player: int) -> tuple[float, int] | None:
    """How far ``player`` is from the ball (its own see, else the nearest teammate's that sees
    it) and how many cycles old that is; None when nobody sees the ball."""
    if view.ball_seen[player]:
        return float(view.ball_distance[player]), int(view.stale[player])
    seer = set_piece_taker(view, exclude=player)
    if seer is None:
        return None
    gap = float(np.linalg.norm(view.ball_position(seer) - view.position[player]))
    return gap, int(max(view.stale[seer], view.stale[player]))


def near_ball(view: TeamView, player: int) -> bool:
    """Whether ``player`` could run into the ball by dashing now: within what it covers in
    the cycles since the see plus two (the dash, then the coast after it) at full speed."""
    gap = _ball_gap(view, player)
    if gap is None:
        return False
    distance, stale = gap
    return distance <= _COLLIDE + _PLAYER_SPEED_MAX * (stale + 2)


def no_second_touch(
    commands: Sequence[Command | None], view: TeamView, state: SecondTouch
) -> list[Command | None]:
    """``commands`` with the banned taker's (``state``, module docstring) replaced by no
    command: a kick, tackle or catch once it has dashed since its kick, and a dash near the
    ball (:func:`near_ball`), which could run into it and would make its next touch a fault.
    Turns and dashes away from the ball's reach go out."""
    out = list(commands)
    taker = state.taker
    if taker is None or not state.in_play:
        return out
    command = out[taker]
    touches = isinstance(command, _TOUCHES) and state.dashed
    if touches or (isinstance(command, Dash) and near_ball(view, taker)):
        out[taker] = None
    return out


CATCH_BAN = 5  # server::catch_ban_cycle: cycles between two catch attempts
MATCH_CLOCK = 400
"""Time left in a ruled team's observations restarts at each kick-off and every this many
cycles of play: policies were trained on episodes of about this length and have never seen a
6000-cycle game."""


def team_view(memory: PerceptMemory, side: int) -> TeamView:
    """One team's row of the memory as a TeamView (ball from the latest see)."""
    ball = memory.entities[side, :, -1, :]
    seen = memory.mask[side, :, -1]
    bearing = np.arctan2(ball[:, 2], ball[:, 1])
    distance = np.where(seen, ball[:, 0] * memory.params.field_length, np.inf)
    close = np.isfinite(memory.ball_distance[side]) & ~seen
    # A ball only felt close behind ((B) outside the cone): its distance, bearing unknown (pi).
    distance = np.where(close, memory.ball_distance[side], distance)
    bearing = np.where(close, math.pi, bearing)
    return TeamView(
        position=memory.position[side].copy(),
        heading=memory.heading[side].copy(),
        ball_seen=seen | close,
        ball_distance=distance,
        ball_bearing=bearing,
        stale=memory.stale[side].copy(),
    )


def staminas(cycle: Any, side: int, n: int) -> tuple[list[float | None], list[float | None]]:
    """Each of a team's players' latest stamina and stamina capacity (unum order; None:
    unknown) from a client Cycle."""
    stamina: list[float | None] = [None] * n
    capacity: list[float | None] = [None] * n
    for player in cycle.players:
        body = player.sense_body
        if player.side == side and body is not None and 1 <= player.unum <= n:
            stamina[player.unum - 1] = float(body.stamina)
            if body.stamina_capacity is not None:
                capacity[player.unum - 1] = float(body.stamina_capacity)
    return stamina, capacity


@dataclasses.dataclass
class MatchRoutines:
    """Every routine of the module docstring for one team over a match (or a training episode
    played as one): what a team runs between its policy and the server each cycle, with the
    bookkeeping that spans cycles (halves, the catch ban, the set-piece taker, the clock of
    the observations). ``elevens robocup match`` and ``RoboCupEnv(episodes="match")`` both use
    it, so a policy trains under the routines it plays under."""

    side: int
    n: int
    kickable: float = KICKABLE
    halves: int = 1  # the half being played (before_kick_off again: the next one)
    previous_mode: str = "before_kick_off"
    cycles: int = 0
    clock: int = 0  # cycles since the last kick-off (the observations' time)
    last_catch: int = -CATCH_BAN
    catches: int = 0
    set_piece_cycles: int = 0
    touch: SecondTouch = dataclasses.field(default_factory=SecondTouch)
    last_kick: LastKick = dataclasses.field(default_factory=LastKick)
    taker: int | None = None  # who is taking our set piece
    # Per player, last cycle: a routine's command went out instead of the policy's (a move,
    # a set piece, the goalie's guard or catch, a blocked second touch). Stamina pacing only
    # lowers the policy's own dash, so it does not count.
    scripted: list[bool] = dataclasses.field(default_factory=list)

    def observe_mode(self, mode: str) -> int:
        """Note this cycle's play mode before the policy acts; the observations' clock."""
        if mode == "before_kick_off" and self.previous_mode != "before_kick_off":
            self.halves += 1  # half time
        if mode.startswith("kick_off"):
            self.clock = 0
        self.previous_mode = mode
        return self.clock % MATCH_CLOCK

    def apply(
        self, commands: Sequence[Command | None], memory: PerceptMemory, cycle: Any
    ) -> tuple[list[Command | None], str]:
        """The policy's commands for this cycle (the one :meth:`observe_mode` saw) with the
        routines applied; (commands, what: "move", "set_piece", "catch" or "policy")."""
        mode = self.previous_mode
        view = team_view(memory, self.side)
        touched = touched_by_another(
            cycle, self.side, self.n, self.touch, memory.team_names, kickable=self.kickable
        )
        self.touch.observe(mode, touched)
        self.last_kick.observe(cycle, mode, self.side, self.n, memory.team_names,
                               kickable=self.kickable)
        policy = list(commands)
        out, what = apply_rules(
            policy,
            view,
            mode,
            self.side,
            halves_played=self.halves,
            # No catch after a teammate's kick: a back pass gives the opponents a free kick in
            # our penalty area (naive's goalie caught its kick-off taker's ball 28 times in 3
            # matches against helios-base; 22 goals followed).
            catch_allowed=self.cycles - self.last_catch >= CATCH_BAN and not self.last_kick.ours,
            taker=self.taker,
        )
        ours = mode_kind(mode, self.side) == "ours"
        self.taker = our_set_piece_taker(view, mode, keep=self.taker) if ours else None
        if what == "set_piece":
            for i, (mine, routine) in enumerate(zip(policy, out, strict=True)):
                if isinstance(routine, Kick) and routine is not mine:
                    self.touch.start(i, mode)
        busy = out[0] is not policy[0]  # a routine's command
        out, _ = guard_goal(out, view, mode, self.side, goalie_busy=busy)
        if what in ("policy", "catch"):
            out = no_second_touch(out, view, self.touch)
            if what == "catch" and not isinstance(out[0], Catch):
                what = "policy"  # the goalie took the set piece and has dashed since
        self.scripted = [mine is not sent for mine, sent in zip(policy, out, strict=True)]
        stamina, capacity = staminas(cycle, self.side, self.n)
        out = pace_dashes(out, stamina, capacity, int(cycle.server_time))
        self.touch.sent(out)
        if what == "catch":
            self.catches += 1
            self.last_catch = self.cycles
        self.set_piece_cycles += what == "set_piece"
        self.cycles += 1
        self.clock += 1
        return out, what
