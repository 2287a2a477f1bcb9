"""TrainConfig: presets, overrides named as flags, validation errors before anything compiles,
JSON with config_version 2, and version-1 files read field by field."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import ClassVar

import pytest

from elevens.env.params import EnvParams
from elevens.train.config import (
    CONFIG_VERSION,
    OPPONENT_KINDS,
    PRESET_DESCRIPTIONS,
    PRESETS,
    EnvConfig,
    LearnerConfig,
    TrainConfig,
    config_differences,
    config_paths,
    load_config,
    make_config,
    migrate_v1,
    mix_schedule,
    opponent_mix,
    scenario_config,
    validate,
)
from elevens.train.ppo import PPOHyperparams
from tests.train.version_1 import as_version_1

ROOT = Path(__file__).resolve().parents[2]
COMMITTED_CONFIGS = sorted(
    [
        *ROOT.glob("src/elevens/teams/trained/*/config.json"),
        *ROOT.glob("docs/results/**/config.json"),
    ]
)

# The core's own presets; a wing's (PRESET_DESCRIPTIONS) exist only once it is imported, so the
# tests are collected alike whatever another test file imported first.
CORE_PRESETS = tuple(sorted(name for name in PRESETS if name not in PRESET_DESCRIPTIONS))


@pytest.mark.parametrize("preset", CORE_PRESETS)
def test_presets_are_valid_and_consistent(preset: str) -> None:
    config = make_config(preset)
    learner = config.learner
    assert config.preset == preset
    assert learner.batch_size == learner.games_per_iteration * learner.players_per_team
    assert learner.batch_size % learner.ppo.minibatch_size == 0
    assert learner.num_minibatches == learner.batch_size // learner.ppo.minibatch_size


def test_thesis_presets_use_table_6_1() -> None:
    for preset in ("2v2", "11v11"):
        learner = make_config(preset).learner
        assert isinstance(learner.ppo, PPOHyperparams)  # the ppo.py class, not a copy
        assert learner.ppo.epochs == 5 and learner.ppo.clip_epsilon == 0.1
        assert learner.ppo.value_weight == 0.5
        assert learner.env.game.episode_length == 400
        assert learner.network.features == 64 and learner.network.lstm_features == 32
    # 11 a side: table 6.1 exactly: a batch of 660 sequences (60 games x 11), whole games in a
    # minibatch, 5 games = 55 sequences, 12 minibatches.
    eleven = make_config("11v11").learner
    assert eleven.ppo == PPOHyperparams(minibatch_size=55)
    assert (eleven.batch_size, eleven.num_minibatches) == (660, 12)
    assert eleven.opponent.kind == "polyak"
    assert eleven.players_per_team == 11 and eleven.env.scenario == "11v11"
    assert make_config("2v2").learner.env.game.spawn == "random"


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
            "ppo.minibatch_size": 60,
            "games_per_iteration": 330,
            "opponent.polyak_tau": 0.01,
            "env.shaping_schedule": True,
            "ppo.entropy_weight": 0.01,
        },
    )
    assert table.learner.ppo == PPOHyperparams()
    assert table.learner.batch_size == 660
    assert table.learner.env == EnvConfig(game=EnvParams(players_per_team=2, spawn="random"))
    assert table.learner.opponent == make_config("11v11").learner.opponent
    tuned = make_config("2v2").learner
    assert tuned.ppo.advantage_estimator == "gae" and tuned.ppo.normalize_advantages
    assert tuned.opponent.kind == "polyak" and tuned.opponent.polyak_tau == 0.05
    assert tuned.ppo.entropy_weight == 1e-3


def test_dotted_and_double_underscore_overrides() -> None:
    config = make_config(
        "2v2",
        **{"ppo.learning_rate": 3e-4, "run.iterations": 7, "env.kick_impulse": 5.0},
        opponent__kind="league", games_per_iteration=32,
    )
    learner = config.learner
    assert learner.ppo.learning_rate == 3e-4
    assert config.run.iterations == 7
    assert learner.opponent.kind == "league"
    assert learner.env.game.kick_impulse == 5.0  # any EnvParams field, not only a copied few
    assert (learner.games_per_iteration, learner.batch_size) == (32, 64)
    # Untouched fields keep the preset's values.
    assert learner.ppo.epochs == 5 and learner.env.scenario == "2v2"
    assert learner.env.game.goal_width == EnvParams().goal_width


def test_overrides_of_one_group_apply_together() -> None:
    # goal_width may exceed the old field_width: the group is rebuilt once, then checked.
    config = make_config("quickstart", **{"env.goal_width": 30.0, "env.field_width": 40.0})
    assert (config.learner.env.game.goal_width, config.learner.env.game.field_width) == (30, 40)


def test_every_env_params_field_is_an_override_and_a_flag() -> None:
    import tyro

    from elevens.cli.train import TrainArgs

    paths = config_paths(make_config("quickstart"))
    for field in dataclasses.fields(EnvParams):
        assert paths[f"env.{field.name}"] == f"learner.env.game.{field.name}"
    args = tyro.cli(
        TrainArgs, args=["quickstart", "--env.wall-restitution", "0.3",
                         "--env.players-per-team", "3", "--games-per-iteration", "8",
                         "--ppo.minibatch-size", "12"],
    )
    learner = args.config.learner
    assert learner.env.game.wall_restitution == 0.3 and learner.env.scenario == "3v3"
    assert learner.batch_size == 24 and learner.num_minibatches == 2


def test_whole_group_override() -> None:
    base = make_config("quickstart").learner
    env = dataclasses.replace(base.env, game=base.env.game.replace(episode_length=50))
    assert make_config("quickstart", env=env).learner.env.game.episode_length == 50
    learner = dataclasses.replace(base, games_per_iteration=32)
    assert make_config("quickstart", learner=learner).learner.batch_size == 32


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        ({"ppo.learning_rate": -1e-4}, ["ppo.learning_rate", "> 0"]),
        ({"ppo.learning_rate": 0.0}, ["ppo.learning_rate", "> 0"]),
        ({"ppo.learning_rate": float("nan")}, ["ppo.learning_rate"]),
        ({"ppo.minibatch_size": 1000}, ["ppo.minibatch_size=1000", "divide", "64 x 1"]),
        ({"ppo.minibatch_size": 7}, ["minibatch_size=7", "divide"]),
        (
            {"env.players_per_team": 2, "games_per_iteration": 32, "ppo.minibatch_size": 1},
            ["ppo.minibatch_size=1", "multiple of 2", "whole games", "2, 4"],
        ),
        ({"ppo.epochs": 0}, ["ppo.epochs"]),
        ({"ppo.gamma": 1.5}, ["ppo", "gamma"]),
        ({"ppo.advantage_estimator": "td"}, ["advantage_estimator", "monte_carlo", "gae"]),
        ({"opponent.kind": "zoo"}, ["opponent.kind='zoo'", "polyak", "self", "league"]),
        ({"opponent.polyak_tau": 0.0}, ["opponent.polyak_tau"]),
        ({"opponent.freeze_threshold": 2.0}, ["opponent.freeze_threshold"]),
        ({"env.scenario": "2v3"}, ["env.scenario", "renamed", "env.players_per_team"]),
        ({"ppo.batch_size": 64}, ["ppo.batch_size", "renamed", "games_per_iteration x players"]),
        ({"run.games_per_iteration": 64}, ["renamed", "use games_per_iteration"]),
        ({"env.players_per_team": 12}, ["env: players_per_team=12", "1 to 11"]),
        ({"env.spawn": "corner"}, ["env: spawn='corner'", "formation", "random"]),
        ({"env.episode_length": 0}, ["env: episode_length=0"]),
        ({"env.goal_width": 80.0}, ["env: goal_width=80.0", "field_width"]),
        ({"env.kick_impulse": -1.0}, ["env: kick_impulse=-1.0", ">= 0"]),
        ({"env.shaping_threshold": -0.1}, ["env.shaping_threshold"]),
        ({"network.num_heads": 3}, ["network.num_heads", "divide", "features"]),
        ({"network.features": 0}, ["network.features"]),
        ({"games_per_iteration": 0}, ["games_per_iteration"]),
        ({"games_per_iteration": 10}, ["ppo.minibatch_size=16", "10 x 1"]),
        ({"run.eval_teams": ("random", "random")}, ["run.eval_teams", "naive", "teamwork"]),
        ({"iterations_per_chunk": 0}, ["iterations_per_chunk"]),
        ({"run.seed": 1.5}, ["run.seed"]),
        ({"run.max_minutes": -5.0}, ["run.max_minutes=-5.0", ">= 0"]),
        ({"run.max_minutes": float("inf")}, ["run.max_minutes=inf", "finite"]),
        ({"run.init_from": 3}, ["run.init_from=3", "checkpoint path"]),
        ({"env.mix": ("2v2",)}, ["env.mix_shares=()", "one share in (0, 1) per game"]),
        ({"env.mix": ("2v2",), "env.mix_shares": (1.0,)}, ["env.mix_shares=(1.0,)"]),
        ({"env.mix": ("1v1",), "env.mix_shares": (0.5,)}, ["env.mix=('1v1',)", "differ"]),
        ({"env.mix": ("2v3",), "env.mix_shares": (0.5,)}, ["env.mix", "NvN"]),
        ({"env.mix": ("3v3",), "env.mix_shares": (0.5,)},
         ["batch of 64 player sequences", "multiples of 3"]),
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
    for name in CORE_PRESETS:
        assert name in str(error.value)


def test_unknown_field_or_group_lists_the_allowed_ones() -> None:
    with pytest.raises(ValueError, match="'run.iters': unknown field.*run.iterations"):
        make_config("quickstart", **{"run.iters": 3})
    with pytest.raises(ValueError, match="'optim.lr': unknown field.*ppo.epochs"):
        make_config("quickstart", **{"optim.lr": 3})


def _with_learner(config: TrainConfig, **fields: object) -> TrainConfig:
    return dataclasses.replace(config, learner=dataclasses.replace(config.learner, **fields))


def test_validate_catches_a_config_built_by_hand() -> None:
    config = make_config("quickstart")
    bad_ppo = dataclasses.replace(config.learner.ppo)
    object.__setattr__(bad_ppo, "learning_rate", -1.0)  # past PPOHyperparams' own check
    with pytest.raises(ValueError, match="ppo.learning_rate=-1.0"):
        validate(_with_learner(config, ppo=bad_ppo))
    with pytest.raises(ValueError, match="env.game must be an EnvParams"):
        _with_learner(config, env=EnvConfig(game="eleven")).validate()  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="learner must be a LearnerConfig"):
        dataclasses.replace(config, learner=config.run).validate()  # type: ignore[arg-type]


def test_validation_compiles_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    # Errors must come before any tracing: the trainer factory refuses a bad config before
    # building (tracing, compiling) anything.
    from elevens.train import learner as learner_module

    monkeypatch.setattr(learner_module, "_build_learner", _not_built)
    config = make_config("11v11")
    bad_ppo = dataclasses.replace(config.learner.ppo)
    object.__setattr__(bad_ppo, "learning_rate", -1.0)  # past PPOHyperparams' own check
    bad = _with_learner(config, ppo=bad_ppo)
    with pytest.raises(ValueError, match="learning_rate"):
        learner_module.make_learner(bad.learner, bad.learner.make_env())


def _not_built(*args: object, **kwargs: object) -> None:
    raise AssertionError("a learner was built (traced and compiled) for a refused config")


def test_the_learner_refuses_a_game_that_is_not_its_configs(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The caller builds the game; a wrong one gets one line, before anything is built.
    from elevens.env.soccer import Soccer
    from elevens.runs.teams import team_on_field
    from elevens.train import learner as learner_module

    monkeypatch.setattr(learner_module, "_build_learner", _not_built)
    learner = make_config("2v2").learner
    refusals = [
        (team_on_field, r"^env=<function team_on_field .*> is not a game: make_learner takes "
                        r"the game to train in, a Soccer \(config.make_env\(\)\)$"),
        (Soccer(3), r"^env plays 3 a side, but the config's game has env.players_per_team=2: "),
    ]
    for env, message in refusals:
        with pytest.raises(ValueError, match=message) as raised:
            learner_module.make_learner(learner, env)  # type: ignore[arg-type]
        assert "\n" not in str(raised.value)


def test_games_built_alike_are_equal() -> None:
    # make_learner caches on its game: one built again (a resume) must find the same learner.
    from elevens.env.soccer import Soccer

    class Tired(Soccer):
        def __init__(self, players_per_team: int, stamina: bool) -> None:
            super().__init__(players_per_team)
            self.stamina = stamina

    assert Soccer(2) == Soccer(2) and hash(Soccer(2)) == hash(Soccer(2))
    assert Soccer(2) != Soccer(3) and Soccer(2) != Tired(2, False)
    assert Tired(2, True) == Tired(2, True) and Tired(2, True) != Tired(2, False)
    assert len({Soccer(2), Soccer(2), Tired(2, True), Tired(2, True)}) == 2


def test_every_opponent_kind_is_accepted() -> None:
    for kind in OPPONENT_KINDS:
        config = make_config("quickstart", **{"opponent.kind": kind})
        assert config.learner.opponent.kind == kind


@pytest.mark.parametrize("preset", CORE_PRESETS)
def test_json_round_trip(preset: str, tmp_path) -> None:
    config = make_config(preset, **{"run.eval_teams": ("naive",), "ppo.entropy_weight": 0})
    text = config.to_json()
    assert json.loads(text)["config_version"] == CONFIG_VERSION == 2  # plain JSON
    again = TrainConfig.from_json(text)
    assert again == config
    assert isinstance(again.run.eval_teams, tuple)
    assert isinstance(again.learner.ppo, PPOHyperparams)
    assert isinstance(again.learner.env.game, EnvParams)
    assert isinstance(again.learner.ppo.entropy_weight, float)  # an int in JSON: a float field
    path = tmp_path / "config.json"
    path.write_text(text)
    assert load_config(path) == config


def test_from_dict_fills_fields_an_older_version_did_not_save() -> None:
    data = make_config("quickstart").to_dict()
    del data["learner"]["opponent"]["league_window"]
    del data["run"]["eval_games"]
    with pytest.warns(UserWarning, match="older version") as caught:
        config = TrainConfig.from_dict(data, fill_missing=True)
    message = str(caught[0].message)
    assert "learner.opponent.league_window" in message and "run.eval_games" in message
    defaults = TrainConfig()
    assert config.learner.opponent.league_window == defaults.learner.opponent.league_window
    assert config.run.eval_games == defaults.run.eval_games
    assert config.learner.ppo == make_config("quickstart").learner.ppo  # the saved values
    data["run"]["colour"] = "blue"  # still an error: a typo, or a newer version's field
    with pytest.raises(ValueError, match=r"unknown keys \['colour'\].*newer version"):
        TrainConfig.from_dict(data, fill_missing=True)


def test_from_dict_rejects_unknown_and_missing_keys() -> None:
    data = make_config("quickstart").to_dict()
    data["run"]["colour"] = "blue"
    with pytest.raises(ValueError, match=r"config\.run.*unknown keys \['colour'\]"):
        TrainConfig.from_dict(data)
    data = make_config("quickstart").to_dict()
    del data["learner"]["ppo"]["gamma"]
    with pytest.raises(ValueError, match=r"config\.learner\.ppo.*missing keys \['gamma'\]"):
        TrainConfig.from_dict(data)
    for version in (3, "2", None):
        data = {**make_config("quickstart").to_dict(), "config_version": version}
        with pytest.raises(ValueError, match=f"config_version={version!r} is not readable"):
            TrainConfig.from_dict(data, fill_missing=True)
    # A version-1 dict is read only as an older version's file (fill_missing).
    with pytest.raises(ValueError, match="config_version=1 is not readable"):
        TrainConfig.from_dict(as_version_1(make_config("quickstart")))


@pytest.mark.parametrize("preset", CORE_PRESETS)
def test_a_version_1_config_reads_back_field_by_field(preset: str) -> None:
    config = make_config(preset, **{"run.seed": 5, "opponent.mix": ("naive=0.25",)}
                         if preset == "quickstart" else {"run.seed": 5})
    assert TrainConfig.from_saved(as_version_1(config), "old.json") == config
    migrated = migrate_v1(as_version_1(config))
    assert migrated["config_version"] == 2 and "batch_size" not in migrated["learner"]["ppo"]
    # A batch that is not games x players cannot be expressed any more: a clear error.
    bad = as_version_1(config)
    bad["ppo"]["batch_size"] += 1
    with pytest.raises(ValueError, match=r"old.json.*ppo.batch_size=.*games_per_iteration x"):
        TrainConfig.from_saved(bad, "old.json")
    bad = as_version_1(config)
    bad["env"]["scenario"] = "2v3"
    with pytest.raises(ValueError, match="old.json.*env.scenario='2v3'"):
        TrainConfig.from_saved(bad, "old.json")


def test_a_version_1_config_without_spawn_keeps_its_old_default() -> None:
    # Version 1's EnvConfig spawned at random by default; EnvParams' default is formation.
    old = as_version_1(make_config("2v2"))
    del old["env"]["spawn"]
    config = TrainConfig.from_saved(old, "old.json")
    assert config.learner.env.game.spawn == "random"


@pytest.mark.parametrize("path", COMMITTED_CONFIGS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_committed_config_loads(path: Path) -> None:
    # Shipped teams and the results' exported teams were saved as version 1.
    config = load_config(path).validate()
    assert isinstance(config.learner, LearnerConfig)
    saved = json.loads(path.read_text())
    if "config_version" not in saved:
        assert config.learner.env.scenario == saved["env"]["scenario"]
        assert config.learner.batch_size == saved["ppo"]["batch_size"]
        assert config.learner.games_per_iteration == saved["run"]["games_per_iteration"]


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
    # K changes no result; the games an iteration do. Names are the flags'.
    assert config_differences(saved, make_config("quickstart", iterations_per_chunk=7)) == []
    assert config_differences(saved, make_config("quickstart", **{"env.kick_impulse": 3.0})) == [
        "env.kick_impulse: 4.0 -> 3.0"
    ]


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
    assert args.config.learner.ppo.learning_rate == 3e-4
    assert args.config.learner.ppo.epochs == 5  # the preset's value where no flag is given
    assert args.config.learner.opponent.kind == "league"
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


def test_cli_train_validates_before_compiling(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import tyro

    from elevens.cli.train import TrainArgs, train_command
    from elevens.runs import loop as loop_module
    from elevens.train import learner as learner_module

    # Refused before the run starts: neither the training loop nor a learner is reached.
    monkeypatch.setattr(loop_module, "train", _not_built)
    monkeypatch.setattr(learner_module, "_build_learner", _not_built)
    # PPOHyperparams refuses the value while tyro builds the config: usage error, exit code 2.
    with pytest.raises(SystemExit) as exit_info:
        train_command(tyro.cli(TrainArgs, args=["11v11", "--ppo.learning-rate", "-0.1"]))
    assert exit_info.value.code == 2
    assert "learning_rate=-0.1 is invalid" in capsys.readouterr().err
    # A value only the whole config can judge is refused by validate() in train_command, also
    # as a usage error (no traceback).
    args = tyro.cli(TrainArgs, args=["11v11", "--games-per-iteration", "7"])
    with pytest.raises(SystemExit) as exit_info:
        train_command(args)
    assert exit_info.value.code == 2
    assert "elevens train: error: ppo.minibatch_size=55 is invalid" in capsys.readouterr().err


def test_a_mixed_run_shares_its_chunks_between_sizes_by_a_fixed_schedule() -> None:
    config = make_config("11v11", **{
        "env.mix": ("2v2", "5v5"), "env.mix_shares": (0.5, 0.25),
        "games_per_iteration": 20, "ppo.minibatch_size": 110,
        "opponent.mix": ("naive=0.25",),
    })
    learner = config.learner
    schedule = mix_schedule(learner, 400)
    assert schedule[:8] == ["2v2", "11v11", "5v5", "2v2", "2v2", "11v11", "5v5", "2v2"]
    assert [schedule.count(game) for game in ("2v2", "5v5", "11v11")] == [200, 100, 100]
    assert mix_schedule(learner, 7) == schedule[:7]  # a resumed run follows the same one
    two = scenario_config(learner, "2v2")
    assert (two.env.scenario, two.games_per_iteration, two.env.mix) == ("2v2", 110, ())
    assert two.batch_size == learner.batch_size == 220
    assert two.ppo == learner.ppo and two.validate() is two
    # Fixed opponents keep their share at every size.
    assert opponent_mix(learner) == [("self", 15), ("naive", 5)]
    assert opponent_mix(two) == [("self", 82), ("naive", 28)]
    # Without a mix, every chunk plays the main game.
    assert set(mix_schedule(make_config("2v2").learner, 5)) == {"2v2"}


def test_the_action_count_is_2_or_12_and_training_takes_2() -> None:
    from elevens.train.config import make_config
    from elevens.train.learner import make_learner

    with pytest.raises(ValueError, match=r"network.actions=5 is invalid: it must be 2 .* or 12"):
        make_config("quickstart", **{"network.actions": 5})
    twelve = make_config("quickstart", **{"network.actions": 12})
    with pytest.raises(ValueError, match=r"network.actions=12: the game Soccer "
                       r"\(env.physics='thesis'\) takes 2 action values"):
        make_learner(twelve.learner, twelve.learner.make_env())
    # A config saved before the field existed reads as 2, without a warning about it.
    saved = make_config("quickstart").to_dict()
    del saved["learner"]["network"]["actions"]
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert TrainConfig.from_saved(saved, "x.json").learner.network.actions == 2


def test_the_learner_takes_the_game_its_config_makes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The core knows one game; another registers its EnvConfig subclass, whose make_env
    builds the game the learner is given and takes the action of, and a saved config of it
    reads back as that class."""
    from elevens.env.soccer import Soccer
    from elevens.train import config as config_module
    from elevens.train.config import EnvConfig, apply_overrides, make_config
    from elevens.train.learner import make_learner

    class WideSoccer(Soccer):
        actions = 12

    @dataclasses.dataclass(frozen=True)
    class WideGame(EnvConfig):
        physics: str = "wide"
        width: int = 3
        PHYSICS: ClassVar[str] = "wide"

        def make_env(self, players_per_team: int) -> Soccer:
            return WideSoccer(players_per_team)

        @property
        def actions(self) -> int:
            return WideSoccer.actions

    base = make_config("quickstart", **{"run.eval_teams": (), "run.write_gif": False})
    fields = {f.name: getattr(base.learner.env, f.name) for f in dataclasses.fields(EnvConfig)}
    wide = dataclasses.replace(base, learner=dataclasses.replace(
        base.learner, env=WideGame(**{**fields, "physics": "wide"})))
    with pytest.raises(ValueError, match=r"env.physics='wide' is invalid here: .* known to this "
                       r"process are (.*, )?thesis"):
        wide.validate()
    monkeypatch.setitem(config_module.GAMES, "wide", WideGame)
    wide.validate()
    with pytest.raises(ValueError, match=r"network.actions=2: the game WideSoccer "
                       r"\(env.physics='wide'\) takes 12 action values"):
        make_learner(wide.learner, wide.learner.make_env())
    wide12 = apply_overrides(wide, {"network.actions": 12, "env.width": 5})
    assert TrainConfig.from_json(wide12.to_json()) == wide12
    assert type(TrainConfig.from_json(wide12.to_json()).learner.env) is WideGame
    with pytest.raises(ValueError, match=r"run.write_gif=True is invalid with env.physics='wide'"):
        apply_overrides(wide12, {"run.write_gif": True}).validate()
    with pytest.raises(ValueError, match=r"run.eval_teams team 'naive' gives 2 action values"):
        apply_overrides(wide12, {"run.eval_teams": ("naive",)}).validate()
    with pytest.raises(ValueError, match="env.physics='wide' is invalid here: this config's game"):
        make_config("quickstart", **{"env.physics": "wide"})
    monkeypatch.delitem(config_module.GAMES, "wide")
    with pytest.raises(ValueError, match=r"physics='wide' names a game this process does not "
                       r"know: known are (.*, )?thesis"):
        TrainConfig.from_json(wide12.to_json())


def test_a_version_2_config_of_the_simulators_game_reads_silently() -> None:
    """Version 2 wrote another game's fields (at their defaults) for every game; the simulator's
    game drops them, and refuses them at any other value."""
    import warnings

    from elevens.train.config import make_config

    saved = make_config("quickstart").to_dict()
    saved["learner"]["env"].update(see_period=1, stamina=False, goalie=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert TrainConfig.from_saved(saved, "x.json") == make_config("quickstart")
    del saved["learner"]["env"]["physics"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert TrainConfig.from_saved(saved, "x.json").learner.env.physics == "thesis"
    saved["learner"]["env"]["stamina"] = True
    with pytest.raises(ValueError, match=r"unknown keys \['stamina'\]"):
        TrainConfig.from_saved(saved, "x.json")
