"""PPO numbers checked by hand: returns, advantages, every loss term, and the epoch loop."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from elevens.train.ppo import (
    PPOHyperparams,
    entropy_bonus,
    explained_variance,
    gae,
    minibatch_indices,
    monte_carlo_returns,
    normalize_advantages,
    policy_loss,
    ppo_loss,
    shuffle_minibatches,
    update_epochs,
    value_loss,
)

# ------------------------------------------------------------------------------------------
# Plain Python references (one scalar stream at a time, no vectorisation to get wrong)
# ------------------------------------------------------------------------------------------


def mc_reference(rewards, dones, gamma, bootstrap):
    rewards = np.asarray(rewards, np.float64)
    flat_r = rewards.reshape(rewards.shape[0], -1)
    flat_d = np.asarray(dones).reshape(rewards.shape[0], -1)
    flat_b = np.broadcast_to(bootstrap, rewards.shape[1:]).reshape(-1)
    out = np.zeros_like(flat_r)
    for j in range(flat_r.shape[1]):
        following = flat_b[j]
        for t in reversed(range(flat_r.shape[0])):
            if flat_d[t, j]:
                following = 0.0
            out[t, j] = flat_r[t, j] + gamma * following
            following = out[t, j]
    return out.reshape(rewards.shape)


def gae_reference(rewards, values, dones, truncs, last_value, gamma, lam, trunc_values):
    length = rewards.shape[0]
    flat = [np.asarray(a, np.float64).reshape(length, -1) for a in (rewards, values)]
    r, v = flat
    d = np.asarray(dones).reshape(length, -1)
    tr = np.asarray(truncs).reshape(length, -1)
    tv = None if trunc_values is None else np.asarray(trunc_values).reshape(length, -1)
    lv = np.broadcast_to(last_value, rewards.shape[1:]).reshape(-1)
    adv = np.zeros_like(r)
    for j in range(r.shape[1]):
        following = 0.0
        for t in reversed(range(length)):
            if tr[t, j]:
                next_value = 0.0 if tv is None else tv[t, j]
                carry = 0.0
            elif d[t, j]:
                next_value, carry = 0.0, 0.0
            else:
                next_value = v[t + 1, j] if t + 1 < length else lv[j]
                carry = following
            delta = r[t, j] + gamma * next_value - v[t, j]
            adv[t, j] = delta + gamma * lam * carry
            following = adv[t, j]
    adv = adv.reshape(rewards.shape)
    return adv, adv + np.asarray(values)


# ------------------------------------------------------------------------------------------
# Monte Carlo returns
# ------------------------------------------------------------------------------------------


def test_monte_carlo_hand_example_with_boundary_and_bootstrap() -> None:
    rewards = jnp.array([1.0, 2.0, 3.0, 4.0, 5.0])
    dones = jnp.array([False, True, False, False, False])
    # gamma = 0.5, episode ends at t = 1, the rollout is cut after t = 4 with V(s_5) = 10:
    # G4 = 5 + .5*10 = 10, G3 = 4 + .5*10 = 9, G2 = 3 + .5*9 = 7.5, G1 = 2 (end), G0 = 1 + .5*2 = 2
    got = monte_carlo_returns(rewards, dones, 0.5, bootstrap_value=10.0)
    np.testing.assert_allclose(got, [2.0, 2.0, 7.5, 9.0, 10.0], rtol=1e-6)
    # No bootstrap: G4 = 5, G3 = 4 + 2.5 = 6.5, G2 = 3 + 3.25 = 6.25; episode 1 unchanged.
    got = monte_carlo_returns(rewards, dones, 0.5)
    np.testing.assert_allclose(got, [2.0, 2.0, 6.25, 6.5, 5.0], rtol=1e-6)
    # A done on the last step ignores the bootstrap: the final whistle as a real end.
    got = monte_carlo_returns(rewards, dones.at[-1].set(True), 0.5, bootstrap_value=10.0)
    np.testing.assert_allclose(got, [2.0, 2.0, 6.25, 6.5, 5.0], rtol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_monte_carlo_matches_python_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    rewards = rng.normal(size=(9, 3, 2)).astype(np.float32)
    dones = rng.random((9, 3, 2)) < 0.2
    bootstrap = rng.normal(size=(3, 2)).astype(np.float32)
    got = jax.jit(monte_carlo_returns)(rewards, dones, 0.9, bootstrap)
    want = mc_reference(rewards, dones, 0.9, bootstrap)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert got.shape == (9, 3, 2)


# ------------------------------------------------------------------------------------------
# GAE
# ------------------------------------------------------------------------------------------

HAND_REWARDS = jnp.array([1.0, 0.0, 2.0, 0.0, 1.0])
HAND_VALUES = jnp.array([0.5, 1.0, 2.0, 1.0, 0.5])
HAND_DONES = jnp.array([False, True, False, True, False])  # terminal at 1, time limit at 3
HAND_TRUNCS = jnp.array([False, False, False, True, False])
HAND_TRUNC_VALUES = jnp.array([0.0, 0.0, 0.0, 4.0, 0.0])  # V of the state truncated at t = 3


def test_gae_hand_example_bootstraps_the_truncation() -> None:
    # gamma = 0.5, lambda = 0.5 (gamma * lambda = 0.25), last_value = V(s_5) = 2.
    # t4: d = 1 + .5*2 - .5 = 1.5                  A4 = 1.5
    # t3: truncated, d = 0 + .5*4 - 1 = 1           A3 = 1    (nothing from t4: new episode)
    # t2: d = 2 + .5*V3 - 2 = 2 + .5 - 2 = .5        A2 = .5 + .25*1 = .75
    # t1: terminal, d = 0 - 1 = -1                   A1 = -1
    # t0: d = 1 + .5*V1 - .5 = 1                     A0 = 1 + .25*(-1) = .75
    out = gae(
        HAND_REWARDS, HAND_VALUES, HAND_DONES, HAND_TRUNCS, 2.0, 0.5, 0.5,
        truncation_values=HAND_TRUNC_VALUES,
    )
    np.testing.assert_allclose(out.advantages, [0.75, -1.0, 0.75, 1.0, 1.5], rtol=1e-6)
    np.testing.assert_allclose(out.returns, [1.25, 0.0, 2.75, 2.0, 2.0], rtol=1e-6)


def test_gae_hand_example_truncation_without_value_is_terminal() -> None:
    # As above but t3 is a terminal: d3 = 0 - 1 = -1, A3 = -1, A2 = .5 + .25*(-1) = .25.
    out = gae(HAND_REWARDS, HAND_VALUES, HAND_DONES, HAND_TRUNCS, 2.0, 0.5, 0.5)
    np.testing.assert_allclose(out.advantages, [0.75, -1.0, 0.25, -1.0, 1.5], rtol=1e-6)
    np.testing.assert_allclose(out.returns, [1.25, 0.0, 2.25, 0.0, 2.0], rtol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("with_trunc_values", [False, True])
def test_gae_matches_python_loop(seed: int, with_trunc_values: bool) -> None:
    rng = np.random.default_rng(seed)
    shape = (11, 4, 3)
    rewards = rng.normal(size=shape).astype(np.float32)
    values = rng.normal(size=shape).astype(np.float32)
    truncs = rng.random(shape) < 0.1
    dones = (rng.random(shape) < 0.15) | truncs
    last_value = rng.normal(size=shape[1:]).astype(np.float32)
    trunc_values = rng.normal(size=shape).astype(np.float32) if with_trunc_values else None
    out = jax.jit(gae)(rewards, values, dones, truncs, last_value, 0.95, 0.9, trunc_values)
    adv, ret = gae_reference(
        rewards, values, dones, truncs, last_value, 0.95, 0.9, trunc_values
    )
    np.testing.assert_allclose(out.advantages, adv, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(out.returns, ret, rtol=1e-5, atol=1e-5)


def test_gae_with_lambda_one_is_monte_carlo_minus_values() -> None:
    rng = np.random.default_rng(3)
    rewards = rng.normal(size=(8, 5)).astype(np.float32)
    values = rng.normal(size=(8, 5)).astype(np.float32)
    dones = rng.random((8, 5)) < 0.2
    last_value = rng.normal(size=(5,)).astype(np.float32)
    out = gae(rewards, values, dones, np.zeros_like(dones), last_value, 0.9, 1.0)
    returns = monte_carlo_returns(rewards, dones, 0.9, last_value)
    np.testing.assert_allclose(out.returns, returns, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(out.advantages, returns - values, rtol=1e-5, atol=1e-5)


# ------------------------------------------------------------------------------------------
# Loss terms
# ------------------------------------------------------------------------------------------

# ratios 1, 1.5, 0.5, 1.5 against advantages 2, 1, -1, -2 with epsilon 0.1:
#   min(1*2, 1*2)        =  2    (ratio 1: unclipped)
#   min(1.5*1, 1.1*1)    =  1.1  (clipped above: no gradient)
#   min(-.5, -.9)        = -0.9  (clipped below: no gradient)
#   min(1.5*-2, 1.1*-2)  = -3    (outside the clip but the unclipped side is the min: gradient)
RATIOS = np.array([1.0, 1.5, 0.5, 1.5], np.float32)
ADVANTAGES = np.array([2.0, 1.0, -1.0, -2.0], np.float32)
LOG_OLD = np.array([-0.3, -1.2, 0.4, -2.0], np.float32)
LOG_NEW = LOG_OLD + np.log(RATIOS)


def test_policy_loss_by_hand_with_clipping_on_both_sides() -> None:
    out = policy_loss(LOG_NEW, LOG_OLD, ADVANTAGES, 0.1)
    # mean objective (2 + 1.1 - .9 - 3) / 4 = -.2, negated into the loss
    np.testing.assert_allclose(out.loss, 0.2, rtol=1e-5)
    # three of four ratios leave [0.9, 1.1]
    np.testing.assert_allclose(out.clip_fraction, 0.75)
    # (r - 1) - log r: 0, .5 - log 1.5, -.5 + log 2, .5 - log 1.5
    kl = (0.0 + 2 * (0.5 - math.log(1.5)) + (-0.5 + math.log(2.0))) / 4
    np.testing.assert_allclose(out.approx_kl, kl, rtol=1e-5)
    # d loss / d log_new = -A * r / N where the unclipped term is the min, else 0
    grads = jax.grad(lambda lp: policy_loss(lp, LOG_OLD, ADVANTAGES, 0.1).loss)(LOG_NEW)
    np.testing.assert_allclose(grads, [-2.0 / 4, 0.0, 0.0, 2.0 * 1.5 / 4], rtol=1e-5)


def test_policy_loss_ratio_one_is_minus_mean_advantage() -> None:
    out = policy_loss(LOG_OLD, LOG_OLD, ADVANTAGES, 0.1)
    np.testing.assert_allclose(out.loss, -np.mean(ADVANTAGES), atol=1e-7)  # -(2+1-1-2)/4 = 0
    assert float(out.approx_kl) == 0.0
    assert float(out.clip_fraction) == 0.0
    grads = jax.grad(lambda lp: policy_loss(lp, LOG_OLD, ADVANTAGES, 0.1).loss)(LOG_OLD)
    np.testing.assert_allclose(grads, -ADVANTAGES / 4, rtol=1e-6)


def test_policy_loss_mask_ignores_masked_entries() -> None:
    mask = np.array([True, False, False, True])
    out = policy_loss(LOG_NEW, LOG_OLD, ADVANTAGES, 0.1, mask=mask)
    np.testing.assert_allclose(out.loss, -(2.0 - 3.0) / 2, rtol=1e-6)  # entries 0 and 3 only
    np.testing.assert_allclose(out.clip_fraction, 0.5)


def test_policy_mask_drops_scripted_entries_from_the_policy_terms_only() -> None:
    values, returns = jnp.array([0.5, 1.0, -1.0, 2.0]), jnp.array([1.0, 0.0, 0.0, 1.0])
    entropy = jnp.array([1.0, 5.0, 7.0, 3.0])
    played = np.array([True, False, False, True])
    hp = PPOHyperparams(normalize_advantages=True)
    both = ppo_loss(LOG_NEW, LOG_OLD, values, returns, entropy, advantages=ADVANTAGES,
                    policy_mask=played, hyperparams=hp)
    subset = ppo_loss(LOG_NEW[played], LOG_OLD[played], values[played], returns[played],
                      entropy[played], advantages=ADVANTAGES[played], hyperparams=hp)
    full = ppo_loss(LOG_NEW, LOG_OLD, values, returns, entropy, advantages=ADVANTAGES,
                    hyperparams=hp)
    # The policy, entropy and advantage terms are those of the played entries alone ...
    for name in ("policy", "entropy", "approx_kl", "clip_fraction", "advantage_mean"):
        np.testing.assert_allclose(getattr(both, name), getattr(subset, name), rtol=1e-6)
    # ... and the critic still learns every state's value.
    np.testing.assert_allclose(both.value, full.value, rtol=1e-6)
    assert not np.isclose(float(both.value), float(subset.value))
    # A scripted entry's log-probability has no gradient.
    grads = jax.grad(lambda lp: ppo_loss(lp, LOG_OLD, values, returns, entropy,
                                         advantages=ADVANTAGES, policy_mask=played).total)(LOG_NEW)
    np.testing.assert_array_equal(np.asarray(grads)[~played], 0.0)
    assert np.all(np.asarray(grads)[played] != 0.0)
    # With a mask too, an entry counts in the policy terms only if both allow it.
    padded = np.array([True, True, False, False])
    one = ppo_loss(LOG_NEW, LOG_OLD, values, returns, entropy, advantages=ADVANTAGES,
                   mask=padded, policy_mask=played)
    np.testing.assert_allclose(one.entropy, 1.0)
    np.testing.assert_allclose(one.value, float(jnp.mean((values - returns)[:2] ** 2)), rtol=1e-6)


def test_value_loss_by_hand() -> None:
    # errors 1 and -2 -> squared 1 and 4 -> mean 2.5
    np.testing.assert_allclose(value_loss(jnp.array([1.0, 2.0]), jnp.array([2.0, 0.0])), 2.5)
    # clipping: old values 1.5, width .2 -> V_clip = [1.3, 1.7]; returns [.9, 0]
    # unclipped [(.9-1)^2, (0-2)^2] = [.01, 4]; clipped [(.9-1.3)^2, 1.7^2] = [.16, 2.89]
    # max per entry [.16, 4] -> mean 2.08
    got = value_loss(
        jnp.array([1.0, 2.0]), jnp.array([0.9, 0.0]), old_values=jnp.array([1.5, 1.5]),
        clip_epsilon=0.2,
    )
    np.testing.assert_allclose(got, 2.08, rtol=1e-5)
    # no gradient into the returns
    grad_returns = jax.grad(lambda g: value_loss(jnp.array([1.0, 2.0]), g))(jnp.array([2.0, 0.0]))
    np.testing.assert_allclose(grad_returns, [0.0, 0.0])


def test_entropy_bonus_is_the_mean() -> None:
    np.testing.assert_allclose(entropy_bonus(jnp.array([1.0, 2.0, 3.0])), 2.0)
    np.testing.assert_allclose(entropy_bonus(jnp.array([1.0, 2.0, 9.0]), jnp.array([1, 1, 0])), 1.5)


def test_ppo_loss_combines_terms_with_table_6_1_weights() -> None:
    values = jnp.array([0.0, 1.0, 0.0, 1.0])
    returns = values + ADVANTAGES  # so that A = G - V = ADVANTAGES
    entropy = jnp.array([1.0, 2.0, 3.0, 4.0])
    out = ppo_loss(LOG_NEW, LOG_OLD, values, returns, entropy)
    # policy .2 (above); value mean(A^2) = (4 + 1 + 1 + 4) / 4 = 2.5; entropy 2.5
    # total = 1.0 * .2 + 0.5 * 2.5 - 0.01 * 2.5 = .2 + 1.25 - .025 = 1.425
    np.testing.assert_allclose(out.policy, 0.2, rtol=1e-5)
    np.testing.assert_allclose(out.value, 2.5, rtol=1e-6)
    np.testing.assert_allclose(out.entropy, 2.5, rtol=1e-6)
    np.testing.assert_allclose(out.total, 1.425, rtol=1e-5)
    np.testing.assert_allclose(out.clip_fraction, 0.75)
    np.testing.assert_allclose(out.advantage_mean, 0.0, atol=1e-7)
    # Explicit advantages give the same result, and the entropy weight enters with a minus sign.
    hp = PPOHyperparams(entropy_weight=0.1, value_weight=1.0, policy_weight=2.0)
    out = ppo_loss(
        LOG_NEW, LOG_OLD, values, returns, entropy, advantages=ADVANTAGES, hyperparams=hp
    )
    np.testing.assert_allclose(out.total, 2.0 * 0.2 + 1.0 * 2.5 - 0.1 * 2.5, rtol=1e-5)


def test_ppo_loss_value_gradient_comes_only_from_the_critic_term() -> None:
    values = jnp.array([0.0, 1.0, 0.0, 1.0])
    returns = values + ADVANTAGES
    entropy = jnp.ones(4)
    grad_v = jax.grad(lambda v: ppo_loss(LOG_NEW, LOG_OLD, v, returns, entropy).total)(values)
    # 0.5 * d/dV mean((G - V)^2) = 0.5 * -2 (G - V) / 4 = -A / 4
    np.testing.assert_allclose(grad_v, -ADVANTAGES / 4, rtol=1e-5)


def test_ppo_loss_normalises_advantages_per_minibatch() -> None:
    values = jnp.zeros(4)
    returns = jnp.array([1.0, 3.0, 5.0, 7.0])  # A = G: mean 4, std sqrt(5)
    hp = PPOHyperparams(normalize_advantages=True)
    out = ppo_loss(LOG_OLD, LOG_OLD, values, returns, jnp.zeros(4), hyperparams=hp)
    # ratio 1: policy loss is -mean(normalised A) = 0
    np.testing.assert_allclose(out.policy, 0.0, atol=1e-6)
    normalised = normalize_advantages(returns)
    np.testing.assert_allclose(normalised, (returns - 4.0) / math.sqrt(5.0), rtol=1e-5)
    masked = normalize_advantages(jnp.array([1.0, 3.0, 100.0]), jnp.array([True, True, False]))
    np.testing.assert_allclose(masked, [-1.0, 1.0, 0.0], rtol=1e-5)


def test_explained_variance_by_hand() -> None:
    # Var(G) = 2.1875 for G = [1,2,3,5]; G - V = [0,0,0,1] has Var .1875 -> 1 - 3/35 = 32/35
    got = explained_variance(jnp.array([1.0, 2.0, 3.0, 4.0]), jnp.array([1.0, 2.0, 3.0, 5.0]))
    np.testing.assert_allclose(got, 32.0 / 35.0, rtol=1e-5)
    perfect = explained_variance(jnp.array([1.0, 2.0, 3.0]), jnp.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(perfect, 1.0)
    constant_critic = explained_variance(jnp.full(3, 2.0), jnp.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(constant_critic, 0.0, atol=1e-6)
    assert float(explained_variance(jnp.array([1.0, 2.0]), jnp.array([3.0, 3.0]))) == 0.0


def test_hyperparams_defaults_and_validation() -> None:
    hp = PPOHyperparams()
    assert (hp.gamma, hp.learning_rate, hp.epochs, hp.clip_epsilon) == (0.999, 1e-4, 5, 0.1)
    assert (hp.value_weight, hp.policy_weight, hp.entropy_weight) == (0.5, 1.0, 0.01)
    assert hp.minibatch_size == 60  # table 6.1; its batch of 660 is games x players
    assert not hasattr(hp, "batch_size")
    assert hp.advantage_estimator == "monte_carlo" and not hp.normalize_advantages
    with pytest.raises(ValueError, match="minibatch_size=0 is invalid: it must be >= 1"):
        PPOHyperparams(minibatch_size=0)
    for bad in (0.0, -1e-4, float("nan")):
        with pytest.raises(ValueError, match=f"learning_rate={bad!r} is invalid"):
            PPOHyperparams(learning_rate=bad)
    with pytest.raises(ValueError, match="advantage_estimator"):
        PPOHyperparams(advantage_estimator="td")  # type: ignore[arg-type]
    assert hp.entropy_estimator == "gaussian"  # the thesis' eq. 3.75
    with pytest.raises(ValueError, match="entropy_estimator='exact' is invalid"):
        PPOHyperparams(entropy_estimator="exact")  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------
# Minibatches and the epoch loop
# ------------------------------------------------------------------------------------------


def test_minibatch_indices_partition_the_batch() -> None:
    indices = minibatch_indices(jax.random.key(0), 12, 3)
    assert indices.shape == (3, 4)
    np.testing.assert_array_equal(np.sort(np.asarray(indices).ravel()), np.arange(12))
    assert not np.array_equal(np.asarray(indices).ravel(), np.arange(12))  # shuffled
    with pytest.raises(ValueError, match="num_minibatches=5 does not divide the batch of 12"):
        minibatch_indices(jax.random.key(0), 12, 5)


def sequence_batch(num_units: int, length: int) -> dict[str, np.ndarray]:
    """Unit i holds the sequence i*length, ..., i*length + length - 1 and an id leaf i."""
    seq = np.arange(num_units * length, dtype=np.float32).reshape(num_units, length)
    return {"seq": seq, "id": np.arange(num_units, dtype=np.float32)}


def test_shuffle_minibatches_keeps_units_whole() -> None:
    batch = sequence_batch(8, 5)
    minibatches = shuffle_minibatches(jax.random.key(1), batch, 4)
    seq, ids = np.asarray(minibatches["seq"]), np.asarray(minibatches["id"])
    assert seq.shape == (4, 2, 5) and ids.shape == (4, 2)
    # every row is one intact sequence, and it travels with its own id
    np.testing.assert_array_equal(seq - seq[..., :1], np.broadcast_to(np.arange(5.0), seq.shape))
    np.testing.assert_array_equal(seq[..., 0], ids * 5)
    np.testing.assert_array_equal(np.sort(ids.ravel()), np.arange(8))


def quadratic_loss(params, minibatch):
    """mean((w - x)^2) over a minibatch of sequences; metrics check the units arrive whole."""
    seq = minibatch["seq"]
    loss = jnp.mean(jnp.square(params["w"] - minibatch["x"]))
    length = seq.shape[1]
    consecutive = jnp.all(seq[:, 1:] - seq[:, :-1] == 1.0)
    intact = consecutive & jnp.all(seq[:, 0] == length * minibatch["id"])
    return loss, {"intact": intact.astype(jnp.float32), "id_sum": jnp.sum(minibatch["id"])}


def test_update_epochs_reduces_a_quadratic_and_keeps_sequences() -> None:
    num_units, length = 16, 4
    rng = np.random.default_rng(0)
    target = np.array([1.0, -2.0, 3.0], np.float32)
    batch = dict(sequence_batch(num_units, length))
    batch["x"] = (target + 0.05 * rng.normal(size=(num_units, length, 3))).astype(np.float32)
    params = {"w": jnp.zeros(3)}
    # the loss averages over the 3 coordinates, so each step contracts w - target by 1 - 2*.5/3
    optimizer = optax.sgd(0.5)

    def run(params, opt_state, batch, key):
        return update_epochs(
            quadratic_loss, optimizer, params, opt_state, batch, key, epochs=5, num_minibatches=4
        )

    result = jax.jit(run)(params, optimizer.init(params), batch, jax.random.key(0))
    initial_loss = float(quadratic_loss(params, batch)[0])
    final_loss = float(quadratic_loss(result.params, batch)[0])
    assert final_loss < 0.05 * initial_loss
    np.testing.assert_allclose(result.params["w"], target, atol=0.05)
    assert float(result.metrics["intact"]) == 1.0
    # each epoch sees every unit once: mean id sum per minibatch = (0 + ... + 15) / 4
    np.testing.assert_allclose(result.metrics["id_sum"], 120.0 / 4)
    assert result.loss.shape == () and float(result.grad_norm) > 0


def test_update_epochs_single_full_batch_step_is_one_sgd_step() -> None:
    x = np.array([[1.0], [3.0]], np.float32)  # mean 2; grad of mean((w - x)^2) at 0 is -4

    def loss_fn(params, minibatch):
        return jnp.mean(jnp.square(params - minibatch)), {}

    optimizer = optax.sgd(0.1)
    result = update_epochs(
        loss_fn, optimizer, jnp.zeros(1), optimizer.init(jnp.zeros(1)), x,
        jax.random.key(0), epochs=1, num_minibatches=1,
    )
    np.testing.assert_allclose(result.params, [0.4], rtol=1e-6)  # 0 - 0.1 * -4
    np.testing.assert_allclose(result.loss, 5.0)  # (1 + 9) / 2 before the step


def test_update_epochs_rejects_bad_minibatch_count_before_tracing() -> None:
    batch = sequence_batch(10, 3)
    optimizer = optax.sgd(0.1)
    params = {"w": jnp.zeros(3)}
    with pytest.raises(ValueError, match="num_minibatches=4 does not divide the batch of 10"):
        update_epochs(
            quadratic_loss, optimizer, params, optimizer.init(params), batch,
            jax.random.key(0), epochs=1, num_minibatches=4,
        )
    with pytest.raises(ValueError, match="same leading"):
        update_epochs(
            quadratic_loss, optimizer, params, optimizer.init(params),
            {"seq": np.zeros((10, 3)), "id": np.zeros(8)},
            jax.random.key(0), epochs=1, num_minibatches=2,
        )
