"""rcssserver percepts -> the simulator's containers (State, Observation), host-side numpy.

Pure conversions, testable on recorded messages without a server. The env (``env.py``) calls
them once per cycle.

Frames (rcssserver's, and the simulator's of elevens.env.state):

* server: x in [-52.5, 52.5] (left goal at -52.5), **y down**, degrees, positive from +x towards
  +y (clockwise on screen); ``see`` directions are relative to the head (we never turn the neck,
  so head = body).
* simulator world frame (= team 0's frame): y up, radians, counter-clockwise positive:
  ``x = x_srv, y = -y_srv, heading = -rad(body_srv)``. Team 1's own frame is the point reflection
  ``(x, y) -> (-x, -y)``, heading + pi, i.e. ``x = -x_srv, y = y_srv, heading = pi - rad(body)``.
  A relative direction ``d`` (see) becomes the bearing ``-rad(d)`` ("+ = to the left") for both
  teams: egocentric quantities do not change under the reflection.

Velocities keep the simulator's meaning. The server reports velocities *after* the step's decay
(checked on see_global_midgame.txt: a player's reported velocity is 0.4 x its last displacement).
The simulator's player velocity is the displacement of its last step, so player velocities are
divided by ``player_decay`` (0.4); its ball velocity is what the ball moves next step, which is
the server's reported ball velocity as it is.

Observation normalisation follows elevens/env/observe.py feature by feature: positions / half
field extents (52.5, 34), distances / field length (105), velocities in m/step, bearings and
headings relative to the player's heading with + = to the left, unknown features 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from elevens.env.params import EnvParams
from elevens.env.state import (
    ENTITY_FEATURES,
    NUM_ENTITY_FEATURES,
    NUM_SELF_FEATURES,
    SELF_FEATURES,
    Observation,
    State,
)
from elevens.robocup.bodies import DEFAULT as RCSS_BODY
from elevens.robocup.bodies import kick_rate_factor
from elevens.robocup.localize import localize
from elevens.robocup.protocol import GlobalView, Kick, SeeMessage, SeenObject, SenseBody, Turn

__all__ = [
    "FIELD_LENGTH",
    "FIELD_WIDTH",
    "GOAL_WIDTH",
    "PLAYER_DECAY",
    "PerceptMemory",
    "PlayerPercepts",
    "SeenEntities",
    "body_from_world_heading",
    "entities_from_see",
    "pose_from_see",
    "server_from_world",
    "state_from_global",
    "team_from_server",
    "team_heading_from_server",
    "world_from_server",
    "world_heading_from_server",
]

FIELD_LENGTH = 105.0  # server::pitch_length (goal line to goal line)
FIELD_WIDTH = 68.0  # server::pitch_width
GOAL_WIDTH = 14.02  # server::goal_width
PLAYER_DECAY = 0.4  # server::player_decay: reported player velocity = 0.4 x last displacement

_TEAM_SIGN = np.array([1.0, -1.0])
_S = {name: i for i, name in enumerate(SELF_FEATURES)}


def _wrap(angle: np.ndarray | float) -> np.ndarray:
    """Radians to [-pi, pi), as elevens.env.physics.wrap_angle."""
    return (np.asarray(angle, np.float64) + np.pi) % (2 * np.pi) - np.pi


# ----------------------------------------------------------------------------- frames
def world_from_server(xy: np.ndarray) -> np.ndarray:
    """Server positions ``[..., 2]`` -> simulator world frame (y flipped)."""
    xy = np.asarray(xy, np.float64)
    return np.stack([xy[..., 0], -xy[..., 1]], axis=-1)


def server_from_world(xy: np.ndarray) -> np.ndarray:
    """Simulator world positions ``[..., 2]`` -> server frame (its own inverse)."""
    return world_from_server(xy)


def world_heading_from_server(body_deg: np.ndarray | float) -> np.ndarray:
    """Server body directions (degrees, clockwise) -> world headings (radians, CCW, [-pi, pi))."""
    return _wrap(-np.radians(np.asarray(body_deg, np.float64)))


def body_from_world_heading(heading: np.ndarray | float) -> np.ndarray:
    """World headings (radians) -> server body directions in degrees, (-180, 180]."""
    deg = -np.degrees(_wrap(heading))
    return np.where(deg <= -180.0, deg + 360.0, deg)


def team_from_server(xy: np.ndarray, team: int | np.ndarray) -> np.ndarray:
    """Server positions ``[..., 2]`` -> the frame of ``team`` (broadcast over leading axes)."""
    sign = _TEAM_SIGN[np.asarray(team)]
    return world_from_server(xy) * np.asarray(sign)[..., None]


def team_heading_from_server(body_deg: np.ndarray | float, team: int | np.ndarray) -> np.ndarray:
    """Server body directions (degrees) -> headings in ``team``'s frame (radians, [-pi, pi))."""
    return _wrap(-np.radians(np.asarray(body_deg, np.float64)) + np.pi * np.asarray(team))


def bearing_from_server(direction_deg: float) -> float:
    """A see direction (degrees, + clockwise) -> simulator bearing (radians, + to the left)."""
    return -math.radians(direction_deg)


# ------------------------------------------------------------------------------ state
def state_from_global(
    view: GlobalView,
    *,
    players_per_team: int,
    team_names: tuple[str, str],
    last_actions: np.ndarray,
    start_positions: np.ndarray,
    score: np.ndarray,
    step: int,
    previous: State | None = None,
    player_decay: float = PLAYER_DECAY,
) -> State:
    """The trainer's ``see_global`` -> a simulator ``State`` (world frame, numpy leaves).

    last_actions f32[2n, 2] (the (move, rot) applied), start_positions f32[2n, 2] (world frame),
    score i32[2], step: env steps this episode. A player or ball missing from the view keeps its
    value from ``previous`` (zeros without one). Player velocity = server velocity / player_decay
    (the simulator's "displacement in the last step"); ball velocity as reported.
    """
    n = players_per_team
    positions = np.zeros((2 * n, 2))
    headings = np.zeros(2 * n)
    velocities = np.zeros((2 * n, 2))
    ball_position = np.zeros(2)
    ball_velocity = np.zeros(2)
    if previous is not None:
        positions[:] = previous.positions
        headings[:] = previous.headings
        velocities[:] = previous.velocities
        ball_position[:] = previous.ball_position
        ball_velocity[:] = previous.ball_velocity
    team_of = {team_names[0]: 0, team_names[1]: 1}
    for player in view.players:
        team = team_of.get(player.team or "")
        if team is None or not 1 <= player.unum <= n:
            continue
        row = team * n + player.unum - 1
        positions[row] = (player.x, -player.y)
        headings[row] = world_heading_from_server(player.body)
        velocities[row] = (player.vx / player_decay, -player.vy / player_decay)
    if view.ball is not None:
        ball_position[:] = (view.ball.x, -view.ball.y)
        ball_velocity[:] = (view.ball.vx, -view.ball.vy)
    leaves: dict[str, Any] = dict(  # numpy leaves where the simulator has jax arrays
        positions=positions.astype(np.float32),
        headings=headings.astype(np.float32),
        velocities=velocities.astype(np.float32),
        last_actions=np.asarray(last_actions, np.float32).reshape(2 * n, 2),
        start_positions=np.asarray(start_positions, np.float32).reshape(2 * n, 2),
        ball_position=ball_position.astype(np.float32),
        ball_velocity=ball_velocity.astype(np.float32),
        score=np.asarray(score, np.int32).reshape(2),
        step=np.asarray(step, np.int32),
    )
    return State(**leaves)


# --------------------------------------------------------------------------- percepts
class PlayerPercepts(Protocol):
    """What the env reads of a player's cycle (elevens.robocup.client.PlayerCycle has it)."""

    @property
    def side(self) -> int: ...
    @property
    def unum(self) -> int: ...
    @property
    def see(self) -> SeeMessage | None: ...
    @property
    def sense_body(self) -> SenseBody | None: ...


class SeenEntities:
    """One observer's entity slots from one see (slot order of elevens.env.observe.entity_layout).

    ``entities`` f32[2n, NUM_ENTITY_FEATURES], ``mask`` bool[2n], ``ball_distance`` (metres,
    the identified ball or the close ``(B)`` form behind the player; inf when neither was seen;
    used only to decide whether a kick can reach the ball), ``dropped`` players seen that found
    no slot (unknown team, or more unum-less players than free slots).
    """

    __slots__ = ("ball_distance", "dropped", "entities", "mask")

    def __init__(
        self, entities: np.ndarray, mask: np.ndarray, ball_distance: float, dropped: int
    ) -> None:
        self.entities = entities
        self.mask = mask
        self.ball_distance = ball_distance
        self.dropped = dropped


def _rotate(forward: float, left: float, angle: float) -> np.ndarray:
    """A vector given in a frame turned ``angle`` radians (CCW), in the outer frame."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * forward - s * left, s * forward + c * left])


def _own_velocity(sense_body: SenseBody | None) -> tuple[float, float]:
    """Own velocity (post-decay, as the server reports it) in the player's frame (fwd, left)."""
    if sense_body is None or sense_body.speed_dir is None:
        return 0.0, 0.0
    b = bearing_from_server(sense_body.speed_dir)
    return sense_body.speed * math.cos(b), sense_body.speed * math.sin(b)


# _features builds rows in this order; fail loudly at import if the simulator's layout changes.
_ROW = (
    "distance", "cos_bearing", "sin_bearing", "vel_forward", "vel_left", "cos_rel_heading",
    "sin_rel_heading", "last_move", "last_rot", "is_teammate", "is_ball",
)
assert ENTITY_FEATURES == _ROW, "observe._features must follow elevens.env.state.ENTITY_FEATURES"


def _features(
    obj: SeenObject,
    own_velocity: tuple[float, float],
    field_length: float,
    is_ball: bool,
    is_teammate: bool,
    player_decay: float,
) -> list[float]:
    """The ENTITY_FEATURES of one seen ball or player (observer's frame, sim signs).

    A plain list (one numpy row per object cost more than the arithmetic): it runs for every
    object of every see.
    """
    distance = obj.distance if obj.distance is not None else 0.0
    bearing = -math.radians(obj.direction)
    cos_b, sin_b = math.cos(bearing), math.sin(bearing)
    forward = left = 0.0
    if obj.dist_change is not None and obj.dir_change is not None:
        # Server: dist_chg = radial relative speed, dir_chg = deg/step of the direction angle
        # (clockwise); relative velocity = dist_chg e + rad(dir_chg) d t, t the clockwise normal,
        # which is (sin b, -cos b) in the (forward, left) frame. Add own velocity for the
        # absolute one, as the simulator shows it.
        tangential = math.radians(obj.dir_change) * distance
        scale = 1.0 if is_ball else 1.0 / player_decay
        forward = (obj.dist_change * cos_b + tangential * sin_b + own_velocity[0]) * scale
        left = (obj.dist_change * sin_b - tangential * cos_b + own_velocity[1]) * scale
    cos_h = sin_h = 0.0
    if not is_ball and obj.body_dir is not None:
        relative = -math.radians(obj.body_dir)
        cos_h, sin_h = math.cos(relative), math.sin(relative)
    return [
        distance / field_length, cos_b, sin_b, forward, left, cos_h, sin_h, 0.0, 0.0,
        float(is_teammate), float(is_ball),
    ]


def entities_from_see(
    see: SeeMessage,
    sense_body: SenseBody | None,
    *,
    team: int,
    unum: int,
    players_per_team: int,
    team_names: tuple[str, str],
    field_length: float = FIELD_LENGTH,
    player_decay: float = PLAYER_DECAY,
) -> SeenEntities:
    """One player's see -> its entity slots (``team`` 0 left / 1 right, ``unum`` 1..n).

    Slots as elevens.env.observe.entity_layout: teammates by unum (self left out), opponents by
    unum, the ball last. A player seen with its unum goes to its own slot; one seen without
    (far away) goes to the first free slot of its team. Close ``(P)``/``(B)`` objects (within
    3 m behind, outside the view cone) are outside the simulator's field of view too and are left
    out (the close ball still counts for ``ball_distance``). Velocities come from distchg/dirchg
    plus own speed from ``sense_body`` (0 when the server omits them, i.e. far objects); the
    relative heading from the body direction (0 when omitted); others' last actions are unknown
    in the server and stay 0.
    """
    n = players_per_team
    slots = 2 * n
    entities = np.zeros((slots, NUM_ENTITY_FEATURES))
    mask = np.zeros(slots, bool)
    own_velocity = _own_velocity(sense_body)
    ball_distance = math.inf
    dropped = 0
    unnumbered: list[tuple[SeenObject, bool]] = []
    me = unum - 1
    for obj in see.objects:
        if obj.kind == "ball":
            if obj.distance is not None:
                ball_distance = min(ball_distance, obj.distance)
            if obj.close:
                continue
            entities[slots - 1] = _features(
                obj, own_velocity, field_length, True, False, player_decay
            )
            mask[slots - 1] = True
        elif obj.kind == "player" and not obj.close:
            if obj.team == team_names[team]:
                mate = True
            elif obj.team == team_names[1 - team] or (obj.team and not team_names[1 - team]):
                mate = False  # an unnamed opponent team: any other named team
            else:
                dropped += 1
                continue
            if obj.unum is None or not 1 <= obj.unum <= n or (mate and obj.unum == unum):
                unnumbered.append((obj, mate))
                continue
            j = obj.unum - 1
            slot = (j if j < me else j - 1) if mate else n - 1 + j
            entities[slot] = _features(obj, own_velocity, field_length, False, mate, player_decay)
            mask[slot] = True
    for obj, mate in unnumbered:
        lo, hi = (0, n - 1) if mate else (n - 1, slots - 1)
        free = np.flatnonzero(~mask[lo:hi])
        if len(free) == 0:
            dropped += 1
            continue
        slot = lo + int(free[0])
        entities[slot] = _features(obj, own_velocity, field_length, False, mate, player_decay)
        mask[slot] = True
    return SeenEntities(entities.astype(np.float32), mask, ball_distance, dropped)


def pose_from_see(
    see: SeeMessage, head_angle: float, team: int
) -> tuple[float, float, float] | None:
    """Self-localisation in ``team``'s frame: (x, y, heading rad) or None when it fails."""
    estimate = localize(see, head_angle)
    if not estimate.valid:
        return None
    x, y = team_from_server(np.array([estimate.x, estimate.y]), team)
    heading = float(team_heading_from_server(estimate.body_dir, team))
    return float(x), float(y), heading


# ----------------------------------------------------------------------------- memory
class PerceptMemory:
    """Each player's latest percepts, kept between see messages.

    In synch-see mode a see arrives every cycle (narrow), 2nd (normal) or 3rd (wide) cycle. Between
    sees a player's observation keeps the entities and the pose of its last see unchanged (no dead
    reckoning), so the whole observation is one consistent snapshot; ``stale`` counts the cycles
    since that see (0: this cycle had one; counted from the reset if none has arrived since).
    ``pose_valid`` is True where the pose is a fix: from the player's latest see, or its spawn
    placement when no see has arrived since the reset; False where the latest see could not be
    localised (the previous fix is kept). Arrays are ``[2, n, ...]`` (team, unum - 1), team frames.
    """

    def __init__(
        self,
        params: EnvParams,
        team_names: tuple[str, str],
        player_decay: float = PLAYER_DECAY,
        dead_reckoning: bool = False,
    ) -> None:
        n = params.players_per_team
        self.params = params
        self.team_names = team_names
        self.player_decay = player_decay
        self.dead_reckoning = dead_reckoning
        # Dead reckoning's estimates, team frame: the ball where the player last saw it, rolled
        # on a cycle at a time, and the player's own speed at its last sense_body.
        self.ball = np.zeros((2, n, 2))
        self.ball_velocity = np.zeros((2, n, 2))  # m/cycle, as the see reports it (post-decay)
        self.ball_known = np.zeros((2, n), bool)
        self.speed = np.zeros((2, n))
        self.position = np.zeros((2, n, 2))  # metres, team frame
        self.heading = np.zeros((2, n))  # radians, team frame
        self.pose_valid = np.zeros((2, n), bool)
        self.entities = np.zeros((2, n, 2 * n, NUM_ENTITY_FEATURES), np.float32)
        self.mask = np.zeros((2, n, 2 * n), bool)
        self.stale = np.zeros((2, n), np.int32)
        self.ball_distance = np.full((2, n), np.inf)  # metres, latest see incl. close (B)
        self.dropped = 0  # seen players that found no slot, since the last reset

    def reset(self, positions: np.ndarray, headings: np.ndarray) -> None:
        """A new play: forget the entities; the pose is the spawn.

        positions f[2, n, 2] metres and headings f[2, n] radians, each team's own frame.
        """
        self.position[:] = positions
        self.heading[:] = headings
        self.pose_valid[:] = True
        self.entities[:] = 0.0
        self.mask[:] = False
        self.stale[:] = 0
        self.ball_distance[:] = np.inf
        self.dropped = 0
        self.ball_known[:] = False
        self.speed[:] = 0.0

    def update(
        self,
        players: Sequence[PlayerPercepts],
        *,
        advance: bool = True,
        commands: dict[tuple[int, int], Any] | None = None,
    ) -> None:
        """Take in one cycle's percepts. ``advance``: a server cycle passed (stale + 1 for all
        players without a see this cycle). ``commands``: the body command each player sent
        in the cycle that passed, by (team, unum - 1), for dead reckoning (turns and kicks)."""
        n = self.params.players_per_team
        if advance:
            self.stale += 1
        for player in players:
            team, i = player.side, player.unum - 1
            if not (team in (0, 1) and 0 <= i < n):
                continue
            if player.see is None:
                if self.dead_reckoning and advance:
                    command = None if commands is None else commands.get((team, i))
                    self._reckon(team, i, player.sense_body, command)
                continue
            see, sense = player.see, player.sense_body
            seen = entities_from_see(
                see,
                sense,
                team=team,
                unum=player.unum,
                players_per_team=n,
                team_names=self.team_names,
                field_length=float(self.params.field_length),
                player_decay=self.player_decay,
            )
            self.entities[team, i] = seen.entities
            self.mask[team, i] = seen.mask
            self.ball_distance[team, i] = seen.ball_distance
            self.dropped += seen.dropped
            self.stale[team, i] = 0
            pose = pose_from_see(see, sense.head_angle if sense is not None else 0.0, team)
            self.pose_valid[team, i] = pose is not None
            if pose is not None:
                self.position[team, i] = pose[:2]
                self.heading[team, i] = pose[2]
            if self.dead_reckoning:
                self.speed[team, i] = math.hypot(*_own_velocity(sense))
                self._sight_ball(team, i)

    # -- dead reckoning: between sees, the pose and the ball move on as the server moves them --

    def _sight_ball(self, team: int, i: int) -> None:
        """The ball of this cycle's see, in the team frame (from the pose), to roll on."""
        self.ball_known[team, i] = bool(self.mask[team, i, -1])
        if not self.ball_known[team, i]:
            return
        row = self.entities[team, i, -1]
        distance = float(row[0]) * float(self.params.field_length)
        heading = self.heading[team, i]
        bearing = heading + math.atan2(float(row[2]), float(row[1]))
        self.ball[team, i] = self.position[team, i] + distance * np.array(
            [math.cos(bearing), math.sin(bearing)]
        )
        self.ball_velocity[team, i] = _rotate(float(row[3]), float(row[4]), heading)

    def _reckon(
        self, team: int, i: int, sense: SenseBody | None, command: Any
    ) -> None:
        """One cycle without a see: the command's turn and kick, the move sense_body reports
        (its velocity is the cycle's displacement times player_decay), the ball rolled on with
        ball_decay; the ball's entity features recomputed from the new estimates."""
        body = RCSS_BODY
        heading, position = self.heading[team, i], self.position[team, i].copy()
        if isinstance(command, Turn):
            moment = max(-180.0, min(180.0, command.moment))
            turned = -math.radians(moment) / (1.0 + body.inertia_moment * self.speed[team, i])
            heading = math.remainder(heading + turned, 2 * math.pi)
        if isinstance(command, Kick) and self.ball_known[team, i]:
            self._kick(team, i, command, position, self.heading[team, i])
        forward, left = _own_velocity(sense)
        self.speed[team, i] = math.hypot(forward, left)
        position = position + _rotate(forward, left, heading) / self.player_decay
        self.heading[team, i], self.position[team, i] = heading, position
        if not self.ball_known[team, i]:
            return
        self.ball[team, i] = self.ball[team, i] + self.ball_velocity[team, i]
        self.ball_velocity[team, i] = self.ball_velocity[team, i] * body.ball_decay
        offset = self.ball[team, i] - position
        distance = math.hypot(*offset)
        bearing = math.remainder(math.atan2(offset[1], offset[0]) - heading, 2 * math.pi)
        ball_velocity = self.ball_velocity[team, i]
        velocity = _rotate(float(ball_velocity[0]), float(ball_velocity[1]), -heading)
        self.entities[team, i, -1, :5] = (
            distance / float(self.params.field_length), math.cos(bearing), math.sin(bearing),
            velocity[0], velocity[1],
        )
        # As in a see: in the view cone only; a close ball counts for kicking either way.
        self.mask[team, i, -1] = abs(bearing) <= float(self.params.fov_half_angle)
        self.ball_distance[team, i] = distance

    def _kick(
        self, team: int, i: int, kick: Kick, position: np.ndarray, heading: float
    ) -> None:
        """rcssserver's kick (``elevens.robocup.bodies.kick_acceleration``) on the ball estimate."""
        body = RCSS_BODY
        offset = self.ball[team, i] - position
        gap = math.hypot(*offset) - body.player_size - body.ball_size
        if gap > body.kickable_margin:
            return
        angle = abs(math.remainder(math.atan2(offset[1], offset[0]) - heading, 2 * math.pi))
        rate = body.kick_power_rate * kick_rate_factor(angle, max(gap, 0.0), body.kickable_margin)
        power = max(0.0, min(body.max_power, kick.power))
        accel = min(power * rate, body.ball_accel_max)
        direction = heading - math.radians(max(-180.0, min(180.0, kick.direction)))
        velocity = self.ball_velocity[team, i] + accel * np.array(
            [math.cos(direction), math.sin(direction)]
        )
        speed = math.hypot(*velocity)
        if speed > body.ball_speed_max:
            velocity = velocity * (body.ball_speed_max / speed)
        self.ball_velocity[team, i] = velocity

    def observation(
        self, step: int, last_actions: np.ndarray, start_positions: np.ndarray
    ) -> Observation:
        """The simulator's Observation [2, n] (numpy).

        step: env steps this episode; last_actions f32[2, n, 2] (own previous (move, rot));
        start_positions f32[2, n, 2] spawn points in each team's own frame (metres).
        """
        p = self.params
        n = p.players_per_team
        extent = np.array([p.half_length, p.half_width], np.float64)
        time_left = float(np.clip(1.0 - step / p.episode_length, 0.0, 1.0))
        features = np.zeros((2, n, NUM_SELF_FEATURES), np.float32)
        features[..., _S["time_left"]] = time_left
        features[..., _S["x"] : _S["y"] + 1] = self.position / extent
        features[..., _S["cos_heading"]] = np.cos(self.heading)
        features[..., _S["sin_heading"]] = np.sin(self.heading)
        features[..., _S["last_move"] : _S["last_rot"] + 1] = last_actions
        features[..., _S["start_x"] : _S["start_y"] + 1] = np.asarray(start_positions) / extent
        features[..., _S["ball_visible"]] = self.mask[..., -1]
        ball = self.entities[..., -1, :]
        features[..., _S["ball_distance"] :] = ball[..., : NUM_SELF_FEATURES - _S["ball_distance"]]
        leaves: dict[str, Any] = dict(
            self_features=features, entities=self.entities.copy(), entity_mask=self.mask.copy()
        )
        return Observation(**leaves)
