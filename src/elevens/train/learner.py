"""The learner: ``make_learner(LearnerConfig, env)`` gives pure ``init`` and ``update_chunk``.

One iteration (thesis Algorithm 4) compiles into one program, and this file reads in its order:

1. **Collect** (``collect``, ``elevens.train.rollout``): G games, one whole episode each, the
   learner against the opponent's current params, with the shaping weights in force put into
   ``EnvParams`` (leaves: no recompile); with ``env.randomize`` each game draws its own
   constants (``elevens.env.randomize``).
2. **Advantages** (``advantages``): Monte Carlo returns G_t (the thesis' choice; A = G - V is
   recomputed with the current critic inside every minibatch, Algorithm 4 lines 15-17), or GAE
   on the rollout-time values (``ppo.advantage_estimator``). The whistle ends the episode for
   the critic, which sees the time left in its global state, so the last step is a terminal.
3. **Epochs and minibatches** (``learn``): the rollout's data, grouped by game (``[G, n, T]``:
   free, games are outermost), shuffled into minibatches of whole games and stepped with one
   Adam on ``ppo.sequence_loss`` (Algorithm 4 lines 12-24).
4. **Opponent** (``elevens.train.opponents``): the strategy of ``opponent.kind`` (Polyak with
   the freeze rule, self-play or league) takes the learner's new policy and its outcomes in the
   self-play games.
5. **Shaping** (``elevens.train.shaping``): off for good once the learner scores in more than
   75% of its recent games.

``improve`` is steps 2 to 5 on a rollout played anywhere: a run whose games are played outside
XLA (an external server, through ``elevens.runs.loop``'s collect seam) improves with the same
function. The game is the caller's: ``make_learner`` trains in the env it is given (built once
from the config, ``LearnerConfig.make_env``: the simulator's own game, or one a package above
the core registers with ``train.config.register_game``) and reads from it what the game decides
(its action size, the players its routines play), with no branch for any particular game.
``update_chunk`` runs K iterations as a ``lax.scan``; the host loop that drives it is
``elevens.runs``.
"""

from __future__ import annotations

import dataclasses
import functools
import re
from collections.abc import Callable
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.sharding import Mesh

from elevens.env.params import EnvParams
from elevens.env.randomize import training_games
from elevens.env.soccer import Soccer
from elevens.env.state import GlobalState, Observation
from elevens.nets import capacity
from elevens.nets.critic import AttentionCritic
from elevens.nets.policy import AttentionPolicy
from elevens.teams.base import Team
from elevens.train import opponents as opp
from elevens.train import parallel, ppo
from elevens.train.config import (
    LearnerConfig,
    opponent_mix,
    self_play_games,
    validate_training,
)
from elevens.train.opponents import OpponentState, OpponentStrategy
from elevens.train.rollout import FixedOpponent, Rollout, Teacher, rollout
from elevens.train.shaping import (
    ShapingState,
    shaping_init,
    shaping_scoring_rate,
    shaping_update,
    shaping_weights,
)

Params = Any
Metrics = dict[str, jax.Array]


class LearnerParams(struct.PyTreeNode):
    """The learning team's networks: one policy and one critic shared by all its players."""

    policy: Params  # {"params": ...} of AttentionPolicy
    critic: Params  # {"params": ...} of AttentionCritic


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


class Learned(NamedTuple):
    """What ``learn`` returns."""

    update: ppo.UpdateResult  # new params, opt state, mean loss terms
    values: jax.Array  # f32[U, T] the critic's values at rollout time (before the update)
    returns: jax.Array  # f32[U, T] the critic's targets


@dataclasses.dataclass(frozen=True, eq=False)
class Setup:
    """What the stages of an iteration share: the config's static parts, built once. Compared
    and hashed by identity (it keys the compile caches, and a mix team's params are arrays)."""

    config: LearnerConfig
    mesh: Mesh
    optimizer: optax.GradientTransformation
    opponent: OpponentStrategy
    self_games: int
    """The games against ``opponent`` (the first ones); the rest are the fixed teams'."""
    fixed_opponents: tuple[FixedOpponent, ...]
    """The teams of ``opponent.mix`` that play the last games of every iteration."""
    mix_blocks: tuple[tuple[str, int, int], ...]
    """With fixed teams: (metric label, first game, games) of each opponent of ``opponent.mix``
    that plays, self-play first, for the outcome against each."""
    policy: AttentionPolicy
    critic: AttentionCritic
    value_and_grad: Callable[[LearnerParams, ppo.UpdateBatch], Any]
    env_params: EnvParams
    env: Soccer
    """The game, the caller's (``make_learner``)."""
    noisy: bool
    """The players see with noise (``Randomize.noisy``): the unroll draws it."""
    teacher: Teacher | None = None
    """The team of ``ppo.teacher`` (None: none, or a setup built without ``load_team``)."""

    @property
    def players(self) -> int:
        return self.env.players_per_team

    @property
    def games(self) -> int:
        return self.config.games_per_iteration

    def shard_games(self, tree: Any) -> Any:
        return parallel.game_constraint(self.mesh)(tree)

    def shard_minibatch_games(self, tree: Any) -> Any:
        return parallel.game_constraint(self.mesh, game_axis=1)(tree)


# --------------------------------------------------------------------------------------------
# One iteration, in execution order
# --------------------------------------------------------------------------------------------


def iteration(setup: Setup, state: TrainState) -> tuple[TrainState, Metrics]:
    """Algorithm 4 once: collect, then improve on what was collected."""
    key, rollout_key, shuffle_key, opponent_key = jax.random.split(state.key, 4)
    data = collect(setup, state, rollout_key)
    return improve(setup, state.replace(key=key), data, shuffle_key, opponent_key)


def collect(setup: Setup, state: TrainState, rollout_key: jax.Array) -> Rollout:
    """1. Algorithm 4 lines 4-11: one episode of every game, shaping as currently in force."""
    game = setup.env_params
    weights = shaping_weights(
        state.shaping,
        game.ball_shaping_weight,
        game.approach_shaping_weight,
        game.possession_shaping_weight,
    )
    # The weights are pytree leaves of EnvParams: a new value is not a recompile.
    shaping: dict[str, Any] = {
        "ball_shaping_weight": weights.ball,
        "approach_shaping_weight": weights.approach,
        "possession_shaping_weight": weights.possession,
    }
    params_now = dataclasses.replace(game, **shaping)
    randomize = setup.config.env.randomize
    if randomize.enabled:
        # Each game its own constants for the episode, drawn from the rollout key.
        params_now = training_games(rollout_key, params_now, randomize, setup.games)
    return rollout(
        setup.env,
        setup.policy,
        params_now,
        state.params.policy,
        setup.opponent.act_params(state.opponent),
        rollout_key,
        num_games=setup.games,
        num_steps=game.episode_length,
        opponent_per_game=setup.opponent.per_game,
        constrain_games=setup.shard_games,
        fixed_opponents=setup.fixed_opponents,
        noisy=setup.noisy,
        teacher=setup.teacher,
    )


def improve(
    setup: Setup, state: TrainState, data: Rollout, shuffle_key: jax.Array,
    opponent_key: jax.Array,
) -> tuple[TrainState, Metrics]:
    """2-5: advantages, the PPO epochs, the opponent and the shaping schedule after a rollout
    (``state.key`` is the run's key for the next iteration)."""
    # The teacher's weight follows the completed iterations: a traced value, no recompile.
    weight = None if setup.teacher is None else setup.config.ppo.teacher_weight_at(
        state.iteration
    )
    learned = learn(setup, state.params, state.opt_state, data, shuffle_key, weight)
    new_params = learned.update.params
    outcomes = opp.game_outcome(data.goals_for, data.goals_against)  # f32[G]
    # The fixed teams' games (the last ones) tell nothing about the opponent.
    opponent = setup.opponent.update(
        state.opponent, new_params.policy, outcomes[: setup.self_games], state.iteration,
        opponent_key,
    )
    shaping = next_shaping(setup, state.shaping, data)
    steps_played = data.goals_for.shape[0] * data.transitions.reward.shape[1]
    new_state = TrainState(
        params=new_params,
        opt_state=learned.update.opt_state,
        opponent=opponent,
        shaping=shaping,
        key=state.key,
        iteration=state.iteration + 1,
        env_steps=state.env_steps + jnp.asarray(steps_played, jnp.uint32),
    )
    metrics = iteration_metrics(setup, data, learned, outcomes, opponent, state.shaping, shaping)
    if weight is not None:
        metrics["train/teacher_weight"] = weight
    return new_state, metrics


def advantages(
    hp: ppo.PPOHyperparams, data: Rollout, values: jax.Array
) -> tuple[jax.Array, jax.Array | None]:
    """2. (returns, advantages or None), each f32[U, T]; values f32[U, T] at rollout time."""
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


def learn(
    setup: Setup, params: LearnerParams, opt_state: optax.OptState, data: Rollout,
    shuffle_key: jax.Array, teacher_weight: jax.Array | None = None,
) -> Learned:
    """2-3. Algorithm 4 lines 12-24: advantages, then the PPO epochs over the sequences;
    ``teacher_weight`` f32[]: w of the teacher loss, where ``data`` has the teacher's actions
    (``ppo.teacher``)."""
    hp, n = setup.config.ppo, setup.players
    # The critic once per game (its input is the same for the n players of a game).
    game_values: Any = setup.critic.apply(params.critic, data.game_global_state)  # f32[G, T]
    values = jnp.repeat(game_values, n, axis=0)  # f32[U, T]
    returns, gae_advantages = advantages(hp, data, values)
    entropy_noise = None
    if hp.entropy_estimator == "squashed":
        shuffle_key, noise_key = jax.random.split(shuffle_key)
        pre_tanh = data.transitions.pre_tanh
        entropy_noise = jax.random.normal(noise_key, pre_tanh.shape, pre_tanh.dtype)
    batch = update_batch(
        setup, data, values, returns, gae_advantages, entropy_noise, teacher_weight
    )
    update = ppo.update_epochs(
        functools.partial(ppo.sequence_loss, setup.policy, setup.critic, hp),
        setup.optimizer,
        params,
        opt_state,
        batch,
        shuffle_key,
        epochs=hp.epochs,
        num_minibatches=setup.config.num_minibatches,
        value_and_grad_fn=setup.value_and_grad,
        constrain_minibatches=setup.shard_minibatch_games,
    )
    return Learned(update=update, values=values, returns=returns)


def update_batch(
    setup: Setup, data: Rollout, values: jax.Array, returns: jax.Array,
    gae_advantages: jax.Array | None, entropy_noise: jax.Array | None,
    teacher_weight: jax.Array | None = None,
) -> ppo.UpdateBatch:
    """The rollout's [U, T] player sequences as [G, n, T] (games outermost: a free reshape)."""
    t, n = data.transitions, setup.players

    def by_game(tree: Any) -> Any:
        return jax.tree.map(lambda x: x.reshape(setup.games, n, *x.shape[1:]), tree)

    maybe = lambda x: None if x is None else by_game(x)  # noqa: E731
    batch = ppo.UpdateBatch(
        obs=by_game(t.obs),
        global_state=data.game_global_state,
        pre_tanh=by_game(t.pre_tanh),
        log_prob=by_game(t.log_prob),
        reset=by_game(t.reset),
        initial_carry=by_game(t.initial_carry),
        returns=by_game(returns),
        advantages=maybe(gae_advantages),
        old_values=by_game(values) if setup.config.ppo.clip_value else None,
        entropy_noise=maybe(entropy_noise),
        policy_mask=policy_played(setup, data),
    )
    if teacher_weight is not None and t.teacher_action is None:
        raise ValueError(f"ppo.teacher={setup.config.ppo.teacher!r}: the rollout has no "
                         "teacher's actions (Transition.teacher_action) to learn from")
    if t.teacher_action is not None:
        if teacher_weight is None:
            raise ValueError("the rollout has the teacher's actions: pass teacher_weight")
        batch = batch.replace(
            teacher_action=by_game(t.teacher_action),
            teacher_weight=jnp.full((setup.games,), teacher_weight, jnp.float32),
        )
    return setup.shard_games(batch)


def policy_played(setup: Setup, data: Rollout) -> jax.Array | None:
    """bool[G, n, T], False where a routine played instead of the policy, whose sampled
    action there was never played, so those entries leave PPO's policy and entropy terms
    (``ppo.ppo_loss`` policy_mask): the game's ``scripted_players``, always; in games played
    outside the simulator whoever their routines played (``Rollout.scripted``). None when the
    policy played everything."""
    games, n, steps = setup.games, setup.players, data.transitions.reset.shape[-1]
    played = None
    if setup.env.scripted_players:
        by_policy = ~jnp.isin(jnp.arange(n), jnp.asarray(setup.env.scripted_players))
        played = jnp.broadcast_to(by_policy[None, :, None], (games, n, steps))
    if data.scripted is not None:
        by_routine = ~data.scripted.reshape(games, n, steps)
        played = by_routine if played is None else played & by_routine
    return played


def next_shaping(setup: Setup, shaping: ShapingState, data: Rollout) -> ShapingState:
    """5. The shaping schedule after this iteration's games."""
    env_config = setup.config.env
    if not env_config.shaping_schedule:
        return shaping
    return shaping_update(shaping, data.goals_for >= 1, env_config.shaping_threshold)


def iteration_metrics(
    setup: Setup,
    data: Rollout,
    learned: Learned,
    outcomes: jax.Array,
    opponent: OpponentState,
    shaping_before: ShapingState,
    shaping_after: ShapingState,
) -> Metrics:
    """One iteration's ``train/``, ``env/`` and ``opponent/`` metrics from its rollout, its
    update, the learner's outcome in each game (f32[G], ``opponents.game_outcome``), the
    opponent after it and the shaping state in force during (before) and after it."""
    t = data.transitions
    loss, values, returns = learned.update.metrics, learned.values, learned.returns
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
        # Share of teammate and opponent slots in view: above the largest capacity of
        # nets.capacity, the update's policy pass runs dense (slower, same result).
        "train/visible_share": jnp.mean(t.obs.entity_mask[..., :-1].astype(jnp.float32)),
        # With ppo.teacher: its action's mean log pi under the params being updated, and how
        # close the policy is to it (the parametrised head's kind, the Gaussian's action).
        **{
            f"train/{name}": value
            for name in ("teacher_log_prob", "teacher_agreement", "teacher_action_error")
            if (value := getattr(loss, name)) is not None
        },
        "env/goal_reward": jnp.mean(data.goal_reward),
        "env/ball_shaping": jnp.mean(data.ball_shaping),
        "env/approach_shaping": jnp.mean(data.approach_shaping),
        "env/possession_shaping": jnp.mean(data.possession_shaping),
        # The learner's share of steps with the ball minus the opponent's (reward.ball_holder).
        "env/possession": jnp.mean(data.possession),
        "env/shaping_active": shaping_before.active.astype(jnp.float32),
        "env/shaping_switched_off": (shaping_before.active & ~shaping_after.active).astype(
            jnp.float32
        ),
        "env/scoring_rate": shaping_scoring_rate(shaping_after),
        **setup.opponent.metrics(opponent),
        # With opponent.mix: the learner's mean outcome against each opponent.
        **{
            f"opponent/{label}/outcome": jnp.mean(outcomes[begin : begin + games])
            for label, begin, games in setup.mix_blocks
        },
    }
    return {name: jnp.asarray(v, jnp.float32) for name, v in metrics.items()}


def metric_label(spec: str) -> str:
    """A team spec as a metric name's part: 'runs/x@30' -> 'runs_x@30'."""
    return re.sub(r"[^A-Za-z0-9_.@=-]+", "_", spec).strip("_") or "team"


# --------------------------------------------------------------------------------------------
# Building a learner
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Learner:
    """Pure functions of one config. ``init(key, start=None) -> TrainState``;
    ``update_chunk(state) -> (state, metrics)`` runs K = ``config.iterations_per_chunk``
    iterations (jitted on first use; metrics are ``{name: f32[K]}``); ``update(state,
    num_iterations)`` another number (compiled once per number). ``iteration``, ``collect``,
    ``learn``, ``improve`` and ``metrics`` are the stages above bound to this config, not
    jitted."""

    config: LearnerConfig
    setup: Setup

    def init(self, key: jax.Array, start: LearnerParams | None = None) -> TrainState:
        return init_state(self.setup, key, start)

    @functools.cached_property
    def update_chunk(self) -> Callable[[TrainState], tuple[TrainState, Metrics]]:
        # Held by the learner: the chunk a run calls again and again never leaves the cache.
        return _scan_iterations(self.setup, self.config.iterations_per_chunk)

    def update(self, state: TrainState, num_iterations: int) -> tuple[TrainState, Metrics]:
        if num_iterations == self.config.iterations_per_chunk:
            return self.update_chunk(state)
        return _scan_iterations(self.setup, num_iterations)(state)

    @property
    def env(self) -> Soccer:
        return self.setup.env

    @property
    def env_params(self) -> EnvParams:
        return self.setup.env_params

    @property
    def policy(self) -> AttentionPolicy:
        return self.setup.policy

    @property
    def critic(self) -> AttentionCritic:
        return self.setup.critic

    @property
    def optimizer(self) -> optax.GradientTransformation:
        return self.setup.optimizer

    @property
    def mesh(self) -> Mesh:
        return self.setup.mesh

    @property
    def opponent(self) -> OpponentStrategy:
        return self.setup.opponent

    @property
    def iteration(self) -> Callable[[TrainState], tuple[TrainState, Metrics]]:
        return functools.partial(iteration, self.setup)

    @property
    def collect(self) -> Callable[[TrainState, jax.Array], Rollout]:
        return functools.partial(collect, self.setup)

    @property
    def learn(self) -> Callable[..., Learned]:
        return functools.partial(learn, self.setup)

    @property
    def improve(self) -> Callable[..., tuple[TrainState, Metrics]]:
        return functools.partial(improve, self.setup)

    @property
    def metrics(self) -> Callable[..., Metrics]:
        return functools.partial(iteration_metrics, self.setup)


TeamLoader = Callable[[str, EnvParams, str], Team]
"""``(team spec, env params, config field) -> Team``: how the learner gets the fixed teams of
``opponent.mix`` (``elevens.runs.teams.team_on_field``: loading runs from disk is the runs
layer's, above this one)."""


def make_learner(
    config: LearnerConfig,
    env: Soccer,
    load_team: TeamLoader | None = None,
    *,
    devices: int = 0,
    external_games: bool = False,
    external_teacher: bool = False,
) -> Learner:
    """Build the pure functions of ``config`` training in the game ``env`` (the caller's, built
    once from the config: ``config.make_env()``) on ``devices`` (``parallel.data_mesh``: 0 =
    all). Both are checked first, the config's fields and that ``env`` is its game's size and
    takes its policy's action: nothing compiles on a bad one. ``load_team`` loads the fixed
    teams of ``opponent.mix``; a config with such teams needs it. ``external_games``: the
    caller plays the games outside the compiled unroll and calls only ``improve``, so the
    policy may give any action size the caller's game takes (``network.actions``), not only
    ``env``'s. ``external_teacher``: that caller also records ``ppo.teacher``'s actions on
    its players' observations in the rollouts it gives (``Transition.teacher_action``); the
    team is loaded here (``Learner.setup.teacher``) for it to act.

    They are cached on their arguments (a game is equal to another built alike): building the
    same learner again in one process (a resume, a longer run, another run directory) reuses
    the compiled chunk.
    """
    validate_training(config)
    _check_game(config, env, external_games)
    if config.ppo.teacher and external_games and not external_teacher:
        raise ValueError(
            f"ppo.teacher={config.ppo.teacher!r} is invalid when the games are played outside "
            "the simulator: the teacher acts beside the learner in the compiled unroll; leave "
            "it out"
        )
    if load_team is None and config.ppo.teacher:
        raise ValueError(
            f"ppo.teacher={config.ppo.teacher!r} names a team: pass load_team "
            "(elevens.runs.teams.team_on_field) to make_learner, or train with elevens.runs.train"
        )
    if load_team is None and len(opponent_mix(config)) > 1:
        raise ValueError(
            f"opponent.mix={config.opponent.mix!r} names fixed teams: pass load_team "
            "(elevens.runs.teams.team_on_field) to make_learner, or train with elevens.runs.train"
        )
    return _build_learner(config, env, load_team, devices)


def train_state_shape(config: LearnerConfig, env: Soccer, devices: int = 0) -> TrainState:
    """The TrainState of ``config`` in the game ``env`` as shapes (``jax.eval_shape``), nothing
    computed or loaded: the target a checkpoint restores into."""
    validate_training(config)
    _check_game(config, env, external_games=True)  # a server-trained run restores too
    setup = make_setup(config, env, devices=devices)
    return cast(TrainState, jax.eval_shape(functools.partial(init_state, setup), jax.random.key(0)))


def _check_game(config: LearnerConfig, env: Soccer, external_games: bool) -> None:
    """``env`` is a game of ``config``'s team size whose action the policy gives (unless the
    games are played outside the simulator)."""
    if not isinstance(env, Soccer):
        raise ValueError(
            f"env={env!r} is not a game: make_learner takes the game to train in, a Soccer "
            "(config.make_env())"
        )
    if env.players_per_team != config.players_per_team:
        raise ValueError(
            f"env plays {env.players_per_team} a side, but the config's game has "
            f"env.players_per_team={config.players_per_team}: build the game from the config "
            "(config.make_env())"
        )
    if config.network.actions != env.actions and not external_games:
        raise ValueError(
            f"network.actions={config.network.actions}: the game {type(env).__name__} "
            f"(env.physics={config.env.physics!r}) takes {env.actions} action values; a policy "
            "of another size plays games outside the simulator (external_games)"
        )


@functools.lru_cache(maxsize=8)
def _build_learner(
    config: LearnerConfig, env: Soccer, load_team: TeamLoader | None, devices: int
) -> Learner:
    # The iterations compile on the first update_chunk (cached with the setup: _scan_iterations);
    # the networks' init compiles on the first init (shared: _network_initializer).
    return Learner(config=config, setup=make_setup(config, env, load_team, devices))


def make_setup(
    config: LearnerConfig, env: Soccer, load_team: TeamLoader | None = None, devices: int = 0
) -> Setup:
    """The static parts of an iteration of ``config`` in the game ``env`` on ``devices`` (the
    fixed teams of ``opponent.mix`` only with ``load_team``), built from the top layer down:
    what the config says, the devices, the optimiser and the opponent, then the fixed teams
    and the networks."""
    mix = opponent_mix(config)
    self_games = mix[0][1]
    mix_blocks = _mix_blocks(mix)
    n = config.players_per_team
    hp = config.ppo
    o = config.opponent
    env_params = config.env.game
    mesh = parallel.data_mesh(devices)
    _check_device_split(config, mesh)
    # Adam with the config's learning rate (table 6.1: 1e-4), one optimiser for both networks
    # (Algorithm 4 lines 22-23 step policy and critic on the same objective J).
    optimizer = optax.adam(hp.learning_rate)
    opponent = opp.make_opponent(
        o.kind, polyak_tau=o.polyak_tau, freeze_threshold=o.freeze_threshold,
        league_capacity=o.league_capacity, league_window=o.league_window,
        league_every=o.league_every, league_psi=o.league_psi,
        league_min_games=o.league_min_games, index_count=_index_count(self_games),
    )
    fixed = (
        _fixed_opponents(mix[1:], n, env.actions, env_params, load_team) if load_team else ()
    )
    teacher = (
        _teacher(hp.teacher, n, env.actions, env_params, load_team)
        if hp.teacher and load_team else None
    )
    policy, critic = config.network.policy(), config.network.critic()
    value_and_grad = capacity.value_and_grad(
        functools.partial(ppo.sequence_loss, policy, critic, hp),
        lambda batch: batch.obs,
        capacity.compacts(config.network.use_attention, n),
    )
    return Setup(
        config=config,
        mesh=mesh,
        optimizer=optimizer,
        opponent=opponent,
        self_games=self_games,
        fixed_opponents=fixed,
        mix_blocks=mix_blocks if fixed else (),
        policy=policy,
        critic=critic,
        value_and_grad=value_and_grad,
        env_params=env_params,
        env=env,
        noisy=config.env.randomize.noisy(env_params),
        teacher=teacher,
    )


def init_state(setup: Setup, key: jax.Array, start: LearnerParams | None = None) -> TrainState:
    """A fresh TrainState; ``start`` (LearnerParams of the same networks, another run's:
    --run.init-from) replaces the random networks, and the opponent starts as its policy."""
    policy_key, critic_key, run_key = jax.random.split(key, 3)
    if start is None:
        initialize = _network_initializer(setup.policy, setup.critic, setup.env)
        policy_params, critic_params = initialize(policy_key, critic_key)
        start = LearnerParams(policy=policy_params, critic=critic_params)
    return TrainState(
        params=start,
        opt_state=setup.optimizer.init(start),
        opponent=setup.opponent.init(start.policy),
        shaping=shaping_init(setup.config.env.shaping_window),
        key=run_key,
        iteration=jnp.asarray(0, jnp.int32),
        env_steps=jnp.asarray(0, jnp.uint32),
    )


@functools.lru_cache(maxsize=8)
def _network_initializer(
    policy: AttentionPolicy, critic: AttentionCritic, env: Soccer
) -> Callable[[jax.Array, jax.Array], tuple[Params, Params]]:
    """Jitted ``(policy_key, critic_key) -> (policy params, critic params)``, one per networks
    and game: its compile is most of ``init``'s, and a sweep or a test suite builds many
    configs that differ only in PPO, opponent or run settings. Parameters depend on the input
    shapes only, so zeros stand in for the observation and the global state."""
    n = env.players_per_team
    env_params = env.default_params()

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


@functools.lru_cache(maxsize=16)
def _scan_iterations(
    setup: Setup, num_iterations: int
) -> Callable[[TrainState], tuple[TrainState, Metrics]]:
    def run(state: TrainState) -> tuple[TrainState, Metrics]:
        return jax.lax.scan(lambda s, _: iteration(setup, s), state, None, length=num_iterations)

    return parallel.jit_replicated(run, setup.mesh)


def _fixed_opponents(
    teams: list[tuple[str, int]], players_per_team: int, actions: int, env_params: EnvParams,
    load_team: TeamLoader,
) -> tuple[FixedOpponent, ...]:
    """The fixed teams of ``opponent.mix`` (``teams``: spec and games an iteration), loaded
    once per learner and checked against the game's size and action."""
    fixed = []
    for spec, games in teams:
        team = _checked_team(spec, "opponent.mix", players_per_team, actions, env_params,
                             load_team)
        fixed.append(FixedOpponent(policy=team.policy, params=team.params, games=games))
    return tuple(fixed)


def check_teacher(config: LearnerConfig, load_team: TeamLoader) -> None:
    """ValueError naming ``ppo.teacher`` unless its team loads and plays ``config``'s game (the
    learner's own check, for a caller that refuses bad input before it starts anything)."""
    if config.ppo.teacher:
        _teacher(config.ppo.teacher, config.players_per_team, config.make_env().actions,
                 config.env.game, load_team)


def _teacher(
    spec: str, players_per_team: int, actions: int, env_params: EnvParams, load_team: TeamLoader,
) -> Teacher:
    """The team of ``ppo.teacher``, loaded once per learner and checked against the game."""
    team = _checked_team(spec, "ppo.teacher", players_per_team, actions, env_params, load_team)
    return Teacher(policy=team.policy, params=team.params)


def _checked_team(
    spec: str, field: str, players_per_team: int, actions: int, env_params: EnvParams,
    load_team: TeamLoader,
) -> Team:
    """``load_team(spec)`` for the config field ``field``, checked against the game's size and
    action (an error names the field and the team)."""
    team = load_team(spec, env_params, field)
    try:
        team.check_size(players_per_team, actions)
    except ValueError as error:
        raise ValueError(f"{field} team {spec!r}: {error}") from error
    return team


def _mix_blocks(mix: list[tuple[str, int]]) -> tuple[tuple[str, int, int], ...]:
    """``opponent_mix`` as (metric label, first game, games) of each opponent that plays."""
    blocks, begin = [], 0
    for spec, games in mix:
        if games:
            blocks.append((metric_label(spec), begin, games))
        begin += games
    return tuple(blocks)


def opponent_index_count(config: LearnerConfig) -> int:
    """Length of ``OpponentState.indices`` for ``config`` (``_index_count``)."""
    return _index_count(self_play_games(config))


def _index_count(self_games: int) -> int:
    """One opponent index per self-play game, and at least one (a checkpoint cannot hold an
    empty array; without self-play nothing reads it)."""
    return max(self_games, 1)


def _check_device_split(config: LearnerConfig, mesh: Mesh) -> None:
    """Every device plays an equal share of the games and of each minibatch's games."""
    n = config.players_per_team
    parallel.check_divisible(
        "games_per_iteration", config.games_per_iteration, mesh,
        "or choose the devices with --run.devices",
    )
    games = config.ppo.minibatch_size // n
    parallel.check_divisible(
        f"the games of a minibatch (ppo.minibatch_size={config.ppo.minibatch_size} / {n} "
        "players)", games, mesh, "ppo.minibatch_size counts player sequences",
    )
