"""The simulator's skill game: every player's action is a skill decision (``decode``: kind,
pointer, target), carried out by the compiled controllers (``controllers``) over rcssserver's
bodies (``elevens.robocup.bodies``: kicks within reach, dash inertia, optional stamina and
goalie routine). The same decisions that the server runtime sends to librcsc's skills, so one
policy plays both.

``SkillsEnvConfig`` is its game for the core (``env.physics = "skills"``), with the presets
``skills-2v2`` and ``skills-11v11`` (the simulator's presets on the server's field, the
4-value action, ``skills_naive`` as the evaluation team) and the handcrafted teams
``skills_naive`` and ``skills_random`` (``elevens.robocup.skills.team``). The players see all
around (``fov_half_angle`` pi): librcsc's world model, which the server runtime decides on,
keeps every player it has seen or heard of.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import EnvParams
from elevens.env.physics import team_signs
from elevens.env.state import Observation, State
from elevens.nets.policy import register_kind_mask
from elevens.robocup.bodies import (
    DEFAULT,
    TACKLE,
    Commands,
    RcssSoccer,
    kickable,
    materialised,
    rcss_field,
)
from elevens.robocup.sim import SERVER_FIELD, RcssEnvConfig
from elevens.robocup.skills import controllers
from elevens.robocup.skills.decode import (
    OPEN_KINDS,
    SKILL_ACTION_SIZE,
    SkillChoice,
    SkillContext,
    decode,
    shirt_numbers,
)
from elevens.robocup.skills.team import (
    SkillsNaiveTeam,
    SkillsRandomTeam,
    ball_kind_mask,
    deferred,
    first_kind_mask,
    nearest_kind_mask,
    random_actions,
    reach_features,
    self_feature_count,
)
from elevens.teams.registry import register_team
from elevens.teams.scripted import Field
from elevens.train.config import (
    EnvConfig,
    LearnerConfig,
    TrainConfig,
    apply_overrides,
    make_config,
    register_game,
    register_preset,
)

__all__ = [
    "DEFER_TO", "SkillSoccer", "SkillsEnvConfig", "register", "skills_config", "skills_field",
    "tackle_draws",
]


def skills_field(players_per_team: int = 11, **overrides: Any) -> EnvParams:
    """The server's field and ball (``rcss_field``), seen all around."""
    return rcss_field(players_per_team, **{"fov_half_angle": math.pi, **overrides})


class SkillSoccer(RcssSoccer):
    """The skill game: actions ``f32[2, n, 4]`` (team, player, (kind, pointer, x, y); the
    layout and its fallbacks in ``elevens.robocup.skills.decode``); the rest is
    ``RcssSoccer``'s, with tackles (``ball_pushes``). With ``reach`` each player's self
    features end with ``team.REACH_FEATURES`` (:meth:`reach_table`), as the server runtime
    reads them from librcsc's intercept table. With ``defer`` a ninth kind, ``team.DEFER``,
    plays what ``skills_naive`` decides for that player on its observation of the state
    (``team.deferred``), as the server runtime does."""

    actions: int = SKILL_ACTION_SIZE
    kickers: int | None = controllers.KICKERS
    """The players nearest the ball that may play it (``controllers.commands``): a with-ball
    kind of a farther player in kicking reach intercepts (None: every player in reach)."""

    def __init__(self, players_per_team: int = 11, body: Any = DEFAULT, see_period: int = 1,
                 stamina: bool = False, goalie: bool = False, reach: bool = False,
                 defer: bool = False):
        super().__init__(players_per_team, body, see_period, stamina, goalie)
        self.reach = reach
        self.defer = defer

    @property
    def kinds(self) -> int:
        """The decision's kinds: the open-play ones, and ``DEFER`` with ``defer``."""
        return OPEN_KINDS + int(self.defer)

    def default_params(self, **overrides: Any) -> EnvParams:
        return skills_field(self.players_per_team, **overrides)

    def reach_table(self, state: State,
                    params: EnvParams) -> tuple[jax.Array, jax.Array, jax.Array]:
        """(self, fastest other teammate, fastest opponent) i32[2, n] each: the cycles to the
        ball (``controllers.reach_steps`` from the true state, as ``skills_naive``'s view
        computes them), ``controllers.HORIZON`` + 1 when not within it."""
        n, m = self.players_per_team, self.num_players
        cycles, _ = controllers.reach_steps(
            state.positions, state.headings, jnp.broadcast_to(state.ball_position, (m, 2)),
            jnp.broadcast_to(state.ball_velocity, (m, 2)), params.ball_friction, self.body,
        )
        own = cycles.reshape(2, n)
        others = jnp.where(jnp.eye(n, dtype=bool)[None], controllers.HORIZON + 1, own[:, None, :])
        theirs = jnp.min(own, axis=1)[::-1]
        return own, jnp.min(others, axis=-1), jnp.broadcast_to(theirs[:, None], (2, n))

    def _with_reach(self, obs: Observation, state: State, params: EnvParams) -> Observation:
        if not self.reach:
            return obs
        own, mate, opp = self.reach_table(state, params)
        extra = reach_features(own, mate, opp, xp=jnp)
        return dataclasses.replace(
            obs, self_features=jnp.concatenate([obs.self_features, extra], axis=-1))

    def observe(self, state: State, params: EnvParams) -> Observation:
        return self._with_reach(super().observe(state, params), state, params)

    def observe_noisy(self, state: State, params: EnvParams, key: jax.Array) -> Observation:
        return self._with_reach(super().observe_noisy(state, params, key), state, params)

    def action_layout(self) -> str:
        return f"(kind 0..{self.kinds - 1}, pointer 0..{2 * self.players_per_team - 1}, x, y)"

    def applied(self, actions: jax.Array) -> jax.Array:
        """The actions f32[..., 2, n, 4] as the decode reads them: NaN counts as 0, the kind
        clipped to 0..7 (0..8 with ``defer``), the pointer to 0..2n-1, (x, y) to [-1, 1] (not
        all to [-1, 1], which would leave only SHOOT and PASS)."""
        actions = jnp.where(jnp.isnan(actions), 0.0, actions)
        top = jnp.array([self.kinds - 1, 2 * self.players_per_team - 1, 1.0, 1.0], actions.dtype)
        bottom = jnp.array([0.0, 0.0, -1.0, -1.0], actions.dtype)
        return jnp.clip(actions, bottom, top)

    def context(self, state: State, params: EnvParams) -> SkillContext:
        """Every player's decode context, each in its team's frame, from the true state."""
        n = self.players_per_team
        sign = jnp.asarray(team_signs(params))[:, None]
        own = sign * state.positions  # [2n, 2] each in its own team's frame
        ball = sign * state.ball_position[None, :]
        # One line a team (its players share it), each in its team's frame.
        opponent_x = jnp.stack([state.positions[n:, 0], -state.positions[:n, 0]])
        team_ball_x = jnp.stack([state.ball_position[0], -state.ball_position[0]])
        offside = jnp.repeat(controllers.offside_line(
            opponent_x, jnp.ones((2, n), bool), team_ball_x, params.half_length
        ), n)
        return SkillContext(
            observer=np.arange(2 * n),  # static: the decode's tables are cut at trace time
            unum=np.tile(shirt_numbers(n), 2),
            position=own,
            ball=ball,
            offside_x=offside,
            kickable=kickable(state.positions, state.ball_position[None, :], self.body)
            & self._near(state),
        )

    def _rank(self, state: State) -> tuple[jax.Array, int] | None:
        """Each player's rank by distance to the ball (``controllers.nearest``) and how many
        may play it, or None when every player may."""
        k = self.kickers
        if k is None or k >= self.num_players:
            return None
        ball = jnp.broadcast_to(state.ball_position, state.positions.shape)
        return controllers.nearest(state.positions, ball), k

    def kicking_rows(self, state: State) -> jax.Array | None:
        """The ``kickers`` players nearest the ball (only they kick, ``controllers.commands``)."""
        ranked = self._rank(state)
        return None if ranked is None else controllers.ranked(*ranked)

    def _near(self, state: State) -> jax.Array:
        """bool[2n]: the players that may play the ball (``kickers``)."""
        ranked = self._rank(state)
        return jnp.ones(self.num_players, bool) if ranked is None else ranked[0] < ranked[1]

    def decode(self, state: State, actions: jax.Array, params: EnvParams) -> SkillChoice:
        """What each player does for ``actions`` f32[2, n, 4] in ``state`` (after the
        fallbacks), each in its team's frame."""
        flat = actions.reshape(self.num_players, SKILL_ACTION_SIZE).astype(jnp.float32)
        return decode(
            flat, self.context(state, params), self.players_per_team,
            half=(params.half_length, params.half_width), goal_half_width=params.goal_width / 2,
            xp=jnp,
        )

    def transition(
        self, key: jax.Array, state: State, actions: jax.Array, params: EnvParams
    ) -> tuple[State, jax.Array, jax.Array, Any]:
        """One server cycle: each player's skill decoded and its controller's command played."""
        self._check_params(params)
        self.check_actions(actions)
        if self.defer:
            naive = SkillsNaiveTeam(field=Field.of(params))
            actions = jax.vmap(deferred, in_axes=(0, 0, None))(
                actions, self.observe(state, params), naive)
        choice = self.decode(state, actions, params)
        m = self.num_players
        body = controllers.Bodies.of(
            state.positions, state.velocities, state.headings,
            jnp.broadcast_to(state.ball_position, (m, 2)),
            jnp.broadcast_to(state.ball_velocity, (m, 2)), self.body,
        )
        command = controllers.commands(
            choice, body, state.positions, jnp.asarray(team_signs(params)), params.half_length,
            params.ball_friction, self.body, *(self._rank(state) or (None, m)),
        )
        return self.play_commands(key, state, command, params)

    def ball_pushes(
        self, key: jax.Array, state: State, command: Commands
    ) -> tuple[jax.Array, jax.Array]:
        """Tackles: each succeeds with rcssserver's probability (drawn with the step's key)
        and pushes the ball towards its direction."""
        ball = jnp.broadcast_to(state.ball_position, state.positions.shape)
        chance = controllers.tackle_probability(state.positions, state.headings, ball)
        # The draws once into memory: else each consumer of ``won`` works the cipher out again.
        (draw,) = materialised(tackle_draws(key, self.num_players))
        won = (command.kind == TACKLE) & (draw < chance)
        push = controllers.tackle_acceleration(
            command.kick_direction, state.positions, state.headings, ball
        )
        return jnp.sum(jnp.where(won[:, None], push, 0.0), axis=0), won

    def sample_actions(self, key: jax.Array, shape: tuple[int, ...] = ()) -> jax.Array:
        """Uniform random actions f32[*shape, 2, n, 4]: every kind, every slot, every point."""
        return random_actions(key, (*shape, 2, self.players_per_team))


_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))


def _threefry2x32(k1: jax.Array, k2: jax.Array, x1: jax.Array,
                  x2: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The Threefry-2x32 block cipher (20 rounds) on uint32 words, as jax.random computes it,
    written out: XLA's CPU backend runs jax's as a loop of 5 trips of several kernels each,
    where this fuses into one."""
    ks = (k1, k2, k1 ^ k2 ^ np.uint32(0x1BD11BDA))
    x1, x2 = x1 + ks[0], x2 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x1 = x1 + x2
            x2 = x1 ^ ((x2 << np.uint32(r)) | (x2 >> np.uint32(32 - r)))
        x1 = x1 + ks[(i + 1) % 3]
        x2 = x2 + ks[(i + 2) % 3] + np.uint32(i + 1)
    return x1, x2


def tackle_draws(key: jax.Array, m: int) -> jax.Array:
    """f32[m]: ``jax.random.uniform(jax.random.fold_in(key, 1), (m,))``, the same values
    (threefry keys, jax's partitionable counters; else jax.random's own draw), drawn without
    its rolled loops."""
    if (str(jax.random.key_impl(key)) != "threefry2x32"
            or not getattr(jax.config, "jax_threefry_partitionable", True)):
        return jax.random.uniform(jax.random.fold_in(key, 1), (m,))
    data = jax.random.key_data(key)
    k1, k2 = _threefry2x32(data[0], data[1], jnp.uint32(0), jnp.uint32(1))  # fold_in(key, 1)
    b1, b2 = _threefry2x32(k1, k2, jnp.zeros(m, jnp.uint32), jnp.arange(m, dtype=jnp.uint32))
    # uniform's mantissa trick: 23 random bits under the exponent of 1.0, minus 1.
    bits = ((b1 ^ b2) >> np.uint32(9)) | np.uint32(0x3F800000)
    return jax.lax.bitcast_convert_type(bits, jnp.float32) - 1.0


#: Who plays a deferring player in the server (``SkillsEnvConfig.defer_to``).
DEFER_TO = ("skills_naive", "helios")


@dataclasses.dataclass(frozen=True)
class SkillsEnvConfig(RcssEnvConfig):
    """The skill game (``SkillSoccer``); the fields are ``RcssEnvConfig``'s (give the server's
    field, seen all around, in ``game``: ``skills_field``)."""

    physics: str = "skills"
    """The game's bodies and action: "skills", rcssserver's bodies and skill decisions."""
    reach_features: bool = False
    """Each player's self features end with librcsc's intercept table (``team.REACH_FEATURES``:
    cycles to the ball for itself, its fastest teammate and the fastest opponent), which the
    server runtime reads from the world model and ``skills_naive`` decides on."""
    defer: bool = False
    """The decision has a ninth kind, DEFER: ``skills_naive`` decides for that player (in the
    simulator and in the server alike). A policy that defers where it has learned nothing
    better starts at ``skills_naive``'s level (``network.kinds 9``, and
    ``network.last_kind_logit`` for how often an untrained one defers)."""

    defer_to: str = "skills_naive"
    """Who plays a deferring player in the server: ``skills_naive``, or ``helios``: helios-base's
    own parts through the proxy (its on-ball planner with the ball, its basic move without:
    ``skills_helios_parts``, which plays helios-base far closer than ``skills_naive``). The
    simulator cannot play helios-base's parts: there ``skills_naive`` stands in for both."""

    PHYSICS: ClassVar[str] = "skills"
    BODIES: ClassVar[type[RcssSoccer]] = SkillSoccer

    def make_env(self, players_per_team: int) -> SkillSoccer:
        return SkillSoccer(
            players_per_team, see_period=self.see_period, stamina=self.stamina,
            goalie=self.goalie, reach=self.reach_features, defer=self.defer,
        )

    @property
    def kinds(self) -> int | None:
        return OPEN_KINDS + (self.defer is True)

    @property
    def self_features(self) -> int:
        return self_feature_count(self.reach_features)

    def check(self) -> None:
        super().check()
        for name in ("reach_features", "defer"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(
                    f"env.{name}={getattr(self, name)!r} is invalid: it must be True or False"
                )
        if self.defer_to not in DEFER_TO:
            raise ValueError(f"env.defer_to={self.defer_to!r} is invalid (allowed: "
                             f"{', '.join(DEFER_TO)})")
        if self.defer_to != "skills_naive" and not self.defer:
            raise ValueError(f"env.defer_to={self.defer_to!r} is invalid without env.defer "
                             "(set --env.defer, or leave env.defer_to at skills_naive)")


def skills_config(preset: str, **overrides: Any) -> TrainConfig:
    """The simulator preset ``preset`` in the skill game: the server's field and ball seen all
    around, the 4-value action, ``skills_naive`` for evaluation and no GIF (its game is
    against the simulator's teams); ``overrides`` as ``make_config`` takes them; validated."""
    config = make_config(preset)
    learner: LearnerConfig = config.learner
    env = learner.env
    server = skills_field(env.players_per_team)
    game = dataclasses.replace(
        env.game, fov_half_angle=server.fov_half_angle,
        **{name: getattr(server, name) for name in SERVER_FIELD},
    )
    shared = {f.name: getattr(env, f.name) for f in dataclasses.fields(EnvConfig)}
    config = dataclasses.replace(
        config,
        preset=f"skills-{preset}",
        learner=dataclasses.replace(
            learner,
            env=SkillsEnvConfig(**{**shared, "game": game, "physics": SkillsEnvConfig.PHYSICS}),
            # The head that matches the decision: a kind, a pointer by attention, a target.
            network=dataclasses.replace(
                learner.network, actions=SKILL_ACTION_SIZE, head="parametrised",
                kinds=OPEN_KINDS,
            ),
        ),
        run=dataclasses.replace(
            config.run, eval_teams=("skills_naive",), write_gif=False,
            run_dir=f"runs/skills-{preset}",
        ),
    )
    return apply_overrides(config, overrides).validate()


def register() -> None:
    """Make the skill game, its presets and teams known to the core (idempotent)."""
    register_game(SkillsEnvConfig)
    register_team("skills_naive", SkillsNaiveTeam())
    register_team("skills_random", SkillsRandomTeam())
    register_kind_mask("ball", ball_kind_mask)
    register_kind_mask("ball_nearest", nearest_kind_mask)
    register_kind_mask("ball_first", first_kind_mask)
    for preset in ("2v2", "11v11"):
        register_preset(
            f"skills-{preset}",
            _preset_factory(preset),
            f"The {preset} preset in the simulator's skill game: rcssserver's bodies, field "
            "and ball, and a skill decision (kind, pointer, target) per player, as the skills "
            "runtime plays the server.",
        )


def _preset_factory(preset: str) -> Any:
    return lambda: skills_config(preset)
