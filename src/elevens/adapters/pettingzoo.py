"""PettingZoo ``ParallelEnv`` front of one elevens game: host-side, NumPy in and out.

    from elevens.adapters.pettingzoo import SoccerParallelEnv

    env = SoccerParallelEnv("2v2", episode_length=200)
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

Agents are named ``team0_0 .. team0_{n-1}, team1_0 .. team1_{n-1}``. Each agent observes its own
partial, egocentric view in its team's frame (both teams see themselves attacking +x), as a dict
``{"self": f32[15], "entities": f32[2n, 11], "entity_mask": bool[2n]}`` (feature names in
``elevens.env.state.SELF_FEATURES`` and ``ENTITY_FEATURES``). An action is ``(move, rot)`` in
[-1, 1]; values outside are clipped, while NaN, Inf, wrong shapes and non-numbers raise
``ValueError``. Soccer episodes never terminate: every agent is truncated together after
``episode_length`` steps, and ``agents`` is then empty until the next ``reset``.

Randomness: ``reset(seed=s)`` starts the key sequence at ``jax.random.key(s)``; ``reset()`` without
a seed continues it. Each reset and each step splits the carried key, ``key, use_key = split(key)``,
and passes ``use_key`` to ``Soccer.reset`` / ``Soccer.step`` (where it only matters for respawns
after a goal). So a rollout is reproducible from the seed and the actions alone.

Every step is one compiled call (physics, rewards, observation, the key split and the clip of the
observation to its declared space) followed by one ``jax.device_get``; the compiled functions are
cached per team size, so every env of the same size shares them.
"""

from __future__ import annotations

import functools
import math
import secrets
from collections.abc import Mapping
from typing import Any, NamedTuple

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer, make
from elevens.env.state import Observation, State, StepInfo

ACTION_SHAPE = (2,)  # (move, rot)


# ------------------------------------------------------------------------------ bounds
class ObservationBounds(NamedTuple):
    """Per-feature bounds of one agent's observation (the same for every agent)."""

    self_low: np.ndarray  # f32[NUM_SELF_FEATURES]
    self_high: np.ndarray  # f32[NUM_SELF_FEATURES]
    entity_low: np.ndarray  # f32[NUM_ENTITY_FEATURES]
    entity_high: np.ndarray  # f32[NUM_ENTITY_FEATURES]


class StateBounds(NamedTuple):
    """Per-feature bounds of the critic's global state (one team's view)."""

    context_low: np.ndarray  # f32[NUM_CONTEXT_FEATURES]
    context_high: np.ndarray  # f32[NUM_CONTEXT_FEATURES]
    player_low: np.ndarray  # f32[NUM_PLAYER_FEATURES]
    player_high: np.ndarray  # f32[NUM_PLAYER_FEATURES]


def _limits(params: EnvParams) -> tuple[float, float, float]:
    """(max distance / field length, max ball speed, max player speed), from the rules.

    Player and ball centres are clamped to the field (a ball past a goal line respawns in the same
    step), so no two centres are further apart than the diagonal. The ball's speed is capped at
    ``ball_max_speed`` before friction and bounces, which only slow it; a player's displacement is
    at most ``move_speed`` (clamping only shortens it).
    """
    length, width = float(params.field_length), float(params.field_width)
    return math.hypot(length, width) / length, float(params.ball_max_speed), float(
        params.move_speed
    )


def observation_bounds(params: EnvParams) -> ObservationBounds:
    """Bounds of every observation feature (SELF_FEATURES and ENTITY_FEATURES order)."""
    distance, ball_speed, player_speed = _limits(params)
    any_speed = max(ball_speed, player_speed)
    # time_left, x, y, cos h, sin h, last_move, last_rot, start_x, start_y, ball_visible,
    # ball_distance, ball cos, ball sin, ball_vel_forward, ball_vel_left
    self_low = [0, -1, -1, -1, -1, -1, -1, -1, -1, 0, 0, -1, -1, -ball_speed, -ball_speed]
    self_high = [1, 1, 1, 1, 1, 1, 1, 1, 1, 1, distance, 1, 1, ball_speed, ball_speed]
    # distance, cos, sin, vel_forward, vel_left, cos rel, sin rel, last_move, last_rot,
    # is_teammate, is_ball
    entity_low = [0, -1, -1, -any_speed, -any_speed, -1, -1, -1, -1, 0, 0]
    entity_high = [distance, 1, 1, any_speed, any_speed, 1, 1, 1, 1, 1, 1]
    return ObservationBounds(
        *(np.asarray(b, np.float32) for b in (self_low, self_high, entity_low, entity_high))
    )


def state_bounds(params: EnvParams) -> StateBounds:
    """Bounds of the critic's state features (CONTEXT_FEATURES and PLAYER_FEATURES order)."""
    _, ball_speed, player_speed = _limits(params)
    # time_left, ball_x, ball_y, ball_vx, ball_vy
    context_low = [0, -1, -1, -ball_speed, -ball_speed]
    context_high = [1, 1, 1, ball_speed, ball_speed]
    # x, y, cos h, sin h, vx, vy, last_move, last_rot, start_x, start_y, is_teammate
    player_low = [-1, -1, -1, -1, -player_speed, -player_speed, -1, -1, -1, -1, 0]
    player_high = [1, 1, 1, 1, player_speed, player_speed, 1, 1, 1, 1, 1]
    return StateBounds(
        *(np.asarray(b, np.float32) for b in (context_low, context_high, player_low, player_high))
    )


# ----------------------------------------------------------------- compiled functions
class HostStep(NamedTuple):
    """The arrays a PettingZoo step needs on the host (one ``device_get``)."""

    observation: Observation  # leading axes [2, n], clipped to the declared bounds
    rewards: jax.Array  # f32[2, n]
    done: jax.Array  # bool[] the episode ran out of time
    info: StepInfo
    score: jax.Array  # i32[2] goals of team 0 and team 1 this episode


class StepOutput(NamedTuple):
    """What one compiled step returns; ``host`` is all that crosses to the host."""

    key: jax.Array  # key[] the carried key after the split
    state: State
    host: HostStep


class ResetOutput(NamedTuple):
    """What one compiled reset returns."""

    key: jax.Array  # key[] the carried key after the split
    state: State
    observation: Observation  # leading axes [2, n], clipped to the declared bounds


def clip_observation(observation: Observation, bounds: ObservationBounds) -> Observation:
    """Clip to the declared bounds. With honest bounds this only removes float rounding (~1e-6)."""
    return Observation(
        self_features=jnp.clip(observation.self_features, bounds.self_low, bounds.self_high),
        entities=jnp.clip(observation.entities, bounds.entity_low, bounds.entity_high),
        entity_mask=observation.entity_mask,
    )


@functools.cache
def _compiled(players_per_team: int) -> tuple[Any, Any, Any]:
    """jitted (reset, step, global state) for one team size, shared by every env of that size."""
    soccer = Soccer(players_per_team)

    def reset(key: jax.Array, params: EnvParams, bounds: ObservationBounds) -> ResetOutput:
        key, reset_key = jax.random.split(key)
        state, observation = soccer.reset(reset_key, params)
        return ResetOutput(key=key, state=state, observation=clip_observation(observation, bounds))

    def step(
        key: jax.Array,
        state: State,
        actions: jax.Array,
        params: EnvParams,
        bounds: ObservationBounds,
    ) -> StepOutput:
        key, step_key = jax.random.split(key)
        state, observation, rewards, done, info = soccer.step(step_key, state, actions, params)
        host = HostStep(
            observation=clip_observation(observation, bounds),
            rewards=rewards,
            done=done,
            info=info,
            score=state.score,
        )
        return StepOutput(key=key, state=state, host=host)

    def flat_global_state(state: State, params: EnvParams, bounds: StateBounds) -> jax.Array:
        critic = soccer.global_state(state, params)
        context = jnp.clip(critic.context, bounds.context_low, bounds.context_high)
        players = jnp.clip(critic.players, bounds.player_low, bounds.player_high)
        return jnp.concatenate([context, players.reshape(2, -1)], axis=-1).reshape(-1)

    return jax.jit(reset), jax.jit(step), jax.jit(flat_global_state)


# ------------------------------------------------------------------------- the env
def agent_names(players_per_team: int) -> list[str]:
    """``team0_0 .. team0_{n-1}, team1_0 .. team1_{n-1}``: the order of the players' axis."""
    return [f"team{team}_{k}" for team in range(2) for k in range(players_per_team)]


class SoccerParallelEnv(ParallelEnv[str, dict[str, np.ndarray], np.ndarray]):
    """One elevens game behind the PettingZoo parallel API (see the module docstring).

    ``SoccerParallelEnv(scenario="2v2", render_mode=None, **env_overrides)``: the overrides go to
    ``elevens.make`` (``EnvParams`` fields, e.g. ``episode_length=200, spawn="random"``).

    Observation space per agent: ``Dict(self=Box f32[15], entities=Box f32[2n, 11],
    entity_mask=MultiBinary(2n))``; the mask is delivered as ``bool``. Bounds follow from the
    rules and the params (distances up to the field diagonal / length, velocities up to the ball's
    speed cap, everything else in [-1, 1] or [0, 1]); see ``observation_bounds``.
    Action space per agent: ``Box(-1, 1, (2,), f32)`` = (move, rot).
    ``state()``: the critic's global state of both teams, flattened: for team 0 then team 1, that
    team's context (``CONTEXT_FEATURES``) then its ``2n`` player rows (``PLAYER_FEATURES``, own team
    first), so ``state().reshape(2, -1)[t]`` is team ``t``'s critic input.
    """

    metadata: dict[str, Any] = {
        "name": "elevens_soccer_v0",
        "render_modes": ["rgb_array"],
        "is_parallelizable": True,
    }

    def __init__(self, scenario: str = "2v2", render_mode: str | None = None, **env_overrides: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode={render_mode!r} is not supported: use None or one of "
                f"{self.metadata['render_modes']}"
            )
        self.render_mode = render_mode
        self.soccer, self.params = make(scenario, **env_overrides)
        self.scenario = scenario
        n = self.soccer.players_per_team
        self.players_per_team = n
        self.possible_agents = agent_names(n)
        self.agents: list[str] = []
        self._agent_index = {name: i for i, name in enumerate(self.possible_agents)}

        self._bounds = observation_bounds(self.params)
        self._state_bounds = state_bounds(self.params)
        self.observation_spaces = {agent: self._make_observation_space() for agent in
                                   self.possible_agents}
        self.action_spaces = {
            agent: spaces.Box(-1.0, 1.0, ACTION_SHAPE, np.float32) for agent in self.possible_agents
        }
        self.state_space = spaces.Box(
            low=np.tile(np.concatenate([self._state_bounds.context_low,
                                        np.tile(self._state_bounds.player_low, 2 * n)]), 2),
            high=np.tile(np.concatenate([self._state_bounds.context_high,
                                         np.tile(self._state_bounds.player_high, 2 * n)]), 2),
            dtype=np.float32,
        )
        self._reset_fn, self._step_fn, self._state_fn = _compiled(n)
        self._key: jax.Array | None = None
        self._state: State | None = None

    def _make_observation_space(self) -> spaces.Dict:
        n, b = self.players_per_team, self._bounds
        return spaces.Dict(
            {
                "self": spaces.Box(b.self_low, b.self_high, dtype=np.float32),
                "entities": spaces.Box(
                    np.tile(b.entity_low, (2 * n, 1)), np.tile(b.entity_high, (2 * n, 1)),
                    dtype=np.float32,
                ),
                "entity_mask": spaces.MultiBinary(2 * n),
            }
        )

    # ---------------------------------------------------------------- spaces
    def observation_space(self, agent: str) -> spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self.action_spaces[agent]

    # ----------------------------------------------------------------- reset
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]]]:
        """Start an episode. ``options`` is accepted for API compatibility and ignored.

        With a seed the key sequence restarts at ``jax.random.key(seed)``; without one it continues
        (the very first unseeded reset draws a seed from the OS).
        """
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
                raise ValueError(f"seed={seed!r} is invalid: use an integer or None")
            self._key = jax.random.key(int(seed))
        elif self._key is None:
            self._key = jax.random.key(secrets.randbits(32))
        out: ResetOutput = self._reset_fn(self._key, self.params, self._bounds)
        self._key, self._state = out.key, out.state
        self.agents = list(self.possible_agents)
        observations = self._split_observation(jax.device_get(out.observation))
        return observations, {agent: {} for agent in self.agents}

    # ------------------------------------------------------------------ step
    def step(
        self, actions: Mapping[str, Any]
    ) -> tuple[
        dict[str, dict[str, np.ndarray]],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Step every agent at once. ``actions``: one ``(move, rot)`` per live agent.

        Values outside [-1, 1] are clipped. Raises ``ValueError`` for an unknown agent, a missing
        live agent, a shape other than (2,), a non-numeric value, NaN or Inf.
        """
        if self._state is None or self._key is None:
            raise RuntimeError("step() called before reset(): call reset() first")
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended (every agent is truncated): call reset()"
            )
        flat_actions = self._validate_actions(actions)
        out: StepOutput = self._step_fn(
            self._key, self._state, flat_actions.reshape(2, self.players_per_team, 2), self.params,
            self._bounds,
        )
        self._key, self._state = out.key, out.state
        host: HostStep = jax.device_get(out.host)

        observations = self._split_observation(host.observation)
        rewards_flat = host.rewards.reshape(-1)
        goal = host.info.goal_reward.reshape(-1)
        ball = host.info.ball_shaping.reshape(-1)
        approach = host.info.approach_shaping.reshape(-1)
        possession = host.info.possession_shaping.reshape(-1)
        kicks, pushes = host.info.kicks, host.info.pushes
        score = (int(host.score[0]), int(host.score[1]))
        rewards, infos = {}, {}
        for agent in self.agents:
            i = self._agent_index[agent]
            rewards[agent] = float(rewards_flat[i])
            infos[agent] = {
                "goal_reward": float(goal[i]),
                "ball_shaping": float(ball[i]),
                "approach_shaping": float(approach[i]),
                "possession_shaping": float(possession[i]),
                "touched": bool(kicks[i] or pushes[i]),
                "kicked": bool(kicks[i]),
                "pushed": bool(pushes[i]),
                "score": score,  # (team 0 goals, team 1 goals) this episode
            }
        done = bool(host.done)
        terminations = dict.fromkeys(self.agents, False)  # soccer episodes only run out of time
        truncations = dict.fromkeys(self.agents, done)
        if done:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _validate_actions(self, actions: Mapping[str, Any]) -> np.ndarray:
        """Check every action and stack them: ``f32[2n, 2]`` in player order, clipped to [-1, 1]."""
        if not isinstance(actions, Mapping):
            raise ValueError(
                f"actions must be a dict from agent name to a (move, rot) pair, got "
                f"{type(actions).__name__}"
            )
        live = set(self.agents)
        unknown = [name for name in actions if name not in live]
        if unknown:
            raise ValueError(
                f"actions given for unknown or finished agent(s) {unknown!r}: the live agents are "
                f"{self.agents}"
            )
        missing = [agent for agent in self.agents if agent not in actions]
        if missing:
            raise ValueError(
                f"actions are missing for live agent(s) {missing}: every live agent acts each step"
            )
        flat = np.zeros((len(self.possible_agents), 2), np.float32)
        for agent, value in actions.items():
            flat[self._agent_index[agent]] = _check_action(agent, value)
        return flat

    def _split_observation(self, observation: Observation) -> dict[str, dict[str, np.ndarray]]:
        """Per-agent dicts from host arrays with leading axes [2, n] (copied: fresh, writable)."""
        num_players = len(self.possible_agents)
        own = np.array(observation.self_features, np.float32).reshape(num_players, -1)
        entities = np.array(observation.entities, np.float32).reshape(num_players, num_players, -1)
        mask = np.array(observation.entity_mask, np.bool_).reshape(num_players, num_players)
        return {
            agent: {"self": own[i], "entities": entities[i], "entity_mask": mask[i]}
            for agent, i in self._agent_index.items()
            if agent in self.agents
        }

    # ------------------------------------------------------------ the rest
    def state(self) -> np.ndarray:
        """The critic's global state of both teams, flattened: ``f32[2 * (5 + 2n * 11)]``."""
        if self._state is None:
            raise RuntimeError("state() called before reset(): call reset() first")
        return np.asarray(
            jax.device_get(self._state_fn(self._state, self.params, self._state_bounds))
        )

    @property
    def game_state(self) -> State:
        """The underlying ``elevens.State`` of the current game (device arrays)."""
        if self._state is None:
            raise RuntimeError("there is no game before reset(): call reset() first")
        return self._state

    def render(self) -> np.ndarray | None:
        """An RGB frame ``u8[H, W, 3]`` of the current state (render_mode="rgb_array")."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode: construct the env with "
                'render_mode="rgb_array"'
            )
            return None
        if self._state is None:
            raise RuntimeError("render() called before reset(): call reset() first")
        try:
            from elevens.env.render import render_frame
        except ImportError as error:  # the renderer is an optional part being written separately
            raise NotImplementedError(
                f"rendering needs elevens.env.render.render_frame, which is not available: {error}"
            ) from error
        return np.asarray(render_frame(jax.device_get(self._state), self.params))

    def close(self) -> None:
        """Nothing to release: the game lives in device arrays that Python frees."""
        self._state = None
        self.agents = []


def _check_action(agent: str, value: Any) -> np.ndarray:
    """One agent's action as ``f32[2]`` clipped to [-1, 1], or a ValueError saying what is wrong."""
    allowed = "expected 2 finite numbers (move, rot) in [-1, 1] (values outside are clipped)"
    try:
        array = np.asarray(value)
    except (ValueError, TypeError) as error:
        raise ValueError(f"action for agent {agent!r} is not numeric: {value!r}; {allowed}") from (
            error
        )
    if array.dtype.kind not in "iuf":
        raise ValueError(
            f"action for agent {agent!r} is not numeric: {value!r} (dtype {array.dtype}); {allowed}"
        )
    if array.shape != ACTION_SHAPE:
        raise ValueError(
            f"action for agent {agent!r} has shape {array.shape} ({value!r}), expected shape "
            f"{ACTION_SHAPE}; {allowed}"
        )
    array = array.astype(np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(
            f"action for agent {agent!r} contains NaN or Inf: {value!r}; {allowed}"
        )
    return np.clip(array, -1.0, 1.0).astype(np.float32)
