"""The parametrised head in the training stack: its flags refused with one line when bad, a
config of it saved and read back, a game of another action count refused, and the learner's
PPO update (critic, squashed entropy, update batch) on a rollout of its 4-value actions."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.play import NetworkActor
from elevens.runs.teams import load_team
from elevens.teams.base import Team
from elevens.teams.network import NetworkTeam
from elevens.teams.trained import save_networks
from elevens.train.config import EnvConfig, TrainConfig, make_config
from elevens.train.learner import make_learner
from elevens.train.rollout import StepRecord, collected

HEAD = {"network.head": "parametrised", "network.kinds": 3, "network.actions": 4}


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"network.head": "pointer"},
         r"^network.head='pointer' is invalid: allowed values are \('gaussian', 'parametrised'\)$"),
        ({**HEAD, "network.kinds": 0},
         r"^network.kinds=0 is invalid with network.head='parametrised': it must be an int >= 1"),
        ({**HEAD, "network.kinds": 2.5}, r"^network.kinds=2.5 is invalid with"),
        ({**HEAD, "network.actions": 2},
         r"^network.actions=2 is invalid with network.head='parametrised': its action is 4 "
         r"values \(kind, pointer, x, y\); set network.actions=4$"),
        ({**HEAD, "network.use_attention": False},
         r"^network.use_attention=False is invalid with network.head='parametrised'"),
        ({"network.kinds": 4}, r"^network.kinds=4 is invalid with network.head='gaussian'"),
        ({**HEAD, "network.kind_mask": "nope"},
         r"^network.kind_mask='nope' is invalid: allowed values are '' \(every kind\) and the "
         r"masks of the games known"),
        ({"network.kind_mask": "ball"},
         r"^network.kind_mask='ball' is invalid with network.head='gaussian'"),
        ({"network.actions": 5}, r"^network.actions=5 is invalid: it must be 2 \(move, rot\), 4 "
         r"\(a parametrised action: kind, pointer, x, y\) or 12 "),
    ],
)
def test_bad_head_flags_get_one_line(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message) as raised:
        make_config("quickstart", **overrides)
    assert "\n" not in str(raised.value)


def test_the_head_is_saved_and_a_config_without_it_reads_as_gaussian() -> None:
    config = make_config("quickstart", **HEAD)
    again = TrainConfig.from_json(config.to_json())
    assert again == config and again.learner.network.policy().kinds == 3
    saved = make_config("quickstart").to_dict()
    for name in ("head", "kinds", "kind_mask"):
        del saved["learner"]["network"][name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        network = TrainConfig.from_saved(saved, "x.json").learner.network
    assert (network.head, network.kinds, network.policy().kinds) == ("gaussian", 0, 0)


def test_a_game_of_another_action_count_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    from elevens.env.soccer import Soccer
    from elevens.train import config as config_module

    class FourValueSoccer(Soccer):
        actions = 4

    @dataclasses.dataclass(frozen=True)
    class FourValueGame(EnvConfig):
        physics: str = "four"
        PHYSICS: ClassVar[str] = "four"

        def make_env(self, players_per_team: int) -> Soccer:
            return FourValueSoccer(players_per_team)

        @property
        def actions(self) -> int:
            return FourValueSoccer.actions

    monkeypatch.setitem(config_module.GAMES, "four", FourValueGame)
    head = make_config("quickstart", **HEAD, **{"run.eval_teams": (), "run.write_gif": False})
    with pytest.raises(ValueError, match=r"^network.actions=4: the game Soccer "
                       r"\(env.physics='thesis'\) takes 2 action values"):
        make_learner(head.learner, head.learner.make_env())
    fields = {f.name: getattr(head.learner.env, f.name) for f in dataclasses.fields(EnvConfig)}
    four = dataclasses.replace(head.learner, env=FourValueGame(**{**fields, "physics": "four"}))
    make_learner(four, four.make_env())  # builds (nothing compiles until it runs)
    gaussian = dataclasses.replace(four, network=make_config("quickstart").learner.network)
    with pytest.raises(ValueError, match=r"^network.actions=2: the game FourValueSoccer "
                       r"\(env.physics='four'\) takes 4 action values"):
        make_learner(gaussian, gaussian.make_env())
    # The game given must be the config's size.
    with pytest.raises(ValueError, match=r"^env plays 3 a side, but the config's game has "
                       r"env.players_per_team=1"):
        make_learner(four, FourValueSoccer(3))
    # A team of the head, met in the simulator's own game (an evaluation, a fixed opponent).
    team = Team(name="pointer", policy=NetworkTeam(), spec="runs/p", actions=4)
    with pytest.raises(ValueError, match=r"^team 'pointer' \(runs/p\) gives 4 action values; "
                       r"this game takes 2"):
        team.check_size(2, 2)


# Slow (compiles the whole learner, ~37 s): the head's PPO learning stays in the default suite in
# tests/nets/test_parametrised.py, the mode and sampling of a NetworkTeam too.
@pytest.mark.slow
def test_ppo_updates_the_parametrised_policy_and_its_export_plays(tmp_path: Path) -> None:
    """Rollouts of the policy's own samples, reward 1 at every step where it picked kind 1:
    two learner updates (squashed entropy: its noise has the 4 columns of the raw sample)
    raise the probability of kind 1 and leave everything finite. The exported networks load
    as a team of 4-value actions that plays the mode."""
    config = make_config(
        "quickstart", **HEAD,
        **{"ppo.entropy_estimator": "squashed", "games_per_iteration": 8,
           "ppo.minibatch_size": 4, "ppo.learning_rate": 3e-3, "env.players_per_team": 2,
           "run.eval_teams": (), "run.write_gif": False},
    )
    learner = make_learner(config.learner, config.learner.make_env(), external_games=True)
    env, params, policy = learner.env, learner.env_params, learner.policy
    games, n, steps = 8, 2, 4
    state = learner.init(jax.random.key(0))
    starts = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(
        jax.random.split(jax.random.key(1), games), params)
    obs = jax.tree.map(lambda x: x[:, 0], starts[1])  # side 0's players, leading [G, n]
    global_states = jax.jit(jax.vmap(env.global_state, in_axes=(0, None)))(starts[0], params)
    global_state = jax.tree.map(lambda x: x[:, 0], global_states)

    @jax.jit
    def play(policy_params: Any, key: jax.Array) -> Any:
        actor = NetworkActor(policy, policy_params)
        carry, records = actor.init_carry(games, n), []
        for t, step_key in enumerate(jax.random.split(key, steps)):
            reset = jnp.full((games, n), t == 0)
            carry, _, sample = actor.act(carry, obs, reset, step_key)
            reward = (sample.pre_tanh[..., 0] == 1).astype(jnp.float32)
            zeros = jnp.zeros((games, n))
            records.append(StepRecord(
                obs=obs, global_state=global_state, pre_tanh=sample.pre_tanh,
                log_prob=sample.log_prob, reward=reward, done=jnp.full(games, t == steps - 1),
                truncated=jnp.full(games, t == steps - 1), reset=jnp.full(games, t == 0),
                goal_reward=reward, ball_shaping=zeros, approach_shaping=zeros,
                possession_shaping=zeros, holder=jnp.zeros(games),
            ))
        history = jax.tree.map(lambda *x: jnp.stack(x), *records)
        goals = jnp.zeros(games, jnp.int32)
        return collected(history, goals, goals, jnp.zeros(games, jnp.int32),
                         actor.init_carry(games, n), n)

    def kind_one(policy_params: Any) -> float:
        carry = policy.initial_carry((games, n))
        _, out = policy.apply(policy_params, carry, obs, jnp.ones((games, n), bool))
        return float(jnp.mean(jax.nn.softmax(out.kind_logits)[..., 1]))

    improve = jax.jit(learner.improve)
    before = kind_one(state.params.policy)
    for iteration in range(2):
        rollout = play(state.params.policy, jax.random.key(10 + iteration))
        assert rollout.transitions.pre_tanh.shape == (games * n, steps, 4)
        state, metrics = improve(state, rollout, jax.random.key(20 + iteration),
                                 jax.random.key(30 + iteration))
        assert all(np.isfinite(np.asarray(value)).all() for value in jax.tree.leaves(metrics))
    after = kind_one(state.params.policy)
    assert after > before + 0.05, (before, after)

    networks = {"policy": state.params.policy, "critic": state.params.critic}
    save_networks(tmp_path / "team", jax.device_get(networks), config.to_dict())
    team = load_team(str(tmp_path / "team"), deterministic=True)
    assert team.actions == 4 and team.policy.policy.kinds == 3  # type: ignore[attr-defined]
    one = jax.tree.map(lambda x: x[0], obs)
    _, actions = team.policy.act(team.params, team.policy.init_carry(n), one, jax.random.key(0))
    _, out = policy.apply(state.params.policy, policy.initial_carry((n,)), one, jnp.zeros(n, bool))
    np.testing.assert_allclose(actions, out.distribution().mode(), rtol=1e-5, atol=1e-6)
