"""Handcrafted teams of the simulator's skill game (``elevens.robocup.skills.game``).

- ``skills_naive``: the yardstick of the server runtime (``elevens.robocup.skills.naive``)
  unchanged in its decisions: its decision logic (``naive_choices``) runs under jnp on the
  arrays the runtime reads from librcsc's world model, here rebuilt from the player's
  observation (:func:`skill_observation`), and its decisions are encoded in the 4-value action
  (``decode.encode``). Outside open play there is nothing to decide in the simulator (no
  set plays, no goalie kind): player 0 (shirt 1) plays as a field player at its slot unless
  the game's goalie routine plays it.
- ``skills_random``: a uniformly random kind, pointer and target for every player.

Both are pure ``TeamPolicy``s of 4-value actions (team frame, one game; vmap for batches).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.state import ENTITY_FEATURES, SELF_FEATURES, Observation
from elevens.robocup.bodies import DEFAULT, rcss_field
from elevens.robocup.skills import controllers
from elevens.robocup.skills.decode import (
    OPEN_KINDS,
    SKILL_ACTION_SIZE,
    SkillContext,
    encode,
    shirt_numbers,
)
from elevens.robocup.skills.naive import naive_choices
from elevens.robocup.skills.observe import PLAYERS
from elevens.robocup.skills.observe import Observation as SkillObservation
from elevens.robocup.skills.space import Kind
from elevens.teams.scripted import Field

__all__ = [
    "DEFER", "REACH_FEATURES", "SkillsNaiveTeam", "SkillsRandomTeam", "ball_kind_mask",
    "deferred", "defers", "first_kind_mask",
    "nearest_kind_mask", "random_actions", "reach_features", "self_feature_count",
    "skill_observation",
]

SKILLS_FIELD = Field.of(rcss_field())

#: The self features a skill game with ``env.reach_features`` adds after ``SELF_FEATURES``:
#: librcsc's intercept table, which ``skills_naive`` decides on (who goes to the ball, who has
#: it): cycles for this player, the fastest other teammate and the fastest opponent to reach
#: the ball, over ``controllers.HORIZON + 1`` (1: not within the horizon).
REACH_FEATURES = ("self_reach", "mate_reach", "opp_reach")


def self_feature_count(reach: bool) -> int:
    """The self features of a skills policy's observation: ``SELF_FEATURES``, then with
    ``reach`` (``env.reach_features``) :data:`REACH_FEATURES`."""
    return len(SELF_FEATURES) + len(REACH_FEATURES) * bool(reach)


def reach_features(self_reach: Any, mate_reach: Any, opp_reach: Any, xp: Any = np) -> Any:
    """f32[..., 3]: the cycles (ints [...]) as :data:`REACH_FEATURES` holds them."""
    steps = xp.stack([self_reach, mate_reach, opp_reach], axis=-1).astype(xp.float32)
    horizon = controllers.HORIZON + 1
    return xp.clip(steps, 0.0, horizon) / horizon

#: The kind after the open-play ones in a game with ``env.defer``: ``skills_naive`` decides.
DEFER = OPEN_KINDS


_S = {name: i for i, name in enumerate(SELF_FEATURES)}
_E = {name: i for i, name in enumerate(ENTITY_FEATURES)}
_PLAY_ON = 2


def ball_kind_mask(obs: Observation, field: Field = SKILLS_FIELD,
                   params: Any = DEFAULT) -> jax.Array:
    """Observation [...] -> bool[..., OPEN_KINDS], ``network.kind_mask='ball'``: a player that
    sees the ball within its kicking reach (as ``skill_observation`` places it) may choose the
    ball kinds only (SHOOT, PASS, DRIBBLE, HOLD), any other player the rest only (the decode
    plays a ball kind without the ball as INTERCEPT anyway): the policy can neither walk away
    from a ball at its feet nor spend probability on kinds it cannot play."""
    distance = obs.entities[..., -1, _E["distance"]] * (2.0 * field.half_length)
    kickable = obs.entity_mask[..., -1] & (distance <= params.kickable_distance)
    return kickable[..., None] == (jnp.arange(OPEN_KINDS) <= Kind.HOLD)


def _mate_ball_gaps(obs: Observation, field: Field) -> jax.Array:
    """f32[..., n - 1]: each teammate's distance to the ball, from the player's entity slots
    (its own is the ball slot's distance); an unseen slot's value is meaningless."""
    e = obs.entities
    scale = 2.0 * field.half_length

    def where(slot: Any) -> jax.Array:  # [..., k, 2] in the player's heading frame
        d = e[..., slot, _E["distance"]] * scale
        return d[..., None] * jnp.stack(
            [e[..., slot, _E["cos_bearing"]], e[..., slot, _E["sin_bearing"]]], axis=-1)

    n = e.shape[-2] // 2
    return jnp.sqrt(jnp.sum((where(slice(0, n - 1)) - where(slice(-1, None))) ** 2, axis=-1))


def _runner_mask(runner: jax.Array, obs: Observation, field: Field, params: Any) -> jax.Array:
    """``ball_kind_mask``, and without the ball in reach the ``runner`` (bool[...]) may only run
    at it (INTERCEPT, TACKLE), any other player only take a place (GO_TO, MARK)."""
    kinds = jnp.arange(OPEN_KINDS)
    runs = (kinds == Kind.INTERCEPT) | (kinds == Kind.TACKLE)
    off_ball = jnp.where(runner[..., None], runs, ~runs & (kinds > Kind.HOLD))
    ball_mask = ball_kind_mask(obs, field, params)
    return jnp.where(ball_mask[..., :1], ball_mask, off_ball)


def nearest_kind_mask(obs: Observation, field: Field = SKILLS_FIELD,
                      params: Any = DEFAULT) -> jax.Array:
    """``network.kind_mask='ball_nearest'``: ``ball_kind_mask``, and without the ball in reach
    the player nearest the ball of its team (as it sees itself and its teammates) may only run
    at it (INTERCEPT, TACKLE), any other only take a place (GO_TO, MARK): who goes to the ball
    is the rule's (by distance, where ``skills_naive`` reads librcsc's intercept table), what
    each player does in its group the policy's."""
    seen = obs.entity_mask
    n = seen.shape[-1] // 2
    mate_gap = jnp.where(seen[..., : n - 1], _mate_ball_gaps(obs, field), jnp.inf)
    own_gap = obs.entities[..., -1, _E["distance"]] * (2.0 * field.half_length)
    nearest = seen[..., -1] & (own_gap <= jnp.min(mate_gap, axis=-1, initial=jnp.inf))
    return _runner_mask(nearest, obs, field, params)


def first_kind_mask(obs: Observation, field: Field = SKILLS_FIELD,
                    params: Any = DEFAULT) -> jax.Array:
    """``network.kind_mask='ball_first'`` (with ``env.reach_features``): ``ball_kind_mask``, and
    without the ball in reach the player who reaches it first of its team by the intercept
    table (``REACH_FEATURES``: its own cycles at most its fastest teammate's) while no teammate
    has it in reach may only run at it (INTERCEPT, TACKLE), any other only take a place
    (GO_TO, MARK): ``skills_naive``'s rule of who goes to the ball."""
    width = self_feature_count(reach=True)
    if obs.self_features.shape[-1] != width:
        raise ValueError(
            "network.kind_mask='ball_first' reads the intercept table: it needs "
            f"--env.reach-features (self features: {obs.self_features.shape[-1]}, not {width})"
        )
    seen = obs.entity_mask
    n = seen.shape[-1] // 2
    mate_has_it = jnp.any(seen[..., : n - 1] & seen[..., -1:]
                          & (_mate_ball_gaps(obs, field) <= params.kickable_distance), axis=-1)
    own, mate = (obs.self_features[..., len(SELF_FEATURES) + i] for i in range(2))
    return _runner_mask((own <= mate) & ~mate_has_it, obs, field, params)


def _slot_tables(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(mate_slot int[n, n], opp_slot int[n]): observer k's entity slot of its teammate p (its
    own row: -1) and of opponent q (``entity_layout``'s order)."""
    mate = np.full((n, n), -1, np.int64)
    for k in range(n):
        for p in range(n):
            if p != k:
                mate[k, p] = p if p < k else p - 1
    return mate, np.arange(n) + n - 1


def skill_observation(obs: Observation, field: Field,
                      params: Any = DEFAULT) -> tuple[SkillObservation, jax.Array]:
    """One team's Observation [n] (team frame) -> the arrays the skills runtime reads from
    librcsc's world model (``elevens.robocup.skills.observe.Observation``, jnp, shirt-number
    slots), and each player's heading (radians, team frame). A ball that a player does not
    see is placed where its teammates see it."""
    n = obs.self_features.shape[0]
    f = obs.self_features
    extent = jnp.array([field.half_length, field.half_width])
    pos = jnp.stack([f[:, _S["x"]], f[:, _S["y"]]], axis=-1) * extent
    heading = jnp.arctan2(f[:, _S["sin_heading"]], f[:, _S["cos_heading"]])
    e = obs.entities
    distance = e[..., _E["distance"]] * (2.0 * field.half_length)
    bearing = heading[:, None] + jnp.arctan2(e[..., _E["sin_bearing"]], e[..., _E["cos_bearing"]])
    where = pos[:, None, :] + distance[..., None] * jnp.stack(
        [jnp.cos(bearing), jnp.sin(bearing)], axis=-1)  # [n, 2n, 2]
    forward = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)[:, None, :]
    left = jnp.stack([-forward[..., 1], forward[..., 0]], axis=-1)
    velocity = e[..., _E["vel_forward"], None] * forward + e[..., _E["vel_left"], None] * left
    other_heading = heading[:, None] + jnp.arctan2(e[..., _E["sin_rel_heading"]],
                                                   e[..., _E["cos_rel_heading"]])
    seen = obs.entity_mask

    sees_ball = seen[:, -1]
    count = jnp.sum(sees_ball)

    def shared(value: jax.Array) -> jax.Array:
        total = jnp.sum(jnp.where(sees_ball[:, None], value, 0.0), axis=0)
        return jnp.where(sees_ball[:, None], value, total / jnp.maximum(count, 1))

    ball, ball_velocity = shared(where[:, -1]), shared(velocity[:, -1])

    mate_slot, opp_slot = _slot_tables(n)
    own = jnp.arange(n)[:, None] == jnp.arange(n)[None, :]
    safe = np.maximum(mate_slot, 0)
    mates = jnp.where(own[..., None], pos[:, None, :], where[jnp.arange(n)[:, None], safe])
    mates_valid = own | seen[jnp.arange(n)[:, None], safe]
    mates_heading = jnp.where(own, heading[:, None], other_heading[jnp.arange(n)[:, None], safe])
    # The observation has no own velocity (SELF_FEATURES): the player's own is zero here.
    mates_velocity = jnp.where(own[..., None], 0.0, velocity[jnp.arange(n)[:, None], safe])
    opps, opps_valid = where[:, opp_slot], seen[:, opp_slot]
    opps_heading = other_heading[:, opp_slot]

    shirts = shirt_numbers(n) - 1

    def by_shirt(values: jax.Array, fill: Any = 0.0) -> jax.Array:
        out = jnp.full((n, PLAYERS, *values.shape[2:]), fill, values.dtype)
        return out.at[:, shirts].set(values)

    def near(xy: jax.Array) -> jax.Array:  # [n, k, 2] -> bool[n, k]: the ball in its reach
        return jnp.sqrt(jnp.sum((xy - ball[:, None, :]) ** 2, axis=-1)) <= params.kickable_distance

    kickable = jnp.sqrt(jnp.sum((ball - pos) ** 2, axis=-1)) <= params.kickable_distance
    kickable_mate = jnp.any(near(mates) & mates_valid & ~own, axis=1)
    kickable_opp = jnp.any(near(opps) & opps_valid, axis=1)

    def steps(xy: jax.Array, head: jax.Array) -> jax.Array:  # [n, k, 2] -> [n, k]
        k = xy.shape[1]
        cycles, _ = controllers.reach_steps(
            xy.reshape(-1, 2), head.reshape(-1), jnp.repeat(ball, k, axis=0),
            jnp.repeat(ball_velocity, k, axis=0), field.ball_friction, params,
        )
        return cycles.reshape(n, k)

    never = controllers.HORIZON + 1
    mate_steps = jnp.where(mates_valid, steps(mates, mates_heading), never)
    opp_steps = jnp.where(opps_valid, steps(opps, opps_heading), never)
    offside = controllers.offside_line(opps[..., 0], opps_valid, ball[:, 0], field.half_length)
    zeros = jnp.zeros(n)
    fields: dict[str, Any] = dict(
        unum=shirt_numbers(n),  # static
        goalie=jnp.zeros(n, bool),
        kickable=kickable,
        pos=pos,
        vel=jnp.zeros((n, 2)),
        body=jnp.degrees(heading),
        stamina=zeros,
        tackle_probability=controllers.tackle_probability(pos, heading, ball),
        ball=ball,
        ball_vel=ball_velocity,
        ball_pos_count=jnp.zeros(n, jnp.int32),
        mates=by_shirt(mates),
        mates_valid=by_shirt(mates_valid, False),
        opps=by_shirt(opps),
        opps_valid=by_shirt(opps_valid, False),
        mates_vel=by_shirt(jnp.where(mates_valid[..., None], mates_velocity, 0.0)),
        opps_vel=by_shirt(jnp.where(opps_valid[..., None], velocity[:, opp_slot], 0.0)),
        mates_body=by_shirt(jnp.where(mates_valid, jnp.degrees(mates_heading), 0.0)),
        opps_body=by_shirt(jnp.where(opps_valid, jnp.degrees(opps_heading), 0.0)),
        opp_goalie=jnp.ones(n, jnp.int32),
        self_reach=jnp.diagonal(mate_steps),
        mate_reach=jnp.min(jnp.where(own, never, mate_steps), axis=1),
        opp_reach=jnp.min(opp_steps, axis=1),
        kickable_mate=kickable_mate,
        kickable_opp=kickable_opp,
        offside_x=offside,
        mode=jnp.full(n, _PLAY_ON, jnp.int32),
        our_set_play=jnp.zeros(n, bool),
        last_kicker=jnp.zeros(n, jnp.int32),
        penalty=jnp.zeros(n, bool),
        cycle=jnp.zeros(n, jnp.int32),
        stopped=jnp.zeros(n, jnp.int32),
        need_preprocess=jnp.zeros(n, bool),
    )
    return SkillObservation(**fields), heading


@dataclasses.dataclass(frozen=True)
class SkillsNaiveTeam:
    """``skills_naive`` in the simulator's skill game (module docstring)."""

    name: str = "skills_naive"
    field: Field = SKILLS_FIELD
    actions: int = SKILL_ACTION_SIZE

    def on_field(self, field: Field) -> SkillsNaiveTeam:
        return dataclasses.replace(self, field=field)

    def init_carry(self, players_per_team: int) -> Any:
        return ()

    def act(self, params: Any, carry: Any, obs: Observation,
            key: jax.Array) -> tuple[Any, jax.Array]:
        """obs: one team's Observation [n] -> ((), actions f32[n, 4])."""
        return carry, self.play(obs)

    def play(self, obs: Observation) -> jax.Array:
        n = obs.self_features.shape[0]
        view, _ = skill_observation(obs, self.field)
        kind, index, point = naive_choices(view, jnp)
        # Only the open-play kinds exist here (the mode is always play on, nobody is the
        # goalie kind); anything else would hold the slot.
        kind = jnp.where(kind < OPEN_KINDS, kind, Kind.GO_TO)
        player_of_shirt = np.full(PLAYERS + 1, -1, np.int32)
        player_of_shirt[shirt_numbers(n)] = np.arange(n)
        mate = jnp.asarray(player_of_shirt)[jnp.clip(index, 0, PLAYERS)]
        target = jnp.where(kind == Kind.PASS, mate, jnp.where(kind == Kind.MARK, n + mate, -1))
        context = SkillContext(
            observer=np.arange(n), unum=view.unum, position=view.pos, ball=view.ball,
            offside_x=view.offside_x, kickable=view.kickable,
        )
        return encode(
            kind, target, jnp.where(kind == Kind.DRIBBLE, index, 0), point, context, n,
            half=(self.field.half_length, self.field.half_width),
            goal_half_width=self.field.goal_half_width, xp=jnp,
        )


@dataclasses.dataclass(frozen=True)
class SkillsRandomTeam:
    """Uniformly random skill actions: every kind, slot and target alike."""

    name: str = "skills_random"
    actions: int = SKILL_ACTION_SIZE

    def init_carry(self, players_per_team: int) -> Any:
        return ()

    def act(self, params: Any, carry: Any, obs: Observation,
            key: jax.Array) -> tuple[Any, jax.Array]:
        return carry, random_actions(key, (obs.self_features.shape[0],))


def random_actions(key: jax.Array, shape: tuple[int, ...]) -> jax.Array:
    """Uniform skill actions f32[*shape, 4] for players of a team of ``shape[-1]``: every kind,
    every slot of its observation, every point (16 bits of each value); one draw of two 32-bit
    words a player (each word drawn is dear on a CPU: half the words of four floats)."""
    n = shape[-1]
    words = jax.random.bits(key, (*shape, 2), jnp.uint32)
    halves = jnp.concatenate([words >> 16, words & 0xFFFF], axis=-1)  # kind, pointer, x, y
    u = (halves.astype(jnp.float32) + 0.5) / 65536.0  # in (0, 1)
    kind = jnp.minimum(jnp.floor(u[..., 0] * OPEN_KINDS), OPEN_KINDS - 1)
    pointer = jnp.minimum(jnp.floor(u[..., 1] * 2 * n), 2 * n - 1)
    return jnp.concatenate([kind[..., None], pointer[..., None], 2.0 * u[..., 2:] - 1.0], axis=-1)


def defers(actions: jax.Array) -> jax.Array:
    """bool [...]: which rows of actions f32[..., 4] chose ``DEFER``."""
    return jnp.round(actions[..., 0]) == DEFER


def deferred(actions: jax.Array, obs: Observation, naive: SkillsNaiveTeam) -> jax.Array:
    """One team's actions f32[n, 4] with every ``DEFER`` row replaced by what ``naive`` (a
    ``SkillsNaiveTeam`` on the game's field) decides on the team's observation ``obs`` [n]
    (its rows in shirt-number order, as the game and the server runtime's padded view hold
    them)."""
    return jnp.where(defers(actions)[..., None], naive.play(obs).astype(actions.dtype), actions)
