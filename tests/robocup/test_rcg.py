"""Game logs (.rcg) read into arrays and told from one team's side: a recorded excerpt of a real
log, and small logs written here whose every touch, goal and stamina figure is known."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from elevens.cli import main
from elevens.robocup.rcg import find_logs, read_rcg, summarize_team

EXCERPT = Path(__file__).parents[1] / "data" / "rcss" / "goal_excerpt.rcg"


def _player(side: str, unum: int, x: float, y: float, *, kicks: int = 0, tackles: int = 0,
            stamina: float = 8000.0, capacity: float = 130600.0) -> str:
    # A player entry as rcssserver 19 writes it (type, state, pose, view, focus, stamina, counts).
    return (f"(({side} {unum}) 0 0x1 {x} {y} 0 0 0 0 (v h 180) (fp 0 0) "
            f"(s {stamina} 1 1 {capacity}) (f {side} 1) "
            f"(c {kicks} 1 1 0 1 1 1 0 {tackles} 0 1 0))")


def _log(path: Path, shows: list[tuple[int, tuple[float, float], list[str]]],
         modes: dict[int, str], score: tuple[int, int]) -> Path:
    lines = ["ULG6", "(server_param (ball_decay 0.94))", "(team 1 us them 0 0)"]
    for cycle, ball, players in shows:
        if cycle in modes:
            lines.append(f"(playmode {cycle} {modes[cycle]})")
        lines.append(f"(show {cycle} ((b) {ball[0]} {ball[1]} 0 0) {' '.join(players)})")
    lines.append(f"(team {shows[-1][0]} us them {score[0]} {score[1]})")
    path.write_text("\n".join(lines) + "\n")
    return path


def _match(path: Path) -> Path:
    """20 cycles: our 2 touches the ball at x 10 (cycle 2); their 2 kicks at the air 5 m from it
    (cycle 3) and then touches it at x 5 (cycle 5); they score at cycle 8; our 2's capacity is
    spent from cycle 6 on."""
    shows = []
    kicks = {("l", 2): 0, ("r", 2): 0}
    for cycle in range(1, 21):
        ball = (10.0, 0.0) if cycle <= 3 else (5.0, 0.0)
        where = {("l", 2): (10.5, 0.0), ("r", 2): (15.0, 0.0) if cycle < 4 else (5.5, 0.0)}
        if cycle == 2:
            kicks[("l", 2)] += 1
        if cycle in (3, 5):
            kicks[("r", 2)] += 1
        players = [_player("l", 1, -50, 0), _player("r", 1, 50, 0)]
        for (side, unum), (x, y) in where.items():
            spent = side == "l" and cycle >= 6
            players.append(_player(side, unum, x, y, kicks=kicks[(side, unum)],
                                   capacity=0.0 if spent else 130600.0,
                                   stamina=1000.0 if spent else 8000.0))
        shows.append((cycle, ball, players))
    return _log(path, shows, {1: "kick_off_l", 2: "play_on", 8: "goal_r", 9: "kick_off_l"},
                (0, 1))


def test_a_small_log_tells_each_touch_goal_and_spent_stamina(tmp_path: Path) -> None:
    game = read_rcg(_match(tmp_path / "m.rcg"))
    assert game.names == ("us", "them") and game.score == (0, 1)
    assert game.pos.shape == (20, 2, 11, 2) and np.isnan(game.pos[0, 0, 5]).all()
    # The air kick at cycle 3 (the ball 5 m away) is no touch.
    assert game.touches.tolist() == [[1, 0, 2], [4, 1, 2]]
    ours = summarize_team([game])
    assert (ours.team, ours.goals_for, ours.goals_against) == ("us", 0, 1)
    assert (ours.touches_for, ours.touches_against) == (1, 1)
    (goal,) = ours.conceded
    assert goal.cycle == 8 and goal.since_kick_off == 7
    assert goal.last_touch_cycle == 2 and goal.last_touch_x == 10.0 and goal.regained_x == 5.0
    assert ours.capacity_empty_cycle == (6.0, 11.0)
    assert ours.ball_in_own_half == 0.0
    # Their side of the same game: x flips, nothing conceded, their capacity never spent.
    theirs = summarize_team([game], "them")
    assert (theirs.goals_for, theirs.conceded) == (1, ())
    assert theirs.ball_in_own_half == 1.0
    assert theirs.capacity_empty_cycle == (float("inf"), float("inf"))


def test_a_recorded_log_of_rcssserver_19_reads_all_22_players(tmp_path: Path) -> None:
    game = read_rcg(EXCERPT)
    assert game.names == ("skills", "HELIOS_base") and game.score == (0, 1)
    assert game.cycle.tolist() == [508, 509, 510, 511, 512]
    assert np.isfinite(game.pos).all() and np.isfinite(game.stamina).all()
    assert game.ball[0].tolist() == [-49.797, 2.0063]
    assert (game.capacity <= 130600).all() and (game.capacity > 0).all()
    (goal,) = summarize_team([game]).conceded
    assert goal.cycle == 511
    assert [c for c, _ in game.playmodes] == [1, 511, 512]


def test_the_command_summarises_a_folder_and_refuses_bad_paths_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "series" / "match_000"
    folder.mkdir(parents=True)
    _match(folder / "a.rcg")
    assert find_logs([str(tmp_path / "series")]) == [folder / "a.rcg"]
    main(["robocup", "logs", str(tmp_path / "series"), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["goals_against"] == 1 and out["conceded"][0]["regained_x"] == 5.0
    assert out["capacity_empty_cycle"] == [6.0, 11.0]
    main(["robocup", "logs", str(folder / "a.rcg"), "--team", "them"])
    assert capsys.readouterr().out.startswith("them: 1 matches, goals 1 - 0")
    (tmp_path / "empty").mkdir()
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "fake.rcg").write_text("hello\n")
    for args, message in (
        ([str(tmp_path / "missing")], "does not exist"),
        ([str(tmp_path / "empty")], "holds no .rcg game log"),
        ([str(tmp_path / "notes.txt")], "is not a .rcg game log"),
        ([str(tmp_path / "fake.rcg")], "is not a text .rcg game log"),
        ([str(folder / "a.rcg"), "--team", "nobody"], "'nobody' did not play"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main(["robocup", "logs", *args])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err
