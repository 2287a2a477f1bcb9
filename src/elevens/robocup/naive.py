"""RoboCupNaiveTeam: the thesis' RoboCup naive team (section 6.7), host-side numpy.

Every player chases the ball and, once it can kick it, kicks it at the centre of the opponent
goal. It reads only its team's Observation (leading axis [n], the team's own frame, attacking the
goal at (+52.5, 0)) as RoboCupEnv builds it, and returns RoboCupEnv actions: "thesis12"
(f32[n, 12], thesis table 4.1: a kick can go in any direction) or "sim" (f32[n, 2]: a kick goes
along the body, so the player first turns to face the goal).

Observations are snapshots of a player's last see, which arrives only every few cycles (every
3rd in the wide view). Three consequences, each measured on rcssserver 19 in 1 v 1 against
random (2-3 goals per 300 steps with "thesis12" actions, none against):

* a player that turned since the snapshot would turn again on the same stale bearing, so the
  team remembers the turns it commanded since the last fresh snapshot and takes them off the
  bearings it reads (turns assumed complete: players turn from a near stop);
* at full power (about 1 m a step) it would run past the ball between two sees, so within
  ``approach_distance`` of kicking range the dash softens;
* after a kick the snapshot still shows the ball at its feet, so it does not kick again until a
  fresh snapshot arrives. A ball right behind it (outside the view, so not in the observation)
  is still kicked, from the team's memory of where it is.

It follows the TeamPolicy calling convention (``init_carry``, ``act(params, carry, obs, key)``)
with numpy in and out; ``params`` and ``key`` are ignored.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from elevens.env.state import SELF_FEATURES, Observation
from elevens.robocup.actions import ACTION_SIZE, ActionIndex
from elevens.robocup.observe import FIELD_LENGTH, FIELD_WIDTH

__all__ = ["NaiveMemory", "RoboCupNaiveTeam"]

_X, _Y = SELF_FEATURES.index("x"), SELF_FEATURES.index("y")
_COS, _SIN = SELF_FEATURES.index("cos_heading"), SELF_FEATURES.index("sin_heading")
_VISIBLE = SELF_FEATURES.index("ball_visible")
_DIST = SELF_FEATURES.index("ball_distance")
_BCOS, _BSIN = SELF_FEATURES.index("ball_cos_bearing"), SELF_FEATURES.index("ball_sin_bearing")
_VF, _VL = SELF_FEATURES.index("ball_vel_forward"), SELF_FEATURES.index("ball_vel_left")
# Columns that change whenever a new see arrives (time_left and last actions change every step).
_SNAPSHOT = [_X, _Y, _COS, _SIN, _VISIBLE, _DIST, _BCOS, _BSIN, _VF, _VL]

NEVER_SEEN = 1 << 20
_DASH, _KICK, _TURN, _NOOP = "dash", "kick", "turn", "noop"


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


@dataclasses.dataclass
class NaiveMemory:
    """The team's carry: where it last knew the ball and the turns since the last snapshot."""

    ball: np.ndarray  # f64[n, 2] last known ball position, team frame, metres
    ball_velocity: np.ndarray  # f64[n, 2] m/step, slowed by ball_decay while out of sight
    age: np.ndarray  # i64[n] steps since the ball was seen by the player or a teammate
    snapshot: np.ndarray  # f32[n, len(_SNAPSHOT)] the previous observation's snapshot columns
    turned: np.ndarray  # f64[n] radians (CCW) commanded since the current snapshot arrived
    kicked: np.ndarray  # bool[n] kicked since the current snapshot arrived

    @classmethod
    def empty(cls, players_per_team: int) -> NaiveMemory:
        n = players_per_team
        return cls(
            ball=np.zeros((n, 2)),
            ball_velocity=np.zeros((n, 2)),
            age=np.full(n, NEVER_SEEN, np.int64),
            snapshot=np.full((n, len(_SNAPSHOT)), np.nan, np.float32),
            turned=np.zeros(n),
            kicked=np.zeros(n, bool),
        )


@dataclasses.dataclass(frozen=True)
class RoboCupNaiveTeam:
    """Chase the ball, kick it at the opponent goal centre (thesis 6.7)."""

    name: str = "robocup_naive"
    action: str = "thesis12"
    """"thesis12" or "sim": the RoboCupEnv action mode this team plays in."""
    turn_scale: float = 180.0
    """RoboCupConfig.turn_scale (degrees of turn moment at rot = 1), for "sim" actions."""
    kickable: float = 1.085
    """Ball distance (m) at which it kicks: player_size + ball_size + kickable_margin."""
    kick_power: float = 100.0
    """Kick power, 0..100."""
    aim_tolerance: float = math.radians(10.0)
    """"sim": kick once the body points within this of the goal centre, else turn first."""
    chase_tolerance: float = math.radians(15.0)
    """Turn towards the ball when its bearing exceeds this, else dash at it."""
    approach_distance: float = 2.5
    """Within kickable + this distance of the ball the dash power falls off linearly (down to
    min_dash_power), so the player arrives next to the ball instead of running past it between
    two sees (about 1 m a step at full power)."""
    min_dash_power: float = 0.3
    """The softest approach (fraction of full power): enough to catch a slowly rolling ball."""
    intercept: bool = False
    """Chase where the rolling ball can first be met (its course, decaying by ``ball_decay``
    a cycle, against ``intercept_speed``) instead of where it is."""
    intercept_speed: float = 0.85
    """Metres a chasing player covers a cycle, for ``intercept``."""
    search_turn: float = 60.0
    """Turn (degrees, clockwise) per step while nobody on the team knows where the ball is."""
    memory_steps: int = 20
    """Steps a ball nobody sees is followed from its last sighting."""
    ball_decay: float = 0.94
    """server::ball_decay: velocity multiplier per step of a ball followed from memory."""
    half_length: float = FIELD_LENGTH / 2
    half_width: float = FIELD_WIDTH / 2
    field_length: float = FIELD_LENGTH

    def __post_init__(self) -> None:
        if self.action not in ("thesis12", "sim"):
            raise ValueError(f"action={self.action!r} is invalid: allowed are 'thesis12', 'sim'")

    @property
    def action_size(self) -> int:
        return ACTION_SIZE if self.action == "thesis12" else 2

    def init_carry(self, players_per_team: int) -> NaiveMemory:
        return NaiveMemory.empty(players_per_team)

    def act(
        self, params: object, carry: NaiveMemory, obs: Observation, key: object = None
    ) -> tuple[NaiveMemory, np.ndarray]:
        """obs: one team's Observation, leading axis [n] -> (carry, actions f32[n, 2 or 12])."""
        features = np.asarray(obs.self_features, np.float64)
        n = features.shape[0]
        snapshot = np.asarray(obs.self_features, np.float32)[:, _SNAPSHOT]
        fresh = ~np.all(snapshot == carry.snapshot, axis=1)
        turned = np.where(fresh, 0.0, carry.turned)

        position = features[:, [_X, _Y]] * np.array([self.half_length, self.half_width])
        heading = np.arctan2(features[:, _SIN], features[:, _COS])
        sees = features[:, _VISIBLE] > 0.5
        distance = features[:, _DIST] * self.field_length
        bearing = np.arctan2(features[:, _BSIN], features[:, _BCOS])
        direction = heading + bearing
        unit = np.stack([np.cos(direction), np.sin(direction)], axis=-1)
        sighting = position + distance[:, None] * unit
        forward = np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        left = np.stack([-forward[:, 1], forward[:, 0]], axis=-1)
        velocity = features[:, _VF, None] * forward + features[:, _VL, None] * left

        # Players who do not see the ball take their teammates' sightings (they call it).
        if sees.any():
            shared_ball = sighting[sees].mean(axis=0)
            shared_velocity = velocity[sees].mean(axis=0)
            ball = np.where(sees[:, None], sighting, shared_ball)
            ball_velocity = np.where(sees[:, None], velocity, shared_velocity)
            age = np.zeros(n, np.int64)
        else:
            extent = np.array([self.half_length, self.half_width])
            ball = np.clip(carry.ball + carry.ball_velocity, -extent, extent)
            ball_velocity = carry.ball_velocity * self.ball_decay
            age = np.minimum(carry.age + 1, NEVER_SEEN)
        knows = age <= self.memory_steps

        # Own sightings are egocentric (no pose error); the rest go through the pose.
        offset = ball - position
        to_ball = np.where(
            sees, bearing, np.arctan2(offset[:, 1], offset[:, 0]) - heading
        )
        if self.intercept:
            meet = self._meeting_points(ball, ball_velocity, position) - position
            to_ball = np.arctan2(meet[:, 1], meet[:, 0]) - heading
        to_ball = _wrap(to_ball - turned)
        ball_distance = np.where(sees, distance, np.hypot(offset[:, 0], offset[:, 1]))
        goal = np.array([self.half_length, 0.0])
        to_goal = _wrap(np.arctan2(goal[1] - position[:, 1], goal[0] - position[:, 0]) - heading)
        to_goal = _wrap(to_goal - turned)

        kinds: list[str] = []
        angles = np.zeros(n)  # sim radians (+ left): the turn, kick or dash direction
        # Close to the ball, dash softer: a see comes only every few steps and a full dash
        # (about 1 m a step) would run past the ball before the next one.
        power = np.clip(
            (ball_distance - self.kickable) / self.approach_distance, self.min_dash_power, 1.0
        )
        # After a kick the snapshot still shows the ball at the foot until the next see.
        can_kick = (ball_distance <= self.kickable) & ~(carry.kicked & ~fresh)
        for i in range(n):
            if not knows[i]:
                kinds.append(_TURN)
                angles[i] = -math.radians(self.search_turn)
            elif can_kick[i]:
                if self.action == "sim" and abs(to_goal[i]) > self.aim_tolerance:
                    kinds.append(_TURN)
                else:
                    kinds.append(_KICK)
                angles[i] = to_goal[i]
            elif abs(to_ball[i]) > self.chase_tolerance:
                kinds.append(_TURN)
                angles[i] = to_ball[i]
            else:
                kinds.append(_DASH)
                angles[i] = to_ball[i]
        turns = np.array([kind == _TURN for kind in kinds])
        commanded = np.where(turns, self._turn_done(angles), 0.0)
        carry = NaiveMemory(
            ball=ball,
            ball_velocity=ball_velocity,
            age=age,
            snapshot=snapshot,
            turned=turned + commanded,
            kicked=np.array([kind == _KICK for kind in kinds]) | (carry.kicked & ~fresh),
        )
        return carry, self._encode(kinds, angles, power)

    def _meeting_points(
        self, ball: np.ndarray, velocity: np.ndarray, position: np.ndarray
    ) -> np.ndarray:
        """Where each player can first reach the rolling ball (f64[n, 2], team frame): the
        first cycle of its course within ``intercept_speed`` a cycle (plus kicking reach)."""
        extent = np.array([self.half_length, self.half_width])
        points = ball.copy()
        found = np.zeros(len(ball), bool)
        course, v = ball.copy(), velocity.copy()
        for cycle in range(1, 41):
            course, v = course + v, v * self.ball_decay
            gap = np.hypot(*(course - position).T)
            reach = ~found & (gap <= self.intercept_speed * cycle + self.kickable)
            points[reach] = course[reach]
            found |= reach
        points[~found] = course[~found]
        return np.clip(points, -extent, extent)

    def _turn_done(self, angles: np.ndarray) -> np.ndarray:
        """The turn (radians) a turn command for ``angles`` asks for, after clipping."""
        limit = math.radians(180.0 if self.action == "thesis12" else self.turn_scale)
        return np.clip(angles, -limit, limit)

    def _encode(self, kinds: list[str], angles: np.ndarray, power: np.ndarray) -> np.ndarray:
        """Decisions -> env actions. Server directions are clockwise: -degrees(sim angle)."""
        n = len(kinds)
        server_deg = -np.degrees(angles)
        if self.action == "sim":
            out = np.zeros((n, 2), np.float32)
            for i, kind in enumerate(kinds):
                if kind == _TURN:
                    out[i] = (0.0, np.clip(server_deg[i] / self.turn_scale, -1.0, 1.0))
                elif kind == _KICK:
                    out[i] = (self.kick_power / 100.0, 0.0)
                elif kind == _DASH:
                    out[i] = (power[i], 0.0)
            return out
        out = np.full((n, ACTION_SIZE), -1.0, np.float32)
        out[:, ActionIndex.DASH_POWER :] = 0.0
        for i, kind in enumerate(kinds):
            if kind == _TURN:
                out[i, ActionIndex.TURN_SCORE] = 1.0
                out[i, ActionIndex.TURN_MOMENT] = np.clip(server_deg[i] / 180.0, -1.0, 1.0)
            elif kind == _KICK:
                out[i, ActionIndex.KICK_SCORE] = 1.0
                out[i, ActionIndex.KICK_POWER] = 2.0 * self.kick_power / 100.0 - 1.0
                out[i, ActionIndex.KICK_DIR] = np.clip(server_deg[i] / 180.0, -1.0, 1.0)
            elif kind == _DASH:
                out[i, ActionIndex.DASH_SCORE] = 1.0
                out[i, ActionIndex.DASH_POWER] = power[i]
                out[i, ActionIndex.DASH_DIR] = np.clip(server_deg[i] / 90.0, -1.0, 1.0)
            else:
                out[i, ActionIndex.NOOP_SCORE] = 1.0
        return out
