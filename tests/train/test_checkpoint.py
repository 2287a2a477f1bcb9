"""Checkpoints: bit-identical round trips, step bookkeeping, atomicity, and clear errors."""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from elevens.train.checkpoint import (
    CONFIG_FILE,
    Checkpointer,
    CheckpointError,
    load_config,
)


@struct.dataclass
class Opponent:
    """A flax struct dataclass inside the state, with a static field that is not saved."""

    params: dict[str, jax.Array]
    win_rates: jax.Array  # f32[4]
    frozen: jax.Array  # bool[]
    name: str = struct.field(pytree_node=False, default="polyak")


CONFIG = {
    "scenario": "2v2",
    "ppo": {"learning_rate": 1e-4, "clip_epsilon": 0.1, "epochs": 5},
    "seeds": [0, 1, 2],
    "shaping": True,
    "note": None,
}


def make_state(seed: int) -> dict[str, Any]:
    """A nested training-state-like pytree whose values depend on ``seed``."""
    rng = np.random.default_rng(seed)
    weights = rng.normal(size=(3, 4)).astype(np.float32)
    weights[0, :3] = [np.nan, -0.0, np.inf]  # bit-identical means these survive too
    return {
        "params": {"dense": {"kernel": jnp.asarray(weights), "bias": jnp.zeros(4, jnp.float32)}},
        "step": jnp.int32(seed),
        "counts": np.arange(seed, seed + 6, dtype=np.int32).reshape(2, 3),
        "done": jnp.array([True, False, seed % 2 == 0]),
        "key": jax.random.key(seed),
        "game_keys": jax.random.split(jax.random.key(seed + 100), 4),
        "opponent": Opponent(
            params={"w": jnp.full((2, 2), float(seed), jnp.float32)},
            win_rates=jnp.asarray(rng.uniform(size=4), jnp.float32),
            frozen=jnp.array(False),
        ),
        "history": [np.float32(0.5 * seed), 7, 2.5, True],
    }


def zeros_like_state(state: Any) -> Any:
    """A restore target with the state's structure and dtypes but none of its values."""

    def zero(leaf: Any) -> Any:
        if isinstance(leaf, bool | int | float):
            return type(leaf)(0)
        if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            return jax.random.split(jax.random.key(999), leaf.shape) if leaf.shape else leaf
        if isinstance(leaf, np.generic):
            return leaf.dtype.type(0)
        if isinstance(leaf, np.ndarray):
            return np.zeros_like(leaf)
        return jnp.zeros_like(leaf)

    return jax.tree.map(zero, state)


def leaf_bytes(leaf: Any) -> tuple[str, str, bytes]:
    """(python type, dtype, raw bytes) of a leaf; keys compare by their key data."""
    if isinstance(leaf, bool | int | float):
        return type(leaf).__name__, "", repr(leaf).encode()
    if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key):
        data = np.asarray(jax.random.key_data(leaf))
        return type(leaf).__name__, str(leaf.dtype), data.tobytes()
    array = np.asarray(leaf)
    return type(leaf).__name__, str(array.dtype), array.tobytes()


def assert_bit_identical(restored: Any, expected: Any) -> None:
    assert str(jax.tree.structure(restored)) == str(jax.tree.structure(expected))
    for got, want in zip(jax.tree.leaves(restored), jax.tree.leaves(expected), strict=True):
        assert leaf_bytes(got) == leaf_bytes(want)


def files_under(path: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()
    }


def largest_array_file(step_dir: Path) -> Path:
    """The biggest file of the state item: tensorstore's data file holding the array bytes."""
    files = [p for p in (step_dir / "state").rglob("*") if p.is_file()]
    return max(files, key=lambda p: p.stat().st_size)


@pytest.fixture
def saved(tmp_path: Path) -> tuple[Checkpointer, dict[str, Any], Path]:
    """A directory with one checkpoint at step 5 whose state holds 16 KiB of random floats."""
    state = make_state(5)
    # Incompressible and large, so that its tensorstore file is the largest in the step directory.
    noise = np.random.default_rng(0).normal(size=4096).astype(np.float32)
    state["params"]["noise"] = jnp.asarray(noise)
    checkpointer = Checkpointer(tmp_path / "ckpt")
    checkpointer.save(5, state, CONFIG, {"iteration": 5})
    return checkpointer, state, tmp_path / "ckpt"


# --------------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------------


def test_round_trip_is_bit_identical(tmp_path: Path) -> None:
    state = make_state(3)
    metadata = {"iteration": 3, "env_steps": 123_456_789_000, "wall_time_s": 12.5, "shaping": False}
    checkpointer = Checkpointer(tmp_path / "ckpt")
    step_dir = checkpointer.save(3, state, CONFIG, metadata)
    assert step_dir == tmp_path / "ckpt" / "3"

    with Checkpointer(tmp_path / "ckpt") as reader:
        restored, config, meta = reader.restore(zeros_like_state(state))
    assert_bit_identical(restored, state)
    assert config == CONFIG
    assert meta == metadata
    # Static fields come from the target, the restored keys draw the same numbers.
    assert restored["opponent"].name == "polyak"
    np.testing.assert_array_equal(
        jax.random.uniform(restored["key"], (5,)), jax.random.uniform(state["key"], (5,))
    )
    # numpy stays numpy, jax stays jax, Python numbers stay Python numbers.
    assert isinstance(restored["counts"], np.ndarray)
    assert isinstance(restored["params"]["dense"]["kernel"], jax.Array)
    assert [type(x) for x in restored["history"]] == [np.float32, int, float, bool]


def test_restored_arrays_keep_the_targets_placement(tmp_path: Path) -> None:
    # Uncommitted leaves (a fresh init) come back uncommitted, so a jitted step compiled for the
    # fresh state runs the restored one without compiling again; committed ones stay committed.
    fresh = {"w": jnp.arange(6.0), "key": jax.random.key(1)}
    device = jax.devices()[0]
    placed = {"w": jax.device_put(jnp.arange(6.0), device)}
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(0, {"fresh": fresh, "placed": placed}, {})
    restored, _, _ = checkpointer.restore({"fresh": fresh, "placed": placed})
    checkpointer.close()
    assert not restored["fresh"]["w"].committed and not restored["fresh"]["key"].committed
    assert restored["placed"]["w"].committed and restored["placed"]["w"].devices() == {device}

    @jax.jit
    def step(state: dict[str, jax.Array]) -> jax.Array:
        return state["w"] * jax.random.uniform(state["key"])

    np.testing.assert_array_equal(step(restored["fresh"]), step(fresh))
    assert step._cache_size() == 1


def test_restore_into_abstract_target(tmp_path: Path) -> None:
    state: dict[str, Any] = {
        "w": jnp.arange(6.0).reshape(2, 3),
        "key": jax.random.key(1),
        "n": np.int32(4),
    }
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(0, state, {})
    target = jax.eval_shape(lambda: state)
    restored, _, metadata = checkpointer.restore(target)
    assert metadata == {}
    assert isinstance(restored["w"], jax.Array)
    np.testing.assert_array_equal(restored["w"], state["w"])
    np.testing.assert_array_equal(
        jax.random.key_data(restored["key"]), jax.random.key_data(state["key"])
    )
    assert int(restored["n"]) == 4


def test_config_is_human_readable_json(tmp_path: Path) -> None:
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(1, {"x": jnp.ones(2)}, {**CONFIG, "sizes": (1, 2), "lr": np.float32(0.5)})
    text = (tmp_path / "1" / "config" / CONFIG_FILE).read_text()
    assert "\n  " in text  # indented, one entry per line
    loaded = json.loads(text)
    assert loaded["sizes"] == [1, 2]  # tuples come back as lists
    assert loaded["lr"] == 0.5
    assert load_config(tmp_path) == loaded
    assert checkpointer.read_metadata() == {}


def test_unsaveable_inputs_fail_before_writing(tmp_path: Path) -> None:
    checkpointer = Checkpointer(tmp_path / "ckpt")
    with pytest.raises(TypeError, match=r"\['name'\]"):
        checkpointer.save(1, {"w": jnp.ones(2), "name": "not an array"}, {})
    with pytest.raises(TypeError, match="config"):
        checkpointer.save(1, {"w": jnp.ones(2)}, {"fn": print})
    with pytest.raises(ValueError, match="no leaves"):
        checkpointer.save(1, {"empty": []}, {})
    assert checkpointer.latest_step() is None
    assert not (tmp_path / "ckpt" / "1").exists()


def test_nothing_is_pickled(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("pickle was used")

    for name in ("dump", "dumps", "load", "loads"):
        monkeypatch.setattr(pickle, name, refuse)
    state = make_state(1)
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(1, state, CONFIG)
    restored, _, _ = checkpointer.restore(zeros_like_state(state))
    assert_bit_identical(restored, state)
    for path in tmp_path.rglob("*"):
        if path.is_file():
            assert not path.read_bytes().startswith(b"\x80"), f"{path} looks like a pickle"


# --------------------------------------------------------------------------------------------
# Steps: latest, max_to_keep, resume
# --------------------------------------------------------------------------------------------


def test_latest_step_max_to_keep_and_resume(tmp_path: Path) -> None:
    directory = tmp_path / "ckpt"
    checkpointer = Checkpointer(directory, max_to_keep=3)
    assert checkpointer.latest_step() is None
    assert checkpointer.all_steps() == []
    assert not directory.exists()  # reading never creates the directory
    for step in (10, 20, 30, 40, 50):
        checkpointer.save(step, make_state(step), {**CONFIG, "saved_at": step}, {"iteration": step})
    assert checkpointer.all_steps() == [30, 40, 50]
    assert checkpointer.latest_step() == 50
    assert sorted(p.name for p in directory.iterdir()) == ["30", "40", "50"]
    checkpointer.close()

    # A new process resumes from the newest checkpoint.
    resumed = Checkpointer(directory, max_to_keep=3)
    assert resumed.latest_step() == 50
    target = zeros_like_state(make_state(0))
    state, config, metadata = resumed.restore(target)
    assert_bit_identical(state, make_state(50))
    assert config["saved_at"] == 50 and metadata == {"iteration": 50}
    older, _, metadata = resumed.restore(target, step=30)
    assert_bit_identical(older, make_state(30))
    assert metadata == {"iteration": 30}
    assert load_config(directory, step=40)["saved_at"] == 40

    with pytest.raises(FileNotFoundError, match="step 20"):
        resumed.restore(target, step=20)
    with pytest.raises(ValueError, match="steps must increase"):
        resumed.save(50, make_state(0), CONFIG)
    resumed.save(60, make_state(60), CONFIG)
    assert resumed.all_steps() == [40, 50, 60]


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("exists", [False, True])
def test_no_checkpoint_is_file_not_found(tmp_path: Path, exists: bool) -> None:
    directory = tmp_path / "nothing_here"
    if exists:
        directory.mkdir()
    checkpointer = Checkpointer(directory)
    with pytest.raises(FileNotFoundError, match="no checkpoint found") as error:
        checkpointer.restore({"w": jnp.ones(2)})
    assert str(directory) in str(error.value)
    with pytest.raises(FileNotFoundError, match="no checkpoint found"):
        load_config(directory)
    assert directory.exists() == exists


@pytest.mark.parametrize("damage", ["truncate", "garble", "delete"])
# A read that fails inside Orbax can leave a TensorStore callback for the asyncio loop that
# Orbax already closed; it is reported from a background thread after the test. The behaviour
# checked here is the error and the untouched files.
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_damaged_array_file_is_a_checkpoint_error(
    saved: tuple[Checkpointer, dict[str, Any], Path], damage: str
) -> None:
    checkpointer, state, directory = saved
    data_file = largest_array_file(directory / "5")
    content = data_file.read_bytes()
    if damage == "truncate":
        data_file.write_bytes(content[: len(content) // 2])
    elif damage == "garble":
        middle = len(content) // 2
        flipped = bytes(b ^ 0xFF for b in content[middle : middle + 64])
        data_file.write_bytes(content[:middle] + flipped + content[middle + 64 :])
    else:
        data_file.unlink()
    before = files_under(directory)

    # Closed on the way out: else Orbax's event loop is left to the garbage collector (a warning).
    with Checkpointer(directory) as reader, pytest.raises(CheckpointError) as error:
        reader.restore(zeros_like_state(state))
    assert str(directory / "5") in str(error.value)
    assert files_under(directory) == before  # nothing deleted or rewritten
    assert checkpointer.latest_step() == 5


def test_shape_mismatch_names_the_leaf(saved: tuple[Checkpointer, dict[str, Any], Path]) -> None:
    checkpointer, state, directory = saved
    before = files_under(directory)
    target = zeros_like_state(state)
    target["params"]["dense"]["kernel"] = jnp.zeros((3, 5), jnp.float32)
    with pytest.raises(CheckpointError) as error:
        checkpointer.restore(target)
    message = str(error.value)
    assert "['params']['dense']['kernel']" in message
    assert "(3, 4)" in message and "(3, 5)" in message
    assert str(directory / "5") in message

    target = zeros_like_state(state)
    target["counts"] = np.zeros((2, 3), np.int64)
    with pytest.raises(CheckpointError, match=r"dtype mismatch at leaf \['counts'\].*int32.*int64"):
        checkpointer.restore(target)

    target = zeros_like_state(state)
    target["opponent"] = target["opponent"].replace(frozen=jax.random.key(0))
    with pytest.raises(CheckpointError, match=r"\['opponent'\]\.frozen.*PRNG key"):
        checkpointer.restore(target)
    assert files_under(directory) == before


def test_tree_structure_mismatch_names_the_leaves(
    saved: tuple[Checkpointer, dict[str, Any], Path],
) -> None:
    checkpointer, state, _ = saved
    target = zeros_like_state(state)
    del target["counts"]
    target["extra"] = jnp.zeros(3)
    with pytest.raises(CheckpointError, match="tree structure") as error:
        checkpointer.restore(target)
    assert "['extra']" in str(error.value) and "['counts']" in str(error.value)


@pytest.mark.parametrize("damage", ["garble", "delete"])
def test_damaged_config_json_is_a_checkpoint_error(
    saved: tuple[Checkpointer, dict[str, Any], Path], damage: str
) -> None:
    checkpointer, state, directory = saved
    config_path = directory / "5" / "config" / CONFIG_FILE
    if damage == "garble":
        config_path.write_text('{"scenario": "2v2", "ppo": {')
    else:
        config_path.unlink()
    before = files_under(directory)
    for read in (
        lambda: checkpointer.restore(zeros_like_state(state)),
        lambda: load_config(directory),
    ):
        with pytest.raises(CheckpointError) as error:
            read()
        assert str(config_path) in str(error.value)
    assert files_under(directory) == before


def test_interrupted_save_leftovers_are_ignored(
    saved: tuple[Checkpointer, dict[str, Any], Path],
) -> None:
    checkpointer, state, directory = saved
    # What a kill during a save leaves: Orbax's temporary directory, never renamed (named with
    # or without a timestamp, depending on the Orbax version) ...
    shutil.copytree(directory / "5", directory / "7.orbax-checkpoint-tmp")
    shutil.copytree(directory / "5", directory / "11.orbax-checkpoint-tmp-1700000000000000")
    # ... and a step directory without the commit marker (a copy cut short).
    shutil.copytree(directory / "5", directory / "9")
    (directory / "9" / "commit_success.txt").unlink()
    leftovers = files_under(directory)

    for reader in (checkpointer, Checkpointer(directory)):
        assert reader.all_steps() == [5]
        assert reader.latest_step() == 5
        restored, _, metadata = reader.restore(zeros_like_state(state))
        assert metadata == {"iteration": 5}
        assert_bit_identical(restored, state)
    assert files_under(directory) == leftovers  # evidence is left alone

    # Saving over the uncommitted directory is refused rather than mixed into it.
    with pytest.raises(CheckpointError, match="not a committed checkpoint"):
        checkpointer.save(9, state, CONFIG)
    checkpointer.save(8, state, CONFIG, {"iteration": 8})
    assert checkpointer.latest_step() == 8


def test_save_failing_midway_leaves_no_checkpoint(
    saved: tuple[Checkpointer, dict[str, Any], Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    checkpointer, state, directory = saved
    from elevens.train import checkpoint as checkpoint_module

    real_save = checkpoint_module._JsonTextHandler.save

    def crash_on_metadata(self: Any, item_dir: Any, args: Any) -> None:
        real_save(self, item_dir, args)
        if Path(os.fspath(item_dir)).name.startswith("metadata"):
            raise KeyboardInterrupt("killed during the save")

    monkeypatch.setattr(checkpoint_module._JsonTextHandler, "save", crash_on_metadata)
    with pytest.raises(KeyboardInterrupt):
        checkpointer.save(6, state, CONFIG, {"iteration": 6})
    monkeypatch.undo()

    for reader in (checkpointer, Checkpointer(directory)):
        assert reader.latest_step() == 5
        _, _, metadata = reader.restore(zeros_like_state(state))
        assert metadata == {"iteration": 5}
    # The next attempt at the same step goes through.
    checkpointer.save(6, state, CONFIG, {"iteration": 6})
    assert checkpointer.latest_step() == 6
    assert checkpointer.read_metadata() == {"iteration": 6}
