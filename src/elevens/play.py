"""One compiled unroll for every game elevens plays: training rollouts, evaluation matches and
recorded games (like Brax's ``acting.generate_unroll``).

``unroll`` plays G games for T steps with ``lax.scan``; every step is batched over the games.
Two teams take part, ``home`` and ``away`` (in training the learner is home). Each is an
``Actor``: it acts for all G games at once and may return extras (the learner's Gaussian
samples and log-probs). Home plays side ``home_side[g]`` of game ``g``. Sides are picked with
``jnp.where`` (a select, not a gather), so one program serves both.

Randomness is the caller's: ``StepKeys`` holds every step's keys, drawn however the caller
draws them. A training rollout draws one key a step per team (one batched sample over all its
players); a match draws one key per game, so a game's result does not depend on the games
beside it. What each step keeps is the caller's too: ``record`` maps a ``StepView`` to the
pytree the scan stacks, and anything it leaves out is never computed.

The scan observes the state it carries and steps with ``env.transition`` (not ``env.step``):
XLA then materialises the state once instead of fusing the physics into every observation
element (docs/architecture.md, "Cost").
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from elevens.env.params import EnvParams
from elevens.env.randomize import game_axis
from elevens.env.soccer import Soccer
from elevens.env.state import Observation, State, StepInfo
from elevens.nets.policy import AttentionPolicy
from elevens.teams.base import TeamPolicy
from elevens.teams.registry import on_game

Carry = Any


class Actor(Protocol):
    """A team acting in G games at once."""

    def init_carry(self, num_games: int, players_per_team: int) -> Carry:
        """The memory at the start of an episode, leading ``[G]``."""
        ...

    def act(
        self, carry: Carry, obs: Observation, reset: jax.Array, key: jax.Array
    ) -> tuple[Carry, jax.Array, Any]:
        """obs leading ``[G, n]``, reset bool[G, n] (an episode starts here), key: the step's
        key for this team -> (carry, actions f32[G, n, 2], extras or None)."""
        ...


class NetworkSample(struct.PyTreeNode):
    """The extras of a ``NetworkActor``: what PPO needs of each action."""

    pre_tanh: jax.Array  # f32[G, n, A] the raw samples: the Gaussian's u, the actions tanh(u)
    #                      (the parametrised head: (kind, pointer, u_x, u_y))
    log_prob: jax.Array  # f32[G, n] log pi(action) under the acting params (exact, from u)
    teacher_action: jax.Array | None = None  # f32[G, n, A] a ``TaughtActor``'s teacher's action
    #                                           on the same observation; None: no teacher


@dataclasses.dataclass(frozen=True)
class NetworkActor:
    """The network on all ``[G, n]`` players in one batched forward pass (thesis 5.2.9),
    sampling with one key a step. ``per_game``: ``params`` has a leading ``[G]`` axis (one
    league snapshot per game) and the forward pass is vmapped over games."""

    policy: AttentionPolicy
    params: Any
    per_game: bool = False

    def init_carry(self, num_games: int, players_per_team: int) -> Carry:
        return self.policy.initial_carry((num_games, players_per_team))

    def act(
        self, carry: Carry, obs: Observation, reset: jax.Array, key: jax.Array
    ) -> tuple[Carry, jax.Array, NetworkSample]:
        apply = jax.vmap(self.policy.apply) if self.per_game else self.policy.apply
        step: Any = apply(self.params, carry, obs, reset)
        carry, output = step
        distribution = output.distribution()
        sample = distribution.sample(key)
        log_prob = distribution.log_prob(sample.pre_tanh)
        return carry, sample.action, NetworkSample(pre_tanh=sample.pre_tanh, log_prob=log_prob)


@dataclasses.dataclass(frozen=True)
class PolicyActor:
    """Any ``TeamPolicy`` (handcrafted, a network behind ``NetworkTeam``), vmapped over games.
    Its key is one per game (``key[G]``), or one key split into G (typed keys, as
    ``jax.random.key`` makes them: the rank tells the two apart)."""

    policy: TeamPolicy
    params: Any = None
    game_params: EnvParams | None = None
    """Per-game EnvParams (leading ``[G]``) of drawn games: the team then plays each game on
    that game's field (``teams.registry.on_game``). None: the field it was made for."""

    def init_carry(self, num_games: int, players_per_team: int) -> Carry:
        one = self.policy.init_carry(players_per_team)
        return jax.tree.map(lambda leaf: jnp.broadcast_to(leaf, (num_games, *leaf.shape)), one)

    def act(
        self, carry: Carry, obs: Observation, reset: jax.Array, key: jax.Array
    ) -> tuple[Carry, jax.Array, None]:
        if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
            raise TypeError(
                f"PolicyActor needs typed keys (jax.random.key), got an array of {key.dtype}"
            )
        num_games = reset.shape[0]
        keys = key if key.ndim == 1 else jax.random.split(key, num_games)
        if self.game_params is None:
            carry, actions = jax.vmap(self.policy.act, in_axes=(None, 0, 0, 0))(
                self.params, carry, obs, keys
            )
            return carry, actions, None

        def act_on(game: EnvParams, memory: Carry, seen: Observation, key: jax.Array) -> Any:
            return on_game(self.policy, game).act(self.params, memory, seen, key)

        carry, actions = jax.vmap(act_on)(self.game_params, carry, obs, keys)
        return carry, actions, None


@dataclasses.dataclass(frozen=True)
class TaughtActor:
    """The network, with a fixed team (``teacher``) acting beside it on the same observations:
    the network's actions are played, the teacher's are only recorded in the extras
    (``NetworkSample.teacher_action``, the game's action format). The teacher gets
    ``fold_in(key, 1)`` of the step's key, so the network's draws are those of an unrolled
    ``NetworkActor``."""

    network: NetworkActor
    teacher: Actor

    def init_carry(self, num_games: int, players_per_team: int) -> Carry:
        return (
            self.network.init_carry(num_games, players_per_team),
            self.teacher.init_carry(num_games, players_per_team),
        )

    def act(
        self, carry: Carry, obs: Observation, reset: jax.Array, key: jax.Array
    ) -> tuple[Carry, jax.Array, NetworkSample]:
        memory, actions, sample = self.network.act(carry[0], obs, reset, key)
        taught, teacher_actions, _ = self.teacher.act(
            carry[1], obs, reset, jax.random.fold_in(key, 1)
        )
        sample = sample.replace(teacher_action=jnp.asarray(teacher_actions, jnp.float32))
        return (memory, taught), actions, sample


@dataclasses.dataclass(frozen=True)
class BlockActor:
    """Several actors, each playing its own block of consecutive games (the learner's
    opponents of ``opponent.mix``: self-play first, then each fixed team). Block 0 gets the
    step's key, block ``b`` gets ``fold_in(key, b)``; extras are dropped."""

    actors: tuple[Actor, ...]
    games: tuple[int, ...]
    """Games of each block, in order; a block of 0 games is skipped."""

    def init_carry(self, num_games: int, players_per_team: int) -> Carry:
        assert num_games == sum(self.games), (num_games, self.games)
        return tuple(
            actor.init_carry(games, players_per_team)
            for actor, games in zip(self.actors, self.games, strict=True)
        )

    def act(
        self, carry: Carry, obs: Observation, reset: jax.Array, key: jax.Array
    ) -> tuple[Carry, jax.Array, None]:
        carries, actions = [], []
        begin = 0
        for block, (actor, games) in enumerate(zip(self.actors, self.games, strict=True)):
            end = begin + games
            if games:
                in_block = lambda x, b=begin, e=end: x[b:e]  # noqa: E731
                block_key = key if block == 0 else jax.random.fold_in(key, block)
                memory, action, _ = actor.act(
                    carry[block], jax.tree.map(in_block, obs), reset[begin:end], block_key
                )
                actions.append(action)
            else:
                memory = carry[block]
            carries.append(memory)
            begin = end
        return tuple(carries), jnp.concatenate(actions, axis=0), None


class StepKeys(struct.PyTreeNode):
    """One step's keys (leading ``[T]`` for a whole episode): each team's and the env's."""

    home: jax.Array  # the home actor's key (one, or key[G])
    away: jax.Array  # the away actor's key
    env: jax.Array  # key[G], each game's respawn key


def per_game_step_keys(play_keys: jax.Array, num_steps: int) -> StepKeys:
    """Every step's keys from one key per game (``key[G]``): game ``g`` draws
    ``split(play_keys[g], (T, 3))`` (home, away, env), so its games are its own."""
    keys = jax.vmap(lambda key: jax.random.split(key, (num_steps, 3)))(play_keys)  # [G, T, 3]
    keys = jnp.moveaxis(keys, 0, 1)  # [T, G, 3]
    return StepKeys(home=keys[:, :, 0], away=keys[:, :, 1], env=keys[:, :, 2])


class UnrollCarry(struct.PyTreeNode):
    """What the step scan carries: the games and both teams' memories."""

    state: State  # leading [G]
    home_carry: Carry
    away_carry: Carry


class StepView(struct.PyTreeNode):
    """One step of every game, from which ``record`` picks what to keep."""

    state: State  # leading [G]: what the players saw (before the step)
    home_obs: Observation  # leading [G, n]
    home_side: jax.Array  # i32[G]
    reset: jax.Array  # bool[G] an episode starts at this step
    actions: jax.Array  # f32[G, 2, n, 2] by side, as applied (clipped, NaN counts as 0)
    home_extras: Any  # the home actor's extras (None for a TeamPolicy)
    rewards: jax.Array  # f32[G, 2, n] by side
    done: jax.Array  # bool[G]
    info: StepInfo  # leading [G]


def home_sides(num_games: int, swap_sides: bool = True) -> np.ndarray:
    """i32[G]: side 0 for the first ceil(G / 2) games and side 1 for the rest (side 0 for all
    without ``swap_sides``). Training rollouts, evaluation matches and the server's games all
    split their sides this way."""
    sides = np.zeros(num_games, np.int32)
    if swap_sides:
        sides[(num_games + 1) // 2 :] = 1
    return sides


def home_sides_in_blocks(blocks: Sequence[int]) -> np.ndarray:
    """``home_sides`` within each block of games (each opponent of a mix sees both sides)."""
    return np.concatenate([home_sides(games) for games in blocks])


def pick_side(tree: Any, side: jax.Array) -> Any:
    """Leaves ``[G, 2, ...]`` -> ``[G, ...]``: entry ``side[g]`` of axis 1, by select."""

    def pick(leaf: jax.Array) -> jax.Array:
        chosen = side.reshape(side.shape + (1,) * (leaf.ndim - 2))
        return jnp.where(chosen == 0, leaf[:, 0], leaf[:, 1])

    return jax.tree.map(pick, tree)


def place_sides(home: jax.Array, away: jax.Array, side: jax.Array) -> jax.Array:
    """Per-team arrays ``[G, ...]`` -> ``[G, 2, ...]`` by side (home's at ``side[g]``)."""
    chosen = side.reshape(side.shape + (1,) * home.ndim)
    first = jnp.stack([home, away], axis=1)
    second = jnp.stack([away, home], axis=1)
    return jnp.where(chosen == 0, first, second)


def unroll(
    env: Soccer,
    params: EnvParams,
    home: Actor,
    away: Actor,
    states: State,
    home_side: jax.Array,
    step_keys: StepKeys,
    record: Callable[[StepView], Any],
    constrain_games: Callable[[Any], Any] = lambda tree: tree,
    noisy: bool = False,
) -> tuple[UnrollCarry, Any]:
    """Play the G games of ``states`` (leading [G]) for as many steps as ``step_keys`` has.

    ``params``: one game for all, or one per game (leading ``[G]`` on every leaf: drawn games,
    ``elevens.env.randomize``). ``record`` picks what each step keeps; the scan stacks it with
    a leading ``[T]``. ``constrain_games`` is applied to the carry after every step (training:
    games split over devices). ``noisy`` (static): the players see with
    ``params.observation_noise`` (``Soccer.observe_noisy``, keyed by a fold of each game's env
    key); False observes exactly, at no cost. Jit this (or call it inside a jit); the actors'
    policies are static. -> (final carry, stacked records).
    """
    n = env.players_per_team
    num_games = home_side.shape[0]
    start = constrain_games(
        UnrollCarry(
            state=states,
            home_carry=home.init_carry(num_games, n),
            away_carry=away.init_carry(num_games, n),
        )
    )
    step = functools.partial(
        _step, env, params, home, away, home_side, record, constrain_games, noisy
    )
    return jax.lax.scan(step, start, step_keys)


def _step(
    env: Soccer,
    params: EnvParams,
    home: Actor,
    away: Actor,
    home_side: jax.Array,
    record: Callable[[StepView], Any],
    constrain_games: Callable[[Any], Any],
    noisy: bool,
    carry: UnrollCarry,
    keys: StepKeys,
) -> tuple[UnrollCarry, Any]:
    """One step of every game: both teams act on the carried state, the env moves on."""
    n = env.players_per_team
    axis = game_axis(params)
    if noisy:
        sight_keys = jax.vmap(lambda key: jax.random.fold_in(key, 1))(keys.env)
        obs = jax.vmap(env.observe_noisy, in_axes=(0, axis, 0))(carry.state, params, sight_keys)
    else:
        obs = jax.vmap(env.observe, in_axes=(0, axis))(carry.state, params)  # leading [G, 2, n]
    home_obs = pick_side(obs, home_side)  # leading [G, n]
    away_obs = pick_side(obs, 1 - home_side)
    game_reset = carry.state.step == 0  # bool[G]
    player_reset = jnp.broadcast_to(game_reset[:, None], (home_side.shape[0], n))
    home_carry, home_actions, home_extras = home.act(
        carry.home_carry, home_obs, player_reset, keys.home
    )
    away_carry, away_actions, _ = away.act(carry.away_carry, away_obs, player_reset, keys.away)
    actions = place_sides(home_actions, away_actions, home_side).astype(jnp.float32)
    actions = env.applied(actions)  # each game's own ranges (the skill game's kind is 0..7)
    transition = jax.vmap(env.transition, in_axes=(0, 0, 0, axis))
    state, rewards, done, info = transition(keys.env, carry.state, actions, params)
    view = StepView(
        state=carry.state, home_obs=home_obs, home_side=home_side, reset=game_reset,
        actions=actions, home_extras=home_extras, rewards=rewards, done=done, info=info,
    )
    next_carry = UnrollCarry(state=state, home_carry=home_carry, away_carry=away_carry)
    return constrain_games(next_carry), record(view)
