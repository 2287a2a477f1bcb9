"""Trained teams shipped with the package, by name (``elevens-11v11``, ``elevens-2v2``).

Each team is a folder beside this file: ``networks.npz`` (the policy's and the critic's
parameters, flat arrays named by their path, read with ``allow_pickle=False``), ``config.json``
(the ``TrainConfig`` of the run it came from, which builds the networks) and ``MODEL_CARD.md``
(how it was trained and how it plays). ``elevens.runs.teams`` makes the names team specs, and
``elevens.runs.teams.load_learner_params`` lets a run start from them (``--run.init-from``).

This module only reads and writes the files (NumPy and JSON); building the networks is left to
its callers.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from flax import traverse_util

from elevens.files import write_atomically

NETWORKS_FILE = "networks.npz"
CONFIG_FILE = "config.json"
CARD_FILE = "MODEL_CARD.md"
NETWORK_GROUPS = ("policy", "critic")
_HERE = Path(__file__).resolve().parent


class ShippedTeamError(ValueError):
    """A shipped team's files are missing or damaged."""


_FOLDERS: list[Path] = [_HERE]
"""Where shipped teams live: beside this file, and folders a package above the core adds for
the teams of its own games (``add_shipped_folder``)."""


def add_shipped_folder(folder: Path) -> None:
    """Ship the team folders inside ``folder`` too (a game's package calls this on import)."""
    folder = Path(folder).resolve()
    if folder not in _FOLDERS:
        _FOLDERS.append(folder)


def _shipped() -> dict[str, Path]:
    return {
        entry.name: entry for folder in _FOLDERS for entry in folder.iterdir()
        if (entry / NETWORKS_FILE).is_file()
    }


def shipped_team_names() -> tuple[str, ...]:
    """The names of the teams shipped with this installation, sorted."""
    return tuple(sorted(_shipped()))


def shipped_team_directory(name: str) -> Path:
    """The folder of shipped team ``name``; an unknown name is a ``ValueError`` listing the
    shipped ones."""
    shipped = _shipped()
    if name not in shipped:
        raise ValueError(
            f"team {name!r} is not a shipped team: shipped teams are "
            f"{', '.join(sorted(shipped)) or 'none in this installation'}"
        )
    return shipped[name]


def save_networks(
    directory: str | Path, networks: Mapping[str, Any], config: Mapping[str, Any],
    card: str | None = None,
) -> Path:
    """Write ``networks`` ({"policy": variables, "critic": variables}, nested dicts of arrays)
    and ``config`` (a ``TrainConfig.to_dict()``) into ``directory``, each file atomically (a
    temporary file renamed into place). Returns the directory."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    missing = [group for group in NETWORK_GROUPS if group not in networks]
    if missing:
        raise ValueError(f"networks lack {', '.join(missing)}: give {', '.join(NETWORK_GROUPS)}")
    flat = {
        f"{group}/{path}": np.asarray(leaf)
        for group in NETWORK_GROUPS
        for path, leaf in traverse_util.flatten_dict(_plain(networks[group]), sep="/").items()
    }
    write_atomically(
        directory / NETWORKS_FILE,
        lambda handle: np.savez(handle, **flat),  # type: ignore[arg-type]
    )
    text = json.dumps(dict(config), indent=2) + "\n"
    write_atomically(directory / CONFIG_FILE, lambda handle: handle.write(text.encode()))
    if card is not None:
        write_atomically(directory / CARD_FILE, lambda handle: handle.write(card.encode()))
    return directory


def load_networks(directory: str | Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(config dict, {"policy": variables, "critic": variables}) of a folder written by
    ``save_networks``; NumPy arrays in nested dicts. A missing or damaged file is a
    ``ShippedTeamError`` that names it."""
    directory = Path(directory)
    config_path, networks_path = directory / CONFIG_FILE, directory / NETWORKS_FILE
    try:
        config = json.loads(config_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise ShippedTeamError(f"{config_path} cannot be read as JSON: {error}") from None
    if not isinstance(config, dict):
        raise ShippedTeamError(f"{config_path} holds no config object")
    try:
        # Our own handle: np.load leaks the one it opens when the zip directory is damaged.
        with networks_path.open("rb") as handle, np.load(handle, allow_pickle=False) as archive:
            flat = {name: np.asarray(archive[name]) for name in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error) as error:
        raise ShippedTeamError(
            f"{networks_path} cannot be read as a NumPy .npz archive: {error}"
        ) from None
    tree = traverse_util.unflatten_dict(flat, sep="/")
    missing = [group for group in NETWORK_GROUPS if group not in tree]
    if missing:
        raise ShippedTeamError(f"{networks_path} has no {', '.join(missing)} arrays")
    return config, {group: tree[group] for group in NETWORK_GROUPS}


def check_like(loaded: Any, expected: Any, where: str) -> None:
    """Raise ``ShippedTeamError`` unless ``loaded`` has ``expected``'s paths and shapes
    (``expected``: arrays or ``jax.ShapeDtypeStruct`` in nested dicts)."""
    have = traverse_util.flatten_dict(_plain(loaded), sep="/")
    want = traverse_util.flatten_dict(_plain(expected), sep="/")
    missing, extra = sorted(set(want) - set(have)), sorted(set(have) - set(want))
    if missing or extra:
        raise ShippedTeamError(
            f"{where}: the arrays do not fit the networks of its config.json "
            f"(missing: {', '.join(missing[:5]) or 'none'}; unexpected: "
            f"{', '.join(extra[:5]) or 'none'})"
        )
    for path, leaf in want.items():
        if tuple(have[path].shape) != tuple(leaf.shape):
            raise ShippedTeamError(
                f"{where}: {path} has shape {tuple(have[path].shape)}, its networks need "
                f"{tuple(leaf.shape)}"
            )


def _plain(tree: Any) -> Any:
    """Nested mappings (Flax FrozenDicts included) as plain dicts."""
    if isinstance(tree, Mapping):
        return {str(key): _plain(value) for key, value in tree.items()}
    return tree
