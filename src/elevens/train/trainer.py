"""The learner: ``make_trainer(config)`` gives pure ``init`` and ``update_chunk``; ``train`` drives
them from Python.

One iteration (thesis Algorithm 4), all inside one compiled function:

1. **Rollout** (``elevens.train.rollout``): G games, one whole episode each, the learner against
   the opponent, with the shaping weights in force put into ``EnvParams`` (leaves: no recompile).
2. **Advantages**: Monte Carlo returns G_t (the thesis' choice; A = G - V is recomputed with the
   current critic inside every minibatch, Algorithm 4 lines 15-17), or GAE on the rollout-time
   values (``ppo.advantage_estimator``). The whistle ends the episode for the critic, which sees
   the time left in its global state, so the last step is a terminal for both estimators.
3. **PPO epochs** (``ppo.update_epochs``): shuffled minibatches of whole games, i.e. of whole
   player sequences with all n players of a game together (games outermost), so that the
   critic, whose input is the same for a game's players, runs once per game and step instead of
   n times (1.9x faster in 11 v 11). The policy is unrolled over each sequence from its recorded
   initial LSTM memory, which is reset wherever the sequence's reset flag says an episode starts.
   Entropy is the pre-tanh Gaussian's closed form (eq. 3.75), as in the thesis; one Adam steps
   both networks on the one objective (Algorithm 4 lines 21-23).
4. **Opponent**: a Polyak step with the freeze rule on the learner's mean outcome of this
   iteration's games (Algorithm 4 lines 25-27), a plain copy (self-play), or the league: record
   the outcomes, maybe add a snapshot (every ``league_every`` iterations), sample the next
   iteration's opponents.
5. **Shaping schedule** (``elevens.train.shaping``): off for good once the learner scores in more
   than 75% of its recent games.

``update_chunk`` runs K iterations as a ``lax.scan``. ``train`` (the host loop) logs each
iteration's metrics, evaluates against the handcrafted teams, checkpoints atomically, stops
cleanly on Ctrl-C with a checkpoint written, and finally draws the learning curve and a GIF.

Evaluation plays the learner as a ``NetworkTeam`` that SAMPLES its actions by default
(``run.eval_deterministic``): that is the policy PPO trained and the one the opponents meet, and
the thesis' executors sampled too; the mean action tanh(mean) is another, untrained, policy.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import signal
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct
from jax.sharding import Mesh

from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer
from elevens.env.state import GlobalState, Observation
from elevens.nets.attention import Capacity
from elevens.nets.critic import AttentionCritic
from elevens.nets.policy import AttentionPolicy, PolicyCarry, visible_capacity_index
from elevens.teams.registry import resolve_team
from elevens.train import opponents as opp
from elevens.train import parallel, ppo
from elevens.train.config import (
    RESUMABLE_FIELDS,
    RunConfig,
    TrainConfig,
    config_differences,
    mix_schedule,
    opponent_mix,
    scenario_config,
    self_play_games,
    validate,
)
from elevens.train.rollout import FixedOpponent, Rollout, rollout
from elevens.train.shaping import (
    ShapingState,
    shaping_init,
    shaping_scoring_rate,
    shaping_update,
    shaping_weights,
)

Params = Any
Metrics = dict[str, jax.Array]

# --------------------------------------------------------------------------------------------
# State
# --------------------------------------------------------------------------------------------


class LearnerParams(struct.PyTreeNode):
    """The learning team's networks: one policy and one critic shared by all its players."""

    policy: Params  # {"params": ...} of AttentionPolicy
    critic: Params  # {"params": ...} of AttentionCritic


class OpponentState(struct.PyTreeNode):
    """The training opponent. Exactly one of ``polyak`` / ``league`` is set, by config kind."""

    polyak: opp.PolyakState | None
    """'polyak' and 'self': the opponent's policy params (for 'self', the latest learner's)."""
    league: opp.LeagueState | None
    """'league': past snapshots of the learner's policy and their results."""
    indices: jax.Array
    """i32[G]: the league snapshot each game of the next iteration is played against (0s
    otherwise)."""


class TrainState(struct.PyTreeNode):
    """Everything a run carries from one iteration to the next (and what a checkpoint holds)."""

    params: LearnerParams
    opt_state: optax.OptState  # Adam's state for params
    opponent: OpponentState
    shaping: ShapingState
    key: jax.Array  # key[] the run's random stream
    iteration: jax.Array  # i32[] completed iterations
    env_steps: jax.Array  # u32[] game steps played (G * T per iteration; wraps after 4.29e9,
    #                       the host loop keeps the exact count as iteration * G * T)


class UpdateBatch(struct.PyTreeNode):
    """What the PPO minibatch steps need, grouped by game: leading [G, n, T] per player sequence
    (G games of n learner players), [G, T] per game. A minibatch is a set of whole games, so the
    critic, whose input is the same for the n players of a game, runs once per game."""

    obs: Observation  # leading [G, n, T]
    global_state: GlobalState  # leading [G, T] the learner's critic input
    pre_tanh: jax.Array  # f32[G, n, T, 2]
    log_prob: jax.Array  # f32[G, n, T] rollout-time log-probabilities
    reset: jax.Array  # bool[G, n, T]
    initial_carry: PolicyCarry  # leaves f32[G, n, lstm_features]
    returns: jax.Array  # f32[G, n, T] critic targets (Monte Carlo returns or GAE lambda-returns)
    advantages: jax.Array | None  # f32[G, n, T] GAE advantages; None: A = G - V in the loss
    old_values: jax.Array | None  # f32[G, n, T] rollout-time values, only for value clipping
    entropy_noise: jax.Array | None = None  # f32[G, n, T, 2] only for the squashed entropy


class Learned(NamedTuple):
    """What ``Trainer.learn`` returns."""

    update: ppo.UpdateResult  # new params, opt state, mean loss terms
    values: jax.Array  # f32[U, T] the critic's values at rollout time (before the update)
    returns: jax.Array  # f32[U, T] the critic's targets


# --------------------------------------------------------------------------------------------
# The trainer
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Trainer:
    """Pure functions of one config. ``init(key) -> TrainState``;
    ``update_chunk(state) -> (state, metrics)`` runs K = ``config.run.iterations_per_chunk``
    iterations (jitted; metrics are ``{name: f32[K]}``). ``update(state, num_iterations)`` runs
    another number of iterations (compiled once per number)."""

    config: TrainConfig
    env: Soccer
    env_params: EnvParams
    policy: AttentionPolicy
    critic: AttentionCritic
    optimizer: optax.GradientTransformation
    init: Callable[..., TrainState]
    """``init(key, start=None)``: a fresh TrainState; ``start`` (LearnerParams of the same
    networks) replaces the random networks, and the opponent starts as its policy."""
    update_chunk: Callable[[TrainState], tuple[TrainState, Metrics]]
    iteration: Callable[[TrainState], tuple[TrainState, Metrics]]
    """One iteration, not jitted (the body of the chunk scan)."""
    collect: Callable[[TrainState, jax.Array], Rollout]
    """``collect(state, rollout_key)``: the iteration's rollout alone, not jitted."""
    learn: Callable[[LearnerParams, optax.OptState, Rollout, jax.Array], Learned]
    """``learn(params, opt_state, rollout, shuffle_key)``: advantages and PPO epochs alone, not
    jitted (the bench times the parts of an iteration with these)."""
    metrics: Callable[[Rollout, Learned, OpponentState, ShapingState, ShapingState], Metrics]
    """``metrics(rollout, learned, opponent, shaping_before, shaping_after)``: an iteration's
    ``train/``, ``env/`` and ``opponent/`` metrics (loops that play elsewhere log the same)."""
    mesh: Mesh
    """The devices the games are split over (``run.devices``); the state is replicated on it."""

    def update(self, state: TrainState, num_iterations: int) -> tuple[TrainState, Metrics]:
        if num_iterations == self.config.run.iterations_per_chunk:
            return self.update_chunk(state)
        return _scan_iterations(self.iteration, num_iterations, self.mesh)(state)


@functools.lru_cache(maxsize=16)
def _scan_iterations(
    iteration: Callable[[TrainState], tuple[TrainState, Metrics]], num_iterations: int,
    mesh: Mesh,
) -> Callable[[TrainState], tuple[TrainState, Metrics]]:
    def run(state: TrainState) -> tuple[TrainState, Metrics]:
        return jax.lax.scan(lambda s, _: iteration(s), state, None, length=num_iterations)

    return parallel.jit_replicated(run, mesh)


def make_optimizer(config: TrainConfig) -> optax.GradientTransformation:
    """Adam with the config's learning rate (table 6.1: 1e-4), one optimiser for both networks
    (Algorithm 4 lines 22-23 step policy and critic on the same objective J)."""
    return optax.adam(config.ppo.learning_rate)


def make_trainer(config: TrainConfig) -> Trainer:
    """Build the pure functions of ``config`` (validated first: nothing compiles on a bad one).

    The functions depend only on what is computed, not on the host loop's fields
    (``RESUMABLE_FIELDS`` but K), so they are cached on the rest: building the same run again in
    one process (a resume, a longer run, another run_dir) reuses the compiled chunk.
    """
    validate(config)
    core = _build_trainer(_computation_config(config))
    return dataclasses.replace(core, config=config)


def _computation_config(config: TrainConfig) -> TrainConfig:
    """``config`` with the host-loop fields set to their defaults (K is kept: it is compiled in)."""
    chunk = config.run.iterations_per_chunk
    defaults = dataclasses.replace(RunConfig(), iterations_per_chunk=chunk)
    overrides = {
        path.split(".", 1)[1]: getattr(defaults, path.split(".", 1)[1])
        for path in RESUMABLE_FIELDS
        if path.startswith("run.")
    }
    return dataclasses.replace(
        config, preset="", run=dataclasses.replace(config.run, **overrides)
    )


VISIBLE_FRACTIONS: tuple[Capacity, ...] = ((0.54, 0.69), (0.6, 0.7), (0.6, 0.75), (0.7, 0.8))
"""Capacities (shares of the teammate slots and of the opponent slots) tried in turn for the
policy's per-entity layers in the update. A minibatch that fits none of them takes the dense
pass, with the same result. In 11 v 11 with the 180 degree view about 50% of the teammates and
66% of the opponents are in view; over a random policy's minibatches the 90% quantiles are 54%
and 69%, and the largest shares about 58% and 73%. The first level holds most of those
minibatches (about 88%) with 4.7% fewer compact rows than the second (docs/results/
throughput.md: `learn` 1.015x to 1.14x); the others keep trained policies, which look at more
players, off the dense pass, with no minibatch getting a larger capacity than before."""

MIN_PLAYERS_TO_COMPACT = 4
"""Below this many players a side the per-entity layers are too small a share of the update
for compaction to pay for its gathers and its extra compiled branches."""


def _compacts(config: TrainConfig) -> bool:
    return config.network.use_attention and config.env.players_per_team >= MIN_PLAYERS_TO_COMPACT


@functools.lru_cache(maxsize=8)
def _network_initializer(
    policy: AttentionPolicy, critic: AttentionCritic, players_per_team: int
) -> Callable[[jax.Array, jax.Array], tuple[Params, Params]]:
    """Jitted ``(policy_key, critic_key) -> (policy params, critic params)``, one per networks
    and team size. Its compile is most of ``init``'s (5 to 6 s on the 2-core CPU), and a sweep
    or a test suite builds many configs that differ only in PPO, opponent or run settings.
    Parameters depend on the input shapes only, so zeros stand in for the observation and the
    global state (the same bits as initialising on a reset game)."""
    n = players_per_team
    env = Soccer(n)
    env_params = EnvParams(players_per_team=n)

    def inputs(key: jax.Array) -> tuple[Observation, GlobalState]:
        state, obs = env.reset(key, env_params)
        return obs.team(0), env.global_state(state, env_params)

    shapes = jax.eval_shape(inputs, jax.random.key(0))

    @jax.jit
    def initialize(policy_key: jax.Array, critic_key: jax.Array) -> tuple[Params, Params]:
        team_obs, global_state = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
        policy_params = policy.init(
            policy_key, policy.initial_carry((n,)), team_obs, jnp.zeros((n,), bool)
        )
        return policy_params, critic.init(critic_key, global_state)

    return initialize


@functools.lru_cache(maxsize=8)
def _build_trainer(config: TrainConfig) -> Trainer:
    env_config, run, hp = config.env, config.run, config.ppo
    n = env_config.players_per_team
    env = Soccer(n)
    env_params = env_config.env_params()
    policy = config.network.policy()
    critic = config.network.critic()
    optimizer = make_optimizer(config)
    num_games = run.games_per_iteration
    kind = config.opponent.kind
    opponent_config = config.opponent
    fixed_opponents = _fixed_opponents(config, env_params)
    self_games = self_play_games(config)  # the games against `kind`; the rest are fixed teams

    initialize_networks = _network_initializer(policy, critic, n)
    # Data parallel (elevens.train.parallel): games split over the mesh, the rest replicated.
    mesh = parallel.data_mesh(run.devices)
    _check_device_split(config, mesh)
    shard_games = parallel.game_constraint(mesh)
    shard_minibatch_games = parallel.game_constraint(mesh, game_axis=1)

    def init(key: jax.Array, start: LearnerParams | None = None) -> TrainState:
        policy_key, critic_key, run_key = jax.random.split(key, 3)
        if start is None:
            policy_params, critic_params = initialize_networks(policy_key, critic_key)
            params = LearnerParams(policy=policy_params, critic=critic_params)
        else:
            # Another run's networks (--run.init-from); the opponent starts as their policy.
            params = start
            policy_params = start.policy
        if kind == "league":
            opponent = OpponentState(
                polyak=None,
                league=opp.league_init(
                    policy_params, opponent_config.league_capacity, opponent_config.league_window
                ),
                indices=jnp.zeros((_index_count(config),), jnp.int32),
            )
        else:
            opponent = OpponentState(
                polyak=opp.polyak_init(policy_params),
                league=None,
                indices=jnp.zeros((_index_count(config),), jnp.int32),
            )
        return TrainState(
            params=params,
            opt_state=optimizer.init(params),
            opponent=opponent,
            shaping=shaping_init(env_config.shaping_window),
            key=run_key,
            iteration=jnp.asarray(0, jnp.int32),
            env_steps=jnp.asarray(0, jnp.uint32),
        )

    def opponent_policy_params(opponent: OpponentState) -> Params:
        if kind == "league":
            assert opponent.league is not None
            return opp.league_params(opponent.league, opponent.indices)
        assert opponent.polyak is not None
        return opponent.polyak.params

    def loss_fn(
        params: LearnerParams, batch: UpdateBatch, visible_fraction: Capacity | None = None
    ) -> tuple[jax.Array, ppo.PPOLoss]:
        """A minibatch of g whole games: leading [g, n, T] (see UpdateBatch).
        ``visible_fraction``: the policy's per-entity layers on the visible slots only
        (``AttentionPolicy.embed``); the caller checks that they fit."""

        def sequences(tree: Any) -> Any:  # [g, n, ...] -> [g * n, ...], games outermost
            return jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), tree)

        # The minibatch's g * n sequences unroll together, batch-major: the encoders run as one
        # [g * n * T] batch of rows (2-D matmuls, see nets.attention.flat_rows), and only the
        # LSTM is scanned over time. (A vmap over sequences would hand XLA 3-D weight gradients.)
        _, output = policy.apply(
            params.policy,
            sequences(batch.initial_carry),
            sequences(batch.obs),
            sequences(batch.reset),
            1,
            visible_fraction,
            method=AttentionPolicy.unroll,
        )
        distribution = output.distribution()
        # The critic once per game and step, shared by the game's n players.
        values = jnp.repeat(critic.apply(params.critic, batch.global_state), n, axis=0)
        loss = ppo.ppo_loss(
            distribution.log_prob(sequences(batch.pre_tanh)),
            sequences(batch.log_prob),
            values,
            sequences(batch.returns),
            # The thesis' entropy term, the closed-form entropy of the pre-tanh Gaussian
            # (eq. 3.75), or an estimate of the action's own (ppo.entropy_estimator).
            distribution.gaussian_entropy()
            if batch.entropy_noise is None
            else distribution.entropy_at(sequences(batch.entropy_noise)),
            advantages=None if batch.advantages is None else sequences(batch.advantages),
            old_values=None if batch.old_values is None else sequences(batch.old_values),
            hyperparams=hp,
        )
        return loss.total, loss

    compaction_fractions = VISIBLE_FRACTIONS if _compacts(config) else ()
    # One whole forward and backward pass per capacity, then the dense one.
    value_and_grad_branches = [
        jax.value_and_grad(functools.partial(loss_fn, visible_fraction=fraction), has_aux=True)
        for fraction in (*compaction_fractions, None)
    ]

    def value_and_grad(params: LearnerParams, batch: UpdateBatch) -> Any:
        """The loss and its gradient; the policy pass uses the smallest compaction of the visible
        entities that holds this minibatch's, or the dense pass where none does. Only the branch
        taken is computed."""
        if not compaction_fractions:
            return value_and_grad_branches[0](params, batch)
        index = visible_capacity_index(batch.obs, compaction_fractions)
        return jax.lax.switch(index, value_and_grad_branches, params, batch)

    def advantages(data: Rollout, values: jax.Array) -> tuple[jax.Array, jax.Array | None]:
        """(returns, advantages or None), each f32[U, T]. values f32[U, T] at rollout time."""
        t = data.transitions
        # The estimators scan over a leading time axis: [U, T] -> [T, U] and back.
        if hp.advantage_estimator == "gae":
            result = ppo.gae(
                t.reward.T, values.T, t.done.T, jnp.zeros_like(t.truncated.T), 0.0,
                hp.gamma, hp.gae_lambda,
            )
            return result.returns.T, result.advantages.T
        returns = ppo.monte_carlo_returns(t.reward.T, t.done.T, hp.gamma)
        return returns.T, None

    def update_opponent(
        state: TrainState, policy_params: Params, outcomes: jax.Array, key: jax.Array
    ) -> OpponentState:
        opponent = state.opponent
        outcomes = outcomes[:self_games]  # the fixed teams' games tell nothing about it
        if kind in ("polyak", "self"):
            assert opponent.polyak is not None
            if self_games == 0:
                return opponent
            polyak = opp.single_opponent_step(
                opponent.polyak,
                kind,
                policy_params,
                jnp.mean(outcomes),
                opponent_config.polyak_tau,
                opponent_config.freeze_threshold,
            )
            return opponent.replace(polyak=polyak)
        assert opponent.league is not None
        league = opp.league_record(opponent.league, opponent.indices, 1.0 - outcomes)
        league = opp.league_maybe_add(
            league,
            policy_params,
            state.iteration + 1,
            opponent_config.league_every,
            opponent_config.league_min_games,
        )
        indices = opp.league_sample(
            league, key, self_games, opponent_config.league_psi, opponent_config.league_min_games
        )
        return opponent.replace(league=league, indices=indices)

    def opponent_metrics(opponent: OpponentState) -> Metrics:
        if opponent.polyak is not None:
            return {
                "opponent/frozen": opponent.polyak.frozen.astype(jnp.float32),
                "opponent/updates": opponent.polyak.num_updates.astype(jnp.float32),
            }
        assert opponent.league is not None
        league = opponent.league
        live = opp.league_live(league)
        rates = opp.league_win_rates(league, opponent_config.league_min_games)
        return {
            "opponent/league_size": league.size.astype(jnp.float32),
            "opponent/league_mean_win_rate": jnp.sum(jnp.where(live, rates, 0.0))
            / jnp.maximum(league.size, 1).astype(jnp.float32),
            "opponent/league_max_win_rate": jnp.max(jnp.where(live, rates, 0.0)),
        }

    mix = opponent_mix(config)

    def mix_metrics(outcomes: jax.Array) -> Metrics:
        """With ``opponent.mix``: the learner's mean outcome against each opponent."""
        if not fixed_opponents:
            return {}
        metrics, begin = {}, 0
        for spec, games in mix:
            if games:
                label = _metric_label(spec)
                metrics[f"opponent/{label}/outcome"] = jnp.mean(outcomes[begin : begin + games])
            begin += games
        return metrics

    def collect(state: TrainState, rollout_key: jax.Array) -> Rollout:
        """Algorithm 4 lines 4-11: one episode of every game, shaping as currently in force."""
        weights = shaping_weights(
            state.shaping, env_config.ball_shaping_weight, env_config.approach_shaping_weight
        )
        # The weights are pytree leaves of EnvParams: a new value is not a recompile.
        shaping: dict[str, Any] = {
            "ball_shaping_weight": weights.ball,
            "approach_shaping_weight": weights.approach,
        }
        params_now = dataclasses.replace(env_params, **shaping)
        return rollout(
            env,
            policy,
            params_now,
            state.params.policy,
            opponent_policy_params(state.opponent),
            rollout_key,
            num_games=num_games,
            num_steps=env_config.episode_length,
            opponent_per_game=kind == "league",
            constrain_games=shard_games,
            fixed_opponents=fixed_opponents,
        )

    def learn(
        params: LearnerParams, opt_state: optax.OptState, data: Rollout, shuffle_key: jax.Array
    ) -> Learned:
        """Algorithm 4 lines 12-24: advantages, then the PPO epochs over the sequences."""
        t = data.transitions
        # The critic once per game (its input is the same for the n players of a game).
        game_values = critic.apply(params.critic, data.game_global_state)  # f32[G, T]
        values = jnp.repeat(game_values, n, axis=0)  # f32[U, T]
        returns, gae_advantages = advantages(data, values)
        def by_game(tree: Any) -> Any:  # [U, ...] -> [G, n, ...]: free, games are outermost
            return jax.tree.map(lambda x: x.reshape(num_games, n, *x.shape[1:]), tree)

        entropy_noise = None
        if hp.entropy_estimator == "squashed":
            shuffle_key, noise_key = jax.random.split(shuffle_key)
            entropy_noise = jax.random.normal(noise_key, t.pre_tanh.shape, t.pre_tanh.dtype)
        batch = shard_games(UpdateBatch(
            obs=by_game(t.obs),
            global_state=data.game_global_state,
            pre_tanh=by_game(t.pre_tanh),
            log_prob=by_game(t.log_prob),
            reset=by_game(t.reset),
            initial_carry=by_game(t.initial_carry),
            returns=by_game(returns),
            advantages=None if gae_advantages is None else by_game(gae_advantages),
            old_values=by_game(values) if hp.clip_value else None,
            entropy_noise=None if entropy_noise is None else by_game(entropy_noise),
        ))
        # minibatch_size counts player sequences; validate() made it a multiple of n.
        update = ppo.update_epochs(
            loss_fn,
            optimizer,
            params,
            opt_state,
            batch,
            shuffle_key,
            epochs=hp.epochs,
            num_minibatches=hp.num_minibatches,
            value_and_grad_fn=value_and_grad,
            constrain_minibatches=shard_minibatch_games,
        )
        return Learned(update=update, values=values, returns=returns)

    def iteration_metrics(
        data: Rollout,
        learned: Learned,
        opponent: OpponentState,
        shaping_before: ShapingState,
        shaping_after: ShapingState,
    ) -> Metrics:
        """One iteration's metrics from its rollout, its update, the opponent after it and the
        shaping state in force during it (before) and after it."""
        t = data.transitions
        loss, values, returns = learned.update.metrics, learned.values, learned.returns
        outcomes = opp.game_outcome(data.goals_for, data.goals_against)
        metrics = {
            "train/loss": loss.total,
            "train/policy_loss": loss.policy,
            "train/value_loss": loss.value,
            "train/entropy": loss.entropy,
            "train/approx_kl": loss.approx_kl,
            "train/clip_fraction": loss.clip_fraction,
            "train/advantage_mean": loss.advantage_mean,
            "train/grad_norm": learned.update.grad_norm,
            "train/explained_variance": ppo.explained_variance(values, returns),
            "train/value_mean": jnp.mean(values),
            "train/return_mean": jnp.mean(returns[:, 0]),
            "train/mean_score": jnp.mean(outcomes),
            "train/win_rate": jnp.mean((outcomes == 1.0).astype(jnp.float32)),
            "train/goals_for": jnp.mean(data.goals_for.astype(jnp.float32)),
            "train/goals_against": jnp.mean(data.goals_against.astype(jnp.float32)),
            "train/episode_reward": jnp.mean(jnp.sum(t.reward, axis=1)),
            # Share of teammate and opponent slots in view: above the largest of
            # VISIBLE_FRACTIONS, the update's policy pass runs dense (slower, same result).
            "train/visible_share": jnp.mean(t.obs.entity_mask[..., :-1].astype(jnp.float32)),
            "env/goal_reward": jnp.mean(data.goal_reward),
            "env/ball_shaping": jnp.mean(data.ball_shaping),
            "env/approach_shaping": jnp.mean(data.approach_shaping),
            "env/shaping_active": shaping_before.active.astype(jnp.float32),
            "env/shaping_switched_off": (shaping_before.active & ~shaping_after.active).astype(
                jnp.float32
            ),
            "env/scoring_rate": shaping_scoring_rate(shaping_after),
            **opponent_metrics(opponent),
            **mix_metrics(outcomes),
        }
        return {name: jnp.asarray(v, jnp.float32) for name, v in metrics.items()}

    def iteration(state: TrainState) -> tuple[TrainState, Metrics]:
        key, rollout_key, shuffle_key, league_key = jax.random.split(state.key, 4)
        data = collect(state, rollout_key)
        learned = learn(state.params, state.opt_state, data, shuffle_key)
        result = learned.update
        outcomes = opp.game_outcome(data.goals_for, data.goals_against)  # f32[G]
        opponent = update_opponent(state, result.params.policy, outcomes, league_key)
        shaping = state.shaping
        if env_config.shaping_schedule:
            shaping = shaping_update(
                shaping, data.goals_for >= 1, env_config.shaping_threshold
            )
        new_state = TrainState(
            params=result.params,
            opt_state=result.opt_state,
            opponent=opponent,
            shaping=shaping,
            key=key,
            iteration=state.iteration + 1,
            env_steps=state.env_steps
            + jnp.asarray(num_games * data.transitions.reward.shape[1], jnp.uint32),
        )
        return new_state, iteration_metrics(data, learned, opponent, state.shaping, shaping)

    chunk = run.iterations_per_chunk

    def update_chunk(state: TrainState) -> tuple[TrainState, Metrics]:
        return jax.lax.scan(lambda s, _: iteration(s), state, None, length=chunk)

    return Trainer(
        config=config,
        env=env,
        env_params=env_params,
        policy=policy,
        critic=critic,
        optimizer=optimizer,
        # Not jitted as a whole: the networks' init is (and is shared, see
        # _network_initializer); the rest is a few zeros and copies.
        init=init,
        update_chunk=parallel.jit_replicated(update_chunk, mesh),
        iteration=iteration,
        collect=collect,
        learn=learn,
        metrics=iteration_metrics,
        mesh=mesh,
    )


def _fixed_opponents(config: TrainConfig, env_params: EnvParams) -> tuple[FixedOpponent, ...]:
    """The teams of ``opponent.mix`` (not self-play), loaded once per trainer."""
    from elevens.eval.teams import check_team_size

    n = config.env.players_per_team
    fixed = []
    for spec, games in opponent_mix(config)[1:]:
        team = _team_on_field(spec, env_params, "opponent.mix")
        try:
            check_team_size(team, n)
        except ValueError as error:
            raise ValueError(f"opponent.mix team {spec!r}: {error}") from error
        fixed.append(FixedOpponent(policy=team.policy, params=team.params, games=games))
    return tuple(fixed)


def _team_on_field(spec: str, env_params: EnvParams, field: str) -> Any:
    """The ``Team`` of a team spec, a handcrafted one told the field of ``env_params``; a spec
    that does not load is a ValueError naming ``field`` (the config field that gave it)."""
    from elevens.eval.teams import fit_to_field

    return fit_to_field(_loaded_team(spec, field), env_params)


@functools.lru_cache(maxsize=8)
def _loaded_team(spec: str, field: str) -> Any:
    """``load_team(spec)``, once per process: evaluations repeat every few iterations."""
    from elevens.eval.teams import load_team

    try:
        return load_team(spec)
    except (ValueError, FileNotFoundError) as error:
        raise ValueError(f"{field} team {spec!r}: {error}") from error


def _index_count(config: TrainConfig) -> int:
    """Length of ``OpponentState.indices``: one per self-play game, and at least one (a
    checkpoint cannot hold an empty array; without self-play nothing reads it)."""
    return max(self_play_games(config), 1)


def _metric_label(spec: str) -> str:
    """A team spec as a metric name's part: 'runs/x@30' -> 'runs_x@30'."""
    return re.sub(r"[^A-Za-z0-9_.@=-]+", "_", spec).strip("_") or "team"


def _check_device_split(config: TrainConfig, mesh: Mesh) -> None:
    """Every device plays an equal share of the games and of each minibatch's games."""
    n = config.env.players_per_team
    parallel.check_divisible(
        "run.games_per_iteration", config.run.games_per_iteration, mesh,
        "or choose the devices with --run.devices",
    )
    games = config.ppo.minibatch_size // n
    parallel.check_divisible(
        f"the games of a minibatch (ppo.minibatch_size={config.ppo.minibatch_size} / {n} "
        "players)", games, mesh, "ppo.minibatch_size counts player sequences",
    )


# --------------------------------------------------------------------------------------------
# The host loop
# --------------------------------------------------------------------------------------------


CHECKPOINT_DIR = "checkpoints"
LEARNING_CURVE = "learning_curve.png"
GIF_NAME = "learner_vs_naive.gif"
CONFIG_JSON = "config.json"
PROGRESS_METRICS = (
    "train/mean_score",
    "train/goals_for",
    "eval/random/outcome",
    "eval/naive/outcome",
    "eval/teamwork/outcome",
)


class RunRefusedError(ValueError):
    """``train`` will not start: the run directory holds another run's checkpoints, or a resume
    does not match them. Raised before anything compiles, and nothing saved is touched."""


@dataclasses.dataclass
class TrainResult:
    """What ``train`` returns."""

    state: TrainState
    """The final TrainState (the one last checkpointed)."""
    iteration: int
    """Completed iterations."""
    env_steps: int
    """Game steps played (exact)."""
    interrupted: bool
    """True if Ctrl-C stopped the run (a checkpoint was still written)."""
    out_of_time: bool
    """True if ``run.max_minutes`` ended the run before ``run.iterations``."""
    run_dir: Path
    checkpoint: Path | None
    """The last checkpoint's directory."""
    evaluation: dict[str, float]
    """The last evaluation's metrics (``eval/<team>/...``); empty if none ran."""
    files: dict[str, Path]
    """What the run wrote: ``metrics_csv``, ``learning_curve``, ``gif``, ``config``."""
    wall_s: float
    """Seconds this call took."""
    train_seconds: float = 0.0
    """Training time of the whole run (``time/hours`` * 3600): compiling, chunks and
    evaluations, summed over resumed sessions; what ``run.max_minutes`` limits."""


ChunkHook = Callable[[TrainState, Mapping[str, float]], None]


def evaluate(
    trainer: Trainer, state: TrainState, key: jax.Array, teams: tuple[str, ...] | None = None,
    num_games: int | None = None,
) -> dict[str, float]:
    """Play the learner (a NetworkTeam) against each team with ``play_match``: handcrafted
    teams by name, or any team spec (a shipped team, a run or checkpoint, an exported folder).

    Returns ``eval/<team>/outcome`` (``<team>``: the spec, ``/`` made ``_``; the mean outcome
    from the learner's view: win 1, draw 0.5, loss 0), ``/win``, ``/draw``, ``/loss``,
    ``/goals_for`` and ``/goals_against``. Games use the training env's params with shaping as
    configured (shaping does not change the score); the learner plays each side in half of
    them.
    """
    from elevens.eval.match import play_match, summary
    from elevens.teams.network import NetworkTeam

    run = trainer.config.run
    teams = run.eval_teams if teams is None else teams
    num_games = run.eval_games if num_games is None else num_games
    learner = NetworkTeam(
        policy=trainer.policy, deterministic=run.eval_deterministic, name="learner"
    )
    results: dict[str, float] = {}
    for index, name in enumerate(teams):
        opponent, opponent_params = evaluation_team(name, trainer.env_params)
        result = play_match(
            trainer.env, trainer.env_params, learner, opponent,
            jax.random.fold_in(key, index), num_games, home_params=state.params.policy,
            away_params=opponent_params,
        )
        numbers = summary(result)
        label = _metric_label(name)
        results[f"eval/{label}/outcome"] = numbers["mean"]
        for field in ("win", "draw", "loss", "goals_for", "goals_against"):
            results[f"eval/{label}/{field}"] = numbers[field]
    return results


def evaluation_team(spec: str, env_params: EnvParams) -> tuple[Any, Any]:
    """(TeamPolicy, params) of an evaluation opponent: a handcrafted team told the field, or
    a trained team (figure 6.4's line against a checkpoint)."""
    team = _team_on_field(spec, env_params, "run.eval_teams")
    return team.policy, team.params


def _host_metrics(metrics: Metrics) -> list[dict[str, float]]:
    """{name: f32[K]} -> K dicts of Python floats, one per iteration."""
    arrays = {name: np.asarray(value) for name, value in metrics.items()}
    length = len(next(iter(arrays.values())))
    return [{name: float(values[i]) for name, values in arrays.items()} for i in range(length)]


def _due(before: int, after: int, every: int) -> bool:
    """Whether a multiple of ``every`` lies in (before, after]."""
    return every > 0 and after // every > before // every


def train(
    config: TrainConfig,
    resume: bool = False,
    progress: bool = True,
    on_chunk: ChunkHook | None = None,
    resume_from_last_good: bool = False,
) -> TrainResult:
    """Train ``config`` from scratch (or from the latest checkpoint in its run_dir, ``resume``).

    Between compiled chunks of K iterations it logs every iteration's metrics (TensorBoard and
    ``metrics.csv`` in ``run.run_dir``), updates the progress display, evaluates against the
    handcrafted teams every ``run.eval_every`` iterations, and checkpoints every
    ``run.checkpoint_every``. At the end (or on Ctrl-C, which stops the run cleanly) it writes a
    final checkpoint; at the end also the evaluation, ``learning_curve.png`` and
    ``learner_vs_naive.gif``.

    Args:
        config: the run; validated before anything compiles.
        resume: continue from the latest checkpoint of ``run.run_dir``. Its config must match
            this one except for the fields of ``config.RESUMABLE_FIELDS`` (e.g. more iterations),
            else ``RunRefusedError`` (a ``ValueError``) lists the differences. Without a
            checkpoint the run starts fresh. Without ``resume``, a run_dir that already holds
            checkpoints is a ``RunRefusedError``; a damaged checkpoint is a ``CheckpointError``.
        progress: show the progress bar (or plain progress lines when not on a terminal).
        on_chunk: called after each chunk's logging with the new state and the last iteration's
            metrics (tests use it; raising KeyboardInterrupt there acts as a Ctrl-C).
        resume_from_last_good: when the latest checkpoint is damaged, resume from the newest
            intact one; the damaged ones after it move to ``run_dir/damaged_checkpoints``
            (kept, not deleted). Without it a damaged latest checkpoint is a
            ``CheckpointError`` that names it and the newest intact one.
    """
    from elevens.train.checkpoint import Checkpointer, CheckpointError
    from elevens.train.logging import RunLogger, TrainProgress

    validate(config)
    start_time = time.perf_counter()
    run = config.run
    run_dir = Path(run.run_dir)
    # Several processes (--distributed) run this same loop in step; process 0 alone writes the
    # run directory (checkpoints go through Orbax's multi-process path) and evaluates.
    lead = parallel.is_lead()
    processes = jax.process_count()
    checkpointer = Checkpointer(run_dir / CHECKPOINT_DIR, max_to_keep=run.keep_checkpoints)
    # A mixed run (env.mix) has one trainer per game size over the same TrainState; the
    # main scenario's evaluates, draws and shapes what is saved.
    games = (config.env.scenario, *config.env.mix)
    game_configs = (
        {game: scenario_config(config, game) for game in games} if config.env.mix
        else {config.env.scenario: config}
    )
    schedule = mix_schedule(config, -(-run.iterations // run.iterations_per_chunk) + 1)
    train_seconds = 0.0  # wall time spent in chunks and evaluation, over all sessions of the run
    shaping_off_at: int | None = None
    try:
        # Refuse a mismatched resume (or an overwrite) before anything compiles.
        latest = latest_resumable_step(
            checkpointer, resume, "resume=True (--resume)", "run.run_dir"
        )
        resuming = latest is not None
        damage: CheckpointError | None = None
        fallback = ""
        if resuming:
            try:
                check_resumable(checkpointer, config)
            except CheckpointError as error:  # its config.json: an earlier one may serve
                damage = error
        for team in run.eval_teams:  # a bad spec fails here, before anything compiles
            evaluation_team(team, config.env.env_params())
        start = None
        if run.init_from and not resuming:
            _, start = load_start_params(run.init_from, config)
        trainers = {game: make_trainer(game_config) for game, game_config in game_configs.items()}
        trainer = trainers[config.env.scenario]
        state = trainer.init(jax.random.key(run.seed), start)
        env_steps = 0  # game steps played, over all sessions of the run
        if resuming:
            assert latest is not None
            fresh = state
            if damage is None:
                try:
                    state, _, meta = checkpointer.restore(fresh)
                except CheckpointError as error:
                    damage = error
            if damage is not None:
                step = _last_good_step(
                    checkpointer, fresh, latest, damage, resume_from_last_good, run_dir
                )
                check_resumable(checkpointer, config, step)
                state, _, meta = checkpointer.restore(fresh, step)
                fallback = (
                    f"checkpoint {latest} is damaged ({damage}); resumed from checkpoint "
                    f"{step}, the damaged ones are in {run_dir / DAMAGED_DIR}"
                )
            saved_processes = int(meta.get("processes", 1))
            if saved_processes != processes:
                raise RunRefusedError(
                    f"cannot resume {run_dir}: it was trained by {saved_processes} process(es) "
                    f"and this run has {processes}; resume with --num-processes "
                    f"{saved_processes} (the games are split over the processes' devices)"
                )
            train_seconds = float(meta.get("train_seconds", 0.0))
            shaping_off_at = meta.get("shaping_off_iteration")
            env_steps = int(
                meta.get("env_steps", int(state.iteration) * config.env_steps_per_iteration)
            )
    except BaseException:
        # Closed here, not left to the garbage collector with Orbax's background thread.
        checkpointer.close()
        raise
    if lead:
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / CONFIG_JSON).write_text(config.to_json(), encoding="utf-8")
    state = parallel.replicate(state, trainer.mesh)

    iteration = int(state.iteration)
    last_saved = iteration if resuming else None
    eval_key = jax.random.key(run.seed + 1)  # evaluation never touches the run's key
    evaluation: dict[str, float] = {}
    evaluated_at: int | None = None
    interrupted = False
    budget_s = run.max_minutes * 60.0 if run.max_minutes > 0 else math.inf
    out_of_time = False
    checkpoint_path: Path | None = None

    def save(current: TrainState) -> Path | None:
        nonlocal last_saved
        it = int(current.iteration)
        if last_saved == it:
            return checkpointer.step_directory(it)
        path = checkpointer.save(
            it,
            current,
            config.to_dict(),
            {
                "iteration": it,
                "env_steps": env_steps,
                "train_seconds": train_seconds,
                "shaping_off_iteration": shaping_off_at,
                "processes": processes,
            },
        )
        last_saved = it
        return path

    def run_eval(current: TrainState) -> dict[str, float]:
        nonlocal train_seconds
        began = time.perf_counter()
        it = int(current.iteration)
        results = evaluate(trainer, _local(current), jax.random.fold_in(eval_key, it))
        train_seconds += time.perf_counter() - began
        # The chunk before logged the time at this step; only the untrained baseline has none.
        time_rows = _time_metrics(env_steps, train_seconds) if it == 0 else {}
        logger.log(it, {**results, **time_rows})
        return results

    logger: Any = (
        RunLogger(run_dir, resumed_at=iteration if resuming else None) if lead else _Silent()
    )
    if fallback:
        logger.event(iteration, fallback)
    bar: Any = (
        TrainProgress(
            run.iterations,
            metrics=PROGRESS_METRICS,
            start=iteration,
            start_env_steps=env_steps,
            plain=None if progress else True,
            plain_every=1 if progress else 10**9,
        )
        if lead
        else _Silent()
    )
    stop_signals = _StopSignals() if processes > 1 else None
    try:
        try:
            if iteration == 0 and run.eval_every > 0 and lead:
                # The baseline: the learning curve starts at iteration 0.
                bar.note(
                    f"evaluating the {'starting' if run.init_from else 'untrained'} networks "
                    f"against {', '.join(run.eval_teams)} ({run.eval_games} games each; the "
                    "first match compiles)"
                )
                evaluation = run_eval(state)
                evaluated_at = 0
            compiled: set[str] = set()
            while iteration < run.iterations:
                if stop_signals is not None and parallel.agree_any(stop_signals.requested):
                    raise KeyboardInterrupt  # every process stops at this same iteration
                if parallel.agree_any(train_seconds >= budget_s):
                    out_of_time = True
                    logger.event(
                        iteration,
                        f"time budget reached: {train_seconds / 60:.1f} of "
                        f"run.max_minutes={run.max_minutes:g} min",
                    )
                    break
                count = min(run.iterations_per_chunk, run.iterations - iteration)
                game = schedule[iteration // run.iterations_per_chunk]
                game_trainer = trainers[game]
                steps_per_iteration = game_configs[game].env_steps_per_iteration
                if game not in compiled:
                    bar.note(
                        f"compiling the {game} training chunk ({count} iteration"
                        f"{'s' if count > 1 else ''}): once per run and size, from about 20 s "
                        "for 1 v 1 to one or two minutes for 11 v 11 on a 2-core CPU"
                    )
                began = time.perf_counter()
                new_state, metrics = game_trainer.update(
                    _with_games(state, game_configs[game]), count
                )
                rows = _host_metrics(metrics)  # blocks until the chunk is done
                chunk_seconds = time.perf_counter() - began
                if game not in compiled:
                    compiled.add(game)
                    bar.note(f"compiled and ran the first {game} chunk in {chunk_seconds:.0f} s")
                state = _with_games(new_state, game_configs[config.env.scenario])
                before, iteration = iteration, int(state.iteration)
                chunk_sps = count * steps_per_iteration / max(chunk_seconds, 1e-9)
                for offset, row in enumerate(rows):
                    it = before + offset + 1
                    env_steps += steps_per_iteration
                    # The chunk's time spread evenly over its iterations.
                    seconds = train_seconds + chunk_seconds * (offset + 1) / len(rows)
                    row = {**row, **_time_metrics(env_steps, seconds)}
                    row["time/env_steps_per_s"] = chunk_sps
                    if config.env.mix:
                        row["env/players_per_team"] = float(game_configs[game].players_per_team)
                    logger.log(it, row)
                    if row["env/shaping_switched_off"] == 1.0:
                        shaping_off_at = it
                        logger.event(it, "reward shaping switched off for good")
                train_seconds += chunk_seconds
                shown = dict(rows[-1])
                if _due(before, iteration, run.eval_every) and lead:
                    evaluation = run_eval(state)
                    evaluated_at = iteration
                shown.update(evaluation)
                bar.update(iteration, env_steps, shown)
                if _due(before, iteration, run.checkpoint_every):
                    checkpoint_path = save(state)
                if on_chunk is not None:
                    on_chunk(state, shown)
        except KeyboardInterrupt:
            interrupted = True
        checkpoint_path = save(state)
        if interrupted:
            logger.event(
                iteration, f"interrupted (Ctrl-C or SIGTERM): checkpoint {checkpoint_path}"
            )
        files = {"metrics_csv": logger.csv_path, "config": run_dir / CONFIG_JSON} if lead else {}
        if not interrupted and evaluated_at != iteration and lead:
            evaluation = run_eval(state)
        logger.flush()
        if run.write_plot and lead:
            # Also after Ctrl-C: the curve so far is what a stopped run is checked by.
            files["learning_curve"] = write_learning_curve(
                run_dir, run_dir / LEARNING_CURVE, title=_title(config)
            )
        if not interrupted and run.write_gif and lead:
            files["gif"] = write_gif(trainer, _local(state), run_dir / GIF_NAME, seed=run.seed)
    finally:
        if stop_signals is not None:
            stop_signals.restore()
        bar.close()
        logger.close()
        checkpointer.close()
    return TrainResult(
        state=state,
        iteration=int(state.iteration),
        env_steps=env_steps,
        interrupted=interrupted,
        out_of_time=out_of_time,
        run_dir=run_dir,
        checkpoint=checkpoint_path,
        evaluation=evaluation,
        files=files,
        wall_s=time.perf_counter() - start_time,
        train_seconds=train_seconds,
    )


DAMAGED_DIR = "damaged_checkpoints"


class _Silent:
    """The logger and progress display of processes other than 0: they log nothing."""

    csv_path = None

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *args, **kwargs: None


class _StopSignals:
    """Ctrl-C and SIGTERM as a flag while several processes train: each process checks it at
    a chunk end and all stop together (an exception mid-chunk in one process would leave the
    others waiting in a collective)."""

    def __init__(self) -> None:
        self.requested = False
        self._previous = {
            number: signal.signal(number, self._request)
            for number in (signal.SIGINT, signal.SIGTERM)
        }

    def _request(self, signum: int, frame: Any) -> None:
        self.requested = True

    def restore(self) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)


def _local(state: TrainState) -> TrainState:
    """``state`` with its networks on the host: evaluation and the GIF play on this process's
    own device, whatever mesh the state is replicated on."""
    return state.replace(params=parallel.to_host(state.params))


def _last_good_step(
    checkpointer: Any, target: TrainState, latest: int, damage: Exception, use_it: bool,
    run_dir: Path,
) -> int:
    """The step a resume falls back to when checkpoint ``latest`` is damaged (``damage``):
    with ``use_it``, the newest intact one, after moving the damaged ones aside; otherwise a
    ``CheckpointError`` naming the damage and what is intact."""
    from elevens.train.checkpoint import CheckpointError

    good = checkpointer.last_intact_step(target, before=latest)
    if good is None:
        raise CheckpointError(f"{damage}; no earlier checkpoint is intact") from damage
    if not use_it:
        raise CheckpointError(
            f"{damage}; checkpoint {good} ({checkpointer.step_directory(good)}) is intact: "
            f"pass --resume-from-last-good to continue from it (the damaged ones move to "
            f"{run_dir / DAMAGED_DIR}, nothing is deleted)"
        ) from damage
    if parallel.is_lead():
        for step in checkpointer.all_steps():
            if step > good:
                checkpointer.set_aside(step, run_dir / DAMAGED_DIR)
    parallel.barrier("elevens: damaged checkpoints set aside")
    return int(good)


def _with_games(state: TrainState, config: TrainConfig) -> TrainState:
    """``state`` with the per-game opponent indices of ``config``'s games per iteration (a mixed
    run's sizes differ in games; the indices are zeros for the opponents a mix allows)."""
    games = _index_count(config)
    if state.opponent.indices.shape == (games,):
        return state
    return state.replace(opponent=state.opponent.replace(indices=jnp.zeros((games,), jnp.int32)))


def _time_metrics(env_steps: int, seconds: float) -> dict[str, float]:
    return {
        "time/env_steps": float(env_steps),
        "time/hours": seconds / 3600.0,
    }


def _title(config: TrainConfig) -> str:
    return (
        f"{config.env.scenario} ({config.preset} preset), opponent: {config.opponent.kind}, "
        f"seed {config.run.seed}"
    )


def latest_resumable_step(
    checkpointer: Any, resume: bool, resume_flag: str, run_dir_flag: str
) -> int | None:
    """The latest checkpoint's step, or None for an empty directory. Without ``resume`` a
    directory that holds checkpoints is a ``RunRefusedError`` (a new run must not overwrite
    another's); the message names the command's own flags."""
    latest = checkpointer.latest_step()
    if latest is not None and not resume:
        raise RunRefusedError(
            f"{checkpointer.directory} already holds checkpoints (latest: iteration {latest}); "
            f"pass {resume_flag} to continue that run, or choose another {run_dir_flag}"
        )
    return latest


def load_learner_params(text: str) -> tuple[TrainConfig, LearnerParams]:
    """(config, LearnerParams) of a shipped team (``elevens-11v11``) or a training checkpoint:
    a run, checkpoints or step directory, optionally ``PATH@ITERATION``."""
    from elevens.eval.teams import load_team_folder, load_train_state, parse_team_spec

    spec = parse_team_spec(text)
    folder = load_team_folder(spec)
    if folder is not None:
        return cast(tuple[TrainConfig, LearnerParams], folder)
    if spec.path is None:
        raise RunRefusedError(
            f"{text!r} is a handcrafted team, not a checkpoint: a run starts only from a "
            "training checkpoint (a run, checkpoints or step directory, or PATH@ITERATION)"
        )
    config, state = load_train_state(spec.path, spec.iteration)
    return config, state.params


def load_start_params(text: str, config: TrainConfig) -> tuple[TrainConfig, LearnerParams]:
    """``load_learner_params(text)``, refused (``RunRefusedError``, listing the fields) unless
    its networks are ``config``'s. The team size may differ: the networks read entity slots,
    so a 2 v 2 team starts an 11 v 11 run (and the other way round)."""
    source, params = load_learner_params(text)
    if source.network != config.network:
        differences = [
            f"--network.{name.replace('_', '-')} {getattr(source.network, name)!r} "
            f"(this run: {getattr(config.network, name)!r})"
            for name in (field.name for field in dataclasses.fields(source.network))
            if getattr(source.network, name) != getattr(config.network, name)
        ]
        raise RunRefusedError(
            f"run.init_from={text!r} has other networks than this run; pass "
            + ", ".join(differences)
        )
    return source, params


def check_resumable(checkpointer: Any, config: TrainConfig, step: int | None = None) -> None:
    """Raise ``RunRefusedError`` unless the checkpoint's config (``step``, default the latest)
    matches ``config`` (outside ``RESUMABLE_FIELDS``), listing every difference. Reads only
    config.json, so it runs before anything compiles (``train`` and ``elevens robocup train``
    call it on a resume)."""
    saved_dict = checkpointer.read_config(step)
    try:
        saved = TrainConfig.from_dict(saved_dict, fill_missing=True)
    except (TypeError, ValueError) as error:
        raise RunRefusedError(
            f"cannot resume from {checkpointer.directory}: its config.json does not describe a "
            f"TrainConfig of this version ({error})"
        ) from error
    differences = config_differences(saved, config)
    if differences:
        raise RunRefusedError(
            f"cannot resume from {checkpointer.directory}: the config differs from the "
            "checkpoint's in fields that change what is computed:\n  "
            + "\n  ".join(differences)
            + "\nuse the checkpoint's values, or another run directory"
        )


# --------------------------------------------------------------------------------------------
# Pictures
# --------------------------------------------------------------------------------------------


def write_learning_curve(
    run_dir: str | Path, path: str | Path, title: str = "learning curve"
) -> Path:
    """Eval outcome against each handcrafted team, vs env steps and vs hours (minutes for runs
    under 2 hours), from metrics.csv.

    Two panels side by side share the y axis (mean outcome: win 1, draw 0.5, loss 0); one line
    per team; a dotted line at 0.5 (even).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from elevens.eval.curves import run_series
    from elevens.train.logging import read_metrics_csv

    curves = read_metrics_csv(run_dir)
    hours_curve = curves.get("time/hours")
    # Short runs read better in minutes.
    longest = float(np.max(hours_curve.values)) if hours_curve is not None else 0.0
    time_scale, time_unit = (1.0, "hours") if longest >= 2.0 else (60.0, "minutes")
    figure, (by_steps, by_hours) = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    teams = sorted(
        name.split("/")[1]
        for name in curves
        if name.startswith("eval/") and name.endswith("/outcome")
    )
    for team in teams:
        for axis, x_name, scale in (
            (by_steps, "time/env_steps", 1e-6), (by_hours, "time/hours", time_scale)
        ):
            if x_name in curves:
                series = run_series(curves, f"eval/{team}/outcome", x_name)
                axis.plot(series.x * scale, series.y, marker="o", markersize=3, label=team)
    for axis in (by_steps, by_hours):
        axis.axhline(0.5, color="grey", linestyle=":", linewidth=1)
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
    by_steps.set_xlabel("env steps (millions of game steps)")
    by_hours.set_xlabel(f"training time ({time_unit}, wall clock)")
    by_steps.set_ylabel("mean outcome vs team (win 1, draw 0.5, loss 0)")
    if teams:
        by_steps.legend(title="evaluated against")
    figure.suptitle(title)
    figure.tight_layout()
    path = Path(path)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def write_gif(
    trainer: Trainer, state: TrainState, path: str | Path, seed: int = 0, opponent: str = "naive"
) -> Path:
    """One game of the learner (side 0) against a handcrafted team, drawn as a GIF or MP4."""
    from elevens.env.render import frames_from_states, save_video
    from elevens.eval.match import play_match
    from elevens.eval.play import states_from_record
    from elevens.teams.network import NetworkTeam

    learner = NetworkTeam(
        policy=trainer.policy, deterministic=trainer.config.run.eval_deterministic,
        name="learner",
    )
    result = play_match(
        trainer.env, trainer.env_params, learner, resolve_team(opponent, trainer.env_params),
        jax.random.key(seed + 2), 1, home_params=state.params.policy, swap_sides=False,
        record=True,
    )
    assert result.record is not None
    states = states_from_record(result.record, 0, trainer.env_params)
    scale = max(2, round(600 / float(trainer.env_params.field_length)))
    frames = frames_from_states(
        states, trainer.env_params, team_names=("learner", opponent), scale=scale
    )
    return save_video(frames, path, fps=20)
