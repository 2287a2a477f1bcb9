"""Training with rcssserver's bodies (elevens.robocup.sim, elevens.robocup.bodies.RcssSoccer):
the core's compiled trainer runs the 12-value game the wing registers, and its team plays
rcssserver's action mode."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.robocup.sim import RcssEnvConfig, rcss_config, rcss_game
from elevens.runs.logging import read_metrics_csv
from elevens.runs.loop import train
from elevens.train.config import TrainConfig, apply_overrides, validate
from tests.train.test_trainer import tiny_config

RCSS = {"env.ball_friction": 0.94, "env.ball_max_speed": 3.0, "run.eval_games": 8}


def rcss_tiny(run_dir: Path | str = "unused", **overrides: Any) -> TrainConfig:
    """The tests' tiny quickstart config in the game with the server's bodies (not validated)."""
    return apply_overrides(rcss_game(tiny_config(run_dir), server_field=False),
                           {**RCSS, **overrides})


@pytest.mark.slow
def test_a_run_with_the_servers_bodies_trains_a_team_for_rcssserver(tmp_path: Path) -> None:
    from elevens.robocup.env import RoboCupConfig, robocup_env_params
    from elevens.robocup.observe import PerceptMemory
    from elevens.robocup.play import load_robocup_team

    # A quarter of the games against the scripted 12-value team, which is also the yardstick.
    config = rcss_tiny(tmp_path, **{"run.iterations": 4, "opponent.mix": ("rcss_naive=0.25",)})
    result = train(config, progress=False)
    assert result.checkpoint is not None and result.checkpoint.is_dir()
    curves = read_metrics_csv(tmp_path)
    losses = curves["train/loss"].values
    assert len(losses) == 4 and all(math.isfinite(v) for v in losses)
    assert curves["time/env_steps"].values[-1] == 4 * 64 * 64
    outcomes = curves["eval/rcss_naive/outcome"].values
    assert len(outcomes) == 2 and all(0.0 <= v <= 1.0 for v in outcomes)  # start and end
    # The run is a 12-value team: rcssserver's thesis12 mode plays it, the "sim" rule refuses it.
    player = load_robocup_team(str(tmp_path), "thesis12")
    assert player.actions == 12
    params = robocup_env_params(RoboCupConfig(players_per_team=1))
    memory = PerceptMemory(params, ("elevens_l", "elevens_r"))
    memory.reset(np.zeros((2, 1, 2)), np.zeros((2, 1)))
    obs = jax.tree.map(lambda leaf: leaf[0], memory.observation(0, np.zeros((2, 1, 2)),
                                                                np.zeros((2, 1, 2))))
    _, actions = player.act(player.init_carry(1), obs, jax.random.key(0))
    assert np.asarray(actions).shape == (1, 12)
    try:
        load_robocup_team(str(tmp_path), "sim")
    except ValueError as error:
        assert "12-value action" in str(error)
    else:
        raise AssertionError("a 12-value team loaded for the 'sim' action mode")


@pytest.mark.parametrize(
    ("game", "flag", "value", "allowed"),
    [
        ("rcss", "run.eval_teams", ("naive",), "rcss_naive"),
        ("rcss", "opponent.mix", ("teamwork=0.5",), "rcss_naive"),
        ("thesis", "run.eval_teams", ("rcss_naive",), "(.*, )?naive, (.*, )?random, teamwork"),
        ("thesis", "opponent.mix", ("rcss_naive=0.5",), "(.*, )?naive, (.*, )?random, teamwork"),
    ],
)
def test_a_handcrafted_team_must_give_the_action_the_game_takes(
    game: str, flag: str, value: tuple[str, ...], allowed: str
) -> None:
    config = rcss_tiny() if game == "rcss" else tiny_config(**{"run.eval_teams": ()})
    with pytest.raises(ValueError, match=f"{flag} team .* takes .*: the handcrafted teams for it "
                       f"are {allowed}"):
        validate(apply_overrides(config, {flag: value}))


def test_the_games_own_fields_exist_in_its_config_only() -> None:
    validate(rcss_tiny(**{"env.see_period": 3, "env.stamina": True}))
    with pytest.raises(ValueError, match="env.see_period=0 is invalid"):
        validate(rcss_tiny(**{"env.see_period": 0}))
    for flag in ("env.see_period", "env.stamina", "env.goalie"):
        with pytest.raises(ValueError, match=f"override '{flag}': unknown field"):
            tiny_config(**{flag: 3})
    # The simulator's config cannot be switched to the other game by its name alone.
    with pytest.raises(ValueError, match="env.physics='rcss' is invalid here: this config's game"):
        tiny_config(**{"env.physics": "rcss"})


def test_the_preset_and_a_saved_config_read_back_as_the_games_class() -> None:
    config = rcss_config("11v11", **{"env.goalie": True, "env.see_period": 3})
    assert isinstance(config.learner.env, RcssEnvConfig) and config.preset == "rcss-11v11"
    assert (config.learner.env.game.field_length, config.learner.network.actions) == (105.0, 12)
    assert TrainConfig.from_json(config.to_json()) == config
    game = config.learner.make_env()
    assert game.scripted_players == (0,) and game.actions == 12
    # Built again alike it is the same game (make_learner caches on it); its settings count.
    assert game == config.learner.make_env() and hash(game) == hash(config.learner.make_env())
    assert game != rcss_config("11v11", **{"env.see_period": 3}).learner.make_env()


def test_the_goalie_routine_needs_a_player_for_the_policy() -> None:
    validate(rcss_tiny(**{"env.goalie": True, "env.players_per_team": 2}))
    with pytest.raises(ValueError, match="env.goalie=True is invalid with 1 player a side"):
        validate(rcss_tiny(**{"env.goalie": True}))


@pytest.mark.slow
def test_with_the_goalie_routine_the_goalies_samples_leave_the_policy_loss() -> None:
    """The routine plays player 0 whatever the policy sampled for it: those samples must not
    move the policy (they used to, one player in n), while the critic still learns there."""
    from elevens.train import learner, ppo

    def loss_of(goalie: bool) -> tuple[ppo.PPOLoss, ppo.PPOLoss, Any]:
        config = rcss_tiny(**{
            "env.goalie": goalie, "env.players_per_team": 2, "games_per_iteration": 4,
            "ppo.minibatch_size": 8, "env.episode_length": 8,
        })
        setup = learner.make_setup(config.learner, config.learner.make_env())
        state = learner.init_state(setup, jax.random.key(0))
        data = learner.collect(setup, state, jax.random.key(1))
        values = jnp.repeat(setup.critic.apply(state.params.critic, data.game_global_state),
                            2, axis=0)
        returns, gae_advantages = learner.advantages(setup.config.ppo, data, values)
        batch = learner.update_batch(setup, data, values, returns, gae_advantages, None)
        # The goalie's recorded samples replaced by others: only a masked loss ignores that.
        other = batch.replace(
            pre_tanh=batch.pre_tanh.at[:, 0].add(0.7),
            log_prob=batch.log_prob.at[:, 0].add(-1.3),
        )
        hp = setup.config.ppo
        losses = [ppo.sequence_loss(setup.policy, setup.critic, hp, state.params, b)[1]
                  for b in (batch, other)]
        return losses[0], losses[1], batch.policy_mask

    masked, masked_other, mask = loss_of(goalie=True)
    assert mask is not None and mask.shape == (4, 2, 8)
    assert not np.asarray(mask)[:, 0].any() and np.asarray(mask)[:, 1].all()
    for name in ("policy", "entropy", "value", "approx_kl"):
        np.testing.assert_allclose(
            float(getattr(masked, name)), float(getattr(masked_other, name)), rtol=1e-6
        )
    plain, plain_other, no_mask = loss_of(goalie=False)
    assert no_mask is None
    assert not np.isclose(float(plain.policy), float(plain_other.policy))


def test_players_a_server_routine_played_leave_the_policy_loss_too() -> None:
    """elevens robocup train records who its match routines played (Rollout.scripted); those
    entries join the goalie routine's in the policy mask."""
    from elevens.train import learner

    config = rcss_tiny(**{
        "env.goalie": True, "env.players_per_team": 2, "games_per_iteration": 4,
        "ppo.minibatch_size": 8, "env.episode_length": 8,
    })
    setup = learner.make_setup(config.learner, config.learner.make_env())
    # The mask reads the rollout's shapes and its scripted entries, not what was played: the
    # rollout collect would return (traced, not compiled), filled with zeros.
    shapes = jax.eval_shape(
        lambda key: learner.collect(setup, learner.init_state(setup, key), key),
        jax.random.key(0),
    )
    data = jax.tree.map(lambda leaf: jnp.zeros(leaf.shape, leaf.dtype), shapes)
    goalie_only = np.asarray(learner.policy_played(setup, data))
    assert not goalie_only[:, 0].any() and goalie_only[:, 1].all()  # [games, players, T]
    scripted = np.zeros((8, 8), bool)  # [U = 4 games x 2 players, T]
    scripted[1, 2:5] = True  # game 0, player 1, steps 2-4: a set piece
    scripted[0, :] = True  # a goalie: already out
    played = np.asarray(learner.policy_played(setup, data.replace(scripted=jnp.asarray(scripted))))
    expected = goalie_only.copy()
    expected[0, 1, 2:5] = False
    np.testing.assert_array_equal(played, expected)


def test_the_wings_teams_are_known_whatever_was_imported_first() -> None:
    """The core's team specs read the registries when asked, not when first imported: a process
    that imported the core's team loading before the wing still finds the wing's teams."""
    import subprocess
    import sys

    code = (
        "import elevens.runs.teams as t; import elevens.robocup; "
        "print(t.parse_team_spec('rcss_naive').handcrafted, t.parse_team_spec('rcss-gpu').shipped)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["rcss_naive", "rcss-gpu"]
