"""The command line: `elevens play` writes a game, `elevens bench env --json` reports figures."""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import pytest

from elevens.cli import main
from tests.refusal import refused


def test_play_writes_a_gif_with_one_frame_per_step(tmp_path, capsys):
    out = tmp_path / "game.gif"
    main(["play", "--home", "naive", "--away", "random", "--players", "1", "--steps", "12",
          "--out", str(out), "--scale", "3"])
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 12 + 1  # one per step, then the full-time frame
    assert frames.shape[-1] in (3, 4)


def test_play_view_of_one_player_and_mp4(tmp_path):
    out = tmp_path / "game.mp4"
    main(["play", "--players", "2", "--steps", "8", "--out", str(out), "--view", "1",
          "--scale", "3"])
    assert out.stat().st_size > 0


@pytest.mark.parametrize(
    "argv,message",
    [
        (["play", "--home", "wizards", "--steps", "4"],
         "wizards does not exist (expected a run directory"),
        (["play", "--players", "12", "--steps", "4"], "players=12 is invalid"),
        (["play", "--players", "1", "--view", "5", "--steps", "4"], "view=5"),
        (["play", "--steps", "4", "--out", "game.avi"], ".gif or .mp4"),
        (["play", "--steps", "4", "--replay", "game.json"], "the suffix must be .npz"),
    ],
)
def test_play_bad_input_is_one_line_and_exit_2(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert message in refused(argv, "play", capsys)
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_bench_env_json_lines(capsys, tmp_path):
    main(["bench", "env", "--players", "1", "--batch", "4", "8", "--steps", "5", "--repeats", "1",
          "--loop-steps", "5", "--json", "--plot", str(tmp_path / "fig_6_1.png")])
    assert (tmp_path / "fig_6_1.png").read_bytes()[:4] == b"\x89PNG"
    lines = [json.loads(line) for line in capsys.readouterr().out.strip().splitlines()]
    assert [(r["players"], r["mode"], r["batch"]) for r in lines] == [
        (1, "loop", 1), (1, "scan", 4), (1, "scan", 8)
    ]
    for record in lines:
        assert record["steps_per_s"] > 0
        assert set(record) >= {"players", "batch", "mode", "steps_per_s"}
    assert lines[1]["ratio_to_loop"] == pytest.approx(
        lines[1]["steps_per_s"] / lines[0]["steps_per_s"]
    )


def test_handcrafted_figures_script_writes_its_table_and_figure(tmp_path):
    import importlib.util

    path = Path(__file__).parent.parent / "scripts" / "handcrafted_figures.py"
    spec = importlib.util.spec_from_file_location("handcrafted_figures", path)
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    rows = [{"home": "naive", "away": "random", "sides": "sides swapped", "games": 500,
             "mean": 0.98, "stderr": 0.006, "win": 0.97, "draw": 0.02, "loss": 0.01,
             "goals_for": 3.1, "goals_against": 0.1, "bar": ">= 0.95", "met": True}]
    table, figure = script.write_outputs(rows, tmp_path, "11v11, 500 games a match")
    assert table.read_text().splitlines()[1].startswith("naive,random,sides swapped,500,0.98")
    assert figure.read_bytes()[:4] == b"\x89PNG"
