"""The opponent panel: handcrafted teams of distinct styles, written to test trained teams.

The shipped 11 v 11 team wins by one habit: every player, the keeper too, rushes the ball up a
touchline to the attacked corner, where the bouncing walls keep the ball in play, and nobody stays
home. Each team here plays a style a real opponent might, chosen to test that habit from another
side: ``man-marking`` stays goal-side of each opponent (a rush meets a defender at every
attacker), ``high-press`` hunts the ball in the opponent's half with three players (the rush is
stopped at its start), ``deep-block`` parks ten players in two lines across its goal and clears
to the wings (the corner is crowded), ``long-ball`` kicks every ball towards three forwards who
wait high (it punishes a team that keeps nobody home), ``wing-play`` carries the ball up the
wings and crosses it to two strikers in front of the goal (the rush's own route, played
deliberately), ``counter`` defends with eight and breaks with three who wait at halfway, and
``possession`` passes to the most advanced teammate near the ball while the others keep a shape
around it.

All of them share one frame: a ``TeamView`` (``scripted.read_view``), the ball-driving skill of
``NaiveTeam`` (line up beside the ball, face where it should go, run past it), a keeper that
stays between the ball and its goal, and ``steer`` to walk to a spot. A style chooses, per
player, whether it goes for the ball and where it kicks it, and where the others stand. Roles
come from the formation slots (``env.params.formation``), so every team plays any size from 1 v
1 to 11 v 11. Positions are written for SPEC.md's 100 x 70 field and scaled to the field a team
is told (``on_field``). No team has parameters; the carry is the ``BallMemory``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import formation
from elevens.env.state import Observation
from elevens.teams.scripted import (
    DEFENDER_SLOT_X,
    BallMemory,
    Field,
    NaiveTeam,
    TeamView,
    _unit,
    _wrap,
    steer,
)

KEEPER_SLOT_X = -45.0
"""The formation slot with x <= this is the keeper (slot (-49.5, 0); teams of 2 or more)."""
ATTACKER_SLOT_X = -15.0
"""Formation slots with x >= this are the forwards (x = -11)."""
DEFAULT_HALF = np.array([50.0, 35.0])
"""SPEC.md's half extents, the field every position below is written for."""


@dataclasses.dataclass(frozen=True)
class Roles:
    """Static roles of a team of n (numpy, from the formation): each a bool or f32 array [n]."""

    slot: np.ndarray  # f32[n, 2] formation slot on the default field
    keeper: np.ndarray  # bool[n]
    defender: np.ndarray  # bool[n] the back line (not the keeper)
    forward: np.ndarray  # bool[n]
    midfield: np.ndarray  # bool[n]

    @classmethod
    def of(cls, n: int) -> Roles:
        slot = formation(n).astype(np.float32)
        keeper = slot[:, 0] <= KEEPER_SLOT_X
        defender = (slot[:, 0] <= DEFENDER_SLOT_X) & ~keeper
        forward = slot[:, 0] >= ATTACKER_SLOT_X
        return cls(slot, keeper, defender, forward, ~(keeper | defender | forward))


@dataclasses.dataclass(frozen=True)
class Plan:
    """What a style asks of each player this step (leading axis [n])."""

    chase: jax.Array  # bool[n] goes for the ball
    direction: jax.Array  # f32[n, 2] unit vector the chasers kick the ball along
    target: jax.Array  # f32[n, 2] where the others stand (team frame, metres)


def ball_rank(view: TeamView, eligible: np.ndarray | jax.Array) -> jax.Array:
    """Each eligible player's place in the order of distance to the ball (0: nearest; ties go
    to the lower index); ineligible players get n. bool[n] -> i32[n]."""
    n = view.position.shape[0]
    distance = jnp.linalg.norm(view.ball - view.position, axis=-1)
    distance = jnp.where(jnp.asarray(eligible), distance, jnp.inf)
    index = jnp.arange(n)
    closer = (distance[None, :] < distance[:, None]) | (
        (distance[None, :] == distance[:, None]) & (index[None, :] < index[:, None])
    )
    return jnp.where(jnp.asarray(eligible), jnp.sum(closer, axis=1), n)


def opponent_positions(obs: Observation, view: TeamView, field: Field) -> tuple[jax.Array,
                                                                               jax.Array]:
    """Where the team sees the opponents: (f32[n, 2] team frame, bool[n] seen by anyone).

    Entity slots n-1 .. 2n-2 hold the opponents in index order for every observer
    (``env.observe``), so the sightings of one opponent by several players are averaged.
    """
    n = view.position.shape[0]
    entities = obs.entities[:, n - 1 : 2 * n - 1]  # [observer, opponent, F]
    seen = obs.entity_mask[:, n - 1 : 2 * n - 1]
    distance = entities[..., 0] * (2.0 * field.half_length)
    bearing = view.heading[:, None] + jnp.arctan2(entities[..., 2], entities[..., 1])
    sighting = view.position[:, None, :] + distance[..., None] * jnp.stack(
        [jnp.cos(bearing), jnp.sin(bearing)], axis=-1
    )
    count = jnp.sum(seen, axis=0)
    total = jnp.sum(jnp.where(seen[..., None], sighting, 0.0), axis=0)
    return total / jnp.maximum(count, 1)[:, None], count > 0


@dataclasses.dataclass(frozen=True)
class PanelTeam:
    """The frame every panel team shares; a style overrides ``plan``.

    Each step: read the view, let the style plan, then the chasers drive the ball along their
    direction, the others walk to their targets and face the ball, and the keeper guards its
    goal (it goes for a ball within ``keeper_reach`` of its goal and clears it to the nearer
    side). A player that does not know where the ball is turns to look for it.
    """

    name: str = "panel"
    skill: NaiveTeam = NaiveTeam()
    """The ball skill (drive_ball), the view (observe) and the search, and the field."""
    keeper_reach: float = 14.0
    """The keeper goes for a ball this close to its goal centre (m on the default field)."""
    keeper_depth: float = 2.5
    """The keeper stands this far in front of its goal line."""
    clear_angle: float = 1.1
    """Clearances go this many radians from straight upfield towards the nearer side line (as
    TeamworkTeam's)."""
    settle_distance: float = 1.5
    """Within this distance of its target a player stops and turns to face the ball."""

    @property
    def field(self) -> Field:
        return self.skill.field

    def on_field(self, field: Field) -> PanelTeam:
        """The same team on another field (``teams.registry.resolve_team`` calls it)."""
        return dataclasses.replace(self, skill=dataclasses.replace(self.skill, field=field))

    def init_carry(self, players_per_team: int) -> BallMemory:
        return BallMemory.empty(players_per_team)

    def act(
        self, params: object, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        """obs: one team's Observation [n] -> (BallMemory, actions f32[n, 2] in [-1, 1])."""
        n = obs.self_features.shape[0]
        roles = Roles.of(n)
        view, carry = self.skill.observe(carry, obs)
        plan = self.plan(view, obs, roles)
        half = jnp.array([self.field.half_length, self.field.half_width])
        chase_actions = self.skill.drive_ball(view.position, view.heading, view.ball,
                                              plan.direction)
        hold_actions = self.hold(view, jnp.clip(plan.target, -half, half))
        actions = jnp.where(plan.chase[:, None], chase_actions, hold_actions)
        actions = jnp.where(jnp.asarray(roles.keeper)[:, None], self.keep(view), actions)
        return carry, self.skill.search(view, jnp.clip(actions, -1.0, 1.0))

    # -- what a style decides ------------------------------------------------------------------

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        """The style: every outfield player chases and shoots (NaiveTeam's play)."""
        n = view.position.shape[0]
        return Plan(jnp.ones(n, bool), self.shoot(view.ball), self.at(roles.slot))

    # -- shared pieces ---------------------------------------------------------------------------

    def at(self, points: Any) -> jax.Array:
        """Points written for the default field, scaled to this one. [..., 2] -> [..., 2]."""
        scale = jnp.array([self.field.half_length, self.field.half_width]) / DEFAULT_HALF
        return jnp.asarray(points, jnp.float32) * scale

    def shoot(self, ball: jax.Array) -> jax.Array:
        """Directions from the ball to the goal-line point nearest it, inside the posts."""
        field, margin = self.field, self.skill.aim_margin
        reach = field.goal_half_width - margin
        aim = jnp.stack(
            [jnp.full(ball.shape[0], field.half_length), jnp.clip(ball[:, 1], -reach, reach)],
            axis=-1,
        )
        return _unit(aim - ball)

    def towards(self, ball: jax.Array, point: jax.Array) -> jax.Array:
        """Directions from the ball to ``point`` (default-field metres, [2] or [n, 2])."""
        return _unit(self.at(point) - ball)

    def clear(self, ball: jax.Array) -> jax.Array:
        """Directions ``clear_angle`` from upfield towards the side line nearer the ball."""
        side = jnp.where(ball[:, 1] >= 0, 1.0, -1.0)
        return jnp.stack(
            [jnp.full(ball.shape[0], jnp.cos(self.clear_angle)),
             side * jnp.sin(self.clear_angle)], axis=-1,
        )

    def hold(self, view: TeamView, target: jax.Array) -> jax.Array:
        """Walk to ``target``; once there, stand and face the ball (or keep the heading)."""
        go = steer(view.position, view.heading, target, self.field)
        to_ball = view.ball - view.position
        facing = jnp.where(view.knows_ball, jnp.arctan2(to_ball[:, 1], to_ball[:, 0]),
                           view.heading)
        rot = jnp.clip(-_wrap(facing - view.heading) / self.field.turn_speed, -1.0, 1.0)
        settle = jnp.stack([jnp.zeros_like(rot), rot], axis=-1)
        near = jnp.linalg.norm(target - view.position, axis=-1) < self.settle_distance
        return jnp.where(near[:, None], settle, go)

    def keep(self, view: TeamView) -> jax.Array:
        """The keeper: on its line between the ball and the goal centre, clearing close balls."""
        field = self.field
        goal = jnp.array([-field.half_length, 0.0])
        reach = field.goal_half_width - 2.0
        spot = jnp.stack(
            [jnp.full(view.ball.shape[0], -field.half_length + self.keeper_depth),
             jnp.clip(0.6 * view.ball[:, 1], -reach, reach)], axis=-1,
        )
        scale = field.half_length / DEFAULT_HALF[0]
        close = view.knows_ball & (
            jnp.linalg.norm(view.ball - goal, axis=-1) < self.keeper_reach * scale
        )
        clearing = self.skill.drive_ball(view.position, view.heading, view.ball,
                                         self.clear(view.ball))
        return jnp.where(close[:, None], clearing, self.hold(view, spot))


def _shifted(team: PanelTeam, roles: Roles, view: TeamView, shift: tuple[float, float],
             squeeze: float, follow: float) -> jax.Array:
    """Formation slots moved ``shift`` upfield, narrowed by ``squeeze`` and drawn ``follow``
    of the way towards the ball's y: a team shape that moves with the ball. -> f32[n, 2]."""
    slot = team.at(roles.slot + np.asarray(shift, np.float32))
    y = (1.0 - squeeze) * slot[:, 1] + follow * view.ball[:, 1]
    return jnp.stack([slot[:, 0], y], axis=-1)


@dataclasses.dataclass(frozen=True)
class ManMarkingTeam(PanelTeam):
    """Every outfield player marks one opponent, standing ``goal_side`` m from it on the line to
    its own goal; the ``chasers`` outfield players nearest the ball go for it. Marks are fixed
    from the formation (the opponent whose slot lies nearest to one's own, defenders first), and
    a player whose mark nobody sees holds its slot."""

    name: str = "man-marking"
    goal_side: float = 3.0
    """Metres between a marker and its mark, towards the marker's goal."""
    chasers: int = 2
    """Outfield players nearest the ball that go for it."""

    def marks(self, roles: Roles) -> np.ndarray:
        """i32[n]: the opponent each player marks (the keeper's entry is unused)."""
        n = roles.slot.shape[0]
        theirs = -roles.slot  # the opponents' slots in this team's frame
        # Both teams use the same formation, so the opponents' keeper has this team's keeper's
        # index: nobody marks it.
        every = [int(k) for k in np.flatnonzero(~roles.keeper)] or list(range(n))
        free = list(every)
        marks = np.zeros(n, np.int32)
        for i in np.argsort(roles.slot[:, 0], kind="stable"):
            if roles.keeper[i]:
                continue
            if not free:
                free = list(every)
            j = min(free, key=lambda k: float(np.linalg.norm(theirs[k] - roles.slot[i])))
            marks[i] = j
            free.remove(j)
        return marks

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        opponents, seen = opponent_positions(obs, view, self.field)
        marks = self.marks(roles)
        mark, known = opponents[marks], seen[marks]
        goal = jnp.array([-self.field.half_length, 0.0])
        guard = mark + self.goal_side * _unit(goal - mark)
        target = jnp.where(known[:, None], guard, self.at(roles.slot))
        chase = ball_rank(view, ~roles.keeper) < self.chasers
        ahead = view.ball[:, 0] > 0.0
        direction = jnp.where(ahead[:, None], self.shoot(view.ball), self.clear(view.ball))
        return Plan(chase, direction, target)


@dataclasses.dataclass(frozen=True)
class HighPressTeam(PanelTeam):
    """The ``pressers`` outfield players nearest the ball hunt it wherever it is and shoot; the
    rest keep a compact shape pushed ``push`` m upfield that follows the ball across."""

    name: str = "high-press"
    pressers: int = 3
    """Outfield players nearest the ball that go for it."""
    push: float = 24.0
    """How far upfield the shape stands (the back line near halfway)."""

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        shape = _shifted(self, roles, view, (self.push, 0.0), squeeze=0.35, follow=0.35)
        # The shape also steps back when the ball is deep in its own half.
        back = jnp.minimum(view.ball[:, 0] + 10.0 * self.field.half_length / 50.0, shape[:, 0])
        shape = shape.at[:, 0].set(jnp.where(roles.defender, back, shape[:, 0]))
        chase = ball_rank(view, ~roles.keeper) < self.pressers
        return Plan(chase, self.shoot(view.ball), shape)


@dataclasses.dataclass(frozen=True)
class DeepBlockTeam(PanelTeam):
    """Park the bus: all but ``outlets`` outfield players hold two lines across the goal (at
    ``back_line`` and ``front_line`` m from the centre) that slide with the ball; the one of
    them nearest the ball goes for it once it is within ``engage`` m of the goal line and
    clears it to the wing. The outlets (the forwards) wait near halfway and shoot."""

    name: str = "deep-block"
    back_line: float = -40.0
    front_line: float = -28.0
    engage: float = 42.0
    """The block's nearest player goes for a ball this close to its goal line."""
    outlets: int = 1
    """Forwards left up (the rest of the forwards join the front line)."""
    width: float = 15.0
    """Half the width of each line."""

    def lines(self, roles: Roles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(outlet bool[n], block bool[n], spot f32[n, 2]): who stays up, who holds the lines,
        and each player's place before it slides with the ball (default-field metres)."""
        n = roles.slot.shape[0]
        outfield = np.flatnonzero(~roles.keeper)
        order = outfield[np.argsort(-roles.slot[outfield, 0], kind="stable")]
        outlet = np.zeros(n, bool)
        outlet[order[: min(self.outlets, max(len(outfield) - 1, 0))]] = True
        block = ~roles.keeper & ~outlet
        # The back line takes the deepest slots; each line spreads across the goal mouth.
        members = np.flatnonzero(block)
        members = members[np.lexsort((roles.slot[members, 1], roles.slot[members, 0]))]
        back_count = (len(members) + 1) // 2
        spot = np.zeros((n, 2), np.float32)
        for rank, i in enumerate(members):
            line = rank < back_count
            count = back_count if line else len(members) - back_count
            place = rank if line else rank - back_count
            y = np.linspace(-self.width, self.width, count)[place] if count > 1 else 0.0
            spot[i] = (self.back_line if line else self.front_line, y)
        spot[outlet] = (-5.0, 0.0)
        return outlet, block, spot

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        n = roles.slot.shape[0]
        outlet, block, spot = self.lines(roles)
        target = self.at(spot) + jnp.stack(
            [jnp.zeros(n), 0.4 * jnp.where(jnp.asarray(outlet), 1.0, 0.6) * view.ball[:, 1]],
            axis=-1,
        )
        deep = view.ball[:, 0] < -self.field.half_length + self.engage * self.field.half_length / 50
        chase = ((ball_rank(view, block) < 1) & deep) | (
            jnp.asarray(outlet) & (view.ball[:, 0] > -10.0 * self.field.half_length / 50)
        )
        direction = jnp.where(jnp.asarray(outlet)[:, None], self.shoot(view.ball),
                              self.clear(view.ball))
        return Plan(chase, direction, target)


@dataclasses.dataclass(frozen=True)
class LongBallTeam(PanelTeam):
    """Three forwards wait high, at ``forward_line`` m; the ``chasers`` other outfield players
    nearest the ball kick it long towards ``drop`` (in front of the forwards), and the forward
    nearest a ball in the attacking half goes for it and shoots. The rest hold their slots,
    moved ``push`` m upfield."""

    name: str = "long-ball"
    forward_line: float = 28.0
    drop: tuple[float, float] = (32.0, 0.0)
    """Where the long balls are aimed (default-field metres)."""
    chasers: int = 2
    push: float = 8.0

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        n = roles.slot.shape[0]
        forward = jnp.asarray(roles.forward)
        shape = _shifted(self, roles, view, (self.push, 0.0), squeeze=0.2, follow=0.2)
        high = self.at(np.stack([np.full(n, self.forward_line), roles.slot[:, 1] * 0.7], -1))
        target = jnp.where(forward[:, None], high, shape)
        attacking = view.ball[:, 0] > 0.0
        back = ~roles.keeper & ~roles.forward
        chase = jnp.where(
            forward, (ball_rank(view, roles.forward) < 1) & attacking,
            ball_rank(view, back) < self.chasers,
        )
        long_ball = self.towards(view.ball, jnp.asarray(self.drop))
        far = view.ball[:, 0] < 15.0 * self.field.half_length / 50
        direction = jnp.where((far & ~forward)[:, None], long_ball, self.shoot(view.ball))
        return Plan(chase, direction, target)


@dataclasses.dataclass(frozen=True)
class WingPlayTeam(PanelTeam):
    """Carry the ball up the nearer wing, then cross it: the ``chasers`` nearest players kick it
    ahead along the wing (``wing_y``) until it passes ``cross_line``, then into the box at
    ``cross_to``, where two strikers wait; a ball in the middle of the box is shot. Two wide
    players hold the wings ahead of the ball."""

    name: str = "wing-play"
    wing_y: float = 27.0
    cross_line: float = 28.0
    cross_to: tuple[float, float] = (40.0, 0.0)
    chasers: int = 2
    carry_ahead: float = 18.0
    """Along the wing the ball is kicked towards a point this far ahead of it."""

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        n = roles.slot.shape[0]
        scale_x = self.field.half_length / 50.0
        shape = _shifted(self, roles, view, (10.0, 0.0), squeeze=0.0, follow=0.15)
        # The forwards: the middle one(s) wait in the box, the wide ones on the wings.
        wide = roles.forward & (np.abs(roles.slot[:, 1]) > 5.0)
        central = roles.forward & ~wide
        box = self.at(np.stack([np.full(n, 36.0), np.where(roles.slot[:, 1] >= 0, 6.0, -6.0)],
                               -1))
        wing = self.at(np.stack([np.full(n, 20.0), np.sign(roles.slot[:, 1]) * self.wing_y], -1))
        wing = wing.at[:, 0].set(jnp.maximum(wing[:, 0], view.ball[:, 0] + 8.0 * scale_x))
        target = jnp.where(jnp.asarray(central)[:, None], box,
                           jnp.where(jnp.asarray(wide)[:, None], wing, shape))
        chase = ball_rank(view, ~roles.keeper) < self.chasers
        side = jnp.where(view.ball[:, 1] >= 0, 1.0, -1.0)
        along = jnp.stack([view.ball[:, 0] / scale_x + self.carry_ahead,
                           side * self.wing_y], axis=-1)
        run = self.towards(view.ball, along)
        cross = self.towards(view.ball, jnp.asarray(self.cross_to))
        past = view.ball[:, 0] > self.cross_line * scale_x
        in_middle = jnp.abs(view.ball[:, 1]) < 0.4 * self.field.half_width
        direction = jnp.where(
            (past & in_middle)[:, None], self.shoot(view.ball),
            jnp.where(past[:, None], cross, run),
        )
        return Plan(chase, direction, target)


@dataclasses.dataclass(frozen=True)
class CounterTeam(PanelTeam):
    """Defend deep and break: the defenders and midfield hold a block (slots moved ``drop`` m
    back) and the one nearest a ball in its own half goes for it and kicks it long to the
    wing ahead (``release``); the forwards wait at halfway, and the ``breakers`` nearest a ball
    beyond ``break_line`` go for it and shoot."""

    name: str = "counter"
    drop: float = 8.0
    release: tuple[float, float] = (25.0, 22.0)
    breakers: int = 2
    break_line: float = -8.0

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        n = roles.slot.shape[0]
        scale_x = self.field.half_length / 50.0
        forward = jnp.asarray(roles.forward)
        block = _shifted(self, roles, view, (-self.drop, 0.0), squeeze=0.3, follow=0.3)
        waiting = self.at(np.stack([np.full(n, 0.0), roles.slot[:, 1] * 0.9], -1))
        target = jnp.where(forward[:, None], waiting, block)
        back = ~roles.keeper & ~roles.forward
        own_half = view.ball[:, 0] < 0.0
        beyond = view.ball[:, 0] > self.break_line * scale_x
        chase = jnp.where(
            forward, (ball_rank(view, roles.forward) < self.breakers) & beyond,
            (ball_rank(view, back) < 1) & own_half,
        )
        side = jnp.where(view.ball[:, 1] >= 0, 1.0, -1.0)
        point = jnp.stack([jnp.full(n, self.release[0]), side * self.release[1]], axis=-1)
        direction = jnp.where(forward[:, None], self.shoot(view.ball),
                              self.towards(view.ball, point))
        return Plan(chase, direction, target)


@dataclasses.dataclass(frozen=True)
class PossessionTeam(PanelTeam):
    """Short passes: the ``chasers`` players nearest the ball pass it to the most advanced
    teammate ``min_gain`` to ``max_pass`` m ahead of it (shooting when nobody is, or from within
    ``shoot_line``); the midfield and forwards keep a shape around the ball, the defenders
    follow it up at a distance."""

    name: str = "possession"
    chasers: int = 2
    min_gain: float = 4.0
    max_pass: float = 22.0
    shoot_line: float = 22.0
    """Balls past this x are shot (default-field metres)."""

    def plan(self, view: TeamView, obs: Observation, roles: Roles) -> Plan:
        n = roles.slot.shape[0]
        scale = jnp.array([self.field.half_length, self.field.half_width]) / DEFAULT_HALF
        chase = ball_rank(view, ~roles.keeper) < self.chasers
        # Supporters: the formation around its centre, 8 m ahead of the ball.
        support = ~(roles.keeper | roles.defender)
        centre = roles.slot[support].mean(0) if support.any() else np.zeros(2, np.float32)
        offset = (roles.slot - centre) * np.array([0.8, 0.6], np.float32) + np.array([8.0, 0.0])
        ring = view.ball + jnp.asarray(offset) * scale
        back = _shifted(self, roles, view, (0.0, 0.0), squeeze=0.2, follow=0.2)
        back = back.at[:, 0].set(jnp.maximum(back[:, 0], view.ball[:, 0] - 25.0 * scale[0]))
        target = jnp.where(jnp.asarray(support)[:, None], ring, back)
        # The pass: each chaser picks the most advanced receiver in range (none: shoot).
        to_mate = view.position[None, :, :] - view.ball[:, None, :]  # [chaser, mate, 2]
        gain = to_mate[..., 0]
        distance = jnp.linalg.norm(to_mate, axis=-1)
        receiver = (
            (gain > self.min_gain * scale[0]) & (distance < self.max_pass * scale[0])
            & ~jnp.eye(n, dtype=bool) & ~chase[None, :] & ~jnp.asarray(roles.keeper)[None, :]
        )
        best = jnp.argmax(jnp.where(receiver, gain, -jnp.inf), axis=1)
        has_receiver = jnp.any(receiver, axis=1)
        pass_to = _unit(view.position[best] - view.ball)
        shoot = ~has_receiver | (view.ball[:, 0] > self.shoot_line * scale[0])
        direction = jnp.where(shoot[:, None], self.shoot(view.ball), pass_to)
        return Plan(chase, direction, target)


PANEL_TEAMS: tuple[PanelTeam, ...] = (
    ManMarkingTeam(),
    HighPressTeam(),
    DeepBlockTeam(),
    LongBallTeam(),
    WingPlayTeam(),
    CounterTeam(),
    PossessionTeam(),
)
"""The panel, one team of each style."""
