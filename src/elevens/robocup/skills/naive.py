"""``skills_naive``: the scripted yardstick team over the skills decision space.

In open play (vectorised over every deciding player, one call a cycle):

- the player with the ball shoots when within :data:`SHOOT_RANGE` of their goal, at the point
  of the goal mouth farthest (in angle) from every opponent; else passes forward to the most
  open teammate (widest gap between the passing lane and any opponent, onside, 4 to 35 m
  away); else dribbles in the direction of the eight nearest the goal whose path is clear;
  when every forward path is blocked by an opponent at arm's length, it holds, unless an
  opponent can kick the ball too: then it clears it at their goal as a shot is kicked (two
  holders kick the ball to either side of it and it stays between them). From our
  third a pass needs a wider lane (:data:`SAFE_GAP`) and never goes across our box;
- otherwise the player who reaches the ball first by librcsc's intercept table intercepts,
  unless a teammate already has it; one with a good chance tackles an opponent who has it;
  while they have the ball, the nearest other outfield player (two, when the interceptor is
  not the nearest) stands :data:`COVER_DISTANCE` goal-side of it, and the free defenders
  and midfielders mark the attackers in our third (:func:`_marks`);
- everyone else goes to a formation slot that slides with the ball (kept onside): while we
  have the ball, stepped up :data:`ATTACK_PUSH`; while they have it, a block
  :data:`DEFEND_DROP` deeper and narrower, drawn to the ball's side, never deeper than
  :data:`DEEPEST` (:func:`_slots`).

Before a kick-off the players move to their slots in their own half. The goalie plays the
proxy's ready goalie behaviour in every mode but the kick-off placing, and set pieces and
penalties are the proxy's ready behaviours: these are the parts a learned team replaces
first. With ``set_plays="decided"`` (:class:`SkillsNaive`) our kick-offs, free kicks, kick-ins
and corners are played by the open-play rules too (``set_plays``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from elevens.robocup.skills.decode import FORMATION, SLIDE, slot_targets
from elevens.robocup.skills.observe import PLAYERS, Observation, observe
from elevens.robocup.skills.planner import Choose
from elevens.robocup.skills.runtime import rowwise
from elevens.robocup.skills.set_plays import TakerGuard, decided_set_play
from elevens.robocup.skills.space import (
    DRIBBLE_DIRECTIONS,
    GOAL,
    GOAL_HALF_WIDTH,
    Decisions,
    Kind,
    to_player_actions,
)

__all__ = [
    "ATTACK_PUSH", "DEEPEST", "DEFEND_DROP", "FORMATION", "SHOOT_RANGE", "SLIDE",
    "kick_off_points", "naive_choices", "outside_open_play", "routine_rows",
    "SkillsNaive", "skills_naive", "SkillsPlanner", "helios_parts", "skills_naive_decisions",
    "skills_planner", "slot_targets",
]

SHOOT_RANGE = 25.0
PASS_MIN, PASS_MAX = 4.0, 35.0
OPEN_ENOUGH = 3.0  # metres between the passing lane and the nearest opponent
DRIBBLE_CLEAR = 6.0  # metres of dribble path that must be free of opponents
PRESSED = 2.5  # an opponent this close blocks every dribble: hold
TACKLE_PROBABILITY = 0.7
COVER_DISTANCE = 3.0  # metres from the ball towards our goal, while they have it
DEFEND_DROP = 6.0  # metres the slots fall back while they have the ball
DEFEND_NARROW = 0.6  # the share of the slots' width kept then, the rest drawn to the ball
DEFEND_BALL_Y = 0.5  # how far the slots follow the ball across then (SLIDE's 0.3 otherwise)
DEEPEST = -45.0  # no slot deeper than this x: the goal line is the goalie's
ATTACK_PUSH = 5.0  # metres the slots step up while we have it (still onside)
OUR_THIRD = -17.5  # x below which the attackers are marked and the passes are safer
SAFE_GAP = 5.0  # OPEN_ENOUGH of a pass from our third
_OUR_GOAL = np.array([-52.5, 0.0], np.float32)
_GOAL_YS = np.linspace(-GOAL_HALF_WIDTH + 1.0, GOAL_HALF_WIDTH - 1.0, 5).astype(np.float32)
_SHOT_TARGETS = np.stack([np.full(5, GOAL[0]), _GOAL_YS], axis=1)  # [5, 2]
_PLAY_ON, _BEFORE_KICK_OFF, _AFTER_GOAL = 2, 0, 8
# The kinds as plain ints: numpy reads an IntEnum member through attribute probes that cost
# more than the where it goes into.
(_SHOOT, _PASS, _DRIBBLE, _HOLD, _INTERCEPT, _GO_TO, _MARK, _TACKLE, _KICKOFF_MOVE, _GOALIE,
 _SET_PLAY, _PENALTY, _KICK, _PLANNER, _HELIOS_MOVE) = (int(k) for k in Kind)
_ON_BALL = np.array([_SHOOT, _PASS, _DRIBBLE, _HOLD], np.int32)
_OFF_BALL = np.array([_INTERCEPT, _GO_TO, _MARK, _TACKLE], np.int32)
_OPEN_PLAY = np.concatenate([_ON_BALL, _OFF_BALL])


def _norm(v: Any, xp: Any = np, keepdims: bool = False) -> Any:
    """Length over the last axis. In numpy the sum of squares that ``np.linalg.norm`` takes
    (the same bits) without its checks, which cost as much as the sum on a host decision's
    few rows."""
    if xp is np:
        squares = np.add.reduce(v * v, axis=-1)
        return np.sqrt(squares[..., None] if keepdims else squares)
    return xp.linalg.norm(v, axis=-1, keepdims=keepdims)


def _segment_gap(a: Any, b: Any, p: Any, xp: Any = np) -> Any:
    """Distance from points ``p`` [..., k, 2] to segments ``a``-``b`` [..., 2]."""
    ab = (b - a)[..., None, :]
    ap = p - a[..., None, :]
    t = xp.clip((ap * ab).sum(-1) / xp.maximum((ab * ab).sum(-1), 1e-6), 0.0, 1.0)
    return _norm(ap - t[..., None] * ab, xp)


def _shot_points(obs: Observation, xp: Any = np) -> Any:
    """The goal-mouth point [n, 2] whose shooting line passes farthest (in angle) from the
    opponents between the shooter and the goal."""
    targets = xp.asarray(_SHOT_TARGETS)
    to_target = targets[None] - obs.pos[:, None]  # [n, 5, 2]
    to_opp = obs.opps - obs.pos[:, None]  # [n, 11, 2]
    ang_t = xp.arctan2(to_target[..., 1], to_target[..., 0])  # [n, 5]
    ang_o = xp.arctan2(to_opp[..., 1], to_opp[..., 0])  # [n, 11]
    diff = xp.abs((ang_t[:, :, None] - ang_o[:, None, :] + np.pi) % (2 * np.pi) - np.pi)
    ahead = obs.opps_valid & (to_opp[..., 0] > -1.0)  # [n, 11]
    clearance = xp.where(ahead[:, None, :], diff, np.pi).min(-1)  # [n, 5]
    return targets[xp.argmax(clearance, axis=1)]


def _best_pass(obs: Observation, any_way: Any, xp: Any = np) -> tuple[Any, Any]:
    """The receiver (shirt number, 0 when none is open) and whether one is; forward only,
    but for the rows of ``any_way`` (bool[n]) outside our third."""
    n = len(obs)
    receivers = obs.mates  # [n, 11, 2]
    dist = _norm(receivers - obs.pos[:, None], xp)
    lanes = _segment_gap(
        xp.repeat(obs.pos[:, None], PLAYERS, 1).reshape(-1, 2),
        receivers.reshape(-1, 2),
        xp.repeat(obs.opps, PLAYERS, 0),
        xp,
    ).reshape(n, PLAYERS, PLAYERS)  # [n, receiver, opponent]
    gap = xp.where(obs.opps_valid[:, None, :], lanes, np.inf).min(-1)  # [n, 11]
    me = xp.arange(1, PLAYERS + 1)[None] == obs.unum[:, None]
    # From our third: a wider lane, and nothing across our box (forward at least half of
    # the sideways distance).
    deep = (obs.pos[:, 0] < OUR_THIRD)[:, None]
    across = xp.abs(receivers[..., 1] - obs.pos[:, None, 1])
    safe = ~deep | ((gap >= SAFE_GAP) & (receivers[..., 0] - obs.pos[:, None, 0] >= 0.5 * across))
    ok = safe & (
        obs.mates_valid & ~me & (xp.arange(PLAYERS) > 0)[None]  # never back to the goalie
        & ((receivers[..., 0] > obs.pos[:, None, 0]) | any_way[:, None])  # forward
        & (receivers[..., 0] < xp.maximum(obs.offside_x, 0.0)[:, None])  # onside
        & (dist >= PASS_MIN) & (dist <= PASS_MAX) & (gap >= OPEN_ENOUGH)
    )
    score = xp.where(ok, xp.minimum(gap, 10.0) + 0.2 * (receivers[..., 0] - obs.pos[:, None, 0]),
                     -np.inf)
    best = xp.argmax(score, axis=1)
    return (best + 1).astype(xp.int32), ok.any(axis=1)


def _dribble(obs: Observation, xp: Any = np) -> tuple[Any, Any]:
    """The dribble direction nearest the goal direction whose first metres are clear, and
    whether any forward one is."""
    directions = xp.asarray(DRIBBLE_DIRECTIONS)
    to_goal = xp.asarray(GOAL)[None] - obs.pos
    to_goal = to_goal / xp.maximum(_norm(to_goal, xp, keepdims=True), 1e-6)
    align = to_goal @ directions.T  # [n, 8]
    ends = obs.pos[:, None] + DRIBBLE_CLEAR * directions[None]  # [n, 8, 2]
    n = len(obs)
    lanes = _segment_gap(
        xp.repeat(obs.pos[:, None], 8, 1).reshape(-1, 2), ends.reshape(-1, 2),
        xp.repeat(obs.opps, 8, 0), xp,
    ).reshape(n, 8, PLAYERS)
    blocked = (xp.where(obs.opps_valid[:, None, :], lanes, np.inf) < PRESSED).any(-1)
    forward = directions[None, :, 0] > -0.1  # towards their goal or across
    ok = forward & ~blocked
    return xp.argmax(xp.where(ok, align, -np.inf), axis=1).astype(xp.int32), xp.any(ok, axis=1)


def _slots(obs: Observation, defending: Any, xp: Any = np) -> Any:
    """Each player's slot [n, 2]: :func:`slot_targets`, stepped up by :data:`ATTACK_PUSH`
    while we have the ball; while they have it, a deeper, narrower block drawn to the ball's
    side (no slot deeper than :data:`DEEPEST`)."""
    base = slot_targets(obs.unum, obs.ball, obs.offside_x, xp)
    home = xp.asarray(FORMATION)[obs.unum - 1]
    onside = xp.maximum(obs.offside_x - 1.0, 0.0)
    attack_x = xp.minimum(base[:, 0] + ATTACK_PUSH, xp.maximum(onside, base[:, 0]))
    defend_x = xp.maximum(base[:, 0] - DEFEND_DROP, DEEPEST)
    defend_y = xp.clip(DEFEND_NARROW * home[:, 1] + DEFEND_BALL_Y * obs.ball[:, 1], -32.0, 32.0)
    return xp.stack([xp.where(defending, defend_x, attack_x),
                     xp.where(defending, defend_y, base[:, 1])], axis=1)


def _marks(obs: Observation, xp: Any = np) -> tuple[Any, Any]:
    """The attacker in our third each player marks (shirt number) and whether it marks one.

    Every seen opponent in our third but the one nearest the ball (the interceptor and the
    cover take that one) goes to the free teammate (a defender or midfielder, not one of the
    two nearest the ball) nearest its goal-side; a player given several marks the one
    nearest our goal."""
    our_goal = xp.asarray(_OUR_GOAL)
    opp_ball = xp.where(obs.opps_valid,
                        _norm(obs.opps - obs.ball[:, None], xp), np.inf)
    on_ball = xp.arange(PLAYERS)[None] == xp.argmin(opp_ball, axis=1)[:, None]
    danger = obs.opps_valid & (obs.opps[..., 0] < OUR_THIRD) & ~on_ball  # [n, 11]
    side = our_goal[None, None] - obs.opps
    spot = obs.opps + 1.5 * side / xp.maximum(_norm(side, xp, keepdims=True), 1e-6)
    mate_ball = xp.where(obs.mates_valid,
                         _norm(obs.mates - obs.ball[:, None], xp), np.inf)
    mate_rank = (mate_ball[:, None, :] < mate_ball[:, :, None]).sum(-1)  # [n, 11]
    shirt = xp.arange(1, PLAYERS + 1)[None]
    free = obs.mates_valid & (shirt >= 2) & (shirt <= 9) & (mate_rank >= 2)
    gap = _norm(obs.mates[:, :, None] - spot[:, None], xp)  # [n, mate, opp]
    nearest = xp.argmin(xp.where(free[:, :, None], gap, np.inf), axis=1)  # [n, opp]
    mine = danger & (nearest == (obs.unum - 1)[:, None]) & free.any(1)[:, None]
    goal_d = xp.where(mine, _norm(obs.opps - our_goal[None, None], xp), np.inf)
    target = xp.argmin(goal_d, axis=1)
    return (target + 1).astype(xp.int32), mine.any(axis=1)


def naive_choices(obs: Observation, xp: Any = np,
                  set_plays: str = "routine") -> tuple[Any, Any, Any]:
    """The yardstick's decisions for every row of ``obs``, as arrays of ``xp`` (numpy, or
    jax.numpy under a trace): kind int32 [n], index int32 [n], point f32 [n, 2] (the fields
    of :class:`Decisions`); our set plays as ``set_plays`` says (:func:`outside_open_play`)."""
    n = len(obs)
    kind = xp.full(n, _GO_TO, xp.int32)
    index = xp.zeros(n, xp.int32)
    ours = obs.kickable | obs.kickable_mate | (
        ~obs.kickable_opp & (xp.minimum(obs.self_reach, obs.mate_reach) < obs.opp_reach))
    point = _slots(obs, ~ours, xp).astype(xp.float32)

    def put(mask: Any, value: Any, into: Any) -> Any:
        return xp.where(mask[:, None] if into.ndim == 2 else mask, value, into)

    # Without the ball.
    first = (obs.self_reach <= obs.mate_reach) & ~obs.kickable_mate
    kind = put(first, _INTERCEPT, kind)
    tackle = obs.kickable_opp & ~obs.kickable_mate & (obs.tackle_probability >= TACKLE_PROBABILITY)
    kind = put(tackle, _TACKLE, kind)
    # While they have the ball, the one or two outfield players nearest it (after the
    # interceptor) stand between it and our goal.
    theirs = their_ball(obs, xp)
    others = obs.mates_valid & (xp.arange(PLAYERS) > 0)[None]  # outfield teammates, me too
    ball_dist = _norm(obs.mates - obs.ball[:, None], xp)
    rank = (others & (ball_dist < _norm(obs.pos - obs.ball, xp)[:, None])).sum(1)
    cover = theirs & ~first & ~tackle & (rank <= 1)
    goalward = xp.asarray(_OUR_GOAL)[None] - obs.ball
    goalward = goalward / xp.maximum(_norm(goalward, xp, keepdims=True), 1e-6)
    point = put(cover, obs.ball + COVER_DISTANCE * goalward, point)
    # numpy skips a part whose rows are all masked out (its puts would keep nothing): the
    # server decides one player at a time, and most have neither an attacker to mark nor
    # the ball. A trace (jnp) cannot branch on values: it computes every part.
    host = xp is np
    # The free defenders and midfielders mark the attackers in our third.
    free = ~ours & ~first & ~tackle & ~cover
    if not host or free.any():
        marked, can_mark = _marks(obs, xp)
        mark = free & can_mark
        kind, index = put(mark, _MARK, kind), put(mark, marked, index)

    # With it.
    if not host or obs.kickable.any():
        # The taker of our decided set play passes any way (back, as a kick-off is taken):
        # no dribble may follow its kick (set_plays).
        taker = obs.kickable & (decided_set_play(obs, xp) if set_plays == "decided"
                                else xp.zeros(n, bool))
        receiver, can_pass = _best_pass(obs, taker, xp)
        direction, can_dribble = _dribble(obs, xp)
        blocked = ~can_pass & ~can_dribble
        shoot = obs.kickable & ((_norm(xp.asarray(GOAL)[None] - obs.pos, xp) < SHOOT_RANGE)
                                | (blocked & obs.kickable_opp))
        passing = obs.kickable & ~shoot & can_pass
        dribble = obs.kickable & ~shoot & ~can_pass & can_dribble
        hold = obs.kickable & ~shoot & blocked
        kind, point = put(shoot, _SHOOT, kind), put(shoot, _shot_points(obs, xp), point)
        kind, index, point = (put(passing, _PASS, kind), put(passing, receiver, index),
                              put(passing, 0.0, point))
        kind, index = put(dribble, _DRIBBLE, kind), put(dribble, direction, index)
        kind = put(hold, _HOLD, kind)
    return outside_open_play(obs, kind, index, point, xp, set_plays)


def kick_off_points(unum: Any, xp: Any = np) -> Any:
    """Where each player (shirt numbers int[m]) stands before a kick-off: its formation slot
    with the ball at the centre spot, in our half (x <= -1), f32[m, 2]."""
    home = xp.asarray(FORMATION)[unum - 1]
    return xp.stack([xp.minimum(home[:, 0], -1.0), home[:, 1]], axis=1)


def outside_open_play(obs: Observation, kind: Any, index: Any, point: Any,
                      xp: Any = np, set_plays: str = "routine") -> tuple[Any, Any, Any]:
    """Open-play decisions (kind, index, point) with what every skills team plays outside
    open play laid over them: before a kick-off everyone moves to :func:`kick_off_points`;
    the goalie plays the proxy's goalie, set pieces and penalties its ready behaviours, but
    with ``set_plays="decided"`` our outfield players keep their open-play decisions in our
    kick-offs, free kicks, kick-ins and corners (``set_plays.decided_set_play``)."""

    def put(mask: Any, value: Any, into: Any) -> Any:
        return xp.where(mask[:, None] if into.ndim == 2 else mask, value, into)

    placing = (obs.mode == _BEFORE_KICK_OFF) | (obs.mode == _AFTER_GOAL)
    set_play = ~placing & (obs.mode != _PLAY_ON)
    if set_plays == "decided":
        set_play = set_play & ~decided_set_play(obs, xp)
    kind = put(set_play, _SET_PLAY, kind)
    kind = put(obs.goalie & ~placing, _GOALIE, kind)
    kind = put(obs.penalty, _PENALTY, kind)
    kind = put(placing, _KICKOFF_MOVE, kind)
    point = put(placing, kick_off_points(obs.unum, xp), point)
    return kind.astype(xp.int32), index.astype(xp.int32), point.astype(xp.float32)


def routine_rows(obs: Observation, set_plays: str = "routine") -> np.ndarray:
    """bool[n]: the rows :func:`outside_open_play` gives a routine whatever open play
    decides: outside play on (but our decided set plays), the goalie, a penalty."""
    stopped = np.asarray(obs.mode) != _PLAY_ON
    if set_plays == "decided":
        stopped &= ~decided_set_play(obs)
    return stopped | np.asarray(obs.goalie) | np.asarray(obs.penalty)


def skills_naive_decisions(obs: Observation, set_plays: str = "routine") -> Decisions:
    """The yardstick's decisions for every row of ``obs``."""
    return Decisions.of(*naive_choices(obs, np, set_plays))


def _naive_answers(states: Sequence[Any], set_plays: str, guard: TakerGuard | None = None,
                   planner: bool = False, chooses_chains: bool = False,
                   helios_move: bool = False, press: int = 0) -> list[Any]:
    """The proxy's States of a cycle to ``skills_naive``'s PlayerActions. When every row plays
    a routine (outside play on and our decided set plays, the goalie, a penalty) open play is
    not decided: none of it reaches the answers (the routine's kind replaces it, the kick-off
    spot its point). With ``planner`` helios-base's planner takes every open-play kick
    (``Kind.PLANNER`` for SHOOT, PASS, DRIBBLE and HOLD), the choice among its chains ours
    with ``chooses_chains``; with ``helios_move`` helios-base's off-ball play takes every
    open-play move (``Kind.HELIOS_MOVE`` for INTERCEPT, GO_TO, MARK and TACKLE); with
    ``press`` (cycles) those moves :func:`pressing` picks run at the ball instead."""
    obs = observe(states)
    if routine_rows(obs, set_plays).all():
        n = len(obs)
        decisions = Decisions.of(*outside_open_play(
            obs, np.full(n, _GO_TO, np.int32), np.zeros(n, np.int32),
            np.zeros((n, 2), np.float32)))
    else:
        decisions = skills_naive_decisions(obs, set_plays)
    if guard is not None:
        decisions, _ = guard.apply(obs, decisions)
    if planner or helios_move:
        decisions = helios_parts(decisions, obs.kickable, on_ball=planner, off_ball=helios_move)
    if press:
        kind = np.where(pressing(obs, press) & (decisions.kind == _HELIOS_MOVE), _INTERCEPT,
                        decisions.kind)
        decisions = Decisions.of(kind, decisions.index, decisions.point)
    return to_player_actions(decisions, obs, chooses_chains)


def their_ball(obs: Observation, xp: Any = np) -> Any:
    """bool [n]: the ball is theirs for this player: no teammate can kick it, and an opponent
    can or reaches it before any of us."""
    return ~obs.kickable_mate & (
        obs.kickable_opp | (obs.opp_reach < xp.minimum(obs.self_reach, obs.mate_reach))
    )


def pressing(obs: Observation, press: int) -> np.ndarray:
    """bool [n]: the outfield players without the ball who press theirs: an opponent is at
    the ball first (it can kick it, or reaches it before any of us), no teammate can kick it,
    and this player reaches it within ``press`` cycles of our fastest other player, so a
    second player closes in beside the one helios-base's basic move sends."""
    near = obs.self_reach <= obs.mate_reach + press
    return their_ball(obs) & near & ~obs.kickable & ~obs.goalie


def helios_parts(decisions: Decisions, kickable: np.ndarray, rows: np.ndarray | None = None, *,
                 on_ball: bool = True, off_ball: bool = True) -> Decisions:
    """``decisions`` with helios-base's play in the open-play decisions of ``rows`` (bool [n];
    None: all), by librcsc's ``kickable`` (bool [n]) as helios-base's own players choose:
    its planner for a player with the ball (``Kind.PLANNER``) with ``on_ball``, its basic move
    for one without (``Kind.HELIOS_MOVE``) with ``off_ball``. Open play: the kicks and moves
    (SHOOT, PASS, DRIBBLE, HOLD, INTERCEPT, GO_TO, MARK, TACKLE); routines stay."""
    kind = decisions.kind
    take = np.isin(kind, _OPEN_PLAY)
    if rows is not None:
        take &= np.asarray(rows, bool)
    kickable = np.asarray(kickable, bool)
    if on_ball:
        kind = np.where(take & kickable, _PLANNER, kind)
    if off_ball:
        kind = np.where(take & ~kickable, _HELIOS_MOVE, kind)
    return Decisions.of(kind, decisions.index, decisions.point)


@rowwise  # every row is decided on its own world model: nothing to gather
def skills_naive(states: Sequence[Any]) -> list[Any]:
    """The decision server's callable: the proxy's States of a cycle to its PlayerActions,
    our set plays the proxy's ready behaviour."""
    return _naive_answers(states, "routine")


class SkillsPlanner:
    """``skills_naive`` with helios-base's play in its place on the ball (``on_ball``: its
    planner) or off it (``off_ball``: its basic move), or both: the decision server's callable
    (rowwise), yardsticks of what each part of the decision is worth against helios-base. The
    planner searches chains of passes, dribbles and shots; which one the player plays is
    helios-base's choice, or with ``choose`` elevens' (the decision server asks
    ``choose_chain``, ``planner.Choose``)."""

    def __init__(self, choose: Choose | None = None, *, on_ball: bool = True,
                 off_ball: bool = False, press: int = 0) -> None:
        if press < 0 or (press and not off_ball):
            raise ValueError(f"press={press!r} is invalid (allowed: 0, or a number of cycles "
                             ">= 1 with off_ball=True)")
        if choose is not None:
            if not on_ball:
                raise ValueError("a chain chooser without the planner on the ball "
                                 "(allowed: on_ball=True with choose)")
            self.choose_chain = choose
        self.chooses = choose is not None
        self.on_ball, self.off_ball, self.press = on_ball, off_ball, press
        rowwise(self)

    def __call__(self, states: Sequence[Any]) -> list[Any]:
        return _naive_answers(states, "routine", planner=self.on_ball,
                              chooses_chains=self.chooses, helios_move=self.off_ball,
                              press=self.press)


#: What the on-ball decision is worth against helios-base.
skills_planner = SkillsPlanner()


class SkillsNaive:
    """``skills_naive`` deciding our set plays too (``set_plays="decided"``), within the
    free-kick rule (``set_plays.TakerGuard``): the decision server's callable. Rowwise like
    :func:`skills_naive`: the guard keeps each shirt's memory apart."""

    def __init__(self) -> None:
        self.guard = TakerGuard()
        rowwise(self)

    def reset(self) -> None:
        self.guard.reset()

    def __call__(self, states: Sequence[Any]) -> list[Any]:
        return _naive_answers(states, "decided", self.guard)
