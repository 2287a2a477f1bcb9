"""The parametrised action head: its distribution against hand computations, masked slots,
the policy's pointer by attention on real observations, jit against eager, and PPO learning the
right kind and pointer in a one-step game."""

from __future__ import annotations

import functools
import itertools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import elevens
from elevens.env.state import ENTITY_FEATURES, Observation
from elevens.nets.distributions import ParametrisedDistribution
from elevens.nets.policy import AttentionPolicy, ParametrisedOutput
from elevens.teams.network import NetworkTeam
from elevens.train.ppo import policy_loss

HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)
DISTANCE_FEATURE = ENTITY_FEATURES.index("distance")


def small_distribution(mask: list[bool] | None = None) -> ParametrisedDistribution:
    """K = 2 kinds, P = 3 slots, one batch row; slot 1 out of view unless ``mask`` says."""
    return ParametrisedDistribution.create(
        kind_logits=jnp.array([[0.3, -0.5]]),
        pointer_logits=jnp.array([[[1.0, 2.0, -1.0], [0.0, 5.0, 0.5]]]),
        pointer_mask=jnp.array([mask or [True, False, True]]),
        target_mean=jnp.array([[[0.2, -0.4], [1.0, 0.0]]]),
        target_log_std=jnp.array([[[-1.0, 0.5], [0.0, -0.3]]]),
    )


def log_softmax(x: np.ndarray) -> np.ndarray:
    return x - np.log(np.sum(np.exp(x)))


def hand_log_prob(kind: int, pointer: int, u: np.ndarray) -> float:
    """log pi(kind) + log pi(pointer | kind, slots 0 and 2 in view) + the tanh Gaussian's."""
    kind_logits = np.array([0.3, -0.5])
    pointer_logits = np.array([[1.0, 2.0, -1.0], [0.0, 5.0, 0.5]])[kind][[0, 2]]
    mean = np.array([[0.2, -0.4], [1.0, 0.0]])[kind]
    log_std = np.array([[-1.0, 0.5], [0.0, -0.3]])[kind]
    z = (u - mean) / np.exp(log_std)
    gaussian = np.sum(-0.5 * z**2 - log_std - HALF_LOG_2PI)
    jacobian = np.sum(np.log(1 - np.tanh(u) ** 2))
    slot = {0: 0, 2: 1}[pointer]
    return float(
        log_softmax(kind_logits)[kind] + log_softmax(pointer_logits)[slot] + gaussian - jacobian
    )


def test_log_prob_of_samples_matches_a_hand_computation() -> None:
    dist = small_distribution()
    keys = jax.random.split(jax.random.key(0), 40)
    # Compiled: eager JAX would compile each small op of the vmapped draw on its own.
    samples = jax.jit(jax.vmap(dist.sample))(keys)
    log_probs = jax.jit(jax.vmap(dist.log_prob))(samples.pre_tanh)
    seen = set()
    for raw, action, log_prob in zip(
        np.asarray(samples.pre_tanh[:, 0]), np.asarray(samples.action[:, 0]),
        np.asarray(log_probs[:, 0]), strict=True,
    ):
        kind, pointer = int(raw[0]), int(raw[1])
        seen.add((kind, pointer))
        assert raw[0] == kind and raw[1] == pointer and pointer != 1  # slot 1 is out of view
        np.testing.assert_array_equal(action[:2], raw[:2])
        np.testing.assert_allclose(action[2:], np.tanh(raw[2:]), rtol=1e-6)
        np.testing.assert_allclose(
            log_prob, hand_log_prob(kind, pointer, raw[2:]), rtol=1e-5, atol=2e-5
        )
        # From the action itself (atanh of the target) too.
        from_action = dist.log_prob_of_action(jnp.asarray(action)[None])
        np.testing.assert_allclose(from_action[0], log_prob, rtol=1e-4, atol=1e-4)
    assert {kind for kind, _ in seen} == {0, 1}  # both kinds drawn, so both rows are checked


def test_the_discrete_entropy_is_exact_and_the_mode_is_the_likeliest() -> None:
    dist = small_distribution()
    # Enumerate (kind, pointer): -sum p log p, plus E_kind of each kind's Gaussian entropy.
    joint = []
    for kind, pointer in itertools.product(range(2), (0, 2)):
        raw = jnp.array([[kind, pointer, 0.0, 0.0]], jnp.float32)
        gaussian_at_zero = dist._given(jnp.array([kind]))[1].log_prob(raw[:, 2:])
        joint.append(float(jnp.exp(dist.log_prob(raw) - gaussian_at_zero)[0]))
    probs = np.array(joint)
    assert probs.sum() == pytest.approx(1.0, abs=1e-6)
    kind_p = np.exp(log_softmax(np.array([0.3, -0.5])))
    gaussian = np.array([np.sum(np.array(s) + 0.5 + HALF_LOG_2PI) for s in ([-1, 0.5], [0, -0.3])])
    expected = -np.sum(probs * np.log(probs)) + np.sum(kind_p * gaussian)
    assert float(dist.gaussian_entropy()[0]) == pytest.approx(expected, rel=1e-5)
    # The entropy with the target's estimate: the Gaussian's at noise 0 plus the log-Jacobian.
    noise = jnp.zeros((1, 4))
    jacobian = np.log(1 - np.tanh(np.array([[0.2, -0.4], [1.0, 0.0]])) ** 2).sum(-1)
    assert float(dist.entropy_at(noise)[0]) == pytest.approx(
        expected + np.sum(kind_p * jacobian), rel=1e-5
    )
    mode = np.asarray(dist.mode()[0])
    # Kind 0 (logit 0.3) and its likeliest slot in view: 0 (slot 1 has a larger logit but is out).
    np.testing.assert_allclose(mode, [0.0, 0.0, np.tanh(0.2), np.tanh(-0.4)], rtol=1e-6)


def test_slots_out_of_view_have_zero_probability() -> None:
    dist = small_distribution()
    for kind in range(2):
        raw = jnp.array([[kind, 1.0, 0.0, 0.0]])
        assert float(jnp.exp(dist.log_prob(raw))[0]) == 0.0
    keys = jax.random.split(jax.random.key(1), 500)
    pointers = np.asarray(jax.jit(jax.vmap(dist.sample))(keys).pre_tanh[:, 0, 1])
    assert set(pointers.tolist()) == {0.0, 2.0}


def test_with_no_slot_in_view_everything_is_finite_and_the_pointer_weighs_nothing() -> None:
    dist = small_distribution([False, False, False])
    with_pointer = [dist.log_prob(jnp.array([[1.0, p, 0.3, -0.2]])) for p in range(3)]
    assert all(np.isfinite(x).all() for x in with_pointer)
    assert float(with_pointer[0][0]) == float(with_pointer[2][0])  # the pointer is irrelevant
    kind_and_target_only = ParametrisedDistribution.create(
        dist.kind_logits, jnp.zeros((1, 2, 1)), jnp.ones((1, 1), bool),
        dist.target.mean, dist.target.log_std,
    )  # one slot, always in view: the pointer's term is log 1 = 0 there too
    assert float(with_pointer[0][0]) == pytest.approx(
        float(kind_and_target_only.log_prob(jnp.array([[1.0, 0.0, 0.3, -0.2]]))[0]), rel=1e-6
    )
    assert np.isfinite(dist.gaussian_entropy()).all()
    assert np.isfinite(dist.entropy_at(jnp.ones((1, 4)))).all()

    def loss(logits: jax.Array) -> jax.Array:
        d = ParametrisedDistribution.create(
            dist.kind_logits, logits, dist.pointer_mask, dist.target.mean, dist.target.log_std
        )
        return d.log_prob(jnp.array([[1.0, 2.0, 0.3, -0.2]]))[0] + d.gaussian_entropy()[0]

    grad = jax.grad(loss)(jnp.array([[[1.0, 2.0, -1.0], [0.0, 5.0, 0.5]]]))
    assert np.isfinite(grad).all() and not np.any(grad)


# ------------------------------------------------------------------------------- the policy


def real_observations(preset: str, games: int, seed: int = 0) -> tuple[Observation, int]:
    """Both teams' observations of ``games`` kick-offs: leading [games * 2, n]."""
    env, params = elevens.make(preset)
    keys = jax.random.split(jax.random.key(seed), games)
    # Compiled: one program costs less than eager JAX compiling each op of the reset alone.
    _, obs = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    n = env.players_per_team
    return jax.tree.map(lambda x: x.reshape(games * 2, n, *x.shape[3:]), obs), n


def small_policy(kinds: int = 3, **fields: Any) -> AttentionPolicy:
    return AttentionPolicy(
        features=16, num_heads=2, lstm_features=8, num_actions=4, kinds=kinds, **fields
    )


def sharpened(variables: Any) -> Any:
    """The pointer's query weights scaled up from their small initial values, so that the
    pointer logits of different slots differ by about 1 and a wrong slot shows."""
    return jax.tree_util.tree_map_with_path(
        lambda path, x: x * 3e4 if "pointer_query" in jax.tree_util.keystr(path) else x, variables
    )


def test_the_pointer_attends_over_the_player_slots_in_view() -> None:
    obs, n = real_observations("3v3", 4)
    obs = obs.replace(entity_mask=obs.entity_mask.at[:, :, 0].set(False))  # a mate out of view
    policy = small_policy()
    reset = jnp.zeros(obs.entity_mask.shape[:-1], bool)
    carry = policy.initial_carry(reset.shape)
    # Compiled: op by op the init alone is about 150 compiles.
    variables = jax.jit(policy.init)(jax.random.key(0), carry, obs, reset)
    variables = sharpened(variables)
    apply = jax.jit(policy.apply)
    _, out = apply(variables, carry, obs, reset)
    assert isinstance(out, ParametrisedOutput)
    assert out.pointer_logits.shape == (8, n, 3, 2 * n - 1)  # teammates, opponents; no ball
    log_p = jax.nn.log_softmax(out.distribution().pointer_logits, axis=-1)
    p = np.asarray(jnp.exp(log_p))
    visible = np.broadcast_to(np.asarray(obs.entity_mask[:, :, None, : 2 * n - 1]), p.shape)
    assert np.all(p[..., 0] == 0.0) and np.all(p[~visible] == 0.0)
    assert np.ptp(p[visible]) > 0.1  # the slots in view are told apart
    # An attention, so permuting the opponents' slots permutes their logits alike.
    perm = np.array([2, 0, 1]) + n - 1
    order = np.concatenate([np.arange(n - 1), perm, [2 * n - 1]])
    swapped = obs.replace(
        entities=obs.entities[:, :, order], entity_mask=obs.entity_mask[:, :, order]
    )
    _, out_swapped = apply(variables, carry, swapped, reset)
    np.testing.assert_allclose(
        out_swapped.pointer_logits, out.pointer_logits[..., order[:-1]], rtol=1e-5, atol=1e-5
    )
    np.testing.assert_allclose(out_swapped.kind_logits, out.kind_logits, rtol=1e-5, atol=1e-6)


def test_jit_equals_eager_and_unroll_equals_steps_and_compaction_equals_dense() -> None:
    # The pointer test's games: its eager passes already compiled the ops of these shapes.
    obs, n = real_observations("3v3", 4)
    policy = small_policy()
    steps = 3
    obs_seq = jax.tree.map(lambda x: jnp.stack([x] * steps), obs)
    reset_seq = jnp.zeros((steps, *obs.entity_mask.shape[:-1]), bool).at[0].set(True)
    carry = policy.initial_carry(reset_seq.shape[1:])
    variables = policy.init(jax.random.key(0), carry, obs, reset_seq[0])
    variables = sharpened(variables)

    def step(carry: Any, obs: Observation, reset: jax.Array) -> Any:
        carry, out = policy.apply(variables, carry, obs, reset)
        dist = out.distribution()
        sample = dist.sample(jax.random.key(3))
        log_prob = dist.log_prob(sample.pre_tanh)
        return carry, (out, sample, log_prob, dist.gaussian_entropy(), dist.mode())

    def close(a: Any, b: Any) -> None:
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-5)

    jitted_step = jax.jit(step)
    close(step(carry, obs, reset_seq[0]), jitted_step(carry, obs, reset_seq[0]))

    @functools.partial(jax.jit, static_argnums=0)
    def unroll(visible_fraction: Any) -> Any:
        return policy.apply(
            variables, carry, obs_seq, reset_seq, 0, visible_fraction,
            method=AttentionPolicy.unroll,
        )[1]

    dense = unroll(None)
    assert np.ptp(np.asarray(dense.pointer_logits)[np.asarray(dense.pointer_mask)[..., None, :]
                  .repeat(3, -2)]) > 0.5
    close(dense, unroll(1.0))  # the per-entity layers on the slots in view only
    stepped = carry
    for t in range(steps):
        stepped, (out, sample, log_prob, *_) = jitted_step(
            stepped, jax.tree.map(lambda x, t=t: x[t], obs_seq), reset_seq[t]
        )
        close(out, jax.tree.map(lambda x, t=t: x[t], dense))
        assert np.isfinite(log_prob).all() and sample.action.shape == (8, n, 4)


def test_network_team_plays_the_mode_and_samples() -> None:
    obs, n = real_observations("2v2", 1)
    policy = small_policy(kinds=2)
    team = NetworkTeam(policy=policy, deterministic=True)
    one = jax.tree.map(lambda x: x[0], obs)
    # Compiled, as a match plays a team (eager JAX would compile each op of the pass alone).
    variables = jax.jit(policy.init)(
        jax.random.key(0), team.init_carry(n), one, jnp.zeros(n, bool)
    )
    act = jax.jit(team.act)
    _, mode = act(variables, team.init_carry(n), one, jax.random.key(1))
    _, again = act(variables, team.init_carry(n), one, jax.random.key(2))
    np.testing.assert_array_equal(mode, again)
    sampler = NetworkTeam(policy=policy)
    _, sampled = jax.jit(sampler.act)(variables, sampler.init_carry(n), one, jax.random.key(1))
    assert mode.shape == sampled.shape == (n, 4)
    assert np.all(np.isin(np.asarray(sampled[:, 0]), [0, 1]))
    assert np.all((sampled[:, 1] >= 0) & (sampled[:, 1] < 2 * n - 1))


def test_a_bad_head_is_refused_by_the_module() -> None:
    obs, n = real_observations("2v2", 1)
    reset = jnp.zeros(obs.entity_mask.shape[:-1], bool)
    for bad in (small_policy(use_attention=False), small_policy().clone(num_actions=2)):
        with pytest.raises(ValueError, match="parametrised head"):
            bad.init(jax.random.key(0), bad.initial_carry(reset.shape), obs, reset)


# ------------------------------------------------------------------------- PPO learns to point


@functools.partial(jax.jit, static_argnums=0)
def _ppo_iteration(
    policy: AttentionPolicy, variables: Any, opt_state: Any, obs: Observation, key: jax.Array
) -> tuple[Any, Any, jax.Array]:
    """One PPO iteration of a one-step game: reward 1 for kind RIGHT_KIND, plus 1 for pointing
    at the opponent in view nearest the player (the smallest distance feature); the baseline is
    the mean reward."""
    optimizer = optax.adam(3e-3)
    reset = jnp.ones(obs.entity_mask.shape[:-1], bool)
    carry = policy.initial_carry(reset.shape)
    _, out = policy.apply(variables, carry, obs, reset)
    dist = out.distribution()
    sample = dist.sample(key)
    old_log_prob = dist.log_prob(sample.pre_tanh)
    n = obs.entity_mask.shape[-1] // 2
    reward = (sample.pre_tanh[..., 0] == RIGHT_KIND).astype(jnp.float32) + (
        sample.pre_tanh[..., 1] == nearest_opponent(obs, n)
    ).astype(jnp.float32)
    advantage = reward - jnp.mean(reward)

    def loss(variables: Any) -> jax.Array:
        _, out = policy.apply(variables, carry, obs, reset)
        new_log_prob = out.distribution().log_prob(sample.pre_tanh)
        return policy_loss(new_log_prob, old_log_prob, advantage, 0.2).loss

    def epoch(state: tuple[Any, Any], _: None) -> tuple[tuple[Any, Any], None]:
        variables, opt_state = state
        updates, opt_state = optimizer.update(jax.grad(loss)(variables), opt_state, variables)
        return (optax.apply_updates(variables, updates), opt_state), None

    (variables, opt_state), _ = jax.lax.scan(epoch, (variables, opt_state), None, length=4)
    return variables, opt_state, jnp.mean(reward)


RIGHT_KIND = 0


def nearest_opponent(obs: Observation, n: int) -> jax.Array:
    """f32[...]: the opponent slot in view with the smallest distance feature."""
    distance = obs.entities[..., n - 1 : 2 * n - 1, DISTANCE_FEATURE]
    distance = jnp.where(obs.entity_mask[..., n - 1 : 2 * n - 1], distance, jnp.inf)
    return (jnp.argmin(distance, axis=-1) + n - 1).astype(jnp.float32)


@pytest.mark.slow
def test_ppo_learns_the_right_kind_and_the_nearest_opponent() -> None:
    obs, n = real_observations("3v3", 32, seed=5)
    # Only players who see at least two opponents: the pointer then has a real choice.
    sees = np.asarray(obs.entity_mask[..., n - 1 : 2 * n - 1].sum(-1)) >= 2
    assert sees.mean() > 0.3
    policy = small_policy(kinds=3, use_lstm=False)
    reset = jnp.ones(obs.entity_mask.shape[:-1], bool)
    variables = jax.jit(policy.init)(
        jax.random.key(0), policy.initial_carry(reset.shape), obs, reset
    )
    opt_state = optax.adam(3e-3).init(variables)
    target = np.asarray(nearest_opponent(obs, n))
    apply = jax.jit(policy.apply)

    def modes() -> tuple[float, float]:
        _, out = apply(variables, policy.initial_carry(reset.shape), obs, reset)
        mode = np.asarray(out.distribution().mode())
        return np.mean(mode[..., 0] == RIGHT_KIND), np.mean((mode[..., 1] == target)[sees])

    right_kind, right_pointer = modes()
    assert right_kind < 0.5 and right_pointer < 0.5  # not right by chance at the start
    rewards = []
    for iteration in range(16):  # right_pointer: 0.93 after 12 iterations, 0.98 after 16
        variables, opt_state, reward = _ppo_iteration(
            policy, variables, opt_state, obs, jax.random.key(100 + iteration)
        )
        rewards.append(float(reward))
    right_kind, right_pointer = modes()
    assert right_kind == 1.0 and right_pointer > 0.9, (right_kind, right_pointer)
    assert np.mean(rewards[-5:]) > np.mean(rewards[:5]) + 0.5
