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
