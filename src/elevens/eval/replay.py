"""Replays: one game saved to a small, documented file, to draw, analyse or watch later.

File format (``.npz``, written with ``numpy.savez_compressed``, read with
``numpy.load(allow_pickle=False)``; never pickle). With ``T`` recorded steps and ``n`` players a
side, world frame (team 0 attacks +x), entry ``t`` being the state the players saw at step ``t``
and the actions they took there:

==================  ===============  =========================================================
array               dtype, shape     meaning
==================  ===============  =========================================================
``header``          uint8[B]         UTF-8 JSON object, below
``positions``       float32[T,2n,2]  player centres, team 0 first (row ``t*n + k``), metres
``headings``        float32[T,2n]    radians, 0 = +x, counter-clockwise positive
``ball_position``   float32[T,2]     metres
``ball_velocity``   float32[T,2]     metres per step
``score``           int32[T,2]       goals of team 0 and team 1 so far
``step``            int32[T]         the step number of each entry (0..T-1)
``actions``         float32[T,2,n,2] (team, player, (move, rot)) as applied (clipped)
==================  ===============  =========================================================

The header::

    {"format": "elevens-replay", "version": 1,
     "team_names": ["naive", "teamwork"],      # team 0 (attacks +x), team 1
     "players_per_team": 11, "steps": 400,
     "final_score": [1, 2],                     # after the last step (the arrays hold the score
                                                #   each step was played at)
     "params": {...},                           # every EnvParams field, enough to rebuild the
                                                #   scenario: EnvParams(**params)
     "source": {...}}                           # free-form provenance (seed, game index, ...)

A reader refuses another ``format`` or a ``version`` it does not know, and any missing, extra-
shaped or non-finite array, with a ``ReplayError`` (a ValueError) naming the file and the problem.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elevens.env.params import EnvParams
from elevens.env.state import State
from elevens.eval.match import MatchRecord, MatchResult

FORMAT = "elevens-replay"
VERSION = 1
SUFFIX = ".npz"
ARRAYS: dict[str, tuple[type, str]] = {
    # name: (dtype, shape in terms of T and n)
    "positions": (np.float32, "T,2n,2"),
    "headings": (np.float32, "T,2n"),
    "ball_position": (np.float32, "T,2"),
    "ball_velocity": (np.float32, "T,2"),
    "score": (np.int32, "T,2"),
    "step": (np.int32, "T"),
    "actions": (np.float32, "T,2,n,2"),
}


class ReplayError(ValueError):
    """A replay file cannot be read: missing, truncated, malformed, or of another version."""


@dataclasses.dataclass(frozen=True, eq=False)
class Replay:
    """One game, world frame (team 0 attacks +x). See the module docstring for the fields."""

    team_names: tuple[str, str]
    params: EnvParams
    final_score: tuple[int, int]
    positions: np.ndarray  # f32[T, 2n, 2]
    headings: np.ndarray  # f32[T, 2n]
    ball_position: np.ndarray  # f32[T, 2]
    ball_velocity: np.ndarray  # f32[T, 2]
    score: np.ndarray  # i32[T, 2]
    step: np.ndarray  # i32[T]
    actions: np.ndarray  # f32[T, 2, n, 2]
    source: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def num_steps(self) -> int:
        return int(self.step.shape[0])

    @property
    def players_per_team(self) -> int:
        return int(self.params.players_per_team)

    def record(self) -> MatchRecord:
        """The replay as a one-game ``MatchRecord`` (leading axis ``[1]``)."""
        import jax.numpy as jnp

        return MatchRecord(
            positions=jnp.asarray(self.positions[None]),
            headings=jnp.asarray(self.headings[None]),
            ball_position=jnp.asarray(self.ball_position[None]),
            ball_velocity=jnp.asarray(self.ball_velocity[None]),
            score=jnp.asarray(self.score[None]),
            actions=jnp.asarray(self.actions[None]),
        )

    def states(self) -> State:
        """The per-step States ``[T, ...]`` for drawing (``elevens.eval.play.states_from_record``:
        velocities and start points are not recorded, so zero and the first position)."""
        import jax

        from elevens.eval.play import states_from_record

        states = states_from_record(self.record(), 0, self.params)
        states = dataclasses.replace(states, step=jax.numpy.asarray(self.step))
        return jax.tree.map(np.asarray, states)

    def header(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": VERSION,
            "team_names": list(self.team_names),
            "players_per_team": self.players_per_team,
            "steps": self.num_steps,
            "final_score": [int(v) for v in self.final_score],
            "params": params_to_dict(self.params),
            "source": self.source,
        }


# --------------------------------------------------------------------------------------------
# EnvParams <-> JSON
# --------------------------------------------------------------------------------------------


def params_to_dict(params: EnvParams) -> dict[str, Any]:
    """Every EnvParams field as a JSON value (numbers as Python floats/ints)."""
    out: dict[str, Any] = {}
    for field in dataclasses.fields(params):
        value = getattr(params, field.name)
        if isinstance(value, str | bool):
            out[field.name] = value
        else:
            array = np.asarray(value)
            if array.ndim != 0:
                raise ValueError(f"EnvParams.{field.name} is not a scalar (shape {array.shape})")
            out[field.name] = array.item()
    return out


def params_from_dict(data: Mapping[str, Any]) -> EnvParams:
    """EnvParams from ``params_to_dict`` output; unknown fields are a ValueError."""
    names = {field.name for field in dataclasses.fields(EnvParams)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"unknown EnvParams fields {unknown}")
    return EnvParams(**dict(data))


# --------------------------------------------------------------------------------------------
# Building replays
# --------------------------------------------------------------------------------------------


def replay_from_match(
    result: MatchResult,
    params: EnvParams,
    game: int,
    home_name: str,
    away_name: str,
    source: Mapping[str, Any] | None = None,
) -> Replay:
    """Game ``game`` of a match played with ``record=True``, as a Replay.

    The replay is in the world frame: team 0 is whichever team played side 0 in that game (the
    home team in the first half of a side-swapped match, the away team in the second).
    """
    record = result.record
    if record is None:
        raise ValueError("the match has no record: play it with record=True")
    num_games = int(np.asarray(result.outcome).shape[0])
    if not 0 <= game < num_games:
        raise ValueError(f"game={game} is invalid: the match has games 0..{num_games - 1}")
    home_side = int(np.asarray(result.home_side)[game])
    goals_for = int(np.asarray(result.goals_for)[game])
    goals_against = int(np.asarray(result.goals_against)[game])
    if home_side == 0:
        names, final = (home_name, away_name), (goals_for, goals_against)
    else:
        names, final = (away_name, home_name), (goals_against, goals_for)
    steps = int(np.asarray(record.positions).shape[1])
    info = {"game": game, "home": home_name, "away": away_name, "home_side": home_side}
    info.update(dict(source or {}))
    return Replay(
        team_names=names,
        params=params,
        final_score=final,
        positions=np.array(record.positions[game], np.float32),
        headings=np.array(record.headings[game], np.float32),
        ball_position=np.array(record.ball_position[game], np.float32),
        ball_velocity=np.array(record.ball_velocity[game], np.float32),
        score=np.array(record.score[game], np.int32),
        step=np.arange(steps, dtype=np.int32),
        actions=np.array(record.actions[game], np.float32),
        source=info,
    )


def save_match_replays(
    result: MatchResult,
    params: EnvParams,
    out_dir: str | Path,
    home_name: str,
    away_name: str,
    games: Sequence[int] | None = None,
    source: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Save games of a recorded match, one file each (``game_0007.npz``); all games by default."""
    num_games = int(np.asarray(result.outcome).shape[0])
    chosen = range(num_games) if games is None else games
    out = Path(out_dir)
    paths = []
    for game in chosen:
        replay = replay_from_match(result, params, int(game), home_name, away_name, source)
        paths.append(save_replay(replay, out / f"game_{int(game):04d}{SUFFIX}"))
    return paths


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def _expected_shape(spec: str, steps: int, n: int) -> tuple[int, ...]:
    sizes = {"T": steps, "2n": 2 * n, "n": n, "2": 2}
    return tuple(sizes[part] for part in spec.split(","))


def _check_arrays(arrays: Mapping[str, np.ndarray], steps: int, n: int, where: str) -> None:
    for name, (dtype, spec) in ARRAYS.items():
        if name not in arrays:
            raise ReplayError(f"{where}: array {name!r} is missing")
        array = arrays[name]
        expected = _expected_shape(spec, steps, n)
        if array.shape != expected:
            raise ReplayError(
                f"{where}: array {name!r} has shape {array.shape}, expected {expected} "
                f"([{spec}] with T={steps}, n={n})"
            )
        if array.dtype != np.dtype(dtype):
            raise ReplayError(
                f"{where}: array {name!r} has dtype {array.dtype}, expected {np.dtype(dtype)}"
            )
        if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
            raise ReplayError(f"{where}: array {name!r} holds NaN or infinite values")


def save_replay(replay: Replay, path: str | Path) -> Path:
    """Write ``replay`` to ``path`` (``.npz`` is appended if missing); returns the path.

    Written to a temporary name and renamed, so a crash never leaves half a replay under the
    final name.
    """
    path = Path(path)
    if path.suffix != SUFFIX:
        path = path.with_name(path.name + SUFFIX)
    arrays = {name: np.asarray(getattr(replay, name)) for name in ARRAYS}
    _check_arrays(arrays, replay.num_steps, replay.players_per_team, str(path))
    header = np.frombuffer(json.dumps(replay.header()).encode("utf-8"), np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.tmp")
    savez: Any = np.savez_compressed  # its stubs type **arrays as its own keyword options
    with temporary.open("wb") as handle:
        savez(handle, header=header, **arrays)
    temporary.replace(path)
    return path


def _header(raw: np.ndarray, where: str) -> dict[str, Any]:
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise ReplayError(f"{where}: the header is not a uint8[B] array of UTF-8 JSON")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ReplayError(f"{where}: the header is not valid UTF-8 JSON: {error}") from None
    if not isinstance(header, dict):
        raise ReplayError(f"{where}: the header is not a JSON object")
    if header.get("format") != FORMAT:
        raise ReplayError(
            f"{where}: not an elevens replay (header format {header.get('format')!r}, expected "
            f"{FORMAT!r})"
        )
    version = header.get("version")
    if version != VERSION:
        raise ReplayError(
            f"{where}: replay format version {version!r} is not supported (this elevens reads "
            f"version {VERSION}); convert it with the elevens version that wrote it"
        )
    return header


def load_replay(path: str | Path) -> Replay:
    """Read a replay file. Any problem is a ``ReplayError`` naming the path and the problem."""
    path = Path(path)
    where = str(path)
    if path.is_dir():
        raise ReplayError(f"{where} is a folder: give a replay file (.npz) of it")
    if not path.is_file():
        raise ReplayError(f"{where}: no such replay file")
    with path.open("rb") as handle:
        magic = handle.read(4)
    if magic != b"PK\x03\x04":  # every .npz is a zip archive; numpy's own error talks of pickles
        raise ReplayError(f"{where}: not an .npz archive (not an elevens replay?)")
    try:
        # Our own handle: np.load leaks the one it opens when the zip directory is damaged.
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as archive:
            names = set(archive.files)
            if "header" not in names:
                raise ReplayError(f"{where}: no header array (not an elevens replay?)")
            arrays = {name: archive[name] for name in names}
    except ReplayError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as error:
        # A truncated or damaged file fails inside zipfile/zlib/numpy with many error types.
        raise ReplayError(
            f"{where}: cannot read the replay (truncated or not an .npz file): "
            f"{type(error).__name__}: {error}"
        ) from None
    except Exception as error:  # zlib.error and friends
        raise ReplayError(
            f"{where}: cannot read the replay (damaged data): {type(error).__name__}: {error}"
        ) from None
    header = _header(arrays.pop("header"), where)
    try:
        steps = int(header["steps"])
        n = int(header["players_per_team"])
        names = header["team_names"]
        final = header["final_score"]
        params = params_from_dict(header["params"])
        source = header.get("source", {})
        if not (isinstance(names, list) and len(names) == 2 and all(isinstance(v, str)
                                                                     for v in names)):
            raise ValueError("team_names must be a list of two strings")
        if not (isinstance(final, list) and len(final) == 2):
            raise ValueError("final_score must be a list of two integers")
        if params.players_per_team != n:
            raise ValueError(
                f"players_per_team={n} but params.players_per_team={params.players_per_team}"
            )
        if not isinstance(source, dict):
            raise ValueError("source must be a JSON object")
    except (KeyError, TypeError, ValueError) as error:
        raise ReplayError(f"{where}: malformed header: {type(error).__name__}: {error}") from None
    _check_arrays(arrays, steps, n, where)
    return Replay(
        team_names=(names[0], names[1]),
        params=params,
        final_score=(int(final[0]), int(final[1])),
        source=source,
        **{name: arrays[name] for name in ARRAYS},
    )


def replay_to_json(replay: Replay, digits: int = 3, actions: bool = True) -> dict[str, Any]:
    """The replay as plain JSON (the web viewer's input): the header plus per-step lists,
    floats rounded to ``digits`` decimals (millimetres) to keep the download small.
    ``actions=False`` leaves the actions out (the viewer does not draw them)."""

    def rounded(array: np.ndarray) -> Any:
        return np.round(np.asarray(array, np.float64), digits).tolist()

    data = {
        **replay.header(),
        "positions": rounded(replay.positions),
        "headings": rounded(replay.headings),
        "ball_position": rounded(replay.ball_position),
        "ball_velocity": rounded(replay.ball_velocity),
        "score": np.asarray(replay.score).tolist(),
        "step": np.asarray(replay.step).tolist(),
    }
    if actions:
        data["actions"] = rounded(replay.actions)
    return data


def render_replay(
    replay: Replay,
    out: str | Path,
    *,
    view: int | None = None,
    fps: float = 20,
    scale: float = 6,
    progress: bool = False,
    follow_ball: float | None = None,
) -> Path:
    """Draw a replay to a GIF or MP4 (by suffix); ``view``: a player row whose field of view
    is drawn (team 0 is 0..n-1, team 1 n..2n-1)."""
    from elevens.env.render import save_video

    frames = replay_frames(replay, view=view, scale=scale, progress=progress,
                           follow_ball=follow_ball)
    return save_video(frames, out, fps=fps)


def replay_frames(
    replay: Replay, *, view: int | None = None, scale: float = 6, progress: bool = False,
    full_time: bool = True, follow_ball: float | None = None,
) -> list[np.ndarray]:
    """The replay's frames ``uint8[H, W, 3]`` (``elevens.env.render.frames_from_states``), and
    with ``full_time`` one more showing the final score."""
    from elevens.env.render import frames_from_states, with_full_time

    num_players = 2 * replay.players_per_team
    if view is not None and not 0 <= view < num_players:
        raise ValueError(
            f"view={view} is invalid: it must be a player row from 0 to {num_players - 1}"
        )
    states = replay.states()
    if full_time:
        states = with_full_time(states, replay.final_score)
    return frames_from_states(
        states, replay.params, player=view, progress=progress,
        team_names=replay.team_names, scale=scale, follow_ball=follow_ball,
    )
