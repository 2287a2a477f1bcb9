"""The Soccer env: pure ``reset(key, params)`` and ``step(key, state, actions, params)``.

The env object holds only static structure (players per team); every number lives in EnvParams.
``step`` reads as a paragraph: move, contacts, ball, goals, reward, respawn, observe.
"""

from __future__ import annotations

import re
from typing import Any

import jax
import jax.numpy as jnp
from jax.experimental import checkify

from elevens.env import observe as observe_lib
from elevens.env import physics
from elevens.env.params import MAX_PLAYERS_PER_TEAM, EnvParams
from elevens.env.reward import next_last_touch, reward_terms
from elevens.env.state import GlobalState, Observation, State, StepInfo

SCENARIO = re.compile(r"^(\d+)v(\d+)$")


def applied_actions(actions: jax.Array) -> jax.Array:
    """The actions as the env applies them: NaN counts as 0, the rest clipped to [-1, 1]."""
    return jnp.clip(jnp.where(jnp.isnan(actions), 0.0, actions), -1.0, 1.0)


def finish_step(
    key: jax.Array,
    state: State,
    positions: jax.Array,
    headings: jax.Array,
    velocities: jax.Array,
    last_actions: jax.Array,
    ball: physics.BallUpdate,
    kicks: jax.Array,
    pushes: jax.Array,
    params: EnvParams,
) -> tuple[State, jax.Array, jax.Array, StepInfo]:
    """The end of a step, whatever moved the bodies and the ball: rewards, the respawn after a
    goal, the new State and StepInfo. ``state`` is the step's start; the rest its outcome."""
    scored = jnp.sum(ball.goals) > 0
    # Hand-built States may leave last_touch None: it stays None (a scan's carry keeps its
    # structure) and the possession reward by touch is 0 for them.
    last_touch = (
        None if state.last_touch is None else next_last_touch(state.last_touch, kicks | pushes)
    )
    terms = reward_terms(
        ball.goals, ball.position, ball.velocity, velocities, state.ball_position, positions,
        params, last_touch,
    )
    respawn = physics.spawn(key, params)
    step = state.step + 1
    new_state = State(
        positions=jnp.where(scored, respawn.positions, positions),
        headings=jnp.where(scored, respawn.headings, headings),
        velocities=jnp.where(scored, 0.0, velocities),
        last_actions=last_actions,
        start_positions=jnp.where(scored, respawn.positions, state.start_positions),
        ball_position=jnp.where(scored, respawn.ball_position, ball.position),
        ball_velocity=jnp.where(scored, 0.0, ball.velocity),
        score=state.score + ball.goals,
        step=step,
        last_touch=None if last_touch is None else jnp.where(scored, -1, last_touch),
    )
    done = step >= params.episode_length
    info = StepInfo(
        goals=ball.goals,
        kicks=kicks,
        pushes=pushes,
        goal_reward=terms.goal,
        ball_shaping=terms.ball,
        approach_shaping=terms.approach,
        possession_shaping=terms.possession,
        holder=terms.holder,
        truncated=done,
    )
    return new_state, terms.total, done, info


class Soccer:
    """A 2D soccer game of ``n`` against ``n`` players. Pure functions; jit and vmap freely.

    Actions are ``f32[2, n, 2]`` (team, player, (move, rot)) in [-1, 1]; out-of-range values are
    clipped and NaN counts as 0 (use ``step_checked`` to have them reported). Rewards are
    ``f32[2, n]``. All episodes last ``params.episode_length`` steps, so a batch of games started
    together ends together; ``step`` does not reset by itself after ``done``.
    """

    actions: int = 2
    """Action values a player gives: (move, rot)."""

    def __init__(self, players_per_team: int = 11):
        EnvParams(players_per_team=players_per_team)  # validates
        self.players_per_team = players_per_team

    # A game is its class and its settings: two built alike are equal, so what is cached on a
    # game (a learner, a compiled program) is found again with another one built the same way.
    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and vars(other) == vars(self)

    def __hash__(self) -> int:
        return hash((type(self), *sorted(vars(self).items())))

    @property
    def num_players(self) -> int:
        return 2 * self.players_per_team

    @property
    def scripted_players(self) -> tuple[int, ...]:
        """Players (indices within a team) a routine of the game plays instead of the policy:
        their sampled actions are never played, so they leave PPO's policy terms."""
        return ()

    def default_params(self, **overrides: Any) -> EnvParams:
        return EnvParams(players_per_team=self.players_per_team, **overrides)

    def _check_params(self, params: EnvParams) -> None:
        if params.players_per_team != self.players_per_team:
            raise ValueError(
                f"params.players_per_team={params.players_per_team} does not match this env "
                f"({self.players_per_team} per team)"
            )

    def check_actions(self, actions: jax.Array) -> None:
        """Raise ``ValueError`` if actions are not ``[2, n, actions]`` floats (shapes are
        static)."""
        expected = (2, self.players_per_team, self.actions)
        shape = tuple(getattr(actions, "shape", ()))
        if shape != expected:
            raise ValueError(
                f"actions have shape {shape}, expected {expected} (team, player, "
                f"{self.action_layout()})"
            )
        if not jnp.issubdtype(actions.dtype, jnp.floating):
            raise ValueError(f"actions have dtype {actions.dtype}, expected a float dtype")

    def action_layout(self) -> str:
        """A player's action values, as the messages about actions name them."""
        return "(move, rot)"

    # ------------------------------------------------------------------ reset
    def reset(self, key: jax.Array, params: EnvParams) -> tuple[State, Observation]:
        """Start an episode. key: a ``jax.random.key`` -> (State, Observation [2, n])."""
        self._check_params(params)
        state = physics.initial_state(key, params)
        return state, self.observe(state, params)

    # ------------------------------------------------------------------- step
    def step(
        self, key: jax.Array, state: State, actions: jax.Array, params: EnvParams
    ) -> tuple[State, Observation, jax.Array, jax.Array, StepInfo]:
        """One step of the game.

        key: used only if a goal respawns everyone. actions f32[2, n, 2].
        Returns (state, obs [2, n], rewards f32[2, n], done bool[], info). After a goal the
        returned state and observation are the respawned ones.
        """
        state, rewards, done, info = self.transition(key, state, actions, params)
        return state, self.observe(state, params), rewards, done, info

    def applied(self, actions: jax.Array) -> jax.Array:
        """The actions f32[..., 2, n, A] as this game applies them, what a rollout passes on and
        records: NaN counts as 0, the rest clipped to [-1, 1] (a game of other ranges says its
        own)."""
        return applied_actions(actions)

    def transition(
        self, key: jax.Array, state: State, actions: jax.Array, params: EnvParams
    ) -> tuple[State, jax.Array, jax.Array, StepInfo]:
        """``step`` without the observation: (state, rewards f32[2, n], done bool[], info).

        Rollouts that observe the state they carry (``observe(state)`` at the top of a scan body)
        use this, so XLA materialises the state instead of fusing physics into every observation
        element (docs/architecture.md, "Cost").
        """
        self._check_params(params)
        self.check_actions(actions)
        flat_actions = actions.reshape(self.num_players, 2).astype(jnp.float32)
        flat_actions = applied_actions(flat_actions)

        positions, headings = physics.move_players(
            state.positions, state.headings, flat_actions, params
        )
        velocities = positions - state.positions
        contacts = physics.ball_contacts(positions, headings, state.ball_position, params)
        ball_velocity = physics.cap_speed(
            state.ball_velocity + contacts.impulse, params.ball_max_speed
        )
        ball = physics.roll_ball(state.ball_position, ball_velocity, params)
        return finish_step(
            key, state, positions, headings, velocities, flat_actions, ball, contacts.kicks,
            contacts.pushes, params,
        )

    def step_checked(
        self, key: jax.Array, state: State, actions: jax.Array, params: EnvParams
    ) -> tuple[State, Observation, jax.Array, jax.Array, StepInfo]:
        """``step`` that reports bad actions instead of clipping them silently.

        Wrong shapes raise ``ValueError`` at trace time; NaN/Inf or out-of-range values raise a
        ``JaxRuntimeError`` that names the bad value (checkify, so it also works under jit).
        """
        self.check_actions(actions)
        error, out = _checked_step(self, key, state, actions, params)
        error.throw()
        return out

    # ---------------------------------------------------------------- observe
    def observe(self, state: State, params: EnvParams) -> Observation:
        """Partial egocentric observations, ``[2, n]`` leading axes (see ``observe.observe``)."""
        return observe_lib.observe(state, params)

    def observe_noisy(self, state: State, params: EnvParams, key: jax.Array) -> Observation:
        """``observe`` with each player seeing the others and the ball off by Gaussian noise of
        std ``params.observation_noise`` metres per axis (``observe.sight_noise``); key: this
        step's. With noise 0 it equals ``observe``."""
        noise = observe_lib.sight_noise(key, params)
        return observe_lib.observe(state, params, noise)

    def global_state(self, state: State, params: EnvParams) -> GlobalState:
        """The critic's full state, leading axis ``[2]`` (each team's own view)."""
        return observe_lib.global_state(state, params)


def _checked_body(
    env: Soccer, key: jax.Array, state: State, actions: jax.Array, params: EnvParams
) -> tuple[State, Observation, jax.Array, jax.Array, StepInfo]:
    finite = jnp.isfinite(actions)
    bad = jnp.argmin(finite.reshape(-1))
    checkify.check(
        jnp.all(finite),
        "actions contain NaN or Inf: first bad value {value} at flat index {index} of "
        "actions[team, player, (move, rot)]",
        value=actions.reshape(-1)[bad],
        index=bad,
    )
    in_range = jnp.abs(actions) <= 1.0
    out = jnp.argmin(in_range.reshape(-1))
    checkify.check(
        jnp.all(in_range | ~finite),
        "actions out of range: value {value} at flat index {index}; allowed is [-1, 1]",
        value=actions.reshape(-1)[out],
        index=out,
    )
    return env.step(key, state, actions, params)


@jax.jit(static_argnums=0)
def _jitted_checked(env, key, state, actions, params):
    return checkify.checkify(_checked_body, errors=checkify.user_checks)(
        env, key, state, actions, params
    )


def _checked_step(env, key, state, actions, params):
    return _jitted_checked(env, key, state, actions, params)


def make(scenario: str = "11v11", **overrides: Any) -> tuple[Soccer, EnvParams]:
    """``make("11v11")`` -> (env, params). Scenarios "1v1" to "11v11"; overrides go to EnvParams."""
    match = SCENARIO.match(scenario)
    if match is None or match.group(1) != match.group(2):
        raise ValueError(
            f"scenario={scenario!r} is invalid: use 'NvN' with N from 1 to {MAX_PLAYERS_PER_TEAM}, "
            "e.g. '2v2' or '11v11'"
        )
    players = int(match.group(1))
    if "players_per_team" in overrides and overrides["players_per_team"] != players:
        raise ValueError(
            f"players_per_team={overrides['players_per_team']} contradicts scenario={scenario!r}"
        )
    overrides.pop("players_per_team", None)
    params = EnvParams(players_per_team=players, **overrides)
    return Soccer(players), params
