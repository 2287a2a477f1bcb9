"""One iteration's experience: G games played at once for one whole episode of T steps.

Layout (Algorithm 4 lines 4-11). The games are played by ``elevens.play.unroll``, the same
compiled unroll as evaluation matches and recorded games: the learner is the home team, a
``NetworkActor`` that runs ONE batched forward pass over all its ``[G, n]`` players (thesis
5.2.9) and returns its Gaussian samples and log-probs. The learner plays side 0 in the first
ceil(G / 2) games and side 1 in the rest, so it learns both sides; the opponent plays the other
side.

The opponent's params are either one tree shared by every game (Polyak, self-play) or a tree with
a leading ``[G]`` axis, one snapshot per game (league: ``league_params(state, indices)``); the
opponent's forward pass is then vmapped over games. With ``opponent.mix`` the last games are
played by fixed teams, each on its own block of games (a ``BlockActor``).

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
from elevens.env.randomize import game_axis, game_slice
from elevens.env.soccer import Soccer
from elevens.env.state import GlobalState, Observation
from elevens.nets.policy import AttentionPolicy, PolicyCarry
from elevens.play import (
    Actor,
    BlockActor,
    NetworkActor,
    PolicyActor,
    StepKeys,
    StepView,
    TaughtActor,
    home_sides_in_blocks,
    pick_side,
    unroll,
)
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
    pre_tanh: jax.Array  # f32[U, T, A] the raw samples (``play.NetworkSample``): the Gaussian's
    #                      u, the actions tanh(u); the parametrised head's (kind, pointer, u)
    log_prob: jax.Array  # f32[U, T] log pi(action) under the rollout params (exact, from u)
    reward: jax.Array  # f32[U, T] goal reward plus the shaping in force this iteration
    done: jax.Array  # bool[U, T] True at the last step of an episode
    truncated: jax.Array  # bool[U, T] True where that end is the time limit (every end here)
    reset: jax.Array  # bool[U, T] True at the first step of an episode: the LSTM memory is zeroed
    initial_carry: PolicyCarry  # leaves f32[U, lstm_features]: the memory before step 0
    teacher_action: jax.Array | None = None  # f32[U, T, A] what the teacher (ppo.teacher) did
    #                                           on the same observation; None: no teacher


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
    possession_shaping: jax.Array  # f32[G] sum over steps of w_p * p (per player)
    possession: jax.Array  # f32[G] the learner's share of steps with the ball minus the opponent's
    # bool[U, T] where a routine, not the policy, played the learner's player (games played
    # outside the simulator, whose match routines take over); None: the policy played every step
    scripted: jax.Array | None = None


@dataclasses.dataclass(frozen=True)
class FixedOpponent:
    """A team that plays ``games`` games of every iteration and does not learn
    (``opponent.mix``): a handcrafted team or a frozen network behind ``TeamPolicy``."""

    policy: TeamPolicy
    params: Any
    """The policy's params (None for the handcrafted teams); constants of the compiled rollout."""
    games: int


class StepRecord(struct.PyTreeNode):
    """One step of every game, as the scan stacks it (leading [T, G, ...] after the scan);
    a run whose games another program plays records their steps in it too and packs them with
    ``collected``."""

    obs: Observation  # leading [G, n]
    global_state: GlobalState  # leading [G]
    pre_tanh: jax.Array  # f32[G, n, A]
    log_prob: jax.Array  # f32[G, n]
    reward: jax.Array  # f32[G, n]
    done: jax.Array  # bool[G]
    truncated: jax.Array  # bool[G]
    reset: jax.Array  # bool[G]
    goal_reward: jax.Array  # f32[G, n]
    ball_shaping: jax.Array  # f32[G, n]
    approach_shaping: jax.Array  # f32[G, n]
    possession_shaping: jax.Array  # f32[G, n]
    holder: jax.Array  # f32[G]
    scripted: jax.Array | None = None  # bool[G, n] a routine played (the server's); None: never
    teacher_action: jax.Array | None = None  # f32[G, n, A] the teacher's; None: no teacher


@dataclasses.dataclass(frozen=True)
class Teacher:
    """A fixed team that acts beside the learner on its observations, its actions recorded for
    the teacher loss (``ppo.teacher``): a handcrafted team or a frozen network behind
    ``TeamPolicy``."""

    policy: TeamPolicy
    params: Any
    """The policy's params (None for the handcrafted teams); constants of the compiled rollout."""


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
    noisy: bool = False,
    teacher: Teacher | None = None,
) -> Rollout:
    """Play ``num_games`` whole episodes of ``num_steps`` steps, learner against opponent.

    Args:
        env, policy: the game and the network both teams run (static).
        params: EnvParams, including the shaping weights in force (pytree leaves: changing them
            does not recompile); one game for all, or one per game (every leaf ``[G]``: drawn
            games, ``elevens.env.randomize``), which the fixed teams play on too.
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
        noisy: the players see with ``params.observation_noise`` (static; ``unroll``).
        teacher: a team acting as the learner's players on their observations in every game
            (``play.TaughtActor``), into ``Transition.teacher_action``; None: nothing is computed.

    Both teams sample their actions from their tanh Gaussians. Jit this (or call it inside a jit)
    with ``env``, ``policy``, ``num_games`` and ``opponent_per_game`` static.
    """
    n = env.players_per_team
    self_games = num_games - sum(opponent.games for opponent in fixed_opponents)
    blocks = (self_games, *(opponent.games for opponent in fixed_opponents))
    side = jnp.asarray(home_sides_in_blocks(blocks))
    reset_key, play_key = jax.random.split(key)
    axis = game_axis(params)
    states, _ = jax.vmap(env.reset, in_axes=(0, axis))(
        constrain_games(jax.random.split(reset_key, num_games)), params
    )
    if opponent_per_game:
        opponent_params = constrain_games(opponent_params)
    opponent: Actor = NetworkActor(policy, opponent_params, per_game=opponent_per_game)
    if fixed_opponents:
        starts = np.cumsum((0, *blocks))
        fixed = tuple(
            PolicyActor(
                team.policy, team.params,
                None if axis is None else game_slice(params, starts[b + 1], starts[b + 2]),
            )
            for b, team in enumerate(fixed_opponents)
        )
        opponent = BlockActor(actors=(opponent, *fixed), games=blocks)
    # All keys of the episode in one draw (each threefry call is a loop of its own on CPU):
    # per step the learner's, the opponent's, and one per game for the env's respawns.
    keys = jax.random.split(play_key, (num_steps, 2 + num_games))
    step_keys = StepKeys(home=keys[:, 0], away=keys[:, 1], env=keys[:, 2:])
    learner = NetworkActor(policy, learner_params)
    final, history = unroll(
        env, params, _taught(learner, teacher, params), opponent, states, side, step_keys,
        functools.partial(_learner_record, env, params), constrain_games, noisy,
    )
    score = final.state.score  # i32[G, 2] by side
    goals_for = jnp.where(side == 0, score[:, 0], score[:, 1])
    goals_against = jnp.where(side == 0, score[:, 1], score[:, 0])
    initial_carry = learner.init_carry(num_games, n)
    return collected(history, goals_for, goals_against, side, initial_carry, n)


def _taught(learner: NetworkActor, teacher: Teacher | None, params: EnvParams) -> Actor:
    """The learner, with ``teacher`` beside it in every game (on each game's field when the
    games are drawn); the learner alone without one."""
    if teacher is None:
        return learner
    game_params = None if game_axis(params) is None else params
    return TaughtActor(learner, PolicyActor(teacher.policy, teacher.params, game_params))


def _learner_record(env: Soccer, params: EnvParams, view: StepView) -> StepRecord:
    """What a training step keeps: the learner's side of everything."""
    side = view.home_side
    global_state = jax.vmap(env.global_state, in_axes=(0, game_axis(params)))(view.state, params)
    return StepRecord(
        obs=view.home_obs,
        global_state=pick_side(global_state, side),
        pre_tanh=view.home_extras.pre_tanh,
        log_prob=view.home_extras.log_prob,
        reward=pick_side(view.rewards, side),
        done=view.done,
        truncated=view.info.truncated,
        reset=view.reset,
        goal_reward=pick_side(view.info.goal_reward, side),
        ball_shaping=pick_side(view.info.ball_shaping, side),
        approach_shaping=pick_side(view.info.approach_shaping, side),
        possession_shaping=pick_side(view.info.possession_shaping, side),
        holder=pick_side(view.info.holder, side),
        teacher_action=view.home_extras.teacher_action,
    )


def collected(
    history: StepRecord, goals_for: jax.Array, goals_against: jax.Array, side: jax.Array,
    initial_carry: PolicyCarry, n: int,
) -> Rollout:
    """The [T, G, ...] step records as the learner's Rollout ([U, T] player sequences);
    ``goals_for``/``goals_against`` i32[G] are the learner's, ``initial_carry`` leading
    [G, n]."""
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
        teacher_action=None if history.teacher_action is None
        else per_player(history.teacher_action),
    )
    scripted = None if history.scripted is None else per_player(history.scripted)
    return Rollout(
        transitions=transitions,
        learner_side=side,
        goals_for=goals_for,
        goals_against=goals_against,
        game_global_state=game_state,
        goal_reward=jnp.sum(history.goal_reward[:, :, 0], axis=0),
        ball_shaping=jnp.sum(history.ball_shaping[:, :, 0], axis=0),
        approach_shaping=jnp.mean(jnp.sum(history.approach_shaping, axis=0), axis=-1),
        possession_shaping=jnp.sum(history.possession_shaping[:, :, 0], axis=0),
        possession=jnp.mean(history.holder, axis=0),
        scripted=scripted,
    )
