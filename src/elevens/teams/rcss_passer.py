"""RcssPasserTeam: a scripted team that keeps the ball, for the simulator with rcssserver's bodies.

An opponent that plays more like helios-base than ``rcss_naive`` does (issue 18: every team
trained against itself or against the chasing naive team concedes about 40 goals a match to
helios-base, whose attacks keep the ball by passing): a formation that moves with the ball, the
one or two players nearest the ball run to where they can meet it, and a player with the ball

- shoots at the far post, at full power, once within ``shoot_distance`` of the goal;
- otherwise passes to the visible teammate with the best open target ahead of it, with the kick
  power that makes the ball arrive at about ``pass_arrival_speed`` (the server's kick model:
  the effective power falls with the ball's angle and distance from the body);
- otherwise dribbles: a soft kick ``dribble_distance`` ahead, towards the goal and away from the
  nearest visible opponent.

Everything it knows comes from its own team's observation (``Observation.team``): teammates and
opponents only where they are in view, the ball shared between teammates as ``rcss_naive``
does. Pure JAX: it jits, vmaps over games and gives the 12-value action.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import formation
from elevens.env.rcss import (
    DASH,
    DEFAULT,
    KICK,
    TURN,
    Commands,
    RcssParams,
    encode_thesis12,
    kick_power_factor,
)
from elevens.env.state import ENTITY_FEATURES, Observation
from elevens.teams.rcss_naive import RCSS_FIELD, RcssNaiveTeam
from elevens.teams.scripted import BallMemory, Field, _wrap, read_view

_DISTANCE = ENTITY_FEATURES.index("distance")
_COS, _SIN = ENTITY_FEATURES.index("cos_bearing"), ENTITY_FEATURES.index("sin_bearing")
_SPEC_HALF_EXTENT = np.array([50.0, 35.0])
"""The field ``formation`` slots are given on (SPEC.md's 100 x 70)."""


@dataclasses.dataclass(frozen=True)
class RcssPasserTeam:
    """Formation, interception, passes to open teammates, dribbles and shots (12 values)."""

    name: str = "rcss_passer"
    field: Field = RCSS_FIELD
    actions: int = 12
    """Action values it gives: the thesis's RoboCup action (``RcssSoccer``)."""
    body: RcssParams = DEFAULT
    """The server's player and ball constants its kicks are sized with."""
    chasers: int = 2
    """A player runs for the ball when fewer than this many teammates it sees are nearer."""
    keeper_leaves_goal: float = 16.0
    """The keeper (formation slot 0) only runs for a ball this close to its goal centre."""
    formation_follow: float = 0.5
    """The formation's x shifts by this fraction of the ball's x (it squeezes the other way:
    each slot's x from the centre is scaled by ``1 - formation_follow / 2``)."""
    formation_follow_y: float = 0.25
    """...and its y by this fraction of the ball's y."""
    home_tolerance: float = 2.0
    """Within this distance of its spot a player turns to face the ball instead of running."""
    position_power: float = 70.0
    """Dash power back to a spot (stamina: the chasers run at full power)."""
    shoot_distance: float = 22.0
    """Shoot once the goal centre is this close."""
    shoot_post_inset: float = 1.5
    """Aim this far inside the far post."""
    pass_min: float = 5.0
    pass_max: float = 32.0
    """Pass targets from this far (m) to this far."""
    pass_lead: float = 1.5
    """Aim this far ahead of the receiver, towards the opponent goal."""
    pass_backwards: float = 8.0
    """A pass may go at most this far back towards the own goal."""
    lane_margin: float = 2.0
    """Cycles the ball must be ahead of every visible opponent at each point of a pass's path
    (an opponent covers ``player_speed_max`` a cycle, and reaches a ball within kicking range)."""
    lane_points: int = 8
    """Points along a pass's path where that race is checked."""
    pass_arrival_speed: float = 0.8
    """m/cycle the ball should still have on reaching the target."""
    pressure_distance: float = 5.0
    """An opponent this close makes the player pass or clear instead of dribbling."""
    clear_line: float = 30.0
    """Behind x = -clear_line (own half) a player with no pass clears the ball long."""
    clear_angle: float = math.radians(30.0)
    """Clearances go this far from straight upfield, towards the nearer side line."""
    dribble_distance: float = 6.0
    """A dribble kicks the ball about this far."""
    dribble_dodge: float = math.radians(45.0)
    """A dribble turns this far away from an opponent in the way."""
    chase: RcssNaiveTeam = RcssNaiveTeam(intercept=True)
    """How the chasers run at the ball (its ``field`` is replaced by this team's)."""

    def init_carry(self, players_per_team: int) -> BallMemory:
        return BallMemory.empty(players_per_team)

    def act(
        self, params: object, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        """obs: one team's Observation [n] -> (BallMemory, actions f32[n, 12])."""
        n = obs.self_features.shape[0]
        chase = dataclasses.replace(self.chase, field=self.field)
        view, carry = read_view(obs, carry, self.field, True, chase.memory_steps)
        chase_actions = chase.play(view, carry.velocity)
        others, visible = self.others(obs, view.position, view.heading)
        mates, mates_visible = others[:, : n - 1], visible[:, : n - 1]
        opponents, opponents_visible = others[:, n - 1 :], visible[:, n - 1 :]

        my_gap = jnp.linalg.norm(view.ball - view.position, axis=-1)  # [n]
        mate_gap = jnp.linalg.norm(mates - view.ball[:, None, :], axis=-1)  # [n, n-1]
        nearer = jnp.sum(mates_visible & (mate_gap < my_gap[:, None]), axis=-1)
        goal_centre = jnp.array([-self.field.half_length, 0.0])
        slots = self.slots(n)
        is_keeper = jnp.asarray(np.arange(n) == 0) if n > 1 else jnp.zeros(n, bool)
        keeper_may_go = jnp.linalg.norm(view.ball - goal_centre, axis=-1) < self.keeper_leaves_goal
        chaser = view.knows_ball & (nearer < self.chasers) & (~is_keeper | keeper_may_go)

        home = self.home(slots, view.ball, view.knows_ball)
        positioning = self.go_to(view.position, view.heading, view.ball, home)
        kicking = self.kick(view, mates, mates_visible, opponents, opponents_visible)
        can_kick = view.knows_ball & (my_gap <= self.body.kickable_distance)
        # Nobody knows where the ball is: look for it as the chasers do.
        play = chaser | ~view.knows_ball
        actions = jnp.where(play[:, None], chase_actions, positioning)
        return carry, jnp.where(can_kick[:, None], kicking, actions)

    def slots(self, n: int) -> jax.Array:
        """Formation slots on this field, f32[n, 2] (team frame)."""
        extent = np.array([self.field.half_length, self.field.half_width])
        return jnp.asarray(formation(n) / _SPEC_HALF_EXTENT * extent, jnp.float32)

    def home(self, slots: jax.Array, ball: jax.Array, knows_ball: jax.Array) -> jax.Array:
        """Each player's spot, the formation moved towards the ball: f32[n, 2]."""
        squeeze = 1.0 - self.formation_follow / 2.0
        shifted = jnp.stack(
            [
                slots[:, 0] * squeeze + self.formation_follow * ball[:, 0],
                slots[:, 1] + self.formation_follow_y * ball[:, 1],
            ],
            axis=-1,
        )
        keeper = jnp.stack(
            [jnp.full_like(ball[:, 0], -self.field.half_length + 2.0), 0.15 * ball[:, 1]], -1
        )
        shifted = shifted.at[0].set(keeper[0]) if slots.shape[0] > 1 else shifted
        extent = jnp.array([self.field.half_length - 2.0, self.field.half_width - 2.0])
        return jnp.where(knows_ball[:, None], jnp.clip(shifted, -extent, extent), slots)

    def others(
        self, obs: Observation, position: jax.Array, heading: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        """Teammates' then opponents' positions, f32[n, 2n-1, 2], and which are in view."""
        entities = obs.entities[:, :-1]  # the ball's slot is last
        distance = entities[..., _DISTANCE] * (2.0 * self.field.half_length)
        bearing = heading[:, None] + jnp.arctan2(entities[..., _SIN], entities[..., _COS])
        offset = distance[..., None] * jnp.stack([jnp.cos(bearing), jnp.sin(bearing)], -1)
        return position[:, None, :] + offset, obs.entity_mask[:, :-1]

    def go_to(
        self, position: jax.Array, heading: jax.Array, ball: jax.Array, spot: jax.Array
    ) -> jax.Array:
        """Run to ``spot`` (turn first if it is well off the body), there face the ball."""
        to_spot = spot - position
        away = jnp.linalg.norm(to_spot, axis=-1)
        spot_bearing = _wrap(jnp.arctan2(to_spot[:, 1], to_spot[:, 0]) - heading)
        to_ball = ball - position
        ball_bearing = _wrap(jnp.arctan2(to_ball[:, 1], to_ball[:, 0]) - heading)
        arrived = away <= self.home_tolerance
        bearing = jnp.where(arrived, ball_bearing, spot_bearing)
        turn_first = jnp.abs(bearing) > math.radians(20.0)
        power = jnp.where(arrived, 0.0, jnp.clip(away * 20.0, 20.0, self.position_power))
        kind = jnp.where(turn_first, TURN, DASH)
        commands = Commands(
            kind=kind,
            dash_power=power,
            dash_direction=-jnp.degrees(spot_bearing) * (~arrived),
            kick_power=jnp.zeros_like(power),
            kick_direction=jnp.zeros_like(power),
            turn_moment=jnp.clip(-jnp.degrees(bearing), -180.0, 180.0),
        )
        return encode_thesis12(commands)

    def kick_power(self, speed: jax.Array, position, heading, ball) -> jax.Array:
        """The kick power (0..100) that gives the ball ``speed`` m/cycle from where it lies."""
        # A floor on the factor keeps the power finite for a ball at the edge of reach behind.
        factor = jnp.maximum(kick_power_factor(heading, position, ball, self.body), 0.1)
        return jnp.clip(speed / (self.body.kick_power_rate * factor), 0.0, self.body.max_power)

    def kick(self, view, mates, mates_visible, opponents, opponents_visible) -> jax.Array:
        """What a player with the ball kicks: a shot, a pass or a dribble. f32[n, 12]."""
        position, ball = view.position, view.ball
        length, decay = self.field.half_length, self.field.ball_friction
        goal = jnp.array([length, 0.0])
        # Shot: at the far post (the side away from the kicker's y).
        post_y = self.field.goal_half_width - self.shoot_post_inset
        shot_target = jnp.stack(
            [jnp.full_like(ball[:, 0], length), -jnp.sign(ball[:, 1] + 1e-3) * post_y], -1
        )
        shoot = jnp.linalg.norm(goal - ball, axis=-1) < self.shoot_distance

        # Pass: the visible teammate whose led target the ball reaches, at every point of its
        # path, at least ``lane_margin`` cycles before any visible opponent can.
        target = mates + jnp.array([self.pass_lead, 0.0])
        path = target - ball[:, None, :]  # [n, m, 2]
        length_of = jnp.linalg.norm(path, axis=-1)
        pass_speed = length_of * (1.0 - decay) + self.pass_arrival_speed * decay
        pass_speed = jnp.minimum(pass_speed, self.body.ball_speed_max)
        fractions = jnp.linspace(0.1, 1.0, self.lane_points)  # [p]
        points = ball[:, None, None, :] + fractions[None, None, :, None] * path[:, :, None, :]
        travelled = jnp.minimum(
            fractions[None, None, :] * length_of[..., None] * (1.0 - decay) / pass_speed[..., None],
            0.999,
        )
        ball_cycles = jnp.log1p(-travelled) / math.log(decay)  # [n, m, p]
        reach = jnp.linalg.norm(
            opponents[:, None, None, :, :] - points[:, :, :, None, :], axis=-1
        )  # [n, m, p, k]
        opponent_cycles = (reach - self.body.kickable_distance) / self.body.player_speed_max
        lead = jnp.where(opponents_visible[:, None, None, :], opponent_cycles, jnp.inf)
        clearance = jnp.min(jnp.min(lead, axis=-1) - ball_cycles, axis=-1)  # [n, m]
        open_pass = (
            mates_visible
            & (length_of >= self.pass_min)
            & (length_of <= self.pass_max)
            & (target[..., 0] >= ball[:, None, 0] - self.pass_backwards)
            & (clearance >= self.lane_margin)
        )
        score = target[..., 0] + jnp.minimum(clearance, 10.0)
        best = jnp.argmax(jnp.where(open_pass, score, -jnp.inf), axis=-1)
        can_pass = jnp.any(open_pass, axis=-1)
        pass_target = jnp.take_along_axis(target, best[:, None, None], axis=1)[:, 0]
        pass_speed = jnp.take_along_axis(pass_speed, best[:, None], axis=1)[:, 0]

        # Under pressure, or when the pass goes further upfield than a dribble would, pass.
        opponent_gap = jnp.linalg.norm(opponents - ball[:, None, :], axis=-1)
        opponent_gap = jnp.where(opponents_visible, opponent_gap, jnp.inf)
        nearest = jnp.argmin(opponent_gap, axis=-1)
        pressed = jnp.min(opponent_gap, axis=-1) < self.pressure_distance
        passes_upfield = pass_target[:, 0] > ball[:, 0] + self.dribble_distance
        do_pass = ~shoot & can_pass & (pressed | passes_upfield)

        # Dribble: towards the goal, turned away from the nearest opponent if it is in the way.
        to_goal = goal - ball
        goal_angle = jnp.arctan2(to_goal[:, 1], to_goal[:, 0])
        threat = jnp.take_along_axis(opponents, nearest[:, None, None], axis=1)[:, 0] - ball
        threat_angle = _wrap(jnp.arctan2(threat[:, 1], threat[:, 0]) - goal_angle)
        in_the_way = pressed & (jnp.abs(threat_angle) < self.dribble_dodge * 1.5)
        dribble_angle = goal_angle - jnp.where(
            in_the_way, jnp.sign(threat_angle + 1e-6) * self.dribble_dodge, 0.0
        )
        dribble_speed = self.dribble_distance * (1.0 - decay)
        # Pressed with no pass, or deep in the own half: clear it long, upfield and wide.
        clear = ~shoot & ~do_pass & (pressed | (ball[:, 0] < -self.clear_line))
        clear_angle = jnp.where(ball[:, 1] >= 0.0, 1.0, -1.0) * self.clear_angle

        shot_offset = shot_target - ball
        angle = jnp.where(
            shoot,
            jnp.arctan2(shot_offset[:, 1], shot_offset[:, 0]),
            jnp.where(
                do_pass,
                jnp.arctan2(pass_target[:, 1] - ball[:, 1], pass_target[:, 0] - ball[:, 0]),
                jnp.where(clear, clear_angle, dribble_angle),
            ),
        )
        speed = jnp.where(do_pass, pass_speed, dribble_speed)
        power = jnp.where(
            shoot | clear, self.body.max_power, self.kick_power(speed, position, view.heading, ball)
        )
        zeros = jnp.zeros_like(power)
        commands = Commands(
            kind=jnp.full(power.shape, KICK),
            dash_power=zeros,
            dash_direction=zeros,
            kick_power=power,
            kick_direction=jnp.clip(-jnp.degrees(_wrap(angle - view.heading)), -180.0, 180.0),
            turn_moment=zeros,
        )
        return encode_thesis12(commands)
