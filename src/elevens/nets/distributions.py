"""The tanh-squashed diagonal Gaussian of the policy (thesis section 3.3.6).

An action is ``a = tanh(u)`` with ``u ~ N(mean, diag(exp(log_std))^2)``, element-wise, so every
action lies in (-1, 1). Its log-density follows from the change of variables (thesis eq. 3.73):

    log pi(a) = log N(u; mean, std) - sum_i log(1 - tanh(u_i)^2),

where ``log(1 - tanh(u)^2) = 2 * (log 2 - u - softplus(-2u))`` is used because the left-hand form
rounds to log(0) in float32 once ``|u| > 9``.

Store the pre-tanh sample ``u`` beside the action when you need its log-probability later (PPO):
``log_prob(u)`` is exact for every ``u``, while ``log_prob_of_action(a)`` has to invert tanh, which
is ill-conditioned near +-1 (a float32 tanh rounds to exactly 1 for ``u > 9.01``). It clips actions
to ``[-1 + ACTION_EPS, 1 - ACTION_EPS]`` first, so an action on the boundary gets the finite
log-density of ``u = +-atanh(1 - ACTION_EPS) = +-7.25``.

The entropy of ``a`` has no closed form (the thesis used the Gaussian's instead, eq. 3.75).
``entropy_estimate`` estimates it without bias from the identity

    H[a] = H[u] + E_u[ sum_i log(1 - tanh(u_i)^2) ],

with the expectation averaged over reparameterised samples ``u = mean + std * eps``, so the
estimate is differentiable in ``mean`` and ``log_std``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

LOG_STD_MIN = -5.0
"""std >= exp(-5) = 0.0067: narrower gives log-densities in the hundreds and unstable PPO ratios."""
LOG_STD_MAX = 2.0
"""std <= exp(2) = 7.4: beyond that almost every sample sits at +-1 after the tanh."""
ACTION_EPS = 1e-6
"""Actions are clipped to 1 - ACTION_EPS before atanh; 1 - 1e-6 is still exact in float32."""

_LOG_2 = math.log(2.0)
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def clamp_log_std(log_std: jax.Array) -> jax.Array:
    """Clip log_std to [LOG_STD_MIN, LOG_STD_MAX] (a hard clip: zero gradient outside)."""
    return jnp.clip(log_std, LOG_STD_MIN, LOG_STD_MAX)


def log_tanh_jacobian(pre_tanh: jax.Array) -> jax.Array:
    """``log(1 - tanh(u)^2)`` element-wise, stable for any ``u`` (no log(0) in float32)."""
    return 2.0 * (_LOG_2 - pre_tanh - jax.nn.softplus(-2.0 * pre_tanh))


class TanhSample(NamedTuple):
    """A sampled action with the Gaussian sample it came from."""

    action: jax.Array  # f32[..., d] tanh(pre_tanh), in (-1, 1) (float32 may round it to +-1)
    pre_tanh: jax.Array  # f32[..., d] the Gaussian sample u


@struct.dataclass
class TanhGaussian:
    """A diagonal Gaussian squashed by tanh. Build it with ``TanhGaussian.create``.

    The last axis holds the action dimensions (2 here: move, rot); leading axes are a batch.
    """

    mean: jax.Array  # f32[..., d] mean of the pre-tanh Gaussian
    log_std: jax.Array  # f32[..., d] in [LOG_STD_MIN, LOG_STD_MAX]

    @classmethod
    def create(cls, mean: jax.Array, log_std: jax.Array) -> TanhGaussian:
        """mean, log_std: f32[..., d]. log_std is clamped with ``clamp_log_std``."""
        return cls(mean=mean, log_std=clamp_log_std(log_std))

    def sample(self, key: jax.Array) -> TanhSample:
        """A reparameterised sample: ``u = mean + std * eps``, ``action = tanh(u)``."""
        noise = jax.random.normal(key, self.mean.shape, self.mean.dtype)
        pre_tanh = self.mean + jnp.exp(self.log_std) * noise
        return TanhSample(action=jnp.tanh(pre_tanh), pre_tanh=pre_tanh)

    def gaussian_log_prob(self, pre_tanh: jax.Array) -> jax.Array:
        """f32[...]: log-density of the pre-tanh Gaussian at ``u`` f32[..., d], summed over d."""
        z = (pre_tanh - self.mean) * jnp.exp(-self.log_std)
        return jnp.sum(-0.5 * z * z - self.log_std - _HALF_LOG_2PI, axis=-1)

    def log_prob(self, pre_tanh: jax.Array) -> jax.Array:
        """f32[...]: log-density of the action ``tanh(u)``, given u f32[..., d]."""
        return self.gaussian_log_prob(pre_tanh) - jnp.sum(log_tanh_jacobian(pre_tanh), axis=-1)

    def log_prob_of_action(self, action: jax.Array) -> jax.Array:
        """f32[...]: log-density of an action f32[..., d] in [-1, 1].

        Actions are clipped to ``1 - ACTION_EPS`` in magnitude before ``atanh`` (see the module
        docstring); prefer ``log_prob(pre_tanh)`` when the pre-tanh value is at hand.
        """
        clipped = jnp.clip(action, -1.0 + ACTION_EPS, 1.0 - ACTION_EPS)
        return self.log_prob(jnp.arctanh(clipped))

    def gaussian_entropy(self) -> jax.Array:
        """f32[...]: the closed-form entropy of the pre-tanh Gaussian (the thesis's eq. 3.75).

        It is an upper bound of the true entropy, since the tanh contracts volume.
        """
        return jnp.sum(self.log_std + 0.5 + _HALF_LOG_2PI, axis=-1)

    def entropy_estimate(self, key: jax.Array, num_samples: int = 1) -> jax.Array:
        """f32[...]: an unbiased, differentiable Monte Carlo estimate of the action entropy.

        ``H[u] + mean over num_samples reparameterised u of sum_i log(1 - tanh(u_i)^2)``. The
        standard error falls as ``1 / sqrt(num_samples)``; one sample per state is usually enough
        inside a PPO minibatch, where the loss averages over many states anyway.
        """
        noise = jax.random.normal(key, (num_samples, *self.mean.shape), self.mean.dtype)
        return jnp.mean(self.entropy_at(noise), axis=0)

    def entropy_at(self, noise: jax.Array) -> jax.Array:
        """f32[..., ...]: the one-sample entropy estimate at given standard normal ``noise``
        f32[..., d] (leading axes broadcast against the distribution's): ``H[u] + sum_i
        log(1 - tanh(u_i)^2)`` with ``u = mean + std * noise``. Never above
        ``gaussian_entropy``; its gradient lowers ``log_std`` once the tanh saturates, where the
        Gaussian's keeps raising it."""
        pre_tanh = self.mean + jnp.exp(self.log_std) * noise
        return self.gaussian_entropy() + jnp.sum(log_tanh_jacobian(pre_tanh), axis=-1)

    def mode(self) -> jax.Array:
        """f32[..., d]: ``tanh(mean)``, the deterministic action (the median of each component;
        the true mode of a squashed Gaussian can sit elsewhere, but this is the usual choice)."""
        return jnp.tanh(self.mean)


MASKED_LOGIT = -1e9
"""The logit of a pointer slot out of view: exp(-1e9 - max) is exactly 0 in float32, and unlike
-inf it keeps ``p * log p`` and every gradient finite."""


def _take(x: jax.Array, index: jax.Array) -> jax.Array:
    """x f32[..., m, *rest] at index i32[...] along the axis after the batch axes. A one-hot
    sum, not a gather: its gradient is then no scatter (serial on XLA's CPU backend)."""
    lead = index.ndim
    size = x.shape[lead]
    one_hot = jax.nn.one_hot(index, size, dtype=x.dtype)
    return jnp.sum(x * one_hot.reshape(*one_hot.shape, *([1] * (x.ndim - lead - 1))), axis=lead)


def _categorical_entropy(log_p: jax.Array, mask: jax.Array | None = None) -> jax.Array:
    """f32[...]: the entropy of a categorical from its log-probabilities f32[..., m]; masked
    entries (probability 0) contribute 0."""
    terms = jnp.exp(log_p) * log_p
    if mask is not None:
        terms = jnp.where(mask, terms, 0.0)
    return -jnp.sum(terms, axis=-1)


@struct.dataclass
class ParametrisedDistribution:
    """A parametrised action: a discrete kind, then, given the kind, a pointer at one entity
    slot and a continuous target in [-1, 1]^2. Build it with ``ParametrisedDistribution.create``.

    The action is f32[..., 4] = (kind, pointer, x, y): kind in ``0..K-1``, pointer in
    ``0..P-1`` (integers stored as floats, exact below 2^24) and ``(x, y) = tanh(u)``. The raw
    sample (``TanhSample.pre_tanh``) is (kind, pointer, u_x, u_y), from which ``log_prob`` is
    exact, as for ``TanhGaussian``. The pointer and the target are conditioned on the kind: the
    network gives their parameters for every kind (``[..., K, ...]``) and the sampled kind picks
    its row, so

        log pi(a) = log pi(kind) + log pi(pointer | kind) + log pi(tanh(u) | kind).

    The pointer's slots out of view have probability 0. Where no slot is in view the pointer
    carries no information: its log-probability and entropy are 0 (any pointer value).
    """

    kind_logits: jax.Array  # f32[..., K]
    pointer_logits: jax.Array  # f32[..., K, P] MASKED_LOGIT where pointer_mask is False
    pointer_mask: jax.Array  # bool[..., P] the slots the pointer may name
    target: TanhGaussian  # mean, log_std f32[..., K, 2]: the target of each kind

    @classmethod
    def create(
        cls,
        kind_logits: jax.Array,
        pointer_logits: jax.Array,
        pointer_mask: jax.Array,
        target_mean: jax.Array,
        target_log_std: jax.Array,
    ) -> ParametrisedDistribution:
        """kind_logits f32[..., K], pointer_logits f32[..., K, P], pointer_mask bool[..., P],
        target_mean and target_log_std f32[..., K, 2]; masked pointer logits are replaced."""
        masked = jnp.where(pointer_mask[..., None, :], pointer_logits, MASKED_LOGIT)
        return cls(
            kind_logits=kind_logits,
            pointer_logits=masked,
            pointer_mask=pointer_mask,
            target=TanhGaussian.create(target_mean, target_log_std),
        )

    def _kind_log_p(self) -> jax.Array:
        return jax.nn.log_softmax(self.kind_logits, axis=-1)

    def _pointer_log_p(self) -> jax.Array:
        return jax.nn.log_softmax(self.pointer_logits, axis=-1)

    def _any_in_view(self) -> jax.Array:
        return jnp.any(self.pointer_mask, axis=-1)

    def _given(self, kind: jax.Array) -> tuple[jax.Array, TanhGaussian]:
        """The pointer's log-probabilities f32[..., P] and the target of ``kind`` i32[...]."""
        target = TanhGaussian(
            mean=_take(self.target.mean, kind), log_std=_take(self.target.log_std, kind)
        )
        return _take(self._pointer_log_p(), kind), target

    def sample(self, key: jax.Array) -> TanhSample:
        """The kind, then its pointer and its target (one reparameterised Gaussian sample)."""
        kind_key, pointer_key, target_key = jax.random.split(key, 3)
        kind = jax.random.categorical(kind_key, self.kind_logits, axis=-1)
        pointer_log_p, target = self._given(kind)
        pointer = jax.random.categorical(pointer_key, pointer_log_p, axis=-1)
        u = target.sample(target_key).pre_tanh
        discrete = jnp.stack([kind, pointer], axis=-1).astype(u.dtype)
        return TanhSample(
            action=jnp.concatenate([discrete, jnp.tanh(u)], axis=-1),
            pre_tanh=jnp.concatenate([discrete, u], axis=-1),
        )

    def _split(self, values: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        kind = jnp.clip(values[..., 0].astype(jnp.int32), 0, self.kind_logits.shape[-1] - 1)
        pointer = jnp.clip(values[..., 1].astype(jnp.int32), 0, self.pointer_mask.shape[-1] - 1)
        return kind, pointer, values[..., 2:]

    def _discrete_log_prob(
        self, kind: jax.Array, pointer: jax.Array
    ) -> tuple[jax.Array, TanhGaussian]:
        pointer_log_p, target = self._given(kind)
        pointer_term = jnp.where(self._any_in_view(), _take(pointer_log_p, pointer), 0.0)
        return _take(self._kind_log_p(), kind) + pointer_term, target

    def log_prob(self, pre_tanh: jax.Array) -> jax.Array:
        """f32[...]: log-probability of the action, given the raw sample f32[..., 4]
        (kind, pointer, u_x, u_y)."""
        kind, pointer, u = self._split(pre_tanh)
        discrete, target = self._discrete_log_prob(kind, pointer)
        return discrete + target.log_prob(u)

    def log_prob_of_action(self, action: jax.Array) -> jax.Array:
        """f32[...]: log-probability of an action f32[..., 4] (kind, pointer, x, y), x and y in
        [-1, 1] (see ``TanhGaussian.log_prob_of_action``)."""
        kind, pointer, xy = self._split(action)
        discrete, target = self._discrete_log_prob(kind, pointer)
        return discrete + target.log_prob_of_action(xy)

    def _expected_over_kinds(self, per_kind: jax.Array) -> jax.Array:
        """H[kind] + E_kind[per_kind]: per_kind f32[..., K] holds each kind's pointer and
        target entropies."""
        log_p = self._kind_log_p()
        return _categorical_entropy(log_p) + jnp.sum(jnp.exp(log_p) * per_kind, axis=-1)

    def _pointer_entropy(self) -> jax.Array:
        """f32[..., K]: each kind's pointer entropy (0 where no slot is in view)."""
        mask = self.pointer_mask[..., None, :]
        return _categorical_entropy(self._pointer_log_p(), mask)

    def gaussian_entropy(self) -> jax.Array:
        """f32[...]: the entropy of (kind, pointer, u), in closed form: the kind's, plus the
        expectation over kinds of the pointer's and the pre-tanh Gaussian's (as
        ``TanhGaussian.gaussian_entropy``, an upper bound of the target's own)."""
        return self._expected_over_kinds(self._pointer_entropy() + self.target.gaussian_entropy())

    def entropy_at(self, noise: jax.Array) -> jax.Array:
        """f32[...]: the entropy with the target's one-sample estimate at standard normal
        ``noise`` f32[..., 4] (its last two columns are used; the discrete parts are exact):
        see ``TanhGaussian.entropy_at``."""
        target = self.target.entropy_at(noise[..., None, 2:])
        return self._expected_over_kinds(self._pointer_entropy() + target)

    def mode(self) -> jax.Array:
        """f32[..., 4]: the likeliest kind, its likeliest slot in view (slot 0 where none is)
        and ``tanh(mean)`` of its target."""
        kind = jnp.argmax(self.kind_logits, axis=-1)
        pointer_log_p, target = self._given(kind)
        pointer = jnp.argmax(pointer_log_p, axis=-1)
        xy = target.mode()
        discrete = jnp.stack([kind, pointer], axis=-1).astype(xy.dtype)
        return jnp.concatenate([discrete, xy], axis=-1)
