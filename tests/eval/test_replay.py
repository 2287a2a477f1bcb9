"""Replays: save and load round trip (the same frames are drawn), clear errors for truncated,
malformed or other-version files, and `elevens render`."""

from __future__ import annotations

import io
import json
import zipfile

import jax
import numpy as np
import pytest

import elevens
from elevens.cli.eval import main as eval_main
from elevens.env.render import frames_from_states
from elevens.eval.match import play_match
from elevens.eval.play import states_from_record
from elevens.eval.replay import (
    ARRAYS,
    ReplayError,
    load_replay,
    replay_frames,
    replay_from_match,
    replay_to_json,
    save_match_replays,
    save_replay,
)
from elevens.teams.scripted import NaiveTeam, RandomTeam


@pytest.fixture(scope="module")
def match():
    # Same compile as test_match's record test (2 v 2, 40 steps, 6 games, random v naive).
    env, params = elevens.make("2v2", episode_length=40)
    result = play_match(env, params, RandomTeam(), NaiveTeam(), jax.random.key(4), 6,
                        record=True)
    return jax.device_get(result), params


def test_round_trip_keeps_every_array_and_draws_the_same_frames(match, tmp_path) -> None:
    result, params = match
    paths = save_match_replays(result, params, tmp_path, "random", "naive", games=[1, 4],
                               source={"seed": 4})
    assert [p.name for p in paths] == ["game_0001.npz", "game_0004.npz"]
    for game, path in zip((1, 4), paths, strict=True):
        replay = load_replay(path)
        record = result.record
        np.testing.assert_array_equal(replay.positions, record.positions[game])
        np.testing.assert_array_equal(replay.headings, record.headings[game])
        np.testing.assert_array_equal(replay.ball_position, record.ball_position[game])
        np.testing.assert_array_equal(replay.ball_velocity, record.ball_velocity[game])
        np.testing.assert_array_equal(replay.score, record.score[game])
        np.testing.assert_array_equal(replay.actions, record.actions[game])
        np.testing.assert_array_equal(replay.step, np.arange(40))
        assert replay.params == params
        assert replay.source == {"game": game, "home": "random", "away": "naive",
                                 "home_side": int(result.home_side[game]), "seed": 4}
        # World frame: team 0 is whoever played side 0 in that game (home in the first half).
        home_side = int(result.home_side[game])
        assert replay.team_names == (("random", "naive") if home_side == 0 else
                                     ("naive", "random"))
        scores = (int(result.goals_for[game]), int(result.goals_against[game]))
        assert replay.final_score == (scores if home_side == 0 else scores[::-1])

    # The loaded replay draws exactly the frames of the original record.
    replay = load_replay(paths[0])
    expected = frames_from_states(states_from_record(result.record, 1, params), params,
                                  team_names=replay.team_names, scale=2)
    drawn = replay_frames(replay, scale=2)
    assert len(drawn) == len(expected) + 1 == 41  # and a full-time frame
    for got, want in zip(drawn, expected, strict=False):
        np.testing.assert_array_equal(got, want)
    assert not np.array_equal(drawn[-1], drawn[-2])  # its header says full time
    assert len(replay_frames(replay, scale=2, full_time=False)) == 40
    view = replay_frames(replay, view=2, scale=2)
    assert not np.array_equal(view[5], drawn[5])
    with pytest.raises(ValueError, match="view=4"):
        replay_frames(replay, view=4)


def test_files_are_small_and_never_pickled(match, tmp_path) -> None:
    result, params = match
    path = save_replay(replay_from_match(result, params, 0, "random", "naive"), tmp_path / "g")
    assert path.name == "g.npz"
    with np.load(path, allow_pickle=False) as archive:
        assert set(archive.files) == {"header", *ARRAYS}
        header = json.loads(archive["header"].tobytes().decode())
    assert (header["format"], header["version"], header["steps"]) == ("elevens-replay", 1, 40)
    assert header["params"]["players_per_team"] == 2
    assert path.stat().st_size < 20_000  # 40 steps of 2 v 2
    data = replay_to_json(load_replay(path))
    json.dumps(data)
    assert len(data["positions"]) == 40 and len(data["positions"][0]) == 4


def _rewrite(source, target, change):
    """Copy a replay with ``change(arrays)`` applied to its dict of arrays."""
    with np.load(source, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    change(arrays)
    with open(target, "wb") as handle:
        np.savez(handle, **arrays)
    return target


def _with_header(**changes):
    def change(arrays):
        header = json.loads(arrays["header"].tobytes().decode())
        header.update(changes)
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)

    return change


def test_damaged_files_give_clear_errors(match, tmp_path) -> None:
    result, params = match
    good = save_replay(replay_from_match(result, params, 0, "random", "naive"),
                       tmp_path / "good.npz")
    data = good.read_bytes()

    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ReplayError, match=r"truncated\.npz: cannot read the replay"):
        load_replay(truncated)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"this is not a zip file at all")
    with pytest.raises(ReplayError, match="garbage.npz"):
        load_replay(garbage)
    with pytest.raises(ReplayError, match="no such replay file"):
        load_replay(tmp_path / "missing.npz")

    cases = {
        "version.npz": (_with_header(version=99), "version 99 is not supported"),
        "format.npz": (_with_header(format="other"), "not an elevens replay"),
        "steps.npz": (_with_header(steps=41), r"'positions' has shape \(40, 4, 2\)"),
        "params.npz": (_with_header(params={"wings": 2}), "malformed header"),
        "names.npz": (_with_header(team_names="ab"), "team_names"),
        "missing.npz": (lambda arrays: arrays.pop("actions"), "'actions' is missing"),
        "dtype.npz": (lambda arrays: arrays.update(score=arrays["score"].astype(np.float32)),
                      "dtype float32"),
        "nan.npz": (lambda arrays: arrays["ball_position"].__setitem__((3, 0), np.nan),
                    "NaN"),
        "no_header.npz": (lambda arrays: arrays.pop("header"), "no header"),
        "bad_json.npz": (lambda arrays: arrays.update(header=np.frombuffer(b"{oops", np.uint8)),
                         "not valid UTF-8 JSON"),
    }
    for name, (change, message) in cases.items():
        path = _rewrite(good, tmp_path / name, change)
        with pytest.raises(ReplayError, match=message) as error:
            load_replay(path)
        assert str(path) in str(error.value)
        assert isinstance(error.value, ValueError)

    # An object array can only be read with pickle, which is never allowed.
    pickled = tmp_path / "pickled.npz"
    with zipfile.ZipFile(good) as archive, zipfile.ZipFile(pickled, "w") as out:
        for item in archive.namelist():
            out.writestr(item, archive.read(item))
        buffer = io.BytesIO()
        np.save(buffer, np.array([{"a": 1}], dtype=object), allow_pickle=True)
        out.writestr("extra.npy", buffer.getvalue())
    with pytest.raises(ReplayError, match="pickled.npz"):
        load_replay(pickled)


def test_save_refuses_bad_arrays(match, tmp_path) -> None:
    result, params = match
    replay = replay_from_match(result, params, 0, "random", "naive")
    replay.positions[0, 0, 0] = np.inf
    with pytest.raises(ReplayError, match="NaN or infinite"):
        save_replay(replay, tmp_path / "bad.npz")
    assert not (tmp_path / "bad.npz").exists()
    with pytest.raises(ValueError, match="game=6"):
        replay_from_match(result, params, 6, "random", "naive")


def test_render_command_writes_one_frame_per_step_and_full_time(match, tmp_path, capsys) -> None:
    import imageio.v3 as iio

    result, params = match
    path = save_replay(replay_from_match(result, params, 2, "random", "naive"),
                       tmp_path / "game.npz")
    out = tmp_path / "game.gif"
    eval_main(["render", str(path), "--out", str(out), "--scale", "2", "--view", "1"])
    assert iio.imread(out, index=None).shape[0] == 41
    assert "(41 frames, the last at full time)" in capsys.readouterr().out
    broken = tmp_path / "broken.npz"
    broken.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ReplayError, match="broken.npz"):
        eval_main(["render", str(broken), "--out", str(out)])
