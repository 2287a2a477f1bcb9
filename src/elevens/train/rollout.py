"""One iteration's experience: G games played at once for one whole episode of T steps.

Layout (Algorithm 4 lines 4-11). ``lax.scan`` runs over the T steps; every step is batched over
the G games (vmapped env functions) and each team's policy runs as ONE batched forward pass over
all its ``[G, n]`` players (thesis 5.2.9). The learning team plays side 0 in the first ceil(G / 2)
games and side 1 in the rest, so it learns both sides; the opponent plays the other side. Sides
are picked with ``jnp.where`` (a select, not a gather), so one program serves both.

The scan body observes the state it carries and steps with ``env.transition`` (not ``env.step``):
XLA then materialises the state once instead of fusing the physics into every observation element
(PERFORMANCE_NOTES.md).

The opponent's params are either one tree shared by every game (Polyak, self-play) or a tree with
a leading ``[G]`` axis, one snapshot per game (league: ``league_params(state, indices)``); the
opponent's forward pass is then vmapped over games.

The output keeps the memory layout the update wants: ``[U, T, ...]`` with ``U = G * n`` player
sequences, games outermost (unit ``g * n + k`` is player ``k`` of game ``g``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer
from elevens.env.state import GlobalState, Observation, State
from elevens.nets.policy import AttentionPolicy, PolicyCarry
from elevens.teams.base import TeamPolicy

Params = Any


@struct.dataclass
class Transition:
    """The learning team's experience. U = G * n player sequences (game-major), T steps.

    Entry ``t`` holds what a player saw at step ``t``, what it did there and the reward that
    action earned (``rewards[t]`` is for the action at ``t``; ``done[t]`` is True at an episode's
    last step), the conventions of ``elevens.train.ppo``.
    """

    obs: Observation  # leading [U, T]: self_features f32[U, T, 15], entities f32[U, T, 2n, 11],
    #                   entity_mask bool[U, T, 2n]; the player's own team view
    global_state: GlobalState  # leading [U, T]: context f32[U, T, 5], players f32[U, T, 2n, 11];
    #                            the learning team's view, the same for the n players of a game
    #                            (the trainer reads Rollout.game_global_state, once per game; in
    #                            its compiled iteration XLA drops this unused copy)
    pre_tanh: jax.Array  # f32[U, T, 2] the Gaussian samples u; the actions are tanh(u)
    log_prob: jax.Array  # f32[U, T] log pi(tanh(u)) under the rollout params (exact, from u)
    reward: jax.Array  # f32[U, T] goal reward plus the shaping in force this iteration
    done: jax.Array  # bool[U, T] True at the last step of an episode
    truncated: jax.Array  # bool[U, T] True where that end is the time limit (every end here)
    reset: jax.Array  # bool[U, T] True at the first step of an episode: the LSTM memory is zeroed
    initial_carry: PolicyCarry  # leaves f32[U, lstm_features]: the memory before step 0


@struct.dataclass
class Rollout:
    """``Transition`` plus per-game facts, from the learning team's view. G games."""

    transitions: Transition
    learner_side: jax.Array  # i32[G] the side (0 or 1) the learner played
    goals_for: jax.Array  # i32[G] the learner's goals
    goals_against: jax.Array  # i32[G] the opponent's goals
    game_global_state: GlobalState  # leading [G, T]: the learner's critic input, once per game
    goal_reward: jax.Array  # f32[G] sum over steps of the learner's goal term g (per player)
    ball_shaping: jax.Array  # f32[G] sum over steps of w_b * b (per player)
    approach_shaping: jax.Array  # f32[G] sum over steps of w_a * a, mean over the n players


@dataclasses.dataclass(frozen=True)
class FixedOpponent:
    """A team that plays ``games`` games of every iteration and does not learn
    (``opponent.mix``): a handcrafted team or a frozen network behind ``TeamPolicy``."""

    policy: TeamPolicy
    params: Any
    """The policy's params (None for the handcrafted teams); constants of the compiled rollout."""
    games: int


class RolloutCarry(struct.PyTreeNode):
    """What the step scan carries: the games and both teams' memories."""

    state: State  # leading [G]
    learner_carry: PolicyCarry  # leaves f32[G, n, lstm_features]
    opponent_carry: PolicyCarry  # leaves f32[G_self, n, lstm_features]: the self-play games
    fixed_carries: tuple[Any, ...] = ()  # each fixed opponent's memory, leading [its games]


class _StepRecord(struct.PyTreeNode):
    """One step of every game, as the scan stacks it (leading [T, G, ...] after the scan)."""

    obs: Observation  # leading [G, n]
    global_state: GlobalState  # leading [G]
    pre_tanh: jax.Array  # f32[G, n, 2]
    log_prob: jax.Array  # f32[G, n]
    reward: jax.Array  # f32[G, n]
    done: jax.Array  # bool[G]
    truncated: jax.Array  # bool[G]
    reset: jax.Array  # bool[G]
    goal_reward: jax.Array  # f32[G, n]
    ball_shaping: jax.Array  # f32[G, n]
    approach_shaping: jax.Array  # f32[G, n]


def learner_sides(num_games: int, swap_sides: bool = True) -> np.ndarray:
    """i32[G]: side 0 for the first ceil(G / 2) games and side 1 for the rest (side 0 for all
    without ``swap_sides``). Training rollouts, evaluation matches and the server's games all
    split their sides this way."""
    sides = np.zeros(num_games, np.int32)
    if swap_sides:
        sides[(num_games + 1) // 2 :] = 1
    return sides


def _pick_side(tree: Any, side: jax.Array) -> Any:
    """Leaves ``[G, 2, ...]`` -> ``[G, ...]``: entry ``side[g]`` of axis 1, by select."""

    def pick(leaf: jax.Array) -> jax.Array:
        chosen = side.reshape(side.shape + (1,) * (leaf.ndim - 2))
        return jnp.where(chosen == 0, leaf[:, 0], leaf[:, 1])

    return jax.tree.map(pick, tree)


def _place_sides(learner: jax.Array, opponent: jax.Array, side: jax.Array) -> jax.Array:
    """Per-team arrays ``[G, ...]`` -> ``[G, 2, ...]`` by side (the learner's at ``side[g]``)."""
    chosen = side.reshape(side.shape + (1,) * learner.ndim)
    first = jnp.stack([learner, opponent], axis=1)
    second = jnp.stack([opponent, learner], axis=1)
    return jnp.where(chosen == 0, first, second)


def _to_units(leaf: jax.Array, n: int) -> jax.Array:
    """A scan output ``[T, G, n, ...]`` -> ``[G * n, T, ...]`` (games outermost)."""
    moved = jnp.moveaxis(leaf, 0, 2)  # [G, n, T, ...]
    return moved.reshape(moved.shape[0] * n, *moved.shape[2:])


def _games_to_units(leaf: jax.Array, n: int) -> jax.Array:
    """A per-game array ``[G, T, ...]`` -> ``[G * n, T, ...]``, repeated for each player."""
    return jnp.repeat(leaf, n, axis=0)


def rollout(
    env: Soccer,
    policy: AttentionPolicy,
    params: EnvParams,
    learner_params: Params,
    opponent_params: Params,
    key: jax.Array,
    *,
    num_games: int,
    num_steps: int,
    opponent_per_game: bool = False,
    constrain_games: Callable[[Any], Any] = lambda tree: tree,
    fixed_opponents: tuple[FixedOpponent, ...] = (),
) -> Rollout:
    """Play ``num_games`` whole episodes of ``num_steps`` steps, learner against opponent.

    Args:
        env, policy: the game and the network both teams run (static).
        params: EnvParams, including the shaping weights in force (pytree leaves: changing them
            does not recompile).
        learner_params: the learner's policy variables ``{"params": ...}``.
        opponent_params: the opponent's policy variables, shared by all games, or with a leading
            ``[G]`` axis on every leaf when ``opponent_per_game`` (one league snapshot per game).
        key: a ``jax.random.key``.
        num_games: G (static).
        num_steps: T (static), the episode length: ``params.episode_length`` is a pytree leaf,
            so it cannot size the scan; pass the same number.
        opponent_per_game: whether ``opponent_params`` has the per-game axis (static).
        constrain_games: applied to every array with a leading game axis that the step scan
            carries (``elevens.train.parallel.game_constraint``: games split over devices).
        fixed_opponents: teams that play the last games instead of the opponent of
            ``opponent_params``, in blocks of their ``games`` in this order; the first G_self =
            G - (their games) games are self-play, and ``opponent_params`` (per game: leading
            [G_self]) play those. The learner plays both sides in every block.

    Both teams sample their actions from their tanh Gaussians. Jit this (or call it inside a jit)
    with ``env``, ``policy``, ``num_games`` and ``opponent_per_game`` static.
    """
    n = env.players_per_team
    self_games = num_games - sum(opponent.games for opponent in fixed_opponents)
    blocks = (self_games, *(opponent.games for opponent in fixed_opponents))
    side = jnp.asarray(np.concatenate([learner_sides(games) for games in blocks]))
    reset_key, play_key = jax.random.split(key)
    states, _ = jax.vmap(env.reset, in_axes=(0, None))(
        constrain_games(jax.random.split(reset_key, num_games)), params
    )
    if opponent_per_game:
        opponent_params = constrain_games(opponent_params)
    game = _Game(
        env=env, policy=policy, params=params, learner_params=learner_params,
        opponent_params=opponent_params, opponent_per_game=opponent_per_game, side=side,
        self_games=self_games, fixed_opponents=fixed_opponents, constrain_games=constrain_games,
    )
    initial_carry = policy.initial_carry((num_games, n))
    fixed_carries = tuple(
        jax.tree.map(
            lambda leaf, games=opponent.games: jnp.broadcast_to(leaf, (games, *leaf.shape)),
            opponent.policy.init_carry(n),
        )
        for opponent in fixed_opponents
    )
    start = constrain_games(
        RolloutCarry(
            state=states,
            learner_carry=initial_carry,
            opponent_carry=policy.initial_carry((self_games, n)),
            fixed_carries=fixed_carries,
        )
    )
    # All keys of the episode in one draw (each threefry call is a loop of its own on CPU):
    # per step the learner's, the opponent's, and one per game for the env's respawns.
    step_keys = jax.random.split(play_key, (num_steps, 2 + num_games))
    final, history = jax.lax.scan(functools.partial(_step, game), start, step_keys)
    return _collected(history, final.state, side, initial_carry, n)


@dataclasses.dataclass
class _Game:
    """What every step of a rollout reads (traced arrays and static settings)."""

    env: Soccer
    policy: AttentionPolicy
    params: EnvParams
    learner_params: Params
    opponent_params: Params
    opponent_per_game: bool
    side: jax.Array  # i32[G] the learner's side in each game
    self_games: int
    fixed_opponents: tuple[FixedOpponent, ...]
    constrain_games: Callable[[Any], Any]

    @property
    def num_games(self) -> int:
        return int(self.side.shape[0])


def _step(
    game: _Game, carry: RolloutCarry, step_keys: jax.Array
) -> tuple[RolloutCarry, _StepRecord]:
    """One step of every game: both teams act on the carried state, the env moves on."""
    env, params, side, n = game.env, game.params, game.side, game.env.players_per_team
    learner_key, opponent_key, env_keys = step_keys[0], step_keys[1], step_keys[2:]
    # Observe the carried state (materialised), see the module docstring.
    obs = jax.vmap(env.observe, in_axes=(0, None))(carry.state, params)  # leading [G, 2, n]
    learner_obs = _pick_side(obs, side)  # leading [G, n]
    opponent_obs = _pick_side(obs, 1 - side)
    game_reset = carry.state.step == 0  # bool[G]: an episode starts here
    player_reset = jnp.broadcast_to(game_reset[:, None], (game.num_games, n))

    learner_step: Any = game.policy.apply(
        game.learner_params, carry.learner_carry, learner_obs, player_reset
    )
    learner_carry, learner_out = learner_step
    learner_sample = learner_out.distribution().sample(learner_key)
    log_prob = learner_out.distribution().log_prob(learner_sample.pre_tanh)
    opponent_carry, fixed_carries, opponent_action = _opponent_actions(
        game, carry, opponent_obs, player_reset, opponent_key
    )

    actions = _place_sides(learner_sample.action, opponent_action, side)  # [G, 2, n, 2]
    transition = jax.vmap(env.transition, in_axes=(0, 0, 0, None))
    state, rewards, done, info = transition(env_keys, carry.state, actions, params)
    global_state = jax.vmap(env.global_state, in_axes=(0, None))(carry.state, params)
    record = _StepRecord(
        obs=learner_obs,
        global_state=_pick_side(global_state, side),
        pre_tanh=learner_sample.pre_tanh,
        log_prob=log_prob,
        reward=_pick_side(rewards, side),
        done=done,
        truncated=info.truncated,
        reset=game_reset,
        goal_reward=_pick_side(info.goal_reward, side),
        ball_shaping=_pick_side(info.ball_shaping, side),
        approach_shaping=_pick_side(info.approach_shaping, side),
    )
    next_carry = RolloutCarry(
        state=state,
        learner_carry=learner_carry,
        opponent_carry=opponent_carry,
        fixed_carries=fixed_carries,
    )
    return game.constrain_games(next_carry), record


def _opponent_forward(game: _Game, carry: PolicyCarry, obs: Observation, reset: jax.Array) -> Any:
    if game.opponent_per_game:
        return jax.vmap(game.policy.apply)(game.opponent_params, carry, obs, reset)
    return game.policy.apply(game.opponent_params, carry, obs, reset)


def _opponent_actions(
    game: _Game, carry: RolloutCarry, obs: Observation, reset: jax.Array, key: jax.Array
) -> tuple[PolicyCarry, tuple[Any, ...], jax.Array]:
    """Every game's opponent: self-play in the first G_self games, then each fixed team on its
    block. -> (self-play memory, fixed memories, actions f32[G, n, 2])."""
    if not game.fixed_opponents:
        opponent_carry, out = _opponent_forward(game, carry.opponent_carry, obs, reset)
        return opponent_carry, (), out.distribution().sample(key).action
    actions = []
    opponent_carry = carry.opponent_carry
    self_games = game.self_games
    if self_games:
        opponent_carry, out = _opponent_forward(
            game,
            carry.opponent_carry,
            jax.tree.map(lambda x: x[:self_games], obs),
            reset[:self_games],
        )
        actions.append(out.distribution().sample(key).action)
    fixed = []
    begin = self_games
    for index, opponent in enumerate(game.fixed_opponents):
        end = begin + opponent.games
        keys = jax.random.split(jax.random.fold_in(key, index + 1), opponent.games)
        memory, action = jax.vmap(opponent.policy.act, in_axes=(None, 0, 0, 0))(
            opponent.params, carry.fixed_carries[index],
            jax.tree.map(lambda x, b=begin, e=end: x[b:e], obs), keys,
        )
        fixed.append(memory)
        actions.append(action)
        begin = end
    return opponent_carry, tuple(fixed), jnp.concatenate(actions, axis=0)


def _collected(
    history: _StepRecord, final: State, side: jax.Array, initial_carry: PolicyCarry, n: int
) -> Rollout:
    """The scan's [T, G, ...] records as the learner's Rollout ([U, T] player sequences)."""
    num_games = side.shape[0]
    per_player = lambda leaf: _to_units(leaf, n)  # noqa: E731
    per_game = lambda leaf: jnp.moveaxis(leaf, 0, 1)  # [T, G, ...] -> [G, T, ...]  # noqa: E731
    game_state = jax.tree.map(per_game, history.global_state)
    game_flags = lambda leaf: _games_to_units(per_game(leaf), n)  # noqa: E731
    transitions = Transition(
        obs=jax.tree.map(per_player, history.obs),
        global_state=jax.tree.map(lambda leaf: _games_to_units(leaf, n), game_state),
        pre_tanh=per_player(history.pre_tanh),
        log_prob=per_player(history.log_prob),
        reward=per_player(history.reward),
        done=game_flags(history.done),
        truncated=game_flags(history.truncated),
        reset=game_flags(history.reset),
        initial_carry=jax.tree.map(
            lambda leaf: leaf.reshape(num_games * n, *leaf.shape[2:]), initial_carry
        ),
    )
    score = final.score  # i32[G, 2] by side
    goals_for = jnp.where(side == 0, score[:, 0], score[:, 1])
    goals_against = jnp.where(side == 0, score[:, 1], score[:, 0])
    return Rollout(
        transitions=transitions,
        learner_side=side,
        goals_for=goals_for,
        goals_against=goals_against,
        game_global_state=game_state,
        goal_reward=jnp.sum(history.goal_reward[:, :, 0], axis=0),
        ball_shaping=jnp.sum(history.ball_shaping[:, :, 0], axis=0),
        approach_shaping=jnp.mean(jnp.sum(history.approach_shaping, axis=0), axis=-1),
    )
