"""TrainConfig: presets, dotted overrides, validation errors before anything compiles, JSON."""

from __future__ import annotations

import dataclasses
import json
import time

import pytest

from elevens.train.config import (
    OPPONENT_KINDS,
    PRESETS,
    EnvConfig,
    TrainConfig,
    config_differences,
    load_config,
    make_config,
    mix_schedule,
    scenario_config,
    validate,
)
from elevens.train.ppo import PPOHyperparams


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_presets_are_valid_and_consistent(preset: str) -> None:
    config = make_config(preset)
    assert config.preset == preset
    assert config.ppo.batch_size == config.run.games_per_iteration * config.players_per_team
    assert config.units_per_iteration % config.ppo.minibatch_size == 0


def test_thesis_presets_use_table_6_1() -> None:
    for preset in ("2v2", "11v11"):
        config = make_config(preset)
        assert isinstance(config.ppo, PPOHyperparams)  # the ppo.py class, not a copy
        assert config.ppo.epochs == 5 and config.ppo.clip_epsilon == 0.1
        assert config.ppo.value_weight == 0.5
        assert config.env.episode_length == 400
        assert config.network.features == 64 and config.network.lstm_features == 32
    # 11 a side: table 6.1 exactly, whole games in a minibatch, 5 games = 55 sequences.
    assert make_config("11v11").ppo == PPOHyperparams(minibatch_size=55)
    assert make_config("11v11").opponent.kind == "polyak"
    assert make_config("11v11").players_per_team == 11
    assert make_config("2v2").env.spawn == "random"


def test_2v2_preset_documents_how_to_get_table_6_1_back() -> None:
    # The 2v2 preset tunes the update for wall-clock; the flags its comment names restore table
    # 6.1 exactly (and the thesis' Polyak rate).
    table = make_config(
        "2v2",
        **{
            "ppo.learning_rate": 1e-4,
            "ppo.advantage_estimator": "monte_carlo",
            "ppo.gamma": 0.999,
            "ppo.normalize_advantages": False,
            "ppo.batch_size": 660,
            "ppo.minibatch_size": 60,
            "run.games_per_iteration": 330,
            "opponent.polyak_tau": 0.01,
            "env.shaping_schedule": True,
            "ppo.entropy_weight": 0.01,
        },
    )
    assert table.ppo == PPOHyperparams()
    assert table.env == EnvConfig(
        scenario="2v2", spawn="random", episode_length=400
    )
    assert table.opponent == make_config("11v11").opponent
    tuned = make_config("2v2")
    assert tuned.ppo.advantage_estimator == "gae" and tuned.ppo.normalize_advantages
    assert tuned.opponent.kind == "polyak" and tuned.opponent.polyak_tau == 0.05
    assert tuned.ppo.entropy_weight == 1e-3


def test_dotted_and_double_underscore_overrides() -> None:
    config = make_config(
        "2v2", **{"ppo.learning_rate": 3e-4, "run.iterations": 7}, opponent__kind="league"
    )
    assert config.ppo.learning_rate == 3e-4
    assert config.run.iterations == 7
    assert config.opponent.kind == "league"
    # Untouched fields keep the preset's values.
    assert config.ppo.epochs == 5 and config.env.scenario == "2v2"


def test_whole_group_override() -> None:
    env = dataclasses.replace(make_config("quickstart").env, episode_length=50)
    assert make_config("quickstart", env=env).env.episode_length == 50


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        ({"ppo.learning_rate": -1e-4}, ["ppo.learning_rate", "> 0"]),
        ({"ppo.learning_rate": 0.0}, ["ppo.learning_rate", "> 0"]),
        ({"ppo.learning_rate": float("nan")}, ["ppo.learning_rate"]),
        ({"ppo.minibatch_size": 1000}, ["ppo.minibatch_size=1000", "larger", "batch_size"]),
        ({"ppo.minibatch_size": 7}, ["minibatch_size=7", "divide"]),
        (
            {"env.scenario": "2v2", "run.games_per_iteration": 32, "ppo.minibatch_size": 1},
            ["ppo.minibatch_size=1", "multiple of 2", "whole games", "2, 4"],
        ),
        ({"ppo.epochs": 0}, ["ppo.epochs"]),
        ({"ppo.gamma": 1.5}, ["ppo", "gamma"]),
        ({"ppo.advantage_estimator": "td"}, ["advantage_estimator", "monte_carlo", "gae"]),
        ({"opponent.kind": "zoo"}, ["opponent.kind='zoo'", "polyak", "self", "league"]),
        ({"opponent.polyak_tau": 0.0}, ["opponent.polyak_tau"]),
        ({"opponent.freeze_threshold": 2.0}, ["opponent.freeze_threshold"]),
        ({"env.scenario": "2v3"}, ["env.scenario", "NvN"]),
        ({"env.scenario": "12v12"}, ["env.scenario", "1 to 11"]),
        ({"env.spawn": "corner"}, ["env.spawn", "formation", "random"]),
        ({"env.episode_length": 0}, ["env.episode_length", ">= 1"]),
        ({"env.goal_width": 80.0}, ["env.goal_width", "field_width"]),
        ({"env.shaping_threshold": -0.1}, ["env.shaping_threshold"]),
        ({"network.num_heads": 3}, ["network.num_heads", "divide", "features"]),
        ({"network.features": 0}, ["network.features"]),
        ({"run.games_per_iteration": 0}, ["run.games_per_iteration"]),
        ({"run.games_per_iteration": 10}, ["ppo.batch_size", "run.games_per_iteration"]),
        ({"run.eval_teams": ("random", "random")}, ["run.eval_teams", "naive", "teamwork"]),
        ({"run.iterations_per_chunk": 0}, ["run.iterations_per_chunk"]),
        ({"run.seed": 1.5}, ["run.seed"]),
        ({"run.max_minutes": -5.0}, ["run.max_minutes=-5.0", ">= 0"]),
        ({"run.max_minutes": float("inf")}, ["run.max_minutes=inf", "finite"]),
        ({"run.init_from": 3}, ["run.init_from=3", "checkpoint path"]),
        ({"env.mix": ("2v2",)}, ["env.mix_shares=()", "one share in (0, 1) per game"]),
        ({"env.mix": ("2v2",), "env.mix_shares": (1.0,)}, ["env.mix_shares=(1.0,)"]),
        ({"env.mix": ("1v1",), "env.mix_shares": (0.5,)}, ["env.mix=('1v1',)", "differ"]),
        ({"env.mix": ("2v3",), "env.mix_shares": (0.5,)}, ["env.mix", "NvN"]),
        ({"env.mix": ("3v3",), "env.mix_shares": (0.5,)},
         ["ppo.batch_size=64", "multiples of 3"]),
        ({"env.mix": ("2v2",), "env.mix_shares": (0.5,), "opponent.kind": "league"},
         ["opponent.kind='league'", "'polyak' or 'self'"]),
        ({"env.mix": ("2v2",), "env.mix_shares": (0.5,), "network.use_attention": False},
         ["network.use_attention=False", "one team size"]),
    ],
)
def test_bad_values_name_the_field(overrides: dict, words: list[str]) -> None:
    with pytest.raises(ValueError) as error:
        make_config("quickstart", **overrides)
    for word in words:
        assert word in str(error.value), (word, str(error.value))


def test_unknown_preset_lists_the_allowed_ones() -> None:
    with pytest.raises(ValueError, match="preset='3v3' is unknown") as error:
        make_config("3v3")
    for name in PRESETS:
        assert name in str(error.value)


def test_unknown_field_or_group_lists_the_allowed_ones() -> None:
    with pytest.raises(ValueError, match="run has no field 'iters'.*iterations"):
        make_config("quickstart", **{"run.iters": 3})
    with pytest.raises(ValueError, match="unknown config group 'optim'.*ppo"):
        make_config("quickstart", **{"optim.lr": 3})


def test_validate_catches_a_config_built_by_hand() -> None:
    config = make_config("quickstart")
    bad_ppo = dataclasses.replace(config.ppo)
    object.__setattr__(bad_ppo, "learning_rate", -1.0)  # past PPOHyperparams' own check
    with pytest.raises(ValueError, match="ppo.learning_rate=-1.0"):
        validate(dataclasses.replace(config, ppo=bad_ppo))
    bad_env = EnvConfig(scenario="eleven")
    with pytest.raises(ValueError, match="env.scenario='eleven'"):
        dataclasses.replace(config, env=bad_env).validate()


def test_validation_is_fast_and_compiles_nothing() -> None:
    # Errors must come before any tracing: a bad config fails in well under a second, and the
    # trainer factory refuses it before building anything.
    from elevens.train.learner import make_learner

    config = make_config("11v11")
    bad_ppo = dataclasses.replace(config.ppo)
    object.__setattr__(bad_ppo, "learning_rate", -1.0)  # past PPOHyperparams' own check
    bad = dataclasses.replace(config, ppo=bad_ppo)
    start = time.perf_counter()
    with pytest.raises(ValueError, match="learning_rate"):
        make_learner(bad)
    assert time.perf_counter() - start < 0.5


def test_every_opponent_kind_is_accepted() -> None:
    for kind in OPPONENT_KINDS:
        assert make_config("quickstart", **{"opponent.kind": kind}).opponent.kind == kind


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_json_round_trip(preset: str, tmp_path) -> None:
    config = make_config(preset, **{"run.eval_teams": ("naive",), "ppo.entropy_weight": 0})
    text = config.to_json()
    json.loads(text)  # plain JSON
    again = TrainConfig.from_json(text)
    assert again == config
    assert isinstance(again.run.eval_teams, tuple)
    assert isinstance(again.ppo, PPOHyperparams)
    assert isinstance(again.ppo.entropy_weight, float)  # an int in JSON is still a float field
    path = tmp_path / "config.json"
    path.write_text(text)
    assert load_config(path) == config


def test_from_dict_fills_fields_an_older_version_did_not_save() -> None:
    data = make_config("quickstart").to_dict()
    del data["opponent"]["league_window"]
    del data["run"]["eval_games"]
    with pytest.warns(UserWarning, match="older version") as caught:
        config = TrainConfig.from_dict(data, fill_missing=True)
    message = str(caught[0].message)
    assert "opponent.league_window" in message and "run.eval_games" in message
    defaults = TrainConfig()
    assert config.opponent.league_window == defaults.opponent.league_window
    assert config.run.eval_games == defaults.run.eval_games
    assert config.ppo == make_config("quickstart").ppo  # what was saved is kept
    data["run"]["colour"] = "blue"  # still an error: a typo, or a newer version's field
    with pytest.raises(ValueError, match=r"unknown keys \['colour'\].*newer version"):
        TrainConfig.from_dict(data, fill_missing=True)


def test_from_dict_rejects_unknown_and_missing_keys() -> None:
    data = make_config("quickstart").to_dict()
    data["run"]["colour"] = "blue"
    with pytest.raises(ValueError, match=r"config\.run.*unknown keys \['colour'\]"):
        TrainConfig.from_dict(data)
    data = make_config("quickstart").to_dict()
    del data["ppo"]["gamma"]
    with pytest.raises(ValueError, match=r"config\.ppo.*missing keys \['gamma'\]"):
        TrainConfig.from_dict(data)


def test_config_differences_ignore_host_loop_fields() -> None:
    saved = make_config("quickstart")
    longer = make_config(
        "quickstart",
        **{"run.iterations": 500, "run.eval_every": 3, "run.run_dir": "elsewhere",
           "run.max_minutes": 30.0},
    )
    assert config_differences(saved, longer) == []
    other = make_config("quickstart", **{"ppo.learning_rate": 5e-4, "run.seed": 3})
    differences = config_differences(saved, other)
    assert len(differences) == 2
    assert any(d.startswith("ppo.learning_rate: 0.001 -> 0.0005") for d in differences)
    assert any(d.startswith("run.seed: 0 -> 3") for d in differences)


def test_cli_args_parse_a_preset_with_flag_overrides() -> None:
    import tyro

    from elevens.cli.bench import TrainBenchArgs
    from elevens.cli.train import TrainArgs, command_flags_first

    args = tyro.cli(
        TrainArgs,
        args=["--resume", "2v2", "--ppo.learning-rate", "3e-4", "--run.run-dir", "runs/x",
              "--opponent.kind", "league"],
    )
    assert args.resume and args.progress
    assert args.config.preset == "2v2"
    assert args.config.ppo.learning_rate == 3e-4
    assert args.config.ppo.epochs == 5  # the preset's value where no flag is given
    assert args.config.opponent.kind == "league"
    assert args.config.run.run_dir == "runs/x"
    # The command's own flags may follow the preset too (moved in front before tyro parses).
    after = tyro.cli(
        TrainArgs, args=command_flags_first(["2v2", "--run.seed", "3", "--resume", "--no-progress"])
    )
    assert after.resume and not after.progress
    assert after.config.preset == "2v2" and after.config.run.seed == 3
    default = tyro.cli(TrainArgs, args=[])
    assert default.config == make_config("quickstart")
    bench = tyro.cli(TrainBenchArgs, args=["--players", "1", "--json"])
    assert bench.players == (1,) and bench.json


def test_cli_train_validates_before_compiling(capsys: pytest.CaptureFixture[str]) -> None:
    import tyro

    from elevens.cli.train import TrainArgs, train_command

    start = time.perf_counter()
    # PPOHyperparams refuses the value while tyro builds the config: usage error, exit code 2.
    with pytest.raises(SystemExit) as exit_info:
        train_command(tyro.cli(TrainArgs, args=["11v11", "--ppo.learning-rate", "-0.1"]))
    assert exit_info.value.code == 2
    assert "learning_rate=-0.1 is invalid" in capsys.readouterr().err
    # A value only the whole config can judge is refused by validate() in train_command, also
    # as a usage error (no traceback).
    args = tyro.cli(TrainArgs, args=["11v11", "--run.games-per-iteration", "7"])
    with pytest.raises(SystemExit) as exit_info:
        train_command(args)
    assert exit_info.value.code == 2
    assert "elevens train: error: ppo.batch_size=660 is invalid" in capsys.readouterr().err
    assert time.perf_counter() - start < 0.5


def test_a_mixed_run_shares_its_chunks_between_sizes_by_a_fixed_schedule() -> None:
    config = make_config("11v11", **{
        "env.mix": ("2v2", "5v5"), "env.mix_shares": (0.5, 0.25),
        "run.games_per_iteration": 20, "ppo.batch_size": 220, "ppo.minibatch_size": 110,
    })
    schedule = mix_schedule(config, 400)
    assert schedule[:8] == ["2v2", "11v11", "5v5", "2v2", "2v2", "11v11", "5v5", "2v2"]
    assert [schedule.count(game) for game in ("2v2", "5v5", "11v11")] == [200, 100, 100]
    assert mix_schedule(config, 7) == schedule[:7]  # a resumed run follows the same one
    two = scenario_config(config, "2v2")
    assert (two.env.scenario, two.run.games_per_iteration, two.env.mix) == ("2v2", 110, ())
    assert two.ppo == config.ppo and two.validate() is two
    # Without a mix, every chunk plays the scenario.
    assert set(mix_schedule(make_config("2v2"), 5)) == {"2v2"}
