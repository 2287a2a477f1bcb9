"""Trained teams as compact folders: export, load, the shipped teams, and `elevens play` with
any team."""

from __future__ import annotations

import gc
import warnings
import zipfile
from pathlib import Path

import jax
import numpy as np
import pytest

from elevens.cli import main
from elevens.eval.replay import load_replay
from elevens.runs.teams import export_team, load_learner_params, load_team, parse_team_spec
from elevens.teams.trained import (
    NETWORKS_FILE,
    ShippedTeamError,
    shipped_team_directory,
    shipped_team_names,
)
from elevens.train.checkpoint import Checkpointer
from elevens.train.learner import make_learner
from tests.train.test_trainer import leaves_equal, tiny_config

SHIPPED = ("elevens-11v11", "elevens-2v2")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run directory with one checkpoint of the trainer tests' networks (an init, no
    training), at 2 v 2."""
    run = tmp_path_factory.mktemp("run")
    config = tiny_config(
        run, **{"env.players_per_team": 2, "ppo.minibatch_size": 32}
    )
    state = make_learner(config.learner, config.learner.make_env()).init(jax.random.key(11))
    with Checkpointer(run / "checkpoints") as checkpointer:
        checkpointer.save(0, state, config.to_dict(), {"iteration": 0})
    return run


def test_an_exported_team_holds_its_checkpoints_networks(
    checkpoint: Path, tmp_path: Path
) -> None:
    folder, config = export_team(str(checkpoint), tmp_path / "team", card="# card\n")
    assert config.learner.env.scenario == "2v2"
    assert (folder / "MODEL_CARD.md").read_text() == "# card\n"
    # Plain arrays, readable without pickle.
    with np.load(folder / NETWORKS_FILE, allow_pickle=False) as archive:
        assert any(name.startswith("policy/params/") for name in archive.files)
        assert any(name.startswith("critic/params/") for name in archive.files)
    _, saved = load_learner_params(str(checkpoint))
    _, exported = load_learner_params(str(folder))
    assert leaves_equal(saved, exported)
    team = load_team(str(folder))
    assert team.trained_players == 2 and team.name == "team"
    assert leaves_equal(team.params, saved.policy)
    with pytest.raises(ValueError, match="drop the '@ITERATION'"):
        load_team(f"{folder}@3")


def test_a_damaged_or_foreign_team_folder_is_a_clear_error(
    checkpoint: Path, tmp_path: Path
) -> None:
    folder, _ = export_team(str(checkpoint), tmp_path / "team")
    (folder / NETWORKS_FILE).write_bytes(b"not a zip archive")
    with pytest.raises(ShippedTeamError, match=f"{NETWORKS_FILE} cannot be read"):
        load_team(str(folder))
    # Cut short or with bytes overwritten in the middle: the same error, no file left open.
    intact = export_team(str(checkpoint), tmp_path / "intact")[0] / NETWORKS_FILE
    data = intact.read_bytes()
    gc.collect()  # other tests' garbage warns now, not below
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ResourceWarning)
        for damaged in (data[: len(data) // 2], data[:100] + b"\xff" * 64 + data[164:]):
            (folder / NETWORKS_FILE).write_bytes(damaged)
            with pytest.raises(ShippedTeamError, match=f"{NETWORKS_FILE} cannot be read"):
                load_team(str(folder))
            gc.collect()  # a leaked handle warns here
    leaked = [str(w.message) for w in caught if str(folder) in str(w.message)]
    assert not leaked, leaked
    # Arrays of other networks than config.json builds: named, with both shapes.
    folder, _ = export_team(str(checkpoint), tmp_path / "other")
    with np.load(folder / NETWORKS_FILE, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    name = next(name for name in arrays if name.endswith("kernel"))
    arrays[name] = np.zeros((3, 3), np.float32)
    with zipfile.ZipFile(folder / NETWORKS_FILE, "w") as handle:
        for key, value in arrays.items():
            with handle.open(f"{key}.npy", "w") as member:
                np.lib.format.write_array(member, value)
    with pytest.raises(ShippedTeamError, match=r"has shape \(3, 3\), its networks need"):
        load_team(str(folder))


def test_the_shipped_teams_are_named_team_specs() -> None:
    # The core's own; a wing adds its teams' folder when imported (robocup: rcss11, rcss-gpu).
    assert set(SHIPPED) <= set(shipped_team_names())
    for name in SHIPPED:
        assert parse_team_spec(name).shipped == name
        assert (shipped_team_directory(name) / "MODEL_CARD.md").is_file()
    with pytest.raises(ValueError, match="elevens-12v12.*shipped teams are elevens-11v11"):
        shipped_team_directory("elevens-12v12")


@pytest.mark.parametrize("name", SHIPPED)
def test_each_shipped_team_beats_random_at_its_own_size(name: str) -> None:
    import elevens
    from elevens.eval.match import play_match

    team, opponent = load_team(name), load_team("random")
    players = team.trained_players
    assert players is not None
    env, params = elevens.make(f"{players}v{players}", episode_length=200)
    result = play_match(
        env, params, team.policy, opponent.policy, jax.random.key(0), num_games=16,
        home_params=team.params, swap_sides=True,
    )
    assert float(np.mean(result.outcome)) > 0.7


def test_play_takes_any_team_writes_a_replay_and_refuses_unknown_names(
    checkpoint: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    replay = tmp_path / "game.npz"
    main(["play", "--home", f"mine={checkpoint}", "--away", "naive", "--players", "2",
          "--steps", "12", "--out", str(tmp_path / "game.gif"), "--replay", str(replay)])
    loaded = load_replay(replay)
    assert loaded.team_names == ("mine", "naive") and loaded.positions.shape[:2] == (12, 4)
    assert (tmp_path / "game.gif").stat().st_size > 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(["play", "--home", "elevens-12v12", "--out", str(tmp_path / "x.gif")])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("elevens play: error: ") and "\n" not in error
    for name in ("random", "naive", "teamwork", "counter", "rcss_naive", "elevens-11v11",
                 "elevens-2v2"):
        assert f" {name}," in error or error.endswith(f" {name}")


def test_a_damaged_latest_checkpoint_names_the_intact_one(
    checkpoint: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    from elevens.train.checkpoint import TREE_FILE, CheckpointError

    run = tmp_path / "run"
    shutil.copytree(checkpoint, run)
    shutil.copytree(run / "checkpoints" / "0", run / "checkpoints" / "1")
    (run / "checkpoints" / "1" / "tree" / TREE_FILE).write_text("{not json")
    with pytest.raises(CheckpointError, match=f"checkpoint 0 is intact: use {run}@0"):
        load_team(str(run))
    assert load_team(f"{run}@0").trained_players == 2
    with pytest.raises(SystemExit) as exit_info:
        main(["tournament", str(run), "naive", "--games", "2", "--players", "2",
              "--out", str(tmp_path / "t")])
    assert exit_info.value.code == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and line.endswith(f"checkpoint 0 is intact: use {run}@0")
