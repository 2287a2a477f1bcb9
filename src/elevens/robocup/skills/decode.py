"""The skill action a policy gives, and its meaning: one decode shared by the simulator's skill
game and the server runtime, so one checkpoint plays both.

A player's action is ``f32[4] = (kind, pointer, x, y)``:

- ``kind``: an open-play :class:`~elevens.robocup.skills.space.Kind`, 0..7 (SHOOT, PASS,
  DRIBBLE, HOLD, INTERCEPT, GO_TO, MARK, TACKLE), an integer held in a float (rounded, then
  clipped to 0..7);
- ``pointer``: an entity slot of the player's observation, 0..2n-1, in the order of
  ``elevens.env.observe.entity_layout(n)``: its n - 1 teammates by index (itself left out), the
  n opponents by index, the ball (slot 2n - 1, never a target). Slot j of observer k is world
  player ``entity_index[k, j]``. PASS reads a teammate from it, MARK an opponent; the other
  kinds ignore it;
- ``(x, y)`` in [-1, 1] (clipped), the kind's continuous argument, in the team's frame (their
  goal at +x):

  ========= ===============================================================================
  SHOOT     the goal-mouth point (goal line, ``y * goal half width``); x is ignored
  PASS      the lead: the ball goes to the teammate plus ``(x, y) * PASS_LEAD`` metres
  DRIBBLE   the direction of ``(x, y)``, rounded to the nearest of eight 45 degree steps
            counter-clockwise from +x ((0, 0): straight at their goal)
  GO_TO     the point ``slot + (x, y) * GO_TO_RANGE`` metres: ``slot`` is the player's
            formation slot slid with the ball and kept onside (:func:`slot_targets`), so
            (0, 0) holds the formation
  others    ignored
  ========= ===============================================================================

What an action that cannot be done does instead (:func:`decode`): a with-ball kind (SHOOT,
PASS, DRIBBLE, HOLD) without the ball in kicking reach intercepts; a PASS whose pointer is not a
teammate holds; a MARK whose pointer is not an opponent goes to its (x, y) point as GO_TO (a
pointer to a slot the player's observation does not place counts as neither).

Array code: every function takes ``xp`` (numpy or jax.numpy) and any leading axes where it
says ``[m]``; the jnp versions trace under jit and vmap.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "DRIBBLE_STEP",
    "FORMATION",
    "GO_TO_RANGE",
    "OPEN_KINDS",
    "PASS_LEAD",
    "SKILL_ACTION_SIZE",
    "SLIDE",
    "SkillChoice",
    "SkillContext",
    "decode",
    "encode",
    "shirt_numbers",
    "slot_targets",
]

SKILL_ACTION_SIZE = 4
OPEN_KINDS = 8  # Kind.SHOOT .. Kind.TACKLE
SHOOT, PASS, DRIBBLE, HOLD, INTERCEPT, GO_TO, MARK, TACKLE = range(OPEN_KINDS)
PASS_LEAD = 8.0
"""Metres of lead at |x| or |y| = 1 of a PASS."""
GO_TO_RANGE = 20.0
"""Metres from the slot at |x| or |y| = 1 of a GO_TO."""
DRIBBLE_STEP = np.pi / 4
SERVER_HALF = (52.5, 34.0)
"""rcssserver's half length and half width, the field :data:`FORMATION` is drawn on."""

#: Slots with the ball at the centre spot, by shirt number (1: goalie); 4-4-2.
FORMATION = np.array([
    [-50.0, 0.0],
    [-30.0, -20.0], [-32.0, -7.0], [-32.0, 7.0], [-30.0, 20.0],
    [-14.0, -22.0], [-16.0, -7.0], [-16.0, 7.0], [-14.0, 22.0],
    [-3.0, -9.0], [-3.0, 9.0],
], np.float32)
#: How far the slots follow the ball, along x and y.
SLIDE = np.array([0.6, 0.3], np.float32)
#: The shirt numbers the simulator's teams of n wear (player k wears SHIRTS[n][k]): the
#: simulator's formation's slots (``EnvParams`` formation), so player 0 is the goalie.
SHIRTS: dict[int, tuple[int, ...]] = {
    1: (10,), 2: (1, 10), 3: (1, 7, 10), 4: (1, 3, 4, 10), 5: (1, 3, 4, 7, 10),
    6: (1, 3, 4, 6, 8, 10), 7: (1, 3, 4, 6, 7, 8, 10), 8: (1, 2, 3, 4, 5, 7, 9, 11),
    9: (1, 2, 3, 4, 5, 7, 9, 10, 11), 10: (1, 2, 3, 4, 5, 6, 8, 9, 10, 11),
    11: tuple(range(1, 12)),
}


def shirt_numbers(players_per_team: int) -> np.ndarray:
    """int32[n]: the shirt number (1..11, the index of :data:`FORMATION` plus one) of each
    player of a simulator team of ``players_per_team``."""
    return np.asarray(SHIRTS[players_per_team], np.int32)


def slot_targets(unum: Any, ball: Any, offside_x: Any, xp: Any = np,
                 half: tuple[Any, Any] = SERVER_HALF) -> Any:
    """Each player's formation slot shifted with the ball, on the pitch and onside: unum
    int[m] (shirt numbers), ball f32[m, 2], offside_x f32[m] -> f32[m, 2], team frame.
    ``half``: the field's half length and width (the slots scale from the server's)."""
    # Shirt numbers known at trace time (a numpy array) cut the table there: no gather.
    home = xp.asarray(FORMATION[unum - 1] if isinstance(unum, np.ndarray) else
                      xp.asarray(FORMATION)[unum - 1])
    limit = (48.0, 32.0)
    if not (isinstance(half[0], float | int) and tuple(half) == SERVER_HALF):
        scale = (half[0] / SERVER_HALF[0], half[1] / SERVER_HALF[1])
        home = home * xp.stack([xp.asarray(scale[0]), xp.asarray(scale[1])]).astype(home.dtype)
        limit = (48.0 * scale[0], 32.0 * scale[1])
    target = home + xp.asarray(SLIDE) * ball
    x = xp.minimum(target[:, 0], xp.maximum(offside_x - 1.0, 0.0))
    return xp.stack([xp.clip(x, -limit[0], limit[0]), xp.clip(target[:, 1], -limit[1], limit[1])],
                    axis=1)


class SkillContext(NamedTuple):
    """What a decode needs of each deciding player, team frame, leading axis [m]."""

    observer: Any  # int[m]: the player's world index (team * n + index)
    unum: Any  # int[m]: its shirt number
    position: Any  # f32[m, 2]
    ball: Any  # f32[m, 2]
    offside_x: Any  # f32[m]
    kickable: Any  # bool[m]: the ball is within its kicking reach


class SkillChoice(NamedTuple):
    """A decoded action, leading axis [m]."""

    kind: Any  # int32[m], 0..7: what the player does (after the fallbacks)
    target: Any  # int32[m]: world index of the teammate passed to or opponent marked, else -1
    direction: Any  # int32[m]: DRIBBLE's direction 0..7 (45 degree steps from +x), else 0
    point: Any  # f32[m, 2]: SHOOT's and GO_TO's point, PASS's lead offset (metres), else 0


def _layout(players_per_team: int) -> np.ndarray:
    """int32[2n, 2n]: world entity of each slot of each observer (``entity_layout``'s table;
    2n is the ball)."""
    n = players_per_team
    index = np.zeros((2 * n, 2 * n), np.int32)
    for team in range(2):
        own = [team * n + i for i in range(n)]
        other = [(1 - team) * n + i for i in range(n)]
        for i, observer in enumerate(own):
            index[observer] = own[:i] + own[i + 1:] + other + [2 * n]
    return index


def decode(action: Any, context: SkillContext, players_per_team: int, *,
           half: tuple[Any, Any] = SERVER_HALF, goal_half_width: Any = 7.01,
           seen: Any = None, xp: Any = np) -> SkillChoice:
    """action f32[m, 4] -> :class:`SkillChoice` for the players of ``context`` (module
    docstring). NaN counts as 0. ``seen`` bool[m, 2n]: the slots each player's observation
    places (None: all, as in the simulator); a PASS or MARK through a slot it does not place
    falls back as one through a slot of the wrong kind."""
    n = players_per_team
    action = xp.where(xp.isnan(action), 0.0, action)
    kind = xp.clip(xp.round(action[:, 0]), 0, OPEN_KINDS - 1).astype(xp.int32)
    pointer = xp.clip(xp.round(action[:, 1]), 0, 2 * n - 1).astype(xp.int32)
    x, y = xp.clip(action[:, 2], -1.0, 1.0), xp.clip(action[:, 3], -1.0, 1.0)
    # World index (2n: the ball); a one-hot sum, not a gather (slow on XLA's CPU backend).
    table = _layout(n)[context.observer] if isinstance(context.observer, np.ndarray) else (
        xp.asarray(_layout(n))[context.observer])
    target = (table * (pointer[:, None] == np.arange(2 * n)[None, :])).sum(axis=1)
    team = context.observer // n
    is_player = target < 2 * n
    if seen is not None:
        is_player = is_player & (xp.asarray(seen) & (pointer[:, None] == np.arange(2 * n))).any(1)
    mate = is_player & (target // n == team)
    opponent = is_player & (target // n != team)

    with_ball = kind <= HOLD
    kind = xp.where((kind == PASS) & ~mate, HOLD, kind)
    kind = xp.where((kind == MARK) & ~opponent, GO_TO, kind)
    kind = xp.where(with_ball & ~context.kickable, INTERCEPT, kind)

    angle = xp.arctan2(y, x)
    direction = xp.mod(xp.round(angle / DRIBBLE_STEP), 8).astype(xp.int32)
    slot = slot_targets(context.unum, context.ball, context.offside_x, xp, half)
    xy = xp.stack([x, y], axis=1)
    shot = xp.stack([xp.broadcast_to(xp.asarray(half[0], xy.dtype), y.shape), y * goal_half_width],
                    axis=1)
    zeros = xp.zeros_like(xy)
    point = xp.where((kind == SHOOT)[:, None], shot,
                     xp.where((kind == PASS)[:, None], PASS_LEAD * xy,
                              xp.where((kind == GO_TO)[:, None], slot + GO_TO_RANGE * xy, zeros)))
    return SkillChoice(
        kind=kind,
        target=xp.where((kind == PASS) | (kind == MARK), target, -1).astype(xp.int32),
        direction=xp.where(kind == DRIBBLE, direction, 0).astype(xp.int32),
        point=point.astype(xp.float32),
    )


def encode(kind: Any, target: Any, direction: Any, point: Any, context: SkillContext,
           players_per_team: int, *, half: tuple[Any, Any] = SERVER_HALF,
           goal_half_width: Any = 7.01, xp: Any = np) -> Any:
    """The action f32[m, 4] that :func:`decode` reads back as these choices (a scripted team
    decides in choices and plays in actions): ``target`` the world index of a PASS's teammate
    or MARK's opponent, ``direction`` DRIBBLE's 0..7, ``point`` as :class:`SkillChoice` holds
    it (within the argument's range)."""
    n = players_per_team
    table = xp.asarray(_layout(n))[context.observer]  # [m, 2n]
    hit = table == target[:, None]
    pointer = xp.where(xp.any(hit, axis=1), xp.argmax(hit, axis=1), 0)
    dribble = xp.asarray(np.stack([np.cos(np.arange(8) * DRIBBLE_STEP),
                                   np.sin(np.arange(8) * DRIBBLE_STEP)], axis=1), xp.float32)
    slot = slot_targets(context.unum, context.ball, context.offside_x, xp, half)
    shot = xp.stack([xp.zeros_like(point[:, 1]), point[:, 1] / goal_half_width], axis=1)
    k = kind[:, None]
    xy = xp.where(k == SHOOT, shot,
                  xp.where(k == PASS, point / PASS_LEAD,
                           xp.where(k == DRIBBLE, dribble[direction],
                                    xp.where(k == GO_TO, (point - slot) / GO_TO_RANGE,
                                             xp.zeros_like(point)))))
    return xp.concatenate(
        [kind[:, None].astype(xp.float32), pointer[:, None].astype(xp.float32),
         xp.clip(xy, -1.0, 1.0).astype(xp.float32)], axis=1,
    )
