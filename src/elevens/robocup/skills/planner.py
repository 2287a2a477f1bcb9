"""helios-base's on-ball planner as a decision of elevens: the proxy searches chains of passes,
dribbles and shots (librcsc's cooperative actions, helios-base's generators) and elevens chooses
which chain its player plays.

A player whose answer holds ``HeliosOffensivePlanner`` with ``server_side_decision`` set makes
a second call in its cycle, ``GetBestPlannerAction``, with every node the planner searched
(:class:`Candidates`); the decision server answers with a ``choose`` callable's node
(:func:`helios_best`, helios-base's own choice, by default) and the proxy plays the first
action of the chain that ends there.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["CATEGORIES", "Candidates", "Choose", "Situation", "helios_best"]

#: The proxy's ``RpcActionCategory`` names, by value.
CATEGORIES = ("hold", "dribble", "pass", "shoot", "clear", "move", "none")


@dataclasses.dataclass(frozen=True)
class Situation:
    """The asking player's world model when it searched (the request's ``state``): the cycle,
    whether we play on the left, the score (ours, theirs), and the ball and the opponents
    seen (f32 [2], [n, 2]) in librcsc's coordinates (we attack +x)."""

    cycle: int
    left: bool
    score: tuple[int, int]
    ball: np.ndarray
    opponents: np.ndarray

    @staticmethod
    def of(state: Any) -> Situation | None:
        """The situation of a ``State`` (None without a world model)."""
        wm = getattr(state, "world_model", None)
        if wm is None:
            return None

        def xy(v: Any) -> tuple[float, float]:
            p = getattr(v, "position", None)
            return (0.0, 0.0) if p is None else (float(p.x or 0.0), float(p.y or 0.0))

        opponents = [xy(o) for o in (wm.opponents or []) if getattr(o, "position", None)]
        return Situation(
            cycle=int(wm.cycle or 0), left=wm.our_side != 2,  # Side.RIGHT
            score=(int(wm.our_team_score or 0), int(wm.their_team_score or 0)),
            ball=np.array(xy(wm.ball), np.float32),
            opponents=np.array(opponents, np.float32).reshape(-1, 2),
        )


@dataclasses.dataclass(frozen=True)
class Candidates:
    """The nodes of one planner search, one row each (k rows, in the order of ``index``):
    ``index`` and ``parent`` (-1: a chain's first action) int32 [k]; ``category`` int32 [k]
    (:data:`CATEGORIES`); ``target_unum`` int32 [k] (a pass's receiver, else -1 or the
    sender); ``target`` f32 [k, 2] (where the ball goes); ``ball_speed`` f32 [k] (the kick's
    first speed); ``steps`` int32 [k] (the chain's predicted cycles so far); ``holder`` int32
    [k] (who has the ball then); ``ball`` f32 [k, 2] (the ball then); ``evaluation`` f32 [k]
    (helios-base's evaluation of the chain ending there). Coordinates are librcsc's: we
    attack +x. ``situation``: the asking player's world model, when the request carried it."""

    index: np.ndarray
    parent: np.ndarray
    category: np.ndarray
    target_unum: np.ndarray
    target: np.ndarray
    ball_speed: np.ndarray
    steps: np.ndarray
    holder: np.ndarray
    ball: np.ndarray
    evaluation: np.ndarray
    situation: Situation | None = None

    def __len__(self) -> int:
        return len(self.index)

    @staticmethod
    def of(pairs: dict[int, Any] | None, state: Any = None) -> Candidates:
        """The candidates of a ``BestPlannerActionRequest``'s ``pairs`` (unset fields read
        as 0, a node without an action is skipped) and its ``state``."""
        rows = sorted((k, v) for k, v in (pairs or {}).items() if v is not None and v.action)

        def num(x: Any) -> float:
            return 0.0 if x is None else float(x)

        def xy(v: Any) -> tuple[float, float]:
            return (0.0, 0.0) if v is None else (num(v.x), num(v.y))

        acts = [v.action for _, v in rows]
        pred = [v.predict_state for _, v in rows]
        i32, f32 = np.int32, np.float32
        return Candidates(
            index=np.array([k for k, _ in rows], i32),
            parent=np.array([num(a.parent_index) for a in acts], i32),
            category=np.array([num(a.category) for a in acts], i32),
            target_unum=np.array([num(a.target_unum) for a in acts], i32),
            target=np.array([xy(a.target_point) for a in acts], f32).reshape(-1, 2),
            ball_speed=np.array([num(a.first_ball_speed) for a in acts], f32),
            steps=np.array([num(p.spend_time) if p else 0 for p in pred], i32),
            holder=np.array([num(p.ball_holder_unum) if p else 0 for p in pred], i32),
            ball=np.array([xy(p.ball_position) if p else (0.0, 0.0) for p in pred],
                          f32).reshape(-1, 2),
            evaluation=np.array([num(v.evaluation) for _, v in rows], f32),
            situation=None if state is None else Situation.of(state),
        )

    def first_actions(self) -> np.ndarray:
        """int32 [k]: the row of each node's chain's first action (what the proxy plays)."""
        return self._chains()[0]

    def depths(self) -> np.ndarray:
        """int32 [k]: the actions in each node's chain (1: a first action)."""
        return self._chains()[1]

    def _chains(self) -> tuple[np.ndarray, np.ndarray]:
        row = {int(i): r for r, i in enumerate(self.index)}
        first = np.arange(len(self), dtype=np.int32)
        depth = np.ones(len(self), dtype=np.int32)
        for r in range(len(self)):
            p, seen = int(self.parent[r]), 0
            while p in row and seen < len(self):  # a malformed cycle cannot hang us
                first[r], p, seen = row[p], int(self.parent[row[p]]), seen + 1
            depth[r] += seen
        return first, depth


#: A chooser: the asking player's shirt number and the candidates to the ``index`` of the
#: node to play (one of ``candidates.index``).
Choose = Callable[[int, Candidates], int]


def helios_best(unum: int, candidates: Candidates) -> int:
    """helios-base's own choice: the node of the best evaluation (-1 when none was searched:
    the proxy then finds no chain and holds the ball)."""
    del unum
    if not len(candidates):
        return -1
    return int(candidates.index[int(np.argmax(candidates.evaluation))])
