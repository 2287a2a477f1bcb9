"""The tanh-squashed Gaussian: densities against an independent change of variables, the
boundary, sampling, and the Monte Carlo entropy against a quadrature reference."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.scipy.stats import norm

from elevens.nets.distributions import (
    ACTION_EPS,
    LOG_STD_MAX,
    LOG_STD_MIN,
    TanhGaussian,
    log_tanh_jacobian,
)


def _random_distribution(key: jax.Array, shape: tuple[int, ...]) -> TanhGaussian:
    mean_key, std_key = jax.random.split(key)
    mean = jax.random.normal(mean_key, (*shape, 2)) * 1.5
    log_std = jax.random.uniform(std_key, (*shape, 2), minval=-2.0, maxval=1.0)
    return TanhGaussian.create(mean, log_std)


def test_log_prob_matches_gaussian_density_over_jacobian() -> None:
    """log pi(tanh u) = log N(u) - log |det d tanh / du|, with the Jacobian from jax.jacfwd."""
    dist = _random_distribution(jax.random.key(0), (50,))
    pre_tanh = dist.mean + jnp.exp(dist.log_std) * jax.random.normal(jax.random.key(1), (50, 2))
    # The reference runs in float64: in float32, 1 - tanh(u)^2 itself loses digits for |u| > 3.
    with jax.enable_x64(True):
        u, mean = np.asarray(pre_tanh, np.float64), np.asarray(dist.mean, np.float64)
        std = np.exp(np.asarray(dist.log_std, np.float64))
        gaussian = jnp.sum(norm.logpdf(u, mean, std), axis=-1)
        jacobians = jax.vmap(jax.jacfwd(jnp.tanh))(jnp.asarray(u))  # [50, 2, 2], diagonal
        expected = np.asarray(gaussian - jnp.log(jnp.abs(jnp.linalg.det(jacobians))))
    np.testing.assert_allclose(dist.log_prob(pre_tanh), expected, rtol=1e-5, atol=1e-4)


def test_density_matches_finite_difference_of_the_cdf() -> None:
    """In 1-D, P(tanh U <= a) = Phi((atanh a - mu) / sigma); its derivative is the density."""
    mu, sigma = 0.4, 0.8
    dist = TanhGaussian.create(jnp.array([mu, 0.0]), jnp.log(jnp.array([sigma, 1.0])))

    def cdf(a: float) -> float:
        return 0.5 * (1.0 + math.erf((math.atanh(a) - mu) / (sigma * math.sqrt(2.0))))

    h = 1e-5
    for a in (-0.95, -0.5, 0.0, 0.3, 0.7, 0.99):
        numeric = (cdf(a + h) - cdf(a - h)) / (2 * h)
        # Second component: tanh of a standard normal at 0, density N(0) / 1 = 1/sqrt(2 pi).
        joint = dist.log_prob_of_action(jnp.array([a, 0.0]))
        analytic = float(jnp.exp(joint)) * math.sqrt(2 * math.pi)
        assert analytic == pytest.approx(numeric, rel=1e-3)


def test_log_jacobian_is_stable_for_large_pre_tanh() -> None:
    u = jnp.array([0.0, 1.0, -3.0, 9.5, -20.0, 50.0])
    # Reference: 1 - tanh(u)^2 = 1 / cosh(u)^2, and log cosh |u| = |u| + log1p(exp(-2|u|)) - log 2
    # in float64. (The naive float32 log(1 - tanh(u)^2) is -inf from |u| > 9.)
    magnitude = np.abs(np.asarray(u, np.float64))
    expected = -2 * (magnitude + np.log1p(np.exp(-2 * magnitude)) - np.log(2))
    got = log_tanh_jacobian(u)
    assert bool(jnp.all(jnp.isfinite(got)))
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)


def test_log_prob_of_pre_tanh_equals_log_prob_of_action_away_from_the_boundary() -> None:
    dist = _random_distribution(jax.random.key(2), (200,))
    sample = dist.sample(jax.random.key(3))
    inside = jnp.all(jnp.abs(sample.pre_tanh) < 3.0, axis=-1)
    from_pre = dist.log_prob(sample.pre_tanh)
    from_action = dist.log_prob_of_action(sample.action)
    assert int(inside.sum()) > 100
    np.testing.assert_allclose(from_action[inside], from_pre[inside], rtol=1e-3, atol=2e-3)


def test_actions_on_the_boundary_get_a_finite_log_prob() -> None:
    dist = TanhGaussian.create(jnp.zeros(2), jnp.zeros(2))
    on_boundary = dist.log_prob_of_action(jnp.array([1.0, -1.0]))
    clipped = dist.log_prob(jnp.full(2, math.atanh(1 - ACTION_EPS)) * jnp.array([1.0, -1.0]))
    assert bool(jnp.isfinite(on_boundary))
    # atanh(1 - 1e-6) in float32 is about 7.25; compare with the same value through log_prob.
    assert float(on_boundary) == pytest.approx(float(clipped), rel=1e-2)


def test_sample_is_reparameterised_and_bounded() -> None:
    dist = TanhGaussian.create(jnp.array([0.5, -1.0]), jnp.array([-1.0, 0.5]))
    batch = jax.tree.map(lambda x: jnp.broadcast_to(x, (20_000, 2)), dist)
    sample = batch.sample(jax.random.key(4))
    assert bool(jnp.all(jnp.abs(sample.action) < 1.0))
    np.testing.assert_allclose(sample.action, jnp.tanh(sample.pre_tanh))
    np.testing.assert_allclose(sample.pre_tanh.mean(0), dist.mean, atol=0.05)
    np.testing.assert_allclose(sample.pre_tanh.std(0), jnp.exp(dist.log_std), rtol=0.05)
    # The sample is differentiable in the distribution's parameters (reparameterisation).
    grad = jax.grad(
        lambda m: TanhGaussian.create(m, dist.log_std).sample(jax.random.key(4)).action.sum()
    )(dist.mean)
    assert bool(jnp.all(grad > 0))


def test_log_std_is_clamped_and_mode_is_tanh_of_mean() -> None:
    dist = TanhGaussian.create(jnp.array([0.3, -2.0]), jnp.array([10.0, -10.0]))
    np.testing.assert_allclose(dist.log_std, [LOG_STD_MAX, LOG_STD_MIN])
    np.testing.assert_allclose(dist.mode(), jnp.tanh(jnp.array([0.3, -2.0])))


def _reference_entropy(mean: np.ndarray, log_std: np.ndarray) -> float:
    """H[tanh U] by Gauss-Hermite quadrature in float64: sum_i H[U_i] + E log(1 - tanh(U_i)^2)."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(200)
    weights = weights / math.sqrt(2 * math.pi)
    total = 0.0
    for mu, log_sigma in zip(mean, log_std, strict=True):
        u = mu + math.exp(log_sigma) * nodes
        log_jacobian = 2 * (math.log(2) - u - np.logaddexp(0.0, -2 * u))
        total += (
            log_sigma + 0.5 + 0.5 * math.log(2 * math.pi) + float(np.sum(weights * log_jacobian))
        )
    return total


@pytest.mark.parametrize(
    ("mean", "log_std"), [((0.0, 0.0), (0.0, 0.0)), ((1.5, -0.5), (-1.0, 1.0))]
)
def test_entropy_estimate_converges_to_the_quadrature_reference(
    mean: tuple[float, float], log_std: tuple[float, float]
) -> None:
    dist = TanhGaussian.create(jnp.array(mean), jnp.array(log_std))
    reference = _reference_entropy(np.array(mean), np.array(log_std))
    # The closed-form Gaussian entropy the thesis used is an upper bound, and not a tight one.
    assert float(dist.gaussian_entropy()) > reference + 0.1

    def estimates(key: jax.Array, repeats: int, num_samples: int) -> jax.Array:
        """f32[repeats]: independent estimates, from one batched call (no vmap to compile)."""
        batch = jax.tree.map(lambda x: jnp.broadcast_to(x, (repeats, 2)), dist)
        return batch.entropy_estimate(key, num_samples)

    errors = {
        num_samples: float(
            jnp.mean(jnp.abs(estimates(jax.random.key(5), 32, num_samples) - reference))
        )
        for num_samples in (1, 100, 10_000)
    }
    # The error falls like 1 / sqrt(samples): by about 10x per 100x more samples.
    assert errors[10_000] < errors[100] / 4 < errors[1] / 16
    assert errors[10_000] < 0.05
    # Unbiased: the mean of many one-sample estimates is the entropy, within 4 standard errors.
    one_sample = estimates(jax.random.key(6), 100_000, 1)
    standard_error = float(one_sample.std()) / math.sqrt(one_sample.size)
    assert abs(float(one_sample.mean()) - reference) < 4 * standard_error


def test_entropy_estimate_is_differentiable() -> None:
    def entropy(log_std: jax.Array) -> jax.Array:
        return TanhGaussian.create(jnp.zeros(2), log_std).entropy_estimate(jax.random.key(7), 64)

    grad = jax.grad(entropy)(jnp.full(2, -2.0))
    # A narrow Gaussian is barely squashed: widening it raises the entropy almost one for one.
    assert bool(jnp.all(jnp.isfinite(grad)))
    np.testing.assert_allclose(grad, 1.0, atol=0.1)


def test_squashed_entropy_stops_rewarding_a_wider_gaussian_once_the_tanh_saturates() -> None:
    noise = jax.random.normal(jax.random.key(8), (4096, 2))

    def mean_entropy(log_std: jax.Array, which: str) -> jax.Array:
        dist = TanhGaussian.create(jnp.array([0.0, 1.0]), log_std)
        if which == "gaussian":
            return jnp.sum(dist.gaussian_entropy())
        return jnp.mean(dist.entropy_at(noise))

    for log_std in (-2.0, 0.0, 1.5):
        dist = TanhGaussian.create(jnp.array([0.0, 1.0]), jnp.full(2, log_std))
        assert bool(jnp.all(dist.entropy_at(noise) <= dist.gaussian_entropy()))
        gaussian = jax.grad(mean_entropy)(jnp.full(2, log_std), "gaussian")
        np.testing.assert_allclose(gaussian, 1.0)  # always: the bonus widens without limit
    narrow = jax.grad(mean_entropy)(jnp.full(2, -2.0), "squashed")
    wide = jax.grad(mean_entropy)(jnp.full(2, 1.5), "squashed")
    assert bool(jnp.all(narrow > 0.8)) and bool(jnp.all(wide < 0.0))
