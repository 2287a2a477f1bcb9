"""Checkpoints: any pytree of arrays, saved atomically with Orbax, its config as JSON beside it.

One step directory holds four Orbax items and a commit marker::

    <directory>/<step>/
        state/            the arrays (Orbax StandardCheckpointHandler: tensorstore, no pickle)
        tree/tree.json    one entry per leaf: its key path, shape, dtype, kind and CRC-32
        config/config.json      the run's config, indented JSON
        metadata/metadata.json  free-form run facts (iteration, env steps, wall time, ...)
        commit_success.txt      Orbax's commit marker

Why the layout looks like this:

* **Atomic.** Orbax writes every item into ``<step>.orbax-checkpoint-tmp`` (with a ``-<time>``
  suffix in some versions) and renames it to ``<step>`` only when all items are on disk (the
  atomic rename is the commit on a POSIX file system). A run killed mid-save leaves a temporary
  directory, which is never listed as a step. We also ignore a step directory that lacks
  ``commit_success.txt``, which Orbax writes just before the rename, so a half-copied checkpoint
  (``cp -r`` or ``rsync`` cut short) is not resumed from either.
* **Generic over pytrees.** The state is flattened with ``jax.tree_util`` key paths, and its
  leaves are stored as a flat dict of host arrays under neutral keys (``leaf_00000``, ...). So any
  container type (dicts, lists, flax struct dataclasses, NamedTuples) works with no registration,
  and leaf names never have to be valid tensorstore paths. The restore target supplies the tree
  structure back, as Orbax itself expects.
* **Typed PRNG keys** (``jax.random.key``) are stored as their ``uint32`` key data and wrapped
  back with the key implementation they were saved with.
* **Checked on restore.** Orbax detects missing or truncated files but not garbled bytes (no
  checksum in its array format), so ``tree.json`` carries a CRC-32 of every leaf. A mismatch of
  structure, shape, dtype or checksum raises ``CheckpointError`` naming the leaf, and nothing on
  disk is touched.
* **No pickle.** Arrays go through tensorstore, everything else is JSON.

Saves are synchronous: the trainer saves between compiled chunks and a finished ``save`` means
the checkpoint is on disk (what a Ctrl-C handler needs). Leaves are fetched to the host with
``np.asarray``: arrays on one device, or replicated ones. Several processes (``jax.distributed``)
all call ``save`` together and Orbax's multi-process path has process 0 write the files.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import logging
import os
import shutil
import sys
import zlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp

PyTree = Any

CONFIG_FILE = "config.json"
METADATA_FILE = "metadata.json"
TREE_FILE = "tree.json"
COMMIT_MARKER = "commit_success.txt"
"""Written by Orbax into the temporary directory right before the atomic rename."""

_STATE_ITEM = "state"
_TREE_ITEM = "tree"
_CONFIG_ITEM = "config"
_METADATA_ITEM = "metadata"
_TREE_FORMAT_VERSION = 1

_KIND_ARRAY = "array"
_KIND_KEY = "prng_key"
_KIND_SCALAR = "python_scalar"


class CheckpointError(RuntimeError):
    """A checkpoint exists but cannot be restored: corrupt, incomplete, or of another shape."""


# --------------------------------------------------------------------------------------------
# Orbax's stray callbacks after a failed read
# --------------------------------------------------------------------------------------------


def _is_closed_loop_error(error: BaseException | None) -> bool:
    return isinstance(error, RuntimeError) and str(error) == "Event loop is closed"


def _quiet_stray_loop_errors() -> None:
    """Drop the unraisable ``RuntimeError: Event loop is closed`` of Orbax's dead event loop.

    When one read of a restore fails, Orbax closes its event loop while tensorstore's other
    reads are still in flight; each of them then calls ``loop.call_soon_threadsafe`` from a
    tensorstore thread, and Python reports the error it cannot raise there through
    ``sys.unraisablehook``: hundreds of tracebacks before the one line that names the damage.
    Every other unraisable exception goes on to the hook that was in place. Installed (once per
    hook) before each restore, since a test harness may swap the hook in between."""
    previous = sys.unraisablehook
    if getattr(previous, "drops_closed_loop_errors", False):
        return

    def hook(unraisable: Any) -> None:
        if not _is_closed_loop_error(unraisable.exc_value):
            previous(unraisable)

    hook.drops_closed_loop_errors = True  # type: ignore[attr-defined]
    sys.unraisablehook = hook


class _DropFailedReads(logging.Filter):
    """Drops asyncio's "Task (Future) exception was never retrieved" for one damaged checkpoint.

    The other reads of a failed restore fail too; their tasks are never awaited, so asyncio logs
    each one (a traceback) when it is garbage-collected, possibly at exit, after the one line that
    names the damage. Only tasks whose error names the damaged directory are dropped. Filters of
    one directory are equal, so a logger keeps one however often its restore fails."""

    def __init__(self, directory: Path) -> None:
        super().__init__()
        self._names = frozenset({os.fspath(directory), os.fspath(Path(directory).absolute())})

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _DropFailedReads) and other._names == self._names

    def __hash__(self) -> int:
        return hash(self._names)

    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        return not (
            str(record.msg).startswith(("Task exception", "Future exception"))
            and error is not None
            and any(name in str(error) for name in self._names)
        )


# --------------------------------------------------------------------------------------------
# JSON items: an Orbax handler that writes indented (human-readable) JSON text
# --------------------------------------------------------------------------------------------


class _JsonTextHandler(ocp.CheckpointHandler):
    """Writes already-serialised JSON text to ``<item dir>/<filename>`` and parses it back.

    Orbax's own ``JsonCheckpointHandler`` writes one unindented line; configs are read by people.
    Serialising before the save starts also means an unserialisable config fails before any
    directory is created.
    """

    def __init__(self, filename: str) -> None:
        self._filename = filename

    def save(self, directory: Any, args: _JsonTextSave) -> None:
        # Every process of a multi-process run saves together; process 0 writes the files.
        if jax.process_index() == 0:
            Path(os.fspath(directory), self._filename).write_text(args.text, encoding="utf-8")

    def restore(self, directory: Any, args: _JsonTextRestore | None = None) -> Any:
        return _read_json(Path(os.fspath(directory), self._filename))


@ocp.args.register_with_handler(_JsonTextHandler, for_save=True)
@dataclasses.dataclass
class _JsonTextSave(ocp.args.CheckpointArgs):
    text: str


@ocp.args.register_with_handler(_JsonTextHandler, for_restore=True)
@dataclasses.dataclass
class _JsonTextRestore(ocp.args.CheckpointArgs):
    pass


def _read_json(path: Path) -> Any:
    """Parses a JSON file of a checkpoint; any problem is a ``CheckpointError`` naming the file."""
    if not path.is_file():
        raise CheckpointError(f"corrupt checkpoint: missing file {path}")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CheckpointError(
            f"corrupt checkpoint: cannot parse JSON file {path}: {error}"
        ) from error


def _json_default(value: Any) -> Any:
    """Converts the non-JSON types a config or metadata dict commonly holds."""
    if isinstance(value, np.generic | jax.Array) and np.ndim(value) == 0:
        return np.asarray(value).item()
    if isinstance(value, np.ndarray | jax.Array):
        return np.asarray(value).tolist()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable: {value!r}")


def _to_json_text(value: Any, what: str) -> str:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if not isinstance(value, Mapping):
        raise TypeError(f"{what} must be a dict (or a dataclass), got {type(value).__name__}")
    try:
        return json.dumps(dict(value), indent=2, default=_json_default) + "\n"
    except (TypeError, ValueError) as error:
        raise TypeError(f"{what} cannot be written as JSON: {error}") from error


# --------------------------------------------------------------------------------------------
# Leaves: pytree <-> flat dict of host arrays + a JSON description
# --------------------------------------------------------------------------------------------


def _is_key(leaf: Any) -> bool:
    dtype = getattr(leaf, "dtype", None)
    return dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)


def _storage_key(index: int) -> str:
    return f"leaf_{index:05d}"


def _crc32(array: np.ndarray) -> int:
    return zlib.crc32(np.ascontiguousarray(array).tobytes())


def _leaf_to_host(name: str, leaf: Any) -> tuple[dict[str, Any], np.ndarray]:
    """One leaf as (its tree.json entry without storage key/CRC, the host array to store)."""
    if _is_key(leaf):
        data = np.asarray(jax.random.key_data(leaf))
        entry = {
            "kind": _KIND_KEY,
            "shape": list(np.shape(leaf)),
            "dtype": str(leaf.dtype),
            "key_impl": str(jax.random.key_impl(leaf)),
        }
        return entry, data
    if isinstance(leaf, bool | int | float | complex):
        data = np.asarray(leaf)
        return {"kind": _KIND_SCALAR, "shape": [], "dtype": str(data.dtype)}, data
    if isinstance(leaf, jax.Array | np.ndarray | np.generic):
        data = np.asarray(leaf)
        if data.dtype == object:
            raise TypeError(f"leaf {name} is an object array, which cannot be saved without pickle")
        return {"kind": _KIND_ARRAY, "shape": list(data.shape), "dtype": str(data.dtype)}, data
    raise TypeError(
        f"leaf {name} has type {type(leaf).__name__}; a checkpointed state may hold only "
        "jax/numpy arrays, typed PRNG keys and Python numbers (store anything else in the "
        "config or metadata, or as a static field)"
    )


def _expected(leaf: Any) -> tuple[str, tuple[int, ...], str, tuple[int, ...]]:
    """(kind, logical shape, logical dtype, stored data shape) that a target leaf asks for."""
    if _is_key(leaf):
        data_shape = tuple(jax.eval_shape(jax.random.key_data, leaf).shape)
        return _KIND_KEY, tuple(np.shape(leaf)), str(leaf.dtype), data_shape
    if isinstance(leaf, bool | int | float | complex):
        return _KIND_SCALAR, (), str(np.asarray(leaf).dtype), ()
    if isinstance(leaf, jax.Array | np.ndarray | np.generic | jax.ShapeDtypeStruct):
        shape = tuple(leaf.shape)
        return _KIND_ARRAY, shape, str(np.dtype(leaf.dtype)), shape
    raise TypeError(
        f"restore target leaf of type {type(leaf).__name__} is not an array, "
        "jax.ShapeDtypeStruct, PRNG key or Python number"
    )


def _host_to_leaf(data: np.ndarray, entry: Mapping[str, Any], target: Any) -> Any:
    """Turns a restored host array back into the kind of leaf the target holds."""
    if entry["kind"] == _KIND_KEY:
        keys = jax.random.wrap_key_data(jnp.asarray(data), impl=entry["key_impl"])
        sharding = _placement(target)
        return keys if sharding is None else jax.device_put(keys, sharding)
    if isinstance(target, bool | int | float | complex):
        return type(target)(data.item())
    if isinstance(target, np.generic):
        return data[()]
    if isinstance(target, np.ndarray):
        return data
    # jax.Array or jax.ShapeDtypeStruct: put it back where the target lives (if it says).
    sharding = _placement(target)
    return jax.device_put(data) if sharding is None else jax.device_put(data, sharding)


def _placement(target: Any) -> Any:
    """The sharding to restore a leaf onto: the target's, or None (the default device,
    uncommitted) for an uncommitted array. A restored state then has the same jit cache key as a
    fresh one (committed arrays are another key): a resume in the process that started the run
    does not compile the training chunk again."""
    if isinstance(target, jax.Array) and not target.committed:
        return None
    return getattr(target, "sharding", None)


@dataclasses.dataclass(frozen=True)
class _Leaf:
    name: str  # jax.tree_util.keystr of the leaf's key path, e.g. "['params']['Dense_0'].kernel"
    value: Any


def _named_leaves(tree: PyTree) -> tuple[list[_Leaf], Any]:
    with_path, treedef = jax.tree_util.tree_flatten_with_path(tree)
    leaves = [_Leaf(jax.tree_util.keystr(path) or "<root>", leaf) for path, leaf in with_path]
    return leaves, treedef


# --------------------------------------------------------------------------------------------
# The checkpointer
# --------------------------------------------------------------------------------------------


class Checkpointer:
    """Saves and restores training states, each with its config and metadata, in one directory.

    Example::

        checkpointer = Checkpointer("runs/a/checkpoints", max_to_keep=3)
        if checkpointer.latest_step() is not None:
            state, config, meta = checkpointer.restore(init_state)   # resume from the latest
        ...
        checkpointer.save(iteration, state, dataclasses.asdict(config), {"env_steps": n})

    Args:
        directory: where step directories go; created on the first save, never by reading.
        max_to_keep: how many of the newest checkpoints to keep (``None`` keeps all). Older ones
            are deleted after a successful save, never after an error.
    """

    def __init__(self, directory: str | os.PathLike[str], max_to_keep: int | None = 3) -> None:
        if max_to_keep is not None and max_to_keep < 1:
            raise ValueError(f"max_to_keep must be None or >= 1, got {max_to_keep}")
        self.directory = Path(directory).absolute()
        self.max_to_keep = max_to_keep
        self._manager: ocp.CheckpointManager | None = None
        self._on_close: list[Callable[[], None]] = []

    # -- Orbax plumbing ---------------------------------------------------------------------

    def _get_manager(self) -> ocp.CheckpointManager:
        if self._manager is None:
            registry = ocp.handlers.DefaultCheckpointHandlerRegistry()
            state_handler = ocp.StandardCheckpointHandler()
            registry.add(_STATE_ITEM, ocp.args.StandardSave, state_handler)
            registry.add(_STATE_ITEM, ocp.args.StandardRestore, state_handler)
            for item, filename in (
                (_TREE_ITEM, TREE_FILE),
                (_CONFIG_ITEM, CONFIG_FILE),
                (_METADATA_ITEM, METADATA_FILE),
            ):
                json_handler = _JsonTextHandler(filename)
                registry.add(item, _JsonTextSave, json_handler)
                registry.add(item, _JsonTextRestore, json_handler)
            options = ocp.CheckpointManagerOptions(
                max_to_keep=self.max_to_keep,
                enable_async_checkpointing=False,
                # Leftover temporary directories are evidence; leave them for a person to look at.
                cleanup_tmp_directories=False,
                create=True,
            )
            self._manager = ocp.CheckpointManager(
                self.directory, options=options, handler_registry=registry
            )
        return self._manager

    def step_directory(self, step: int) -> Path:
        """The directory of one step's checkpoint (whether or not it exists)."""
        return self.directory / str(step)

    # -- listing ----------------------------------------------------------------------------

    def all_steps(self) -> list[int]:
        """Committed checkpoint steps, ascending. Interrupted or half-copied saves are left out."""
        if not self.directory.is_dir():
            return []
        try:
            manager = self._get_manager()
            manager.reload()  # see steps written or removed by anyone since the last call
            listed = manager.all_steps()
        except Exception as error:  # Orbax reads every step's metadata file here
            raise CheckpointError(
                f"corrupt checkpoint in {self.directory}: Orbax cannot list its steps: "
                f"{type(error).__name__}: {error}"
            ) from error
        steps = (int(step) for step in listed)
        return sorted(s for s in steps if (self.step_directory(s) / COMMIT_MARKER).is_file())

    def latest_step(self) -> int | None:
        """The newest committed step, or ``None`` if there is no checkpoint."""
        steps = self.all_steps()
        return steps[-1] if steps else None

    def _resolve_step(self, step: int | None) -> int:
        steps = self.all_steps()
        if not steps:
            where = "" if self.directory.is_dir() else " (the directory does not exist)"
            raise FileNotFoundError(f"no checkpoint found in {self.directory}{where}")
        if step is None:
            return steps[-1]
        if step not in steps:
            raise FileNotFoundError(
                f"no checkpoint for step {step} in {self.directory}; saved steps: {steps}"
            )
        return step

    # -- save -------------------------------------------------------------------------------

    def save(
        self,
        step: int,
        state: PyTree,
        config: Mapping[str, Any] | Any,
        metadata: Mapping[str, Any] | None = None,
    ) -> Path:
        """Writes one checkpoint atomically and returns its directory.

        Args:
            step: the checkpoint's number (e.g. the iteration); must exceed every saved step.
            state: any pytree of jax/numpy arrays, typed PRNG keys and Python numbers.
            config: a JSON-serialisable dict (or a dataclass, turned into one), written as
                ``config.json``. Tuples come back as lists.
            metadata: a JSON-serialisable dict of run facts, written as ``metadata.json``.
        """
        step = int(step)
        if step < 0:
            raise ValueError(f"step must be >= 0, got {step}")
        latest = self.latest_step()
        if latest is not None and step <= latest:
            raise ValueError(
                f"cannot save step {step} in {self.directory}: step {latest} is already saved "
                "(steps must increase)"
            )
        config_text = _to_json_text(config, "config")
        metadata_text = _to_json_text({} if metadata is None else metadata, "metadata")

        leaves, _ = _named_leaves(state)
        if not leaves:
            raise ValueError("state has no leaves: there is nothing to checkpoint")
        arrays: dict[str, np.ndarray] = {}
        entries: list[dict[str, Any]] = []
        for index, leaf in enumerate(leaves):
            entry, data = _leaf_to_host(leaf.name, leaf.value)
            key = _storage_key(index)
            arrays[key] = data
            entries.append({"name": leaf.name, "storage_key": key, **entry, "crc32": _crc32(data)})
        names = [entry["name"] for entry in entries]
        if len(set(names)) != len(names):
            raise ValueError(f"state has leaves with the same key path: {sorted(names)}")
        # One leaf per line: readable, and diffs of two checkpoints' layouts stay short.
        leaf_lines = ",\n".join("    " + json.dumps(entry) for entry in entries)
        tree_text = "\n".join(
            [
                "{",
                f'  "format_version": {_TREE_FORMAT_VERSION},',
                '  "leaves": [',
                leaf_lines,
                "  ]",
                "}",
                "",
            ]
        )

        if jax.process_index() == 0:  # Orbax's manager makes the directory on process 0 too
            self.directory.mkdir(parents=True, exist_ok=True)
        manager = self._get_manager()
        args = ocp.args.Composite(
            **{
                _STATE_ITEM: ocp.args.StandardSave(arrays),
                _TREE_ITEM: _JsonTextSave(tree_text),
                _CONFIG_ITEM: _JsonTextSave(config_text),
                _METADATA_ITEM: _JsonTextSave(metadata_text),
            }
        )
        try:
            # force: the caller decides when to save; Orbax's save-interval policy must not skip.
            saved = manager.save(step, args=args, force=True)
        except ocp.checkpoint_manager.StepAlreadyExistsError as error:
            raise CheckpointError(
                f"cannot save step {step}: {self.step_directory(step)} already exists but is not "
                "a committed checkpoint (an interrupted copy?); move it away and save again"
            ) from error
        manager.wait_until_finished()
        if not saved:
            raise CheckpointError(f"Orbax declined to save step {step} in {self.directory}")
        return self.step_directory(step)

    # -- restore ----------------------------------------------------------------------------

    def restore(
        self, target: PyTree, step: int | None = None
    ) -> tuple[PyTree, dict[str, Any], dict[str, Any]]:
        """Restores ``(state, config, metadata)`` of ``step`` (default: the latest).

        Args:
            target: a pytree with the structure of the saved state: concrete arrays or
                ``jax.ShapeDtypeStruct`` (e.g. ``jax.eval_shape(init, key)``). Leaves come back as
                the target's kind: numpy stays numpy, jax arrays land on the target's sharding,
                PRNG keys come back as typed keys, Python numbers as Python numbers.
            step: which checkpoint; ``None`` for the latest.

        Raises:
            FileNotFoundError: there is no checkpoint (or none for ``step``) in the directory.
            CheckpointError: the checkpoint is corrupt or does not match the target (structure,
                shape, dtype); the message names the path and the leaf. Nothing is deleted.
        """
        step = self._resolve_step(step)
        step_dir = self.step_directory(step)
        saved = self._read_tree(step_dir)
        target_leaves, treedef = _named_leaves(target)
        plan = _match_leaves(step_dir, saved, target_leaves)

        abstract = {
            entry["storage_key"]: jax.ShapeDtypeStruct(tuple(data_shape), np.dtype(data_dtype))
            for entry, data_shape, data_dtype in plan
        }
        _quiet_stray_loop_errors()
        try:
            restored = self._get_manager().restore(
                step,
                args=ocp.args.Composite(
                    **{
                        _STATE_ITEM: ocp.args.StandardRestore(abstract),
                        _CONFIG_ITEM: _JsonTextRestore(),
                        _METADATA_ITEM: _JsonTextRestore(),
                    }
                ),
            )
        except CheckpointError:
            raise
        except Exception as error:  # tensorstore/Orbax raise ValueError, OSError, ... for damage
            logging.getLogger("asyncio").addFilter(_DropFailedReads(step_dir))
            raise CheckpointError(
                f"corrupt checkpoint {step_dir}: cannot read it: {type(error).__name__}: {error}"
            ) from error

        arrays = restored[_STATE_ITEM]
        values = []
        for (entry, _, _), leaf in zip(plan, target_leaves, strict=True):
            data = np.asarray(arrays[entry["storage_key"]])
            if _crc32(data) != entry["crc32"]:
                raise CheckpointError(
                    f"corrupt checkpoint {step_dir / _STATE_ITEM}: leaf {entry['name']} does not "
                    "match its saved checksum (the array data is damaged)"
                )
            values.append(_host_to_leaf(data, entry, leaf.value))
        state = jax.tree_util.tree_unflatten(treedef, values)
        config = _expect_dict(restored[_CONFIG_ITEM], step_dir / _CONFIG_ITEM / CONFIG_FILE)
        metadata = _expect_dict(restored[_METADATA_ITEM], step_dir / _METADATA_ITEM / METADATA_FILE)
        return state, config, metadata

    def _read_tree(self, step_dir: Path) -> list[dict[str, Any]]:
        path = step_dir / _TREE_ITEM / TREE_FILE
        tree = _read_json(path)
        if not isinstance(tree, dict) or not isinstance(tree.get("leaves"), list):
            raise CheckpointError(f"corrupt checkpoint: {path} has no list of leaves")
        return tree["leaves"]

    def last_intact_step(self, target: PyTree, before: int) -> int | None:
        """The newest step before ``before`` that restores into ``target`` (its checksums, tree
        and JSON all intact), or None. Reads each candidate in full, newest first."""
        for step in sorted((s for s in self.all_steps() if s < before), reverse=True):
            try:
                self.restore(target, step)
            except CheckpointError:
                continue
            return step
        return None

    def set_aside(self, step: int, destination: str | os.PathLike[str]) -> Path:
        """Move step ``step``'s directory into ``destination`` (kept for a person to look at,
        never deleted), so the run can save that step again. Returns its new path."""
        source = self.step_directory(step)
        folder = Path(destination)
        folder.mkdir(parents=True, exist_ok=True)
        target = folder / str(step)
        suffix = 1
        while target.exists():
            suffix += 1
            target = folder / f"{step}.{suffix}"
        shutil.move(str(source), str(target))
        if self._manager is not None:
            self._manager.reload()
        return target

    def read_config(self, step: int | None = None) -> dict[str, Any]:
        """The config of ``step`` (default: the latest), without reading any array."""
        step_dir = self.step_directory(self._resolve_step(step))
        path = step_dir / _CONFIG_ITEM / CONFIG_FILE
        return _expect_dict(_read_json(path), path)

    def read_metadata(self, step: int | None = None) -> dict[str, Any]:
        """The metadata of ``step`` (default: the latest), without reading any array."""
        step_dir = self.step_directory(self._resolve_step(step))
        path = step_dir / _METADATA_ITEM / METADATA_FILE
        return _expect_dict(_read_json(path), path)

    # -- lifetime ---------------------------------------------------------------------------

    def wait(self) -> None:
        """Blocks until pending writes finish (saves are synchronous, so this returns at once)."""
        if self._manager is not None:
            self._manager.wait_until_finished()

    def close(self) -> None:
        """Releases Orbax's resources (and whatever ``release_on_close`` was given); the
        checkpointer can still be used afterwards."""
        if self._manager is not None:
            self._manager.close()
            self._manager = None
        while self._on_close:
            self._on_close.pop()()

    def release_on_close(self, release: Callable[[], None]) -> None:
        """Call ``release`` at the next ``close``: a run directory's lock is held for as long
        as the run's checkpointer is open."""
        self._on_close.append(release)

    def __enter__(self) -> Checkpointer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _expect_dict(value: Any, path: Path) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise CheckpointError(
            f"corrupt checkpoint: {path} holds a {type(value).__name__}, not a JSON object"
        )
    return value


def _match_leaves(
    step_dir: Path, saved: list[dict[str, Any]], target: list[_Leaf]
) -> list[tuple[dict[str, Any], tuple[int, ...], str]]:
    """Pairs each target leaf with its saved entry; any disagreement is a CheckpointError.

    Returns, in the target's leaf order, (saved entry, stored data shape, stored data dtype).
    """
    where = step_dir / _STATE_ITEM
    try:
        by_name = {entry["name"]: entry for entry in saved}
    except (TypeError, KeyError) as error:
        raise CheckpointError(
            f"corrupt checkpoint: {step_dir / _TREE_ITEM} is malformed"
        ) from error
    target_names = [leaf.name for leaf in target]
    missing = [name for name in target_names if name not in by_name]
    extra = [name for name in by_name if name not in set(target_names)]
    if missing or extra:
        raise CheckpointError(
            f"checkpoint {where} has another tree structure than the restore target: "
            f"leaves the target has but the checkpoint lacks: {_some(missing)}; "
            f"leaves the checkpoint has but the target lacks: {_some(extra)}"
        )
    plan = []
    for leaf in target:
        entry = by_name[leaf.name]
        kind, shape, dtype, data_shape = _expected(leaf.value)
        try:
            saved_kind, saved_shape = entry["kind"], tuple(entry["shape"])
            saved_dtype, crc = entry["dtype"], entry["crc32"]
            if not isinstance(entry["storage_key"], str):
                raise TypeError("storage_key is not a string")
        except (KeyError, TypeError) as error:
            raise CheckpointError(
                f"corrupt checkpoint: {step_dir / _TREE_ITEM}: the entry of leaf {leaf.name} "
                "is malformed"
            ) from error
        if (saved_kind == _KIND_KEY) != (kind == _KIND_KEY):
            what = {True: "a PRNG key", False: "an array"}
            saved_what, target_what = what[saved_kind == _KIND_KEY], what[kind == _KIND_KEY]
            raise CheckpointError(
                f"checkpoint {where}: leaf {leaf.name} was saved as {saved_what} "
                f"but the target expects {target_what}"
            )
        if saved_shape != shape:
            raise CheckpointError(
                f"checkpoint {where}: shape mismatch at leaf {leaf.name}: saved shape "
                f"{saved_shape}, expected shape {shape}"
            )
        if saved_dtype != dtype:
            raise CheckpointError(
                f"checkpoint {where}: dtype mismatch at leaf {leaf.name}: saved dtype "
                f"{saved_dtype}, expected dtype {dtype}"
            )
        if not isinstance(crc, int):
            raise CheckpointError(f"corrupt checkpoint: leaf {leaf.name} has no valid checksum")
        if kind == _KIND_KEY:
            data_dtype = str(jax.eval_shape(jax.random.key_data, leaf.value).dtype)
        else:
            data_dtype = dtype
        plan.append((entry, data_shape, data_dtype))
    return plan


def _some(names: list[str], shown: int = 5) -> str:
    """The first few names and how many more (a whole tree's names are kilobytes long)."""
    if not names:
        return "none"
    more = len(names) - shown
    return str(names[:shown]) + (f" and {more} more" if more > 0 else "")


def load_config(directory: str | os.PathLike[str], step: int | None = None) -> dict[str, Any]:
    """``config.json`` of the latest (or the given) checkpoint in ``directory``; no array is read.

    Raises:
        FileNotFoundError: no checkpoint in ``directory``.
        CheckpointError: the config file is missing or not valid JSON.
    """
    checkpointer = Checkpointer(directory, max_to_keep=None)
    try:
        return checkpointer.read_config(step)
    finally:
        checkpointer.close()
