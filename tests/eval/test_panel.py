"""A team against the opponent panel: `play_panel` and `elevens tournament TEAM --panel`."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import elevens
from elevens.cli.eval import main as eval_main
from elevens.eval.panel import PanelResult, play_panel
from elevens.runs.teams import load_team
from elevens.teams.registry import PANEL
from tests.refusal import refused


def test_mean_and_worst_weigh_every_opponent_the_same() -> None:
    result = PanelResult(
        "x", ("a", "b", "c"),
        tuple({"mean": value, "games": 10.0} for value in (0.9, 0.3, 0.6)),
    )
    assert result.mean == pytest.approx(0.6)
    assert result.worst == ("b", 0.3)


def test_play_panel_plays_each_opponent_on_its_own_key() -> None:
    env, params = elevens.make("1v1", episode_length=40)
    team = load_team("naive")
    panel = [load_team("random"), load_team("naive")]
    seen: list[str] = []
    result = play_panel(team, panel, env, params, num_games=6, seed=3,
                        on_match=lambda k, total, name, r: seen.append(name))
    assert seen == ["random", "naive"] and result.opponents == ("random", "naive")
    assert [n["games"] for n in result.numbers] == [6.0, 6.0]
    # The same seed gives the same games; the panel's order only picks each match's key.
    again = play_panel(team, panel[:1], env, params, num_games=6, seed=3)
    assert again.numbers[0] == result.numbers[0]
    with pytest.raises(ValueError, match="the panel is empty"):
        play_panel(team, [], env, params, num_games=6)


def test_tournament_panel_reports_mean_and_worst_and_writes_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The command reads the registry's panel: two of its teams (a compile each) show that it
    # plays them in order and sums them up. Every panel team's own play is tests/teams'.
    panel = PANEL[:2]
    monkeypatch.setattr("elevens.teams.registry.PANEL", panel)
    out = tmp_path / "panel"
    (result,) = eval_main(["tournament", "naive", "--panel", "--games", "2", "--players",
                           "1", "--steps", "30", "--out", str(out)])
    printed = capsys.readouterr().out
    saved = json.loads((out / "panel.json").read_text())
    (entry,) = saved["teams"]
    assert [o["opponent"] for o in entry["opponents"]] == list(panel)
    means = np.array([o["mean"] for o in entry["opponents"]])
    assert entry["mean"] == pytest.approx(means.mean()) == pytest.approx(result.mean)
    assert entry["worst"]["mean"] == pytest.approx(means.min())
    assert f"naive: mean {entry['mean']:.3f} over the panel" in printed
    with (out / "panel.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [row["opponent"] for row in rows] == list(panel)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["tournament", "--panel"], "--panel needs the team(s) to measure"),
        (["tournament", "nobody", "--panel"], "nobody does not exist"),
        (["tournament", "naive", "--panel", "--anchor", "naive"], "--anchor cannot be used"),
        (["tournament", "rcss_naive", "--panel"], "12-value"),
    ],
)
def test_bad_panel_input_is_one_line_and_exit_2(
    argv: list[str], message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    assert message in refused(argv, "tournament", capsys)
    assert list(tmp_path.iterdir()) == []  # no game was played, nothing written
