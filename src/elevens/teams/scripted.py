"""Handcrafted teams: random, naive (every player chases the ball) and teamwork (a back line).

Each team is a pure-JAX ``TeamPolicy`` that reads only its own team's ``Observation`` (leading
axis ``[n]``, in the team's frame, where the team attacks the goal at ``(+50, 0)`` and defends the
goal at ``(-50, 0)``). None of them has parameters (``params`` is ignored). RandomTeam has no
memory (its carry is an empty tuple); the others carry a ``BallMemory``, where the team last saw
the ball. All numbers are dataclass fields whose defaults are explained beside them.

Ball mechanics the players exploit (SPEC.md): a leg kick adds 4 m/step along the kicker's heading
when the ball is within ``kick_band = 1`` of the leg line (beside the player) and within 4 m of its
centre, while body contact (distance < 2) only nudges it by 0.6 m/step. So the players do not run
into the ball: they line up *beside* it (``ball_offset`` to one side of the line through the ball
along the wanted direction), face that direction and run past it, and the ball is kicked where
they face.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from elevens.env.params import formation
from elevens.env.state import SELF_FEATURES, Observation

# Column indices of the self features this module reads (names from SELF_FEATURES).
_X, _Y = SELF_FEATURES.index("x"), SELF_FEATURES.index("y")
_COS, _SIN = SELF_FEATURES.index("cos_heading"), SELF_FEATURES.index("sin_heading")
_BALL_VISIBLE = SELF_FEATURES.index("ball_visible")
_BALL_DISTANCE = SELF_FEATURES.index("ball_distance")
_BALL_COS, _BALL_SIN = SELF_FEATURES.index("ball_cos_bearing"), SELF_FEATURES.index(
    "ball_sin_bearing"
)
_BALL_VEL_FORWARD = SELF_FEATURES.index("ball_vel_forward")
_BALL_VEL_LEFT = SELF_FEATURES.index("ball_vel_left")

DEFENDER_SLOT_X = -33.0
"""Formation slots with x <= this (keeper and back line) are defenders in TeamworkTeam."""
NEVER_SEEN = 1 << 20
"""BallMemory.age of a ball nobody has seen yet this episode."""


def _wrap(angle: jax.Array) -> jax.Array:
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def _unit(vector: jax.Array) -> jax.Array:
    norm = jnp.sqrt(jnp.sum(vector * vector, axis=-1, keepdims=True))
    return vector / jnp.maximum(norm, 1e-6)


def _perp(vector: jax.Array) -> jax.Array:
    """The vector turned +90 degrees (to the left)."""
    return jnp.stack([-vector[..., 1], vector[..., 0]], axis=-1)


@dataclasses.dataclass(frozen=True)
class Field:
    """The geometry the teams assume (SPEC.md defaults), to un-normalise their observations."""

    half_length: float = 50.0
    """Goal line at x = +-half_length; observations hold x / half_length."""
    half_width: float = 35.0
    """Side lines at y = +-half_width; observations hold y / half_width."""
    goal_half_width: float = 20.0
    """The goal mouth is |y| <= goal_half_width."""
    turn_speed: float = 0.4
    """Radians per step at rot = 1 (EnvParams.turn_speed), for one-step heading corrections."""
    ball_friction: float = 0.9
    """Ball velocity multiplier per step (EnvParams.ball_friction), to follow an unseen ball."""

    @classmethod
    def of(cls, params: Any) -> Field:
        """The geometry of ``params`` (an ``EnvParams``): floats, or the tracers of one drawn
        game inside a trace (``teams.registry.on_game``)."""

        def number(value: Any) -> Any:
            return value if isinstance(value, jax.core.Tracer) else float(value)

        return cls(
            half_length=number(params.half_length),
            half_width=number(params.half_width),
            goal_half_width=number(params.goal_width / 2),
            turn_speed=number(params.turn_speed),
            ball_friction=number(params.ball_friction),
        )


@struct.dataclass
class BallMemory:
    """Where a team last knew the ball, in its own frame: the carry of the ball-chasing teams."""

    position: jax.Array  # f32[n, 2] last sighting, rolled on while out of sight
    velocity: jax.Array  # f32[n, 2] m/step, slowed by friction while out of sight
    age: jax.Array  # i32[n] steps since the player (or, when shared, a teammate) saw the ball

    @classmethod
    def empty(cls, players_per_team: int) -> BallMemory:
        n = players_per_team
        return cls(
            position=jnp.zeros((n, 2)),
            velocity=jnp.zeros((n, 2)),
            age=jnp.full(n, NEVER_SEEN, jnp.int32),
        )


class TeamView(NamedTuple):
    """What a team knows, in its own frame (metres, radians). Leading axis [n] (players)."""

    position: jax.Array  # f32[n, 2]
    heading: jax.Array  # f32[n] radians, 0 = +x (towards the opponent goal)
    sees_ball: jax.Array  # bool[n] the player itself sees the ball
    knows_ball: jax.Array  # bool[n] seen by the player, (when shared) a teammate, or recently
    ball: jax.Array  # f32[n, 2] where the player believes the ball is (0 when unknown)


def read_view(
    obs: Observation,
    memory: BallMemory,
    field: Field,
    share_sightings: bool,
    memory_steps: int,
) -> tuple[TeamView, BallMemory]:
    """Un-normalise one team's self features. obs: leading axis [n] -> (TeamView, BallMemory).

    With ``share_sightings`` a player that does not see the ball uses a teammate's sighting (the
    players call the ball to each other; all sightings are exact, so their mean is the ball).
    When nobody sees it, the last sighting is rolled on with friction for ``memory_steps`` steps
    (it often left the view only because the player turned to line up with it).
    """
    features = obs.self_features
    extent = jnp.array([field.half_length, field.half_width])
    position = features[:, jnp.array([_X, _Y])] * extent
    heading = jnp.arctan2(features[:, _SIN], features[:, _COS])
    sees_ball = features[:, _BALL_VISIBLE] > 0.5
    distance = features[:, _BALL_DISTANCE] * (2.0 * field.half_length)
    bearing = heading + jnp.arctan2(features[:, _BALL_SIN], features[:, _BALL_COS])
    sighting = position + distance[:, None] * jnp.stack(
        [jnp.cos(bearing), jnp.sin(bearing)], axis=-1
    )
    forward = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
    velocity = (
        features[:, _BALL_VEL_FORWARD, None] * forward
        + features[:, _BALL_VEL_LEFT, None] * _perp(forward)
    )
    if share_sightings:
        count = jnp.sum(sees_ball)

        def shared(value: jax.Array) -> jax.Array:
            total = jnp.sum(jnp.where(sees_ball[:, None], value, 0.0), axis=0)
            return jnp.where(sees_ball[:, None], value, total / jnp.maximum(count, 1))

        seen = sees_ball | (count > 0)
        sighting, velocity = shared(sighting), shared(velocity)
    else:
        seen = sees_ball
    extent = jnp.array([field.half_length, field.half_width])
    rolled = jnp.clip(memory.position + memory.velocity, -extent, extent)
    memory = BallMemory(
        position=jnp.where(seen[:, None], sighting, rolled),
        velocity=jnp.where(seen[:, None], velocity, field.ball_friction * memory.velocity),
        age=jnp.where(seen, 0, jnp.minimum(memory.age + 1, NEVER_SEEN)),
    )
    knows_ball = memory.age <= memory_steps
    ball = jnp.where(knows_ball[:, None], memory.position, 0.0)
    return TeamView(position, heading, sees_ball, knows_ball, ball), memory


def steer(
    position: jax.Array,
    heading: jax.Array,
    target: jax.Array,
    field: Field,
    walk_cone: float = 0.6,
    slow_move: float = 0.2,
) -> jax.Array:
    """Actions that turn towards ``target`` and walk there. Shapes [n, 2], [n], [n, 2] -> [n, 2].

    The env turns before it moves, so a heading error the turn can fix this step (0.4 rad) costs
    nothing; with a larger error the player walks slowly (``slow_move``) while turning, because
    full speed would send it round in a circle of radius 2.5 m.
    """
    offset = target - position
    desired = jnp.arctan2(offset[:, 1], offset[:, 0])
    error = _wrap(desired - heading)
    rot = jnp.clip(-error / field.turn_speed, -1.0, 1.0)
    remaining = jnp.abs(error) - field.turn_speed * jnp.abs(rot)
    move = jnp.where(remaining < walk_cone, 1.0, slow_move)
    return jnp.stack([move, rot], axis=-1)


@dataclasses.dataclass(frozen=True)
class RandomTeam:
    """Uniform random actions in [-1, 1] for every player (the thesis's weakest baseline)."""

    name: str = "random"

    def init_carry(self, players_per_team: int) -> tuple[()]:
        return ()

    def act(
        self, params: object, carry: tuple[()], obs: Observation, key: jax.Array
    ) -> tuple[tuple[()], jax.Array]:
        """obs: one team's Observation [n] -> ((), actions f32[n, 2] uniform in [-1, 1])."""
        n = obs.self_features.shape[0]
        return carry, jax.random.uniform(key, (n, 2), minval=-1.0, maxval=1.0)


@dataclasses.dataclass(frozen=True)
class NaiveTeam:
    """Every player chases the ball and kicks it into the opponent goal.

    A player lines up ``ball_offset`` beside the line through the ball along the wanted direction
    (ball -> aim point on the goal line), ``approach_distance`` behind the ball, faces the goal
    and runs past the ball, which its legs then kick towards the goal. From in front of the ball it
    goes round it at ``clearance``, outside kicking range, so it never kicks towards its own goal.
    When nobody sees the ball (nor saw it in the last ``memory_steps`` steps) it turns on the
    spot to find it. The carry is a ``BallMemory``.
    """

    name: str = "naive"
    field: Field = Field()
    aim_margin: float = 6.0
    """Aim at the goal-line point nearest the ball, at least this far inside the posts."""
    ball_offset: float = 2.5
    """Lateral distance at which a player passes the ball: > 2 (no body push, which would only
    nudge it) and < 4 (inside leg reach), so the ball meets the leg line and is kicked."""
    approach_distance: float = 3.0
    """How far behind the ball the player lines up before its run (6 m lost 0.40 to 3 m)."""
    line_tolerance: float = 1.8
    """Lateral error from the run line allowed for the run; a larger error sends the player back
    to its line-up point (1.8 beat 1.2 by 0.6 to 0.4 in 11 v 11; asking the heading to match as
    well made it worse: the run itself turns the player)."""
    run_through: float = 8.0
    """During the run the player steers at a point this far past the ball on its run line."""
    clearance: float = 5.5
    """Going round the ball it keeps this far from it, beyond leg reach (4 m)."""
    search_turn: float = 1.0
    """rot while no teammate sees the ball (positive: clockwise)."""
    share_sightings: bool = True
    """Players that do not see the ball use a teammate's sighting of it."""
    memory_steps: int = 20
    """A ball nobody sees is followed from its last sighting for this many steps (0: forget).
    It matters in small teams: in 1 v 1 against random, 5.1 goals for and 0.0 against per game
    with it, 4.7 and 0.4 without."""

    def init_carry(self, players_per_team: int) -> BallMemory:
        return BallMemory.empty(players_per_team)

    def act(
        self, params: object, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        """obs: one team's Observation [n] -> (BallMemory, actions f32[n, 2] in [-1, 1])."""
        view, carry = self.observe(carry, obs)
        return carry, self.play(view)

    def observe(self, carry: BallMemory, obs: Observation) -> tuple[TeamView, BallMemory]:
        """What the team knows this step, and its updated memory."""
        return read_view(obs, carry, self.field, self.share_sightings, self.memory_steps)

    def play(self, view: TeamView) -> jax.Array:
        """Every player goes for the ball and drives it at the goal: TeamView -> f32[n, 2]."""
        aim = jnp.stack(
            [
                jnp.full(view.ball.shape[0], self.field.half_length),
                jnp.clip(
                    view.ball[:, 1],
                    -(self.field.goal_half_width - self.aim_margin),
                    self.field.goal_half_width - self.aim_margin,
                ),
            ],
            axis=-1,
        )
        direction = _unit(aim - view.ball)
        actions = self.drive_ball(view.position, view.heading, view.ball, direction)
        return self.search(view, actions)

    def drive_ball(
        self, position: jax.Array, heading: jax.Array, ball: jax.Array, direction: jax.Array
    ) -> jax.Array:
        """Actions that kick the ball along ``direction``: position/ball/direction f32[n, 2]
        (direction a unit vector), heading f32[n] -> actions f32[n, 2].

        Shared by every team that wants the ball somewhere (TeamworkTeam's clearances too).
        """
        side = _perp(direction)
        relative = position - ball
        along = jnp.sum(relative * direction, axis=-1)
        lateral = jnp.sum(relative * side, axis=-1)
        # Pass the ball on the side the player is already on, unless that line runs outside
        # the field (ball at a side line): then take the other side.
        sign = jnp.where(lateral >= 0, 1.0, -1.0)
        lane = ball + sign[:, None] * self.ball_offset * side
        outside = jnp.abs(lane[:, 1]) > self.field.half_width - 0.5
        sign = jnp.where(outside, -sign, sign)
        lane = ball + sign[:, None] * self.ball_offset * side
        lane_error = lateral - sign * self.ball_offset

        behind = along < -0.5
        on_line = jnp.abs(lane_error) < self.line_tolerance
        run = on_line & behind
        run_target = lane + self.run_through * direction
        setup_target = lane - self.approach_distance * direction
        # In front of (or level with) the ball, the straight path to the set-up point crosses the
        # kick zone: detour through a point beside the ball at the clearance.
        in_front = along > -self.approach_distance / 2
        close_beside = jnp.abs(lateral) < self.clearance
        detour_target = ball + sign[:, None] * self.clearance * side - 1.0 * direction
        target = jnp.where(
            run[:, None],
            run_target,
            jnp.where((in_front & close_beside)[:, None], detour_target, setup_target),
        )
        half = jnp.array([self.field.half_length, self.field.half_width])
        target = jnp.clip(target, -half, half)
        return steer(position, heading, target, self.field)

    def search(self, view: TeamView, actions: jax.Array) -> jax.Array:
        """Replace the actions of players who do not know where the ball is by a turn."""
        turn = jnp.broadcast_to(jnp.array([0.0, self.search_turn]), actions.shape)
        return jnp.where(view.knows_ball[:, None], actions, turn)


@dataclasses.dataclass(frozen=True)
class TeamworkTeam:
    """Defenders hold an arc in front of their own goal; attackers play like NaiveTeam.

    Defenders are the players whose formation slot has x <= DEFENDER_SLOT_X (the keeper and the
    back line). Each holds its own spot on a semicircle of radius ``arc_radius`` around its goal
    centre (-50, 0), facing outwards, so that its legs sweep a ball coming at the goal back out.
    When the ball comes within ``engage_radius`` of its spot, or is the nearest defender to a
    ball within ``danger_radius`` of the goal, it goes to the ball and clears it towards the
    nearer side line, then returns to its spot. When no player of the team sees the ball, the
    defenders on their spots turn to look for it, since it is then most likely behind them.
    """

    name: str = "teamwork"
    attack: NaiveTeam = NaiveTeam()
    """How the attackers play, and the ball-driving skill the defenders clear with."""
    arc_radius: float = 14.0
    """Distance of the defenders' spots from their goal centre (12 to 16 m did best; at 20 m
    balls slip past the outer spots)."""
    arc_half_angle: float = float(np.pi / 2)
    """The outermost spots sit this many radians either side of straight out: pi/2 puts them on
    the goal line beside the posts, where most goals against a narrower arc came in from the
    corners (measured: 0.66 vs 0.61 mean outcome against NaiveTeam with 1.2 rad)."""
    engage_radius: float = 11.0
    """A defender goes for a ball this close to its spot."""
    danger_radius: float = 40.0
    """The defender nearest the ball goes for it when the ball is this close to the goal centre
    (measured against NaiveTeam in 11 v 11: 0.68 at 24 m, 0.72 at 32 m, 0.80 at 40 m)."""
    clear_angle: float = 1.1
    """Clearances go this many radians (about 63 deg) from straight upfield towards the nearer
    side line: away from the goal mouth, yet upfield enough not to feed the corners."""
    home_tolerance: float = 3.0
    """Within this distance of its spot a defender turns to face outwards and corrects the rest
    of the offset by stepping forwards or backwards, so it keeps facing out."""

    def init_carry(self, players_per_team: int) -> BallMemory:
        return self.attack.init_carry(players_per_team)

    def act(
        self, params: object, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        """obs: one team's Observation [n] -> (BallMemory, actions f32[n, 2] in [-1, 1])."""
        n = obs.self_features.shape[0]
        is_defender, spot_angle = self.roles(n)
        view, carry = self.attack.observe(carry, obs)
        attack_actions = self.attack.play(view)
        field = self.attack.field

        goal = jnp.array([-field.half_length, 0.0])
        outwards = jnp.stack([jnp.cos(spot_angle), jnp.sin(spot_angle)], axis=-1)  # f32[n, 2]
        spot = goal + self.arc_radius * outwards

        ball_to_spot = jnp.linalg.norm(view.ball - spot, axis=-1)
        ball_to_goal = jnp.linalg.norm(view.ball - goal, axis=-1)
        ball_to_me = jnp.linalg.norm(view.ball - view.position, axis=-1)
        nearest = ball_to_me <= jnp.min(jnp.where(jnp.asarray(is_defender), ball_to_me, jnp.inf))
        engage = view.knows_ball & (
            (ball_to_spot < self.engage_radius) | ((ball_to_goal < self.danger_radius) & nearest)
        )

        side = jnp.where(view.ball[:, 1] >= 0, 1.0, -1.0)
        clear_direction = jnp.stack(
            [jnp.full(n, jnp.cos(self.clear_angle)), side * jnp.sin(self.clear_angle)], axis=-1
        )
        clear_actions = self.attack.drive_ball(
            view.position, view.heading, view.ball, clear_direction
        )
        hold_actions = self.hold(view.position, view.heading, spot, jnp.asarray(spot_angle))
        # A ball nobody sees is most likely behind the defenders, who face out: once back on
        # its spot, a defender looks round for it.
        at_home = jnp.linalg.norm(spot - view.position, axis=-1) <= self.home_tolerance
        hold_actions = jnp.where(
            at_home[:, None], self.attack.search(view, hold_actions), hold_actions
        )
        defender_actions = jnp.where(engage[:, None], clear_actions, hold_actions)
        actions = jnp.where(jnp.asarray(is_defender)[:, None], defender_actions, attack_actions)
        return carry, actions

    def roles(self, players_per_team: int) -> tuple[np.ndarray, np.ndarray]:
        """Static roles: (is_defender bool[n], spot_angle f32[n] on the arc, 0 for attackers).

        Defenders get angles spread over the arc in the order of their slots' y (right to left
        as seen from the goal), so neighbours in the formation are neighbours on the arc.
        """
        slots = formation(players_per_team)
        is_defender = slots[:, 0] <= DEFENDER_SLOT_X
        angles = np.zeros(players_per_team, np.float32)
        defenders = np.flatnonzero(is_defender)
        if len(defenders) > 0:
            order = defenders[np.argsort(slots[defenders, 1], kind="stable")]
            spread = (
                np.linspace(-self.arc_half_angle, self.arc_half_angle, len(order))
                if len(order) > 1
                else np.zeros(1)
            )
            angles[order] = spread
        return is_defender, angles

    def hold(
        self, position: jax.Array, heading: jax.Array, spot: jax.Array, spot_angle: jax.Array
    ) -> jax.Array:
        """Walk back to the spot, then face outwards. f32[n, 2], [n], [n, 2], [n] -> [n, 2]."""
        field = self.attack.field
        go = steer(position, heading, spot, field)
        facing_error = _wrap(spot_angle - heading)
        rot = jnp.clip(-facing_error / field.turn_speed, -1.0, 1.0)
        # Close to the spot: fix the small remaining offset by stepping along the heading
        # (backwards too), so the player keeps facing out.
        facing = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
        forward = jnp.sum((spot - position) * facing, axis=-1)
        settle = jnp.stack([jnp.clip(forward, -1.0, 1.0), rot], axis=-1)
        away = jnp.linalg.norm(spot - position, axis=-1) > self.home_tolerance
        return jnp.where(away[:, None], go, settle)
