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
FAULT_EXCERPT = Path(__file__).parents[1] / "data" / "rcss" / "fault_excerpt.rcg"


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


def _faults(path: Path) -> Path:
    """40 cycles, the half at 20, the ball at the centre spot and our 2 and 3 and their 2 beside
    it. Our 2 kicks off at 2, 11 and 19 and gives away a free kick each time (at 5 by a kick, at
    12 and 20 by running into the ball); their 2 takes each free kick. After the first they
    score at 9 before we touch the ball; after the second our 3 touches it at 15 and they score
    at 17 all the same; after the third they score at 25, in the other half. Their 2 gives one
    away after its kick-in (30), and we never score."""
    kicks_at = {("l", 2): (2, 5, 11, 19), ("l", 3): (15,), ("r", 2): (7, 14, 22, 29)}
    where = {("l", 2): (-0.5, 0.0), ("l", 3): (0.0, 1.0), ("r", 2): (0.5, 0.0)}
    shows = []
    for cycle in range(1, 41):
        players = [_player("l", 1, -50, 0), _player("r", 1, 50, 0)]
        for (side, unum), (x, y) in where.items():
            kicks = sum(at <= cycle for at in kicks_at[(side, unum)])
            players.append(_player(side, unum, x, y, kicks=kicks))
        shows.append((cycle, (0.0, 0.0), players))
    modes = {1: "kick_off_l", 2: "play_on", 5: "free_kick_fault_l", 6: "free_kick_r",
             7: "play_on", 9: "goal_r", 10: "kick_off_l", 11: "play_on",
             12: "free_kick_fault_l", 13: "free_kick_r", 14: "play_on", 17: "goal_r",
             18: "kick_off_l", 19: "play_on", 20: "free_kick_fault_l", 21: "free_kick_r",
             22: "play_on", 25: "goal_r", 26: "kick_off_l", 28: "kick_in_r", 29: "play_on",
             30: "free_kick_fault_r", 31: "free_kick_l", 32: "play_on"}
    return _log(path, shows, modes, (0, 3))


def test_free_kick_faults_count_the_goals_conceded_before_the_next_touch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    game = read_rcg(_faults(tmp_path / "f.rcg"))
    ours = summarize_team([game])
    assert [(f.cycle, f.set_piece, f.conceded_cycle) for f in ours.faults] == [
        (5, "kick_off", 9), (12, "kick_off", None), (20, "kick_off", None)]
    theirs = summarize_team([game], "them")
    assert [(f.cycle, f.set_piece, f.conceded_cycle) for f in theirs.faults] == [
        (30, "kick_in", None)]
    assert ("  free-kick faults given away: 3 (after its kick_off 3), 1 followed by a goal "
            "conceded before its next touch") in ours.lines()
    main(["robocup", "logs", str(tmp_path / "f.rcg"), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["faults"][0] == {"cycle": 5, "set_piece": "kick_off", "conceded_cycle": 9}


def test_a_recorded_free_kick_fault_and_the_goal_after_it() -> None:
    # rcss-gpu's kick-off taker (its 10) ran into its own kick 45 cycles later; helios-base
    # took the free kick and scored before rcss-gpu touched the ball again.
    game = read_rcg(FAULT_EXCERPT)
    assert game.names == ("rcssgpu", "HELIOS_base")
    assert game.touches[0].tolist() == [1, 0, 10]  # the kick-off, at cycle 3472
    (fault,) = summarize_team([game]).faults
    assert (fault.cycle, fault.set_piece, fault.conceded_cycle) == (3517, "kick_off", 3589)
    assert summarize_team([game], "HELIOS_base").faults == ()


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
