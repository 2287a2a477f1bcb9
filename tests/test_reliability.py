"""Bad input fails the same way everywhere: every numeric flag is range-checked before anything
compiles, random bad arguments end in exit 2 with one line and no traceback, and mutated replay
and checkpoint files raise only the loaders' documented errors."""

from __future__ import annotations

import dataclasses
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import elevens
from elevens.cli import main
from elevens.cli.bench import TrainBenchArgs
from elevens.cli.checks import NUMERIC_RANGES
from elevens.cli.eval import (
    AnalyzeArgs,
    CurvesArgs,
    RenderArgs,
    TournamentArgs,
    ViewArgs,
)
from elevens.cli.robocup import (
    RoboCupBenchArgs,
    RoboCupPlayArgs,
    RoboCupServeArgs,
    RoboCupTrainArgs,
)
from elevens.cli.robocup_skills import RoboCupSkillsTeamArgs
from elevens.eval.replay import Replay, ReplayError, load_replay, save_replay
from elevens.train.checkpoint import Checkpointer, CheckpointError

ARG_CLASSES = (
    AnalyzeArgs, CurvesArgs, RenderArgs, TournamentArgs, ViewArgs, RoboCupBenchArgs,
    RoboCupPlayArgs, RoboCupServeArgs, RoboCupTrainArgs, TrainBenchArgs, RoboCupSkillsTeamArgs,
)
NUMERIC_TYPES = ("int", "float")
FIXTURES = [HealthCheck.function_scoped_fixture]  # tmp_path and capsys serve every example


def _cli_arg_classes() -> tuple[type, ...]:
    from elevens.cli import app as cli

    return (*ARG_CLASSES, cli.PlayArgs, cli.EnvBenchArgs, cli.ExportTeamArgs)


def test_every_numeric_flag_has_a_range() -> None:
    unchecked = [
        f"{cls.__name__}.{field.name}"
        for cls in _cli_arg_classes()
        for field in dataclasses.fields(cls)
        if any(kind in str(field.type) for kind in NUMERIC_TYPES)
        and field.name not in NUMERIC_RANGES
    ]
    assert unchecked == []


# A command line of each subcommand that would run (or start a server) if nothing were wrong,
# and its numeric flags with a value each. The fuzz puts one bad value in.
COMMANDS: dict[str, list[str]] = {
    "play": ["play", "--out", "unused.gif"],
    "bench env": ["bench", "env"],
    "bench train": ["bench", "train"],
    "tournament": ["tournament", "random", "naive"],
    "analyze": ["analyze", "naive", "--against", "random"],
    "render": ["render", "missing.npz"],
    "robocup play": ["robocup", "play"],
    "robocup train": ["robocup", "train"],
    "robocup bench": ["robocup", "bench"],
}
FLAGS: dict[str, tuple[str, ...]] = {
    "play": ("players", "seed", "steps", "fps", "scale", "view"),
    "bench env": ("players", "batch", "steps", "repeats", "loop_steps", "host_devices"),
    "bench train": ("players", "episode_length", "repeats"),
    "tournament": ("games", "players", "seed", "steps", "bootstrap", "chunk_size", "see_period"),
    "analyze": ("games", "players", "seed", "steps", "replays", "chunk_size"),
    "render": ("fps", "scale", "view"),
    "robocup play": ("players", "episodes", "steps", "seed"),
    "robocup train": ("players", "servers", "steps", "minutes", "iterations", "checkpoint_every",
                      "seed", "learning_rate"),
    "robocup bench": ("players", "cycles"),
}


def bad_values(flag: str) -> list[str]:
    low, high = NUMERIC_RANGES[flag]
    values = [str(low - 1), "nan", "-inf", "12abc", ""]
    if high != math.inf:
        values.append(str(high + 1))
    if isinstance(low, float) or flag in ("minutes", "learning_rate", "threshold"):
        values.append("0")
    return values


@st.composite
def bad_command_lines(draw: Any) -> tuple[str, list[str]]:
    command = draw(st.sampled_from(sorted(COMMANDS)))
    flag = draw(st.sampled_from(FLAGS[command]))
    value = draw(st.sampled_from(bad_values(flag)))
    return command, [*COMMANDS[command], f"--{flag.replace('_', '-')}", value]


@settings(max_examples=60, deadline=15000, suppress_health_check=FIXTURES)
@given(case=bad_command_lines())
def test_random_bad_flags_exit_2_with_one_line(
    case: tuple[str, list[str]], capsys: pytest.CaptureFixture[str], tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    command, argv = case
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2, argv
    error = capsys.readouterr().err
    assert "Traceback" not in error
    # Values that parse are refused by range, values that do not by tyro: one line either way,
    # naming the flag.
    line = error.strip()
    assert "\n" not in line and "╭" not in line, line
    assert line.startswith(f"elevens {command}: error: "), line
    assert argv[-2] in line or f"--{argv[-2].lstrip('-')}" in line, line
    assert list(tmp_path.iterdir()) == []


TEAM_WORDS = st.text(
    alphabet=st.sampled_from("abcdefgh-_.0123456789"), min_size=1, max_size=12
).filter(  # words that start with '-' are flags, which tyro reports
    lambda word: word not in ("random", "naive", "teamwork") and word.strip(".")
    and not word.startswith("-")
)


@settings(max_examples=30, deadline=5000, suppress_health_check=FIXTURES)
@given(word=TEAM_WORDS, command=st.sampled_from(["play", "tournament", "analyze"]))
def test_unknown_team_words_exit_2_naming_the_allowed_teams(
    word: str, command: str, capsys: pytest.CaptureFixture[str], tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    argv = {
        "play": ["play", "--home", word, "--out", "x.gif"],
        "tournament": ["tournament", "naive", word, "--games", "2"],
        "analyze": ["analyze", word, "--against", "naive", "--games", "2"],
    }[command]
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and line.startswith(f"elevens {command}: error: ")
    assert "random, naive, teamwork" in line


# --------------------------------------------------------------------------------------------
# Mutated files
# --------------------------------------------------------------------------------------------


def small_replay() -> Replay:
    _, params = elevens.make("1v1", episode_length=5)
    steps = 5
    return Replay(
        team_names=("a", "b"), params=params, final_score=(0, 0),
        positions=np.zeros((steps, 2, 2), np.float32), headings=np.zeros((steps, 2), np.float32),
        ball_position=np.zeros((steps, 2), np.float32),
        ball_velocity=np.zeros((steps, 2), np.float32), score=np.zeros((steps, 2), np.int32),
        step=np.arange(steps, dtype=np.int32), actions=np.zeros((steps, 2, 1, 2), np.float32),
    )


MUTATIONS = st.lists(
    st.tuples(st.integers(min_value=0), st.integers(min_value=0, max_value=255)),
    min_size=1, max_size=8,
)


def mutate(path: Path, edits: list[tuple[int, int]], truncate: int | None) -> None:
    data = bytearray(path.read_bytes())
    for position, value in edits:
        if data:
            data[position % len(data)] = value
    if truncate is not None and data:
        data = data[: truncate % len(data)]
    path.write_bytes(bytes(data))


@pytest.mark.filterwarnings("error::ResourceWarning")  # a damaged replay leaves no file open
@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
@settings(max_examples=60, deadline=15000, suppress_health_check=FIXTURES)
@given(edits=MUTATIONS, truncate=st.none() | st.integers(min_value=0))
def test_mutated_replays_raise_only_replay_errors(
    edits: list[tuple[int, int]], truncate: int | None, tmp_path: Path
) -> None:
    path = save_replay(small_replay(), tmp_path / "game.npz")
    mutate(path, edits, truncate)
    try:
        load_replay(path)
    except ReplayError as error:
        assert str(path) in str(error)


@pytest.fixture(scope="module")
def clean_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("clean") / "ckpt"
    state = {"w": np.arange(64, dtype=np.float32), "step": np.asarray(3, np.int32)}
    with Checkpointer(directory) as checkpointer:
        checkpointer.save(3, state, {"name": "tiny"}, {"iteration": 3})
    return directory


def _restore_edited_copy(
    clean_checkpoint: Path, tmp_path: Path, filename: str, replacements: dict[str, str]
) -> None:
    """Restore a copy of the clean checkpoint whose ``filename`` had each key string of
    ``replacements`` replaced (each must be there)."""
    directory = tmp_path / "ckpt"
    shutil.copytree(clean_checkpoint, directory)
    (edited,) = directory.rglob(filename)
    text = edited.read_text()
    for old, new in replacements.items():
        assert old in text, old
        text = text.replace(old, new)
    edited.write_text(text)
    target = {"w": np.zeros(64, np.float32), "step": np.asarray(0, np.int32)}
    with Checkpointer(directory) as checkpointer:
        checkpointer.restore(target, 3)


def test_a_tree_entry_without_its_storage_key_is_a_checkpoint_error(
    clean_checkpoint: Path, tmp_path: Path
) -> None:
    # Found by the fuzz test below: one byte changed a key's name and the JSON stayed valid.
    with pytest.raises(CheckpointError, match="malformed"):
        _restore_edited_copy(
            clean_checkpoint, tmp_path, "tree.json", {'"storage_key"': '"storage_kez"'}
        )


def test_a_damaged_step_metadata_file_is_a_checkpoint_error(
    clean_checkpoint: Path, tmp_path: Path
) -> None:
    # Found by the fuzz test below: two bytes changed two keys of Orbax's own metadata file
    # (Orbax files the first unknown key under custom_metadata and refuses the second), which
    # Orbax reads while listing the steps.
    replacements = {
        '"item_handlers"': '" tem_handlers"',
        '"commit_timestamp_nsecs"': '" ommit_timestamp_nsecs"',
    }
    with pytest.raises(CheckpointError, match="cannot list its steps"):
        _restore_edited_copy(clean_checkpoint, tmp_path, "_CHECKPOINT_METADATA", replacements)


@settings(max_examples=40, deadline=10000, suppress_health_check=FIXTURES)
@given(edits=MUTATIONS, truncate=st.none() | st.integers(min_value=0), pick=st.integers(0))
def test_mutated_checkpoints_raise_only_checkpoint_errors(
    edits: list[tuple[int, int]], truncate: int | None, pick: int, clean_checkpoint: Path,
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    directory = tmp_path_factory.mktemp("mutated") / "ckpt"
    shutil.copytree(clean_checkpoint, directory)
    files = sorted(p for p in directory.rglob("*") if p.is_file())
    mutate(files[pick % len(files)], edits, truncate)
    target = {"w": np.zeros(64, np.float32), "step": np.asarray(0, np.int32)}
    with Checkpointer(directory) as checkpointer:
        try:
            state, config, _ = checkpointer.restore(target, 3)
        except (CheckpointError, FileNotFoundError):
            return
    # A mutation the checksums cannot see (metadata Orbax ignores) restores the saved values.
    np.testing.assert_array_equal(state["w"], np.arange(64, dtype=np.float32))
    assert config == {"name": "tiny"}


# --------------------------------------------------------------------------------------------
# Refused before the work: sizes, output paths, names
# --------------------------------------------------------------------------------------------

COMPILES: list[str] = []
"""Every XLA compile of this process, by its monitoring event (registered once, below)."""


def _count_compiles() -> None:
    import jax.monitoring

    if not getattr(_count_compiles, "registered", False):
        jax.monitoring.register_event_duration_secs_listener(
            lambda event, duration, **kwargs: COMPILES.append(event)
            if event == "/jax/core/compile/backend_compile_duration" else None
        )
        _count_compiles.registered = True  # type: ignore[attr-defined]


def _a_run_with_metrics(folder: Path) -> Path:
    folder.mkdir()
    (folder / "metrics.csv").write_text(
        "step,name,value\n1,eval/random/outcome,0.5\n2,eval/random/outcome,0.6\n"
    )
    return folder


BEFORE_THE_WORK = [
    (["play", "--players", "1", "--steps", "99999999999"], "--steps=99999999999"),
    (["play", "--players", "1", "--steps", "4", "--out", "/proc/nope/x.gif"],
     "--out '/proc/nope/x.gif' cannot be written"),
    (["play", "--players", "1", "--steps", "4", "--out", "a_file/x.gif"], "a_file is a file"),
    (["bench", "env", "--players", "1", "--batch", "2000000000"], "--batch 2000000000 needs"),
    (["bench", "env", "--players", "1", "--batch", "4", "--plot", "out.txt"],
     "--plot 'out.txt' is invalid: the suffix must be .png"),
    (["tournament", "naive", "random", "--players", "1", "--games", "2", "--out", "a_file"],
     "--out 'a_file' is a file"),
    (["tournament", "naive", "random", "--players", "1", "--games", "2", "--anchor", "wizards"],
     "--anchor 'wizards' is not one of the teams: naive, random"),
    (["analyze", "naive", "--against", "random", "--players", "1", "--out", "a_file"],
     "--out 'a_file' is a file"),
    (["train", "quickstart", "--run.run-dir", "a_file"], "a_file' is not a directory"),
    (["train", "quickstart", "--resume", "--run.run-dir", "no_such_run"],
     "no_such_run holds no run"),
    (["render", "game.npz", "--out", "r.avi"], "--out 'r.avi' is invalid: the suffix must be"),
    (["render", "empty_folder"], "empty_folder is a folder"),
    (["curves", "run", "--against", "wizards"], "run run has no metric 'eval/wizards/outcome'"),
    (["curves", "run", "--out", "curves.txt"], "--out 'curves.txt' is invalid"),
    (["curves", "real.npz"], "real.npz is not a metrics.csv (not text)"),
    (["robocup", "play", "--team0", "wizards", "--rcssserver", "no_such_server"],
     "wizards does not exist"),
    # Sizes whose memory cannot fit (below int32, so only the estimate refuses them).
    (["play", "--players", "11", "--steps", "2000000000"], "--steps=2000000000 needs about"),
    (["tournament", "naive", "random", "--players", "11", "--games", "2000000000",
      "--chunk-size", "2000000000"], "--chunk-size=2000000000 needs about"),
    (["train", "quickstart", "--games-per-iteration", "20000000"],
     "games_per_iteration=20000000 needs about"),
]


@pytest.mark.parametrize(
    ("argv", "message"), BEFORE_THE_WORK, ids=[" ".join(argv) for argv, _ in BEFORE_THE_WORK]
)
def test_bad_sizes_paths_and_names_are_one_line_before_any_compile(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "empty_folder").mkdir()
    np.savez(tmp_path / "real.npz", a=np.arange(3))
    _a_run_with_metrics(tmp_path / "run")
    _count_compiles()
    compiled = len(COMPILES)
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines
    assert len(COMPILES) == compiled, "compiled before refusing"
    assert not (tmp_path / "no_such_run").exists()


def test_ctrl_c_on_view_exits_130(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from elevens.eval import viewer

    def ctrl_c(self: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(viewer.ReplayServer, "serve_forever", ctrl_c)
    path = save_replay(small_replay(), tmp_path / "game.npz")
    with pytest.raises(SystemExit) as exit_info:
        main(["view", str(path), "--port", "0"])
    assert exit_info.value.code == 130
    assert capsys.readouterr().err.strip() == "elevens view: interrupted"
