"""PPO: returns and advantages, the loss terms, and the update over epochs and minibatches.

Everything here is pure JAX on plain arrays and pytrees, so the trainer can compile a whole
iteration (rollout, advantages, epochs, opponent update) into one program. Losses are split into
small functions so that each can be checked by hand (tests/train/test_ppo.py), as Brax does.

Thesis references (seeds/000): section 3.3.5 (the PPO objective, eq. 3.59-3.67), Algorithm 4 and
section 5.2 (the multi-agent changes: clip 0.1, 5 epochs), table 6.1 (the numbers).

Time-axis conventions used by both estimators below:

* ``rewards[t]`` is the reward received for the action at step ``t``.
* ``dones[t]`` is True when step ``t`` is the LAST step of its episode: nothing flows from
  ``t + 1`` back into ``t`` (the next step, if any, belongs to a new episode).
* A time limit is a truncation, not a terminal. Where the value after a truncation is
  known it is bootstrapped from; where it is not, the truncation is treated as a terminal. See the
  docstrings of ``monte_carlo_returns`` and ``gae`` for exactly which argument carries that value.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.typing import ArrayLike

from elevens.env.state import GlobalState, Observation
from elevens.nets.attention import Capacity
from elevens.nets.critic import AttentionCritic
from elevens.nets.distributions import MASKED_LOGIT
from elevens.nets.policy import AttentionPolicy, PolicyCarry

PyTree = Any
Metrics = Any

# --------------------------------------------------------------------------------------------
# Hyperparameters
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PPOHyperparams:
    """The PPO numbers of the thesis (table 6.1, Algorithm 4) plus a few switches, all static."""

    gamma: float = 0.999
    """Reward discount factor gamma (table 6.1)."""
    gae_lambda: float = 0.95
    """GAE lambda, used only when ``advantage_estimator == "gae"``. Not in the thesis (it uses
    Monte Carlo returns, section 3.3.5); 0.95 is the default of Schulman et al. (2016)."""
    advantage_estimator: Literal["monte_carlo", "gae"] = "monte_carlo"
    """The thesis' choice is Monte Carlo returns, A = G - V (eq. 3.62-3.63, section 3.3.5:
    "we found Monte Carlo sampling to work better in our multi-agent setting"). "gae" is the
    original PPO estimator, kept as a switch for ablations."""
    learning_rate: float = 1e-4
    """Learning rate of the Adam optimiser (table 6.1)."""
    epochs: int = 5
    """epochs_per_step (Algorithm 4, table 6.1, section 5.2.2: 5 instead of PPO's usual more)."""
    minibatch_size: int = 60
    """Mini-batch size (table 6.1), in the sampling units of ``update_epochs``: one
    game-team-player sequence for the recurrent policy. Table 6.1's batch of 660 such sequences
    is not a field here: it is games per iteration x players (``LearnerConfig.batch_size``), so
    660 / 60 = 11 minibatches."""
    clip_epsilon: float = 0.1
    """PPO clipping value epsilon_p (table 6.1, section 5.2.1: 0.1 instead of PPO's 0.2)."""
    policy_weight: float = 1.0
    """Policy loss weighting alpha_p (table 6.1, Algorithm 4)."""
    value_weight: float = 0.5
    """Critic loss weighting alpha_v (table 6.1). It multiplies the plain squared error
    (G - V)^2 of eq. 3.61, so the value term is 0.5 * (G - V)^2 as in Algorithm 4 line 21."""
    entropy_weight: float = 0.01
    """Entropy loss weighting alpha_e (table 6.1)."""
    entropy_estimator: Literal["gaussian", "squashed"] = "gaussian"
    """The entropy in the bonus. "gaussian": the thesis' closed-form entropy of the pre-tanh
    Gaussian (eq. 3.75), an upper bound that grows with log_std without limit, so the bonus keeps
    widening a policy whose actions already sit at +-1. "squashed": a one-sample Monte Carlo
    estimate of the entropy of the action itself (``TanhGaussian.entropy_at``, with noise drawn
    once per sample and iteration), which stops rewarding a wider Gaussian once the tanh
    saturates. Its log(1 - tanh(u)^2) term also pulls the mean towards 0, away from full-speed
    moves: in the 2v2 preset it peaked at 0.39 against naive in an hour where "gaussian" reached
    0.62 (docs/results/2v2_learning.md). A smaller entropy_weight is the better remedy there."""
    normalize_advantages: bool = False
    """Standardise advantages per minibatch (mean 0, std 1 over the minibatch's valid entries).
    Off by default: Algorithm 4 uses the raw A = G - V. CleanRL and Brax turn it on."""
    clip_value: bool = False
    """Clip the critic's change around the rollout-time value (PPO2-style). Off by default: the
    thesis' critic objective is the plain squared error (eq. 3.61)."""
    value_clip_epsilon: float = 0.1
    """Width of the value clip when ``clip_value`` is on; not in the thesis, set to epsilon_p as
    CleanRL ties the two."""
    teacher: str = ""
    """A fixed team (a team spec, as ``opponent.mix``'s teams: 'naive', a shipped or trained
    team) that acts beside the learner on the learner's own observations at every step; the
    loss then pulls the policy towards its actions (kickstarting, Schmitt et al. 2018):
    ``- w * mean(log pi(teacher's action))``. '': no teacher."""
    teacher_weight: float = 1.0
    """w at iteration 0 (with ``teacher``)."""
    teacher_iterations: int = 0
    """w falls linearly from ``teacher_weight`` to 0 over this many iterations, then PPO alone
    trains; 0: w stays ``teacher_weight``."""
    teacher_balance: bool = False
    """Parametrised head: weight each entry by the inverse share of its teacher kind in the
    minibatch, so that every kind the teacher played counts alike. Without it the common kind
    drowns the rare decisive ones: taught by ``skills_naive`` at 11 v 11 (85% GO_TO, 14%
    INTERCEPT), a policy agreed on 98% of GO_TO and 9% of INTERCEPT after 20 iterations. The
    reported ``train/teacher_log_prob`` is then the balanced mean."""
    teacher_group_balance: bool = False
    """Parametrised head with a kind mask (``network.kind_mask``): weight each entry by the
    inverse share of its group, the kinds the mask allows there (the ball holder's, the
    runner's, the others'), among the entries that count, so that each group of decisions counts
    alike while within a group the teacher's kinds keep their shares (``teacher_balance``
    shifts the policy towards the rare kinds: taught so in the server, it passed every ball).
    The ball holder is 1.5% of the rows in the skill game."""

    def teacher_weight_at(self, iteration: jax.Array) -> jax.Array:
        """f32[]: the teacher's weight w after ``iteration`` i32[] completed iterations (traced:
        the schedule is no recompile)."""
        if self.teacher_iterations == 0:
            return jnp.asarray(self.teacher_weight, jnp.float32)
        done = jnp.asarray(iteration, jnp.float32) / self.teacher_iterations
        return self.teacher_weight * jnp.maximum(1.0 - done, 0.0)

    def __post_init__(self) -> None:
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma={self.gamma!r} is invalid: it must be in [0, 1]")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError(f"gae_lambda={self.gae_lambda!r} is invalid: it must be in [0, 1]")
        if self.advantage_estimator not in ("monte_carlo", "gae"):
            raise ValueError(
                f"advantage_estimator={self.advantage_estimator!r} is invalid: "
                "allowed values are ('monte_carlo', 'gae')"
            )
        if not self.learning_rate > 0:  # also catches NaN
            raise ValueError(
                f"learning_rate={self.learning_rate!r} is invalid: it must be a number > 0"
            )
        if self.entropy_estimator not in ("gaussian", "squashed"):
            raise ValueError(
                f"entropy_estimator={self.entropy_estimator!r} is invalid: "
                "it must be 'gaussian' or 'squashed'"
            )
        if self.epochs < 1:
            raise ValueError(f"epochs={self.epochs!r} is invalid: it must be >= 1")
        if self.minibatch_size < 1:
            raise ValueError(
                f"minibatch_size={self.minibatch_size!r} is invalid: it must be >= 1"
            )
        if self.clip_epsilon <= 0 or self.value_clip_epsilon <= 0:
            raise ValueError(
                f"clip_epsilon={self.clip_epsilon!r}, value_clip_epsilon="
                f"{self.value_clip_epsilon!r} are invalid: both must be > 0"
            )


# --------------------------------------------------------------------------------------------
# Returns and advantages (reverse scans over the leading time axis)
# --------------------------------------------------------------------------------------------


class Advantages(NamedTuple):
    """Output of ``gae``; every field has the shape of ``rewards``, ``f32[T, ...]``."""

    advantages: jax.Array
    """A_t, the lambda-advantage."""
    returns: jax.Array
    """A_t + V(s_t): the critic's regression target (the lambda-return)."""


def monte_carlo_returns(
    rewards: ArrayLike,
    dones: ArrayLike,
    gamma: ArrayLike,
    bootstrap_value: ArrayLike | None = None,
) -> jax.Array:
    """Discounted returns G_t = r_t + gamma * G_{t+1} (eq. 3.62), cut at episode ends.

    Args:
        rewards: ``f32[T, ...]``, any trailing axes (games, players).
        dones: ``bool[T, ...]`` (or broadcastable to ``rewards``): True at the last step of an
            episode. The return of that step is its reward alone; later rewards belong to the next
            episode and never leak back.
        gamma: discount factor, a scalar.
        bootstrap_value: ``f32[...]``, the critic's value of the state that follows the LAST step
            of the rollout, or None for 0. It is used only where ``dones[-1]`` is False, that is,
            where the rollout was cut before its episode ended (a truncation by the rollout
            length, or a time limit that the caller chose to bootstrap).

    Truncation convention: a time limit inside the rollout cannot be bootstrapped here (the value
    after it is not an argument): mark it in ``dones`` and it is treated as a terminal; use ``gae``
    with ``truncation_values`` where that matters. In the thesis' setting a rollout is one whole
    game and the critic sees the time left, so the final whistle really ends the game for the
    critic: pass ``dones[-1] = True`` (or ``bootstrap_value=None``), as Algorithm 4's
    ``discounted_return`` does.

    Returns:
        ``f32[T, ...]`` the returns G_t.
    """
    rewards = jnp.asarray(rewards, jnp.float32)
    continues = 1.0 - jnp.broadcast_to(jnp.asarray(dones), rewards.shape).astype(jnp.float32)
    if bootstrap_value is None:
        last_return = jnp.zeros(rewards.shape[1:], jnp.float32)
    else:
        last_return = jnp.broadcast_to(
            jnp.asarray(bootstrap_value, jnp.float32), rewards.shape[1:]
        )

    def backward_step(
        next_return: jax.Array, step: tuple[jax.Array, jax.Array]
    ) -> tuple[jax.Array, jax.Array]:
        reward, cont = step
        current = reward + gamma * cont * next_return
        return current, current

    _, returns = jax.lax.scan(backward_step, last_return, (rewards, continues), reverse=True)
    return returns


def gae(
    rewards: ArrayLike,
    values: ArrayLike,
    dones: ArrayLike,
    truncations: ArrayLike,
    last_value: ArrayLike,
    gamma: ArrayLike,
    lambda_: ArrayLike,
    truncation_values: ArrayLike | None = None,
) -> Advantages:
    """Generalised advantage estimation (Schulman et al. 2016) by a reverse ``lax.scan``.

    Args:
        rewards: ``f32[T, ...]``, any trailing axes.
        values: ``f32[T, ...]``, V(s_t) as seen by the critic at rollout time.
        dones: ``bool[T, ...]``: True at the last step of an episode, for any reason.
        truncations: ``bool[T, ...]``: True where that end was a time limit rather than a real
            terminal. A truncation is an episode end even where ``dones`` is False.
        last_value: ``f32[...]``, V(s_T), the value of the state after the last rollout step;
            used only where the last step is not an episode end.
        gamma, lambda_: scalars.
        truncation_values: ``f32[T, ...]`` or None. Where ``truncations[t]``, the value of the
            state reached by step t (the truncated state, before any reset).

    The next-state value used at step t is, exactly:

    * not an episode end: ``values[t + 1]`` (``last_value`` at t = T - 1), and the advantage
      accumulates ``gamma * lambda_ * A_{t+1}``;
    * a terminal: 0, and nothing accumulates from ``t + 1``;
    * a truncation with ``truncation_values`` given: ``truncation_values[t]``, and nothing
      accumulates from ``t + 1`` (it is another episode);
    * a truncation with ``truncation_values=None``: treated as a terminal (value 0).

    In this env there is no auto-reset and a rollout is whole games, so the simple way to bootstrap
    the final whistle is ``dones[-1] = truncations[-1] = False`` with ``last_value = V(s_T)``.

    Returns:
        ``Advantages(advantages, returns)``, each ``f32[T, ...]``; returns = advantages + values.
    """
    rewards = jnp.asarray(rewards, jnp.float32)
    values = jnp.broadcast_to(jnp.asarray(values, jnp.float32), rewards.shape)
    truncated = jnp.broadcast_to(jnp.asarray(truncations), rewards.shape).astype(bool)
    ended = jnp.broadcast_to(jnp.asarray(dones), rewards.shape).astype(bool) | truncated
    last_value = jnp.broadcast_to(jnp.asarray(last_value, jnp.float32), rewards.shape[1:])
    next_values = jnp.concatenate([values[1:], last_value[None]], axis=0)
    if truncation_values is None:
        end_values = jnp.zeros_like(values)
    else:
        trunc_values = jnp.broadcast_to(jnp.asarray(truncation_values, jnp.float32), values.shape)
        end_values = jnp.where(truncated, trunc_values, 0.0)
    bootstrap = jnp.where(ended, end_values, next_values)
    deltas = rewards + gamma * bootstrap - values
    continues = 1.0 - ended.astype(jnp.float32)

    def backward_step(
        next_advantage: jax.Array, step: tuple[jax.Array, jax.Array]
    ) -> tuple[jax.Array, jax.Array]:
        delta, cont = step
        advantage = delta + gamma * lambda_ * cont * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(
        backward_step, jnp.zeros_like(last_value), (deltas, continues), reverse=True
    )
    return Advantages(advantages=advantages, returns=advantages + values)


# --------------------------------------------------------------------------------------------
# Loss terms
# --------------------------------------------------------------------------------------------


def _masked_mean(x: jax.Array, mask: ArrayLike | None) -> jax.Array:
    """Mean of x over the entries where mask is True (all entries when mask is None)."""
    if mask is None:
        return jnp.mean(x)
    weights = jnp.broadcast_to(jnp.asarray(mask), x.shape).astype(x.dtype)
    return jnp.sum(x * weights) / jnp.maximum(jnp.sum(weights), 1.0)


def _both(first: ArrayLike | None, second: ArrayLike | None) -> jax.Array | None:
    """The entries True in both masks (a missing mask is all True)."""
    if first is None or second is None:
        return None if first is None and second is None else jnp.asarray(
            second if first is None else first, bool
        )
    return jnp.asarray(first, bool) & jnp.asarray(second, bool)


class PolicyLoss(NamedTuple):
    """Output of ``policy_loss``; all scalars ``f32[]``."""

    loss: jax.Array
    """-mean(min(ratio * A, clip(ratio, 1 - eps, 1 + eps) * A)), to be minimised."""
    approx_kl: jax.Array
    """mean((ratio - 1) - log ratio): the low-variance, non-negative KL(old || new) estimator."""
    clip_fraction: jax.Array
    """Fraction of samples with |ratio - 1| > eps (where clipping can cut the gradient)."""


def policy_loss(
    log_prob_new: ArrayLike,
    log_prob_old: ArrayLike,
    advantages: ArrayLike,
    clip_epsilon: float,
    mask: ArrayLike | None = None,
) -> PolicyLoss:
    """The clipped surrogate of PPO (eq. 3.67), negated into a loss.

    Args:
        log_prob_new: ``f32[...]`` log pi_theta(a_t | o_t) under the params being optimised.
        log_prob_old: ``f32[...]`` the same at rollout time (no gradient flows into it).
        advantages: ``f32[...]`` (no gradient flows into it).
        clip_epsilon: epsilon_p, 0.1 in the thesis.
        mask: optional ``bool[...]``: only True entries count (padded players, for example).
    """
    log_ratio = jnp.asarray(log_prob_new) - jax.lax.stop_gradient(jnp.asarray(log_prob_old))
    ratio = jnp.exp(log_ratio)
    advantages = jax.lax.stop_gradient(jnp.asarray(advantages, jnp.float32))
    unclipped = ratio * advantages
    clipped = jnp.clip(ratio, 1.0 - clip_epsilon, 1.0 + clip_epsilon) * advantages
    objective = jnp.minimum(unclipped, clipped)
    # Diagnostics only: they must not add gradients if someone puts them into a loss.
    ratio_sg = jax.lax.stop_gradient(ratio)
    log_ratio_sg = jax.lax.stop_gradient(log_ratio)
    return PolicyLoss(
        loss=-_masked_mean(objective, mask),
        approx_kl=_masked_mean((ratio_sg - 1.0) - log_ratio_sg, mask),
        clip_fraction=_masked_mean(
            (jnp.abs(ratio_sg - 1.0) > clip_epsilon).astype(jnp.float32), mask
        ),
    )


def value_loss(
    values: ArrayLike,
    returns: ArrayLike,
    old_values: ArrayLike | None = None,
    clip_epsilon: float | None = None,
    mask: ArrayLike | None = None,
) -> jax.Array:
    """The critic loss mean((G_t - V(s_t))^2) of eq. 3.61, ``f32[]``.

    This is the plain squared error; ``ppo_loss`` multiplies it by ``value_weight = 0.5``, which
    gives the 0.5 * (G - V)^2 of Algorithm 4 (V_obj = -A^2 weighted by alpha_v = 0.5).

    Value clipping (PPO2-style) is on only when both ``old_values`` and ``clip_epsilon`` are
    given: the per-sample loss becomes max((G - V)^2, (G - V_clip)^2) with
    V_clip = V_old + clip(V - V_old, -clip_epsilon, clip_epsilon).

    Args:
        values: ``f32[...]`` the critic's current values.
        returns: ``f32[...]`` targets (no gradient flows into them).
        old_values: ``f32[...]`` values at rollout time, for clipping.
        clip_epsilon: clip width, or None for no clipping.
        mask: optional ``bool[...]``.
    """
    values = jnp.asarray(values, jnp.float32)
    returns = jax.lax.stop_gradient(jnp.asarray(returns, jnp.float32))
    squared_error = jnp.square(returns - values)
    if old_values is not None and clip_epsilon is not None:
        old_values = jax.lax.stop_gradient(jnp.asarray(old_values, jnp.float32))
        clipped_values = old_values + jnp.clip(values - old_values, -clip_epsilon, clip_epsilon)
        squared_error = jnp.maximum(squared_error, jnp.square(returns - clipped_values))
    return _masked_mean(squared_error, mask)


def entropy_bonus(entropy: ArrayLike, mask: ArrayLike | None = None) -> jax.Array:
    """Mean policy entropy, ``f32[]``: a bonus, so ``ppo_loss`` SUBTRACTS it (weighted)."""
    return _masked_mean(jnp.asarray(entropy, jnp.float32), mask)


def normalize_advantages(advantages: ArrayLike, mask: ArrayLike | None = None) -> jax.Array:
    """(A - mean) / (std + 1e-8) over the valid entries; masked-out entries come back as 0."""
    advantages = jnp.asarray(advantages, jnp.float32)
    mean = _masked_mean(advantages, mask)
    std = jnp.sqrt(_masked_mean(jnp.square(advantages - mean), mask))
    normalized = (advantages - mean) / (std + 1e-8)
    if mask is None:
        return normalized
    return jnp.where(jnp.broadcast_to(jnp.asarray(mask), normalized.shape), normalized, 0.0)


class PPOLoss(NamedTuple):
    """Output of ``ppo_loss``; all scalars ``f32[]``. ``total`` is what gets differentiated."""

    total: jax.Array
    """policy_weight * policy + value_weight * value - entropy_weight * entropy
    (- teacher_weight * teacher_log_prob with a teacher)."""
    policy: jax.Array
    """The clipped-surrogate loss (``PolicyLoss.loss``)."""
    value: jax.Array
    """The critic's mean squared error (``value_loss``), unweighted."""
    entropy: jax.Array
    """Mean entropy (``entropy_bonus``), unweighted."""
    approx_kl: jax.Array
    clip_fraction: jax.Array
    advantage_mean: jax.Array
    """Mean advantage before normalisation (a sanity signal: near 0 when the critic is right)."""
    teacher_log_prob: jax.Array | None = None
    """With a teacher: mean log pi(teacher's action) over the entries the policy played."""
    teacher_agreement: jax.Array | None = None
    """With a teacher and the parametrised head: the share of those entries whose likeliest
    kind is the teacher's kind."""
    teacher_action_error: jax.Array | None = None
    """With a teacher and the Gaussian head: mean |tanh(mean) - teacher's action| there."""


def ppo_loss(
    log_prob_new: ArrayLike,
    log_prob_old: ArrayLike,
    values: ArrayLike,
    returns: ArrayLike,
    entropy: ArrayLike,
    *,
    advantages: ArrayLike | None = None,
    old_values: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    policy_mask: ArrayLike | None = None,
    hyperparams: PPOHyperparams | None = None,
    teacher_log_prob: ArrayLike | None = None,
    teacher_weight: ArrayLike = 0.0, teacher_mask: ArrayLike | None = None,
) -> PPOLoss:
    """The PPO loss of eq. 3.59 / Algorithm 4 line 21 (negated into a minimisation).

    Args:
        log_prob_new, log_prob_old: ``f32[...]`` log-probabilities of the taken actions, under the
            params being optimised and at rollout time.
        values: ``f32[...]`` the critic's current values V_phi(s_t).
        returns: ``f32[...]`` targets G_t (Monte Carlo returns, or the GAE lambda-returns).
        entropy: ``f32[...]`` policy entropies.
        advantages: ``f32[...]``, or None to use A = G - V with the CURRENT critic (stopped
            gradient), as Algorithm 4 lines 15-17 recompute it inside every epoch. Pass the GAE
            advantages here when using GAE.
        old_values: ``f32[...]`` rollout-time values, needed only for value clipping.
        mask: optional ``bool[...]``; only True entries count (in every term and statistic).
        policy_mask: optional ``bool[...]``, True where the policy's own action was played;
            where a scripted routine played instead (a game's ``scripted_players``), the entry
            counts in the value loss only, not in the policy, entropy or advantage terms.
        hyperparams: weights, clip and switches; ``PPOHyperparams()`` when None.
        teacher_log_prob: optional ``f32[...]`` log pi(teacher's action) (``teacher_terms``): its
            mean where the policy played and ``teacher_mask`` holds, times ``teacher_weight``
            (``f32[]``, may be traced), is subtracted.

    Advantage normalisation (``hyperparams.normalize_advantages``) happens here, so it is per
    minibatch: call this inside the minibatch loss.
    """
    hp = PPOHyperparams() if hyperparams is None else hyperparams
    values = jnp.asarray(values, jnp.float32)
    returns = jnp.asarray(returns, jnp.float32)
    if advantages is None:
        advantages = returns - jax.lax.stop_gradient(values)
    advantages = jax.lax.stop_gradient(jnp.asarray(advantages, jnp.float32))
    acted = _both(policy_mask, mask)
    advantage_mean = _masked_mean(advantages, acted)
    if hp.normalize_advantages:
        advantages = normalize_advantages(advantages, acted)
    policy = policy_loss(log_prob_new, log_prob_old, advantages, hp.clip_epsilon, acted)
    value = value_loss(
        values,
        returns,
        old_values=old_values if hp.clip_value else None,
        clip_epsilon=hp.value_clip_epsilon if hp.clip_value else None,
        mask=mask,
    )
    entropy_mean = entropy_bonus(entropy, acted)
    total = (
        hp.policy_weight * policy.loss
        + hp.value_weight * value
        - hp.entropy_weight * entropy_mean
    )
    taught = None
    if teacher_log_prob is not None:
        taught = _masked_mean(jnp.asarray(teacher_log_prob), _both(teacher_mask, acted))
        total = total - jnp.asarray(teacher_weight, jnp.float32) * taught
    return PPOLoss(
        total=total,
        policy=policy.loss,
        value=value,
        entropy=entropy_mean,
        approx_kl=policy.approx_kl,
        clip_fraction=policy.clip_fraction,
        advantage_mean=advantage_mean,
        teacher_log_prob=None if taught is None else jax.lax.stop_gradient(taught),
    )


TEACHER_ACTION_LIMIT = 0.99
"""The teacher's continuous action values are clipped to +-0.99 before ``atanh`` (u = +-2.65):
a scripted team plays +-1 often (full speed), whose pre-tanh value is +-inf, and even
``ACTION_EPS``'s +-7.25 would drive the policy's means far into the saturated tanh for an
action that 0.99 already plays almost alike."""


class TeacherTerms(NamedTuple):
    """Output of ``teacher_terms``, each ``f32[...]`` per entry."""

    log_prob: jax.Array
    """log pi(teacher's action), differentiable in the distribution's params."""
    mask: jax.Array | None
    """bool[...] where the teacher's action counts: where the policy played (``played``), and
    not where the parametrised head's teacher points at no slot in the policy's view or plays
    a kind the policy's kind mask rules out
    (probability 0: log pi would be -1e9); None: everywhere."""
    agreement: jax.Array | None
    """Parametrised head: 1 where the policy's likeliest kind is the teacher's."""
    action_error: jax.Array | None
    """Gaussian head: mean |tanh(mean) - teacher's action| over the action values."""


def teacher_terms(
    distribution: Any, action: jax.Array, balance: bool = False, played: ArrayLike | None = None,
    group_balance: bool = False,
) -> TeacherTerms:
    """The policy's ``distribution`` (``TanhGaussian`` or ``ParametrisedDistribution``, leading
    [...]) scored on a teacher's ``action`` f32[..., A], the game's action format (the format of
    the policy's own sampled action), continuous values clipped to ``TEACHER_ACTION_LIMIT``;
    ``played``: bool[...] where the policy's action was played (None: everywhere), the only
    entries that count; ``balance``: the parametrised head's log-probabilities weighted by the
    inverse share of the teacher's kind among the entries that count
    (``PPOHyperparams.teacher_balance``); ``group_balance``: weighted by the inverse share of
    the entry's kind-mask group (``PPOHyperparams.teacher_group_balance``)."""
    from elevens.nets.distributions import ParametrisedDistribution

    action = jax.lax.stop_gradient(jnp.asarray(action, jnp.float32))
    limit = TEACHER_ACTION_LIMIT
    if isinstance(distribution, ParametrisedDistribution):
        clipped = jnp.concatenate(
            [action[..., :2], jnp.clip(action[..., 2:], -limit, limit)], axis=-1
        )
        slots = jnp.arange(distribution.pointer_mask.shape[-1])
        pointer = action[..., 1].astype(jnp.int32)[..., None]
        seen = jnp.any(distribution.pointer_mask & (slots == pointer), axis=-1)
        kinds = distribution.kind_logits.shape[-1]
        kind = jnp.clip(action[..., 0].astype(jnp.int32), 0, kinds - 1)
        # A kind the policy's kind mask rules out here (network.kind_mask) has probability 0.
        allowed = jnp.take_along_axis(distribution.kind_logits, kind[..., None], axis=-1)[
            ..., 0] > MASKED_LOGIT / 2
        mask = _both((seen | ~jnp.any(distribution.pointer_mask, axis=-1)) & allowed, played)
        assert mask is not None
        likeliest = jnp.argmax(jax.lax.stop_gradient(distribution.kind_logits), axis=-1)
        log_prob = distribution.log_prob_of_action(clipped)
        if balance:
            log_prob = log_prob * _kind_balance(kind, mask, kinds)
        if group_balance:
            allowed_kinds = distribution.kind_logits > MASKED_LOGIT / 2
            group = jnp.sum(allowed_kinds * (2 ** jnp.arange(kinds)), axis=-1)
            log_prob = log_prob * _kind_balance(group, mask, 2**kinds)
        return TeacherTerms(
            log_prob=log_prob,
            mask=mask,
            agreement=(likeliest == kind).astype(jnp.float32),
            action_error=None,
        )
    clipped = jnp.clip(action, -limit, limit)
    mode = jax.lax.stop_gradient(distribution.mode())
    return TeacherTerms(
        log_prob=distribution.log_prob_of_action(clipped),
        mask=None if played is None else jnp.asarray(played, bool),
        agreement=None,
        action_error=jnp.mean(jnp.abs(mode - clipped), axis=-1),
    )


def _kind_balance(kind: jax.Array, counts: jax.Array, kinds: int) -> jax.Array:
    """f32[...]: N / (K * N_k) for an entry of kind k, where N entries count (``counts``), N_k of
    them of kind k and K kinds occur: each kind present weighs alike, the mean weight is 1."""
    one_hot = jax.nn.one_hot(kind, kinds) * counts[..., None]
    per_kind = jnp.sum(one_hot.reshape(-1, kinds), axis=0)
    present = jnp.maximum(jnp.sum(per_kind > 0), 1)
    total = jnp.sum(per_kind)
    weight = total / (present * jnp.maximum(per_kind[kind], 1.0))
    return jax.lax.stop_gradient(jnp.where(counts, weight, 0.0))


class UpdateBatch(struct.PyTreeNode):
    """The PPO update's data, grouped by game: leading [G, n, T] per player sequence (G games of
    n learner players), [G, T] per game. A minibatch is a set of whole games, so the critic,
    whose input is the same for the n players of a game, runs once per game."""

    obs: Observation  # leading [G, n, T]
    global_state: GlobalState  # leading [G, T] the learner's critic input
    pre_tanh: jax.Array  # f32[G, n, T, A] the raw samples (``play.NetworkSample``)
    log_prob: jax.Array  # f32[G, n, T] rollout-time log-probabilities
    reset: jax.Array  # bool[G, n, T]
    initial_carry: PolicyCarry  # leaves f32[G, n, lstm_features]
    returns: jax.Array  # f32[G, n, T] critic targets (Monte Carlo returns or GAE lambda-returns)
    advantages: jax.Array | None  # f32[G, n, T] GAE advantages; None: A = G - V in the loss
    old_values: jax.Array | None  # f32[G, n, T] rollout-time values, only for value clipping
    entropy_noise: jax.Array | None = None  # f32[G, n, T, A] only for the squashed entropy
    policy_mask: jax.Array | None = None  # bool[G, n, T] False where a routine played (ppo_loss)
    teacher_action: jax.Array | None = None  # f32[G, n, T, A] the teacher's (ppo.teacher)
    teacher_weight: jax.Array | None = None  # f32[G] w this iteration, the same in every game
    #                                          (a leaf with the game axis, so it is shuffled)


def sequence_loss(
    policy: AttentionPolicy,
    critic: AttentionCritic,
    hp: PPOHyperparams,
    params: Any,
    batch: UpdateBatch,
    visible_fraction: Capacity | None = None,
) -> tuple[jax.Array, PPOLoss]:
    """The PPO loss of a minibatch of g whole games (leading [g, n, T], see ``UpdateBatch``):
    the policy unrolled over each player's sequence from its recorded memory, the critic once
    per game and step. ``params`` has ``.policy`` and ``.critic``; ``visible_fraction``: the
    policy's per-entity layers on the visible slots only (``elevens.nets.capacity``)."""
    n = batch.pre_tanh.shape[1]

    def sequences(tree: Any) -> Any:  # [g, n, ...] -> [g * n, ...], games outermost
        return jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), tree)

    # The g * n sequences unroll together, batch-major: the encoders run as one [g * n * T]
    # batch of rows (2-D matmuls), and only the LSTM is scanned over time.
    unrolled: Any = policy.apply(
        params.policy,
        sequences(batch.initial_carry),
        sequences(batch.obs),
        sequences(batch.reset),
        1,
        visible_fraction,
        method=AttentionPolicy.unroll,
    )
    distribution = unrolled[1].distribution()
    game_values: Any = critic.apply(params.critic, batch.global_state)
    values = jnp.repeat(game_values, n, axis=0)
    terms, taught = None, dict[str, Any]()
    if batch.teacher_action is not None:
        assert batch.teacher_weight is not None
        terms = teacher_terms(
            distribution, sequences(batch.teacher_action), hp.teacher_balance,
            None if batch.policy_mask is None else sequences(batch.policy_mask),
            hp.teacher_group_balance,
        )
        taught = {
            "teacher_log_prob": terms.log_prob,
            "teacher_weight": batch.teacher_weight[0],
            "teacher_mask": terms.mask,
        }
    loss = ppo_loss(
        distribution.log_prob(sequences(batch.pre_tanh)),
        sequences(batch.log_prob),
        values,
        sequences(batch.returns),
        # The thesis' entropy term, the closed-form entropy of the pre-tanh Gaussian (eq.
        # 3.75), or an estimate of the action's own (hp.entropy_estimator).
        distribution.gaussian_entropy()
        if batch.entropy_noise is None
        else distribution.entropy_at(sequences(batch.entropy_noise)),
        advantages=None if batch.advantages is None else sequences(batch.advantages),
        old_values=None if batch.old_values is None else sequences(batch.old_values),
        policy_mask=None if batch.policy_mask is None else sequences(batch.policy_mask),
        hyperparams=hp,
        **taught,
    )
    if terms is None:
        return loss.total, loss
    # The teacher's diagnostics, where its action counts (as in the loss).
    return loss.total, loss._replace(
        teacher_agreement=None if terms.agreement is None
        else _masked_mean(terms.agreement, terms.mask),
        teacher_action_error=None if terms.action_error is None
        else _masked_mean(terms.action_error, terms.mask),
    )


def explained_variance(
    values: ArrayLike, returns: ArrayLike, mask: ArrayLike | None = None
) -> jax.Array:
    """1 - Var(G - V) / Var(G) over all (valid) entries, ``f32[]``.

    1 is a perfect critic, 0 one no better than a constant, negative one worse than that. Where
    the returns have no variance there is nothing to explain and the result is 0 (not NaN), so
    logs stay finite.
    """
    values = jnp.asarray(values, jnp.float32)
    returns = jnp.asarray(returns, jnp.float32)

    def variance(x: jax.Array) -> jax.Array:
        return _masked_mean(jnp.square(x - _masked_mean(x, mask)), mask)

    var_returns = variance(returns)
    var_error = variance(returns - values)
    safe = jnp.where(var_returns > 0, var_returns, 1.0)
    return jnp.where(var_returns > 0, 1.0 - var_error / safe, 0.0)


# --------------------------------------------------------------------------------------------
# The update: epochs of shuffled minibatches
# --------------------------------------------------------------------------------------------


def _check_minibatches(num_items: int, num_minibatches: int) -> None:
    if not isinstance(num_minibatches, int) or num_minibatches < 1:
        raise ValueError(f"num_minibatches={num_minibatches!r} is invalid: it must be an int >= 1")
    if num_items % num_minibatches != 0:
        raise ValueError(
            f"num_minibatches={num_minibatches} does not divide the batch of "
            f"{num_items} units (leading axis); choose a divisor of {num_items}"
        )


def minibatch_indices(key: jax.Array, num_items: int, num_minibatches: int) -> jax.Array:
    """A random partition of ``range(num_items)`` into equal minibatches.

    Returns ``i32[num_minibatches, num_items // num_minibatches]``; every index appears exactly
    once. Raises ``ValueError`` (before tracing) if ``num_minibatches`` does not divide
    ``num_items``.
    """
    _check_minibatches(num_items, num_minibatches)
    permutation = jax.random.permutation(key, num_items)
    return permutation.reshape(num_minibatches, num_items // num_minibatches)


def _batch_size(batch: PyTree) -> int:
    leaves = jax.tree_util.tree_leaves(batch)
    if not leaves:
        raise ValueError("the batch is empty: it has no array leaves")
    sizes = {int(jnp.shape(leaf)[0]) if jnp.ndim(leaf) > 0 else -1 for leaf in leaves}
    if len(sizes) != 1 or -1 in sizes:
        raise ValueError(
            "every leaf of the batch needs the same leading (unit) axis; found sizes "
            f"{sorted(sizes)} (-1 is a scalar leaf)"
        )
    return sizes.pop()


def shuffle_minibatches(key: jax.Array, batch: PyTree, num_minibatches: int) -> PyTree:
    """Split ``batch`` (leading axis = units) into shuffled minibatches.

    Every leaf ``[N, ...]`` becomes ``[num_minibatches, N // num_minibatches, ...]``. Only the
    leading axis is permuted, so whatever follows it (a sequence's time axis, its players) stays
    intact inside each unit.
    """
    indices = minibatch_indices(key, _batch_size(batch), num_minibatches)
    return jax.tree_util.tree_map(lambda leaf: jnp.take(leaf, indices, axis=0), batch)


def _global_norm(tree: PyTree) -> jax.Array:
    """sqrt of the sum of squares of every leaf (optax renamed its helper across versions)."""
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.sqrt(sum((jnp.sum(jnp.square(leaf)) for leaf in leaves), jnp.zeros(())))


class UpdateResult(NamedTuple):
    """Output of ``update_epochs``."""

    params: PyTree
    opt_state: optax.OptState
    loss: jax.Array
    """``f32[]`` mean of the loss over all epochs and minibatches (before each step)."""
    grad_norm: jax.Array
    """``f32[]`` mean global gradient norm."""
    metrics: Metrics
    """The loss function's metrics pytree, averaged over all epochs and minibatches."""


class _TrainCarry(NamedTuple):
    params: PyTree
    opt_state: optax.OptState


class _StepStats(NamedTuple):
    loss: jax.Array
    grad_norm: jax.Array
    metrics: Metrics


def update_epochs(
    loss_fn: Callable[[PyTree, PyTree], tuple[jax.Array, Metrics]],
    optimizer: optax.GradientTransformation,
    params: PyTree,
    opt_state: optax.OptState,
    batch: PyTree,
    shuffle_key: jax.Array,
    *,
    epochs: int,
    num_minibatches: int,
    value_and_grad_fn: Callable[[PyTree, PyTree], tuple[tuple[jax.Array, Metrics], PyTree]]
    | None = None,
    constrain_minibatches: Callable[[PyTree], PyTree] = lambda tree: tree,
) -> UpdateResult:
    """Run ``epochs`` passes over ``batch`` in shuffled minibatches (nested ``lax.scan``).

    Args:
        loss_fn: ``loss_fn(params, minibatch) -> (loss f32[], metrics pytree)``; differentiated
            with respect to ``params``.
        optimizer: an optax transformation (Adam, lr 1e-4 in the thesis) and ``opt_state`` its
            state for ``params``.
        batch: a pytree whose every leaf has the same leading axis of N sampling units. For the
            recurrent policy a unit is a whole game-team-player sequence ``[N, T, ...]`` (with its
            initial LSTM carry as another leaf), so the time axis stays intact in a minibatch.
        shuffle_key: one key; each epoch draws its own permutation from it.
        epochs: number of passes (5 in the thesis), static.
        num_minibatches: minibatches per epoch (11 in the thesis), static; must divide N.
        value_and_grad_fn: ``jax.value_and_grad(loss_fn, has_aux=True)`` computed another way,
            or None for exactly that (the trainer picks a cheaper policy pass per minibatch).
        constrain_minibatches: applied to an epoch's ``[num_minibatches, N / num_minibatches,
            ...]`` minibatches (the trainer splits each minibatch's units over its devices).

    Raises ``ValueError`` before tracing if ``num_minibatches`` does not divide N, or the leaves
    disagree on N. Jit this whole function with ``loss_fn``/``optimizer``/``epochs``/
    ``num_minibatches`` static (or close over them), as the trainer does.
    """
    if not isinstance(epochs, int) or epochs < 1:
        raise ValueError(f"epochs={epochs!r} is invalid: it must be an int >= 1")
    num_items = _batch_size(batch)
    _check_minibatches(num_items, num_minibatches)
    grad_fn = value_and_grad_fn or jax.value_and_grad(loss_fn, has_aux=True)

    def minibatch_step(carry: _TrainCarry, minibatch: PyTree) -> tuple[_TrainCarry, _StepStats]:
        (loss, metrics), grads = grad_fn(carry.params, minibatch)
        updates, opt_state = optimizer.update(grads, carry.opt_state, carry.params)
        params = optax.apply_updates(carry.params, updates)
        stats = _StepStats(loss=loss, grad_norm=_global_norm(grads), metrics=metrics)
        return _TrainCarry(params=params, opt_state=opt_state), stats

    def epoch_step(carry: _TrainCarry, epoch_key: jax.Array) -> tuple[_TrainCarry, _StepStats]:
        minibatches = constrain_minibatches(shuffle_minibatches(epoch_key, batch, num_minibatches))
        return jax.lax.scan(minibatch_step, carry, minibatches)

    epoch_keys = jax.random.split(shuffle_key, epochs)
    carry, stats = jax.lax.scan(
        epoch_step, _TrainCarry(params=params, opt_state=opt_state), epoch_keys
    )
    mean_stats = jax.tree_util.tree_map(lambda x: jnp.mean(x, axis=(0, 1)), stats)
    return UpdateResult(
        params=carry.params,
        opt_state=carry.opt_state,
        loss=mean_stats.loss,
        grad_norm=mean_stats.grad_norm,
        metrics=mean_stats.metrics,
    )
