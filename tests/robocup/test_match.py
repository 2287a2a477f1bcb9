"""One elevens team in a match (robocup.team) and full matches (robocup.match): against the
fake server everywhere, against rcssserver and a fake external team where rcssserver is
installed, and against helios-base where it is built."""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from elevens.cli import main
from elevens.robocup.external import connected_players, start_team, stop_team, wait_connected
from elevens.robocup.match import (
    MATCH_OPTIONS,
    ElevensTeam,
    ExternalTeam,
    MatchResult,
    SkillsTeam,
    parse_team,
    play_match,
    play_matches,
    played_cycles,
    summarize,
    t_quantile_975,
)
from elevens.robocup.server import ServerAddress, ServerProcess
from elevens.robocup.skills.proxy import BUILD_HINT, ProxyNotFound, find_proxy
from elevens.robocup.team import RoboCupTeam, TeamResult
from tests.refusal import refused
from tests.robocup.conftest import needs_rcssserver
from tests.robocup.test_client import FakeServer

FAKE_TEAM = Path(__file__).with_name("fake_team.py")


def _proxy_built() -> bool:
    try:
        find_proxy()
    except ProxyNotFound:
        return False
    return True

HELIOS = os.environ.get("ELEVENS_HELIOS_START", "")
needs_helios = pytest.mark.skipif(
    not (HELIOS and Path(HELIOS).is_file() and (os.environ.get("ELEVENS_RCSSSERVER") or
                                                 __import__("shutil").which("rcssserver"))),
    reason=(
        "helios-base not built: build librcsc (github.com/helios-base/librcsc, cmake with "
        "-DHAVE_NETINET_IN_H=1) and helios-base (github.com/helios-base/helios-base) outside "
        "the repository, then set ELEVENS_HELIOS_START=/path/to/helios-base/build/bin/start.sh "
        "(and install rcssserver); see docs/results/robocup.md"
    ),
)

needs_proxy = pytest.mark.skipif(
    not _proxy_built(),
    reason=f"the skills proxy is not built: {BUILD_HINT}",
)


def _fake_team(name: str = "fake", players: int = 11, real_time: bool = False) -> ExternalTeam:
    flags = " --real-time" if real_time else ""
    cmd = f"{sys.executable} {FAKE_TEAM} --port {{port}} --team {{team}} --players {players}"
    return ExternalTeam(cmd + flags, name)


def _slow_first_call(team: RoboCupTeam, seconds: float) -> list[float]:
    """Make the team's first policy call take ``seconds`` (as a compile would); returns the
    list each call appends to (True for the slow one)."""
    act = team.player.act
    calls: list[bool] = []

    def slow(carry: Any, obs: Any, key: Any) -> Any:
        if not calls:
            time.sleep(seconds)
        calls.append(not calls)
        return act(carry, obs, key)

    team.player.act = slow
    return calls


def _play_in_thread(team: RoboCupTeam, address: Any, **kwargs: Any) -> dict[str, Any]:
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["result"] = team.play(address, **kwargs)
        except BaseException as error:  # reported by the test
            box["error"] = error

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    box["thread"] = thread
    return box


# -- against the fake server ----------------------------------------------------------------


def _referee(server: FakeServer, at: int, mode: str) -> None:
    server.extra.setdefault(at, []).append(
        ("players", f"(hear {at} referee {mode})".encode() + b"\x00")
    )


def test_team_moves_before_kick_off_plays_after_it_and_leaves_at_time_over() -> None:
    server = FakeServer(2, teams=1, wait_s=1.0)
    try:
        _referee(server, 6, "play_on")
        _referee(server, 14, "time_over")
        team = RoboCupTeam("naive", players_per_team=2, team_name="mine")
        result = team.play(server.address, max_cycles=100)
    finally:
        server.close()
    assert isinstance(result, TeamResult) and result.ended == "time_over"
    assert result.side == 0 and result.goals_for == result.goals_against == 0
    assert result.missed == 0 and server.timeouts == 0 and server.early_dones == 0
    sent = [d.decode() for d in server.players[0].received]
    moves = [i for i, d in enumerate(sent) if d.startswith("(move ")]
    bodies = [i for i, d in enumerate(sent) if d.startswith(("(dash", "(turn ", "(kick"))]
    assert moves and bodies and max(moves) < min(bodies)  # moved before kick-off only
    assert sent[-1].startswith("(bye)")


def test_a_team_not_told_its_opponents_name_sees_them() -> None:
    """The recorded see shows players of "RightTeam". A team given no opponent name takes any
    other named team as the opponent; it used to make one up and see no opponent at all."""
    server = FakeServer(1, teams=1, wait_s=1.0)
    masks: list[np.ndarray] = []
    try:
        _referee(server, 2, "play_on")
        team = RoboCupTeam("naive", players_per_team=1, team_name="mine")
        team.warm_up()
        act = team.player.act

        def spy(carry: Any, obs: Any, key: Any) -> Any:
            masks.append(np.asarray(obs.entity_mask))
            return act(carry, obs, key)

        team.player.act = spy
        team.play(server.address, max_cycles=8)
    finally:
        server.close()
    # One player a side: entity slot 0 is the opponent (unum 1), slot 1 the ball.
    assert len(masks) == 8 and any(mask[0, 0] for mask in masks)


def test_a_slow_first_policy_call_happens_before_connecting() -> None:
    """Compile before connect: a first call as slow as a JIT compile (longer than the
    server's wait) costs no cycle, because warm_up makes it before (init) goes out."""
    server = FakeServer(1, teams=1, wait_s=0.6)
    try:
        team = RoboCupTeam("naive", players_per_team=1, team_name="mine")
        calls = _slow_first_call(team, 1.0)
        team.warm_up()
        assert calls[0] >= 1.0 and not server.players  # paid before connecting
        result = team.play(server.address, max_cycles=12)
    finally:
        server.close()
    assert result.cycles == 12 and server.timeouts == 0
    assert server.players[0].dones == server.players[0].thinks - 1  # lockstep to the end


def test_without_warm_up_the_slow_first_call_costs_the_server_a_cycle() -> None:
    # The control for the test above: the same slow call after connecting is a missed cycle.
    server = FakeServer(1, teams=1, wait_s=0.6)
    try:
        team = RoboCupTeam("naive", players_per_team=1, team_name="mine")
        _slow_first_call(team, 1.0)
        team._warm = True  # skip the warm-up
        team.play(server.address, max_cycles=6)
    finally:
        server.close()
    assert server.timeouts >= 1


# -- the match runner without a server -------------------------------------------------------


def _result(m: int, score: tuple[int, int]) -> MatchResult:
    return MatchResult(m, ("a", "b"), score, 1.0, 6000, 0, None)


def test_summarize_counts_results_and_brackets_the_mean_difference() -> None:
    results = [_result(i, s) for i, s in enumerate([(0, 3), (1, 1), (2, 0), (0, 5), (0, 2)])]
    summary = summarize(results)
    assert (summary.wins, summary.draws, summary.losses) == (1, 1, 3)
    assert summary.difference == pytest.approx(-1.6)
    assert summary.goals_for == pytest.approx(0.6) and summary.goals_against == pytest.approx(2.2)
    low, high = summary.difference_ci
    assert -5.0 <= low < summary.difference < high <= 2.0
    assert "W/D/L 1/1/3" in summary.line() and "-1.60" in summary.line()
    assert np.isnan(summarize(results[:1]).difference_ci[0])
    with pytest.raises(ValueError, match="no matches"):
        summarize([])


def test_the_interval_of_the_mean_difference_is_students_t() -> None:
    # Differences -3, 0, 2: mean -1/3, standard error 1.453, t(2) = 4.303. A bootstrap's
    # interval of three matches stays inside the range of the scores, [-3, 2].
    summary = summarize([_result(i, s) for i, s in enumerate([(0, 3), (1, 1), (2, 0)])])
    low, high = summary.difference_ci
    half = 4.303 * float(np.std([-3, 0, 2], ddof=1)) / math.sqrt(3)
    assert (low, high) == pytest.approx((-1 / 3 - half, -1 / 3 + half))
    assert low < -6.5 and high > 5.9
    assert "95% t-interval; under 5 matches: rough" in summary.line()
    five = summarize([_result(i, (0, i)) for i in range(5)])
    assert five.line().endswith("(95% t-interval), cycles lost ?")  # no game log read
    assert "one match: no interval" in summarize([_result(0, (1, 0))]).line()


@pytest.mark.parametrize(
    ("df", "quantile"),
    [(1, 12.706), (2, 4.303), (4, 2.776), (30, 2.042), (31, 2.0395), (40, 2.0211),
     (60, 2.0003), (120, 1.9799), (10_000, 1.9602)],
)
def test_t_quantiles_match_the_tables(df: int, quantile: float) -> None:
    assert t_quantile_975(df) == pytest.approx(quantile, abs=2e-4)


def test_a_t_quantile_needs_a_degree_of_freedom() -> None:
    with pytest.raises(ValueError, match="df=0 is invalid: a t quantile needs >= 1"):
        t_quantile_975(0)


FAKE_SERVER = Path(__file__).with_name("fake_rcssserver.py")


def _fake_server(tmp_path: Path, cycles: int, score: str = "0-2", missed: str = "") -> str:
    """A server binary (the fake) that ends its game at ``cycles`` with ``score``."""
    path = tmp_path / f"rcssserver-{cycles}-{score}"
    path.write_text(
        f"#!/bin/sh\nexec {sys.executable} {FAKE_SERVER} --players 2 --cycles {cycles} "
        f"--score {score} --missed '{missed}' \"$@\"\n"
    )
    path.chmod(0o755)
    return str(path)


def _leaving_team(name: str) -> ExternalTeam:
    cmd = f"{sys.executable} {FAKE_TEAM} --port {{port}} --team {{team}} --players 2 --leave"
    return ExternalTeam(cmd, name)


def test_a_match_the_server_ended_early_shows_the_cycles_it_lost(tmp_path: Path) -> None:
    """The server exits after 20 cycles in a row without every (done) and still prints a
    score: only its game log shows that 19 of the 60 cycles were never played."""
    short = play_match(
        _leaving_team("a"), _leaving_team("b"), players_per_team=2, half_time=3,
        rcssserver=_fake_server(tmp_path, 41, "0-2", missed="20,21"),
    )
    assert short.score == (0, 2) and short.missed_cycles == 2
    assert short.server_cycles == 41 and short.lost_cycles == 19
    full = play_match(
        _leaving_team("a"), _leaving_team("b"), players_per_team=2, half_time=3,
        rcssserver=_fake_server(tmp_path, 60, "1-1"), log_dir=tmp_path / "logs",
    )
    assert full.score == (1, 1) and full.server_cycles == 60 and full.lost_cycles == 0
    assert played_cycles(tmp_path / "logs" / "match_000") == 60
    assert played_cycles(tmp_path) is None  # no game log here
    summary = summarize([short, full])
    assert summary.lost_cycles == 19 and "cycles lost 19" in summary.line()


def test_match_cli_json_prints_each_match_as_it_ends(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One JSON line per match as soon as it ends (a long run shows its progress), then the
    summary; it used to print nothing until the last match had ended."""
    server = tmp_path / "server"
    server.write_text(  # each match's server first says how much the CLI has printed so far
        f"#!/bin/sh\ncat {tmp_path}/printed >> {tmp_path}/seen 2>/dev/null; echo --- >> "
        f"{tmp_path}/seen\nexec {_fake_server(tmp_path, 60, '0-1')} \"$@\"\n"
    )
    server.chmod(0o755)
    printed: list[str] = []

    class Tee:
        def write(self, text: str) -> int:
            printed.append(text)
            (tmp_path / "printed").write_text("".join(printed))
            return len(text)

        def flush(self) -> None:
            pass

    with contextlib.redirect_stdout(Tee()):  # type: ignore[type-var]
        main(["robocup", "match", "--team0-cmd", _leaving_team("a").cmd, "--team0-name", "a",
              "--team1-cmd", _leaving_team("b").cmd, "--team1-name", "b", "--players", "2",
              "--half-time", "3", "--matches", "2", "--json", "--rcssserver", str(server)])
    before = (tmp_path / "seen").read_text().split("---\n")
    assert before[0] == ""  # the first match: nothing printed yet
    first = json.loads(before[1].strip())  # the second: the first match's line
    assert first["match"] == 0 and first["score"] == [0, 1] and first["lost_cycles"] == 0
    lines = "".join(printed).strip().splitlines()
    assert [json.loads(line).get("match") for line in lines] == [0, 1, None]
    assert json.loads(lines[-1])["matches"] == 2


def test_match_cli_help_names_every_placeholder_of_a_start_command(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["robocup", "match", "--help"])
    lines = [line.strip("│ ") for line in capsys.readouterr().out.splitlines()]
    for flag in ("--team0-cmd", "--team1-cmd"):
        first = next(i for i, line in enumerate(lines) if line.startswith(flag + " "))
        end = next(i for i in range(first + 1, len(lines)) if lines[i].startswith("--"))
        help_text = " ".join(lines[first:end]).removeprefix(flag)
        for placeholder in ("{host}", "{port}", "{coach_port}", "{team}"):
            assert placeholder in help_text, (flag, placeholder)


def test_parse_team_takes_exactly_one_of_a_spec_and_a_command() -> None:
    assert parse_team("naive", None, "x") == ElevensTeam("naive", "x")
    external = parse_team(None, "start.sh -p {port} -t {team}", "H")
    assert external == ExternalTeam("start.sh -p {port} -t {team}", "H")
    for spec, cmd in (("naive", "start.sh"), (None, None)):
        with pytest.raises(ValueError, match="not both"):
            parse_team(spec, cmd, "x")
    with pytest.raises(ValueError, match="empty"):
        parse_team(None, "  ", "x")
    narrow = parse_team("naive", None, "x", view="narrow")
    assert narrow == ElevensTeam("naive", "x", view="narrow")
    command = narrow.command("127.0.0.1", 6000, 11, synch=True)
    assert command[command.index("--view") + 1] == "narrow"
    with pytest.raises(ValueError, match="team 'x': view width 'huge' must be one of"):
        parse_team("naive", None, "x", view="huge")


def test_a_skills_team_runs_as_elevens_robocup_skills_team() -> None:
    team = parse_team("skills_naive", None, "skills")
    assert team == SkillsTeam("skills_naive", "skills")
    command = team.command("127.0.0.1", 6100, 7, synch=True)
    assert command[1:5] == ["-m", "elevens", "robocup", "skills-team"]
    assert command[command.index("--skills") + 1] == "skills_naive"
    assert command[command.index("--port") + 1] == "6100"
    assert command[command.index("--players") + 1] == "7" and "--json" in command
    assert "--proxy" not in command
    given = SkillsTeam("skills_naive", "skills", proxy="/opt/proxy")
    assert given.command("h", 1, 11, synch=False)[-2:] == ["--proxy", "/opt/proxy"]
    assert "--set-plays" not in command  # the routine is the default
    decided = parse_team("skills_naive", None, "skills", set_plays="decided")
    command = decided.command("127.0.0.1", 6100, 11, synch=True)
    assert command[command.index("--set-plays") + 1] == "decided"


def test_set_plays_are_refused_in_one_line_unless_a_skills_team_decides_them() -> None:
    with pytest.raises(ValueError, match=r"--team0-set-plays 'own' is invalid \(allowed: "
                                         r"routine, decided\)"):
        parse_team("skills_naive", None, "x", set_plays="own", set_plays_flag="--team0-set-plays")
    for spec, cmd in (("naive", None), (None, "start.sh -p {port}")):
        with pytest.raises(ValueError, match="team 'naive' is not a skills team|--set-plays "
                                             "'decided' is for a skills team"):
            parse_team(spec, cmd, "x", set_plays="decided")
    with pytest.raises(ValueError, match="skills team 'runs/none@30' is unknown"):
        parse_team("runs/none@30", None, "x", set_plays="decided")


def test_match_refuses_a_skills_team_without_the_proxy_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before any server starts: the line says where it looked and how to build the proxy."""
    monkeypatch.setenv("ELEVENS_SKILLS_PROXY", str(tmp_path))
    server = tmp_path / "rcssserver"  # never started: the refusal comes first
    server.write_text("#!/bin/sh\nexit 1\n")
    server.chmod(0o755)
    error = refused(
        ["robocup", "match", "--team0", "skills_naive", "--team1", "naive", "--team1-name",
         "other", "--rcssserver", str(server)],
        "robocup match", capsys,
    )
    assert str(tmp_path) in error and "soccer-simulation-proxy" in error


def test_match_cli_gives_each_elevens_side_its_own_flags() -> None:
    from elevens.cli.robocup import RoboCupMatchArgs, match_teams

    args = RoboCupMatchArgs(
        team0="naive", team1="random", team1_name="b", team0_dead_reckoning=True,
        team1_sample=True, team1_view="narrow",
    )
    team0, team1 = match_teams(args)
    assert team0 == ElevensTeam("naive", "elevens", dead_reckoning=True)
    assert team1 == ElevensTeam("random", "b", view="narrow", sample=True)
    command0 = team0.command("127.0.0.1", 6000, 11, synch=True)
    command1 = team1.command("127.0.0.1", 6000, 11, synch=True)
    assert "--dead-reckoning" in command0 and "--sample" not in command0
    assert "--sample" in command1 and "--dead-reckoning" not in command1


def test_an_external_team_command_gets_the_servers_ports_and_its_name(tmp_path: Path) -> None:
    output = tmp_path / "out.txt"
    proc = start_team("echo {host} {port} {coach_port} {team}", ServerAddress(7000, 7001, 7002),
                      "H", output)
    assert proc.wait(10) == 0
    assert output.read_text().split() == ["127.0.0.1", "7000", "7002", "H"]
    assert connected_players("A new (v18) player (H 1) connected.\nA new (v18) player (Hx 2) "
                             "connected.\nA new (v18) player (H 3) connected.", "H") == 2


def test_a_start_command_that_fails_is_an_error_at_once_not_after_the_timeout(
    tmp_path: Path,
) -> None:
    address = ServerAddress(7000, 7001, 7002)
    log = tmp_path / "rcssserver.log"
    log.write_text("Waiting for players to connect\n")
    proc = start_team(str(tmp_path / "missing_start.sh"), address, "H", tmp_path / "out.txt")
    # At once: the shell's status, not the 120 s timeout's "connected 0 of 11 players".
    with pytest.raises(FileNotFoundError, match=r"start command failed \(status 127\)") as error:
        wait_connected(log, "H", 11, proc, tmp_path / "out.txt", 120.0, failed_start_grace_s=0.5)
    assert "missing_start.sh" in str(error.value)  # the shell's own message, from its output
    # A launcher that exits 0 at once (start.sh leaves its players running) is waited for.
    proc = start_team("true", address, "H", tmp_path / "out2.txt")
    with pytest.raises(RuntimeError, match="connected 0 of 11 players within 1 s"):
        wait_connected(log, "H", 11, proc, tmp_path / "out2.txt", 1.0)


def test_match_cli_refuses_equal_team_names(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "match", "--team1", "random", "--team1-name", "elevens",
              "--rcssserver", sys.executable])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "both 'elevens'" in err[0]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--host", "no.such.host.invalid"], "--host 'no.such.host.invalid' cannot be resolved"),
        (["--team-name", "bad/name"], "team name 'bad/name' must be 1-15 characters"),
    ],
)
def test_team_cli_refuses_a_bad_host_or_name_before_compiling(
    flags: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "team", "--team", "naive", *flags])
    assert exit_info.value.code == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert "compiled" not in captured.out  # refused before the policy's warm-up


def test_match_cli_refuses_a_used_log_folder_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "match_000").mkdir()
    (tmp_path / "match_000" / "rcssserver.log").write_text("Score: 0 - 0\n")
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "match", "--team1", "random", "--log-dir", str(tmp_path),
              "--rcssserver", sys.executable])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "match_000 already holds" in err[0]


@needs_rcssserver
def test_match_cli_names_a_start_command_that_does_not_exist_at_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "match", "--team1-cmd", str(tmp_path / "start.sh"),
              "--team1-name", "other", "--half-time", "3"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "team 'other': its start command failed (status 127)" in err
    assert "Traceback" not in err


def test_match_cli_refuses_an_unknown_team_before_starting_anything(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["robocup", "match", "--team0", "wizards", "--team1", "naive",
              "--team1-name", "b", "--rcssserver", sys.executable])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "wizards does not exist" in err[0] and "elevens-11v11" in err[0]


def test_a_log_folder_holding_an_earlier_match_is_refused_before_any_server_starts(
    tmp_path: Path,
) -> None:
    # The server appends to an existing rcssserver.log: the earlier match's score line came
    # first and was reported as this match's score.
    (tmp_path / "match_001").mkdir()
    (tmp_path / "match_001" / "rcssserver.log").write_text("Score: 0 - 0\n")
    with pytest.raises(FileExistsError, match="match_001 already holds"):
        play_matches(
            ElevensTeam("naive", "elevens"), ExternalTeam("false", "other"), matches=2,
            log_dir=tmp_path, rcssserver="/nonexistent/rcssserver", print_fn=lambda _: None,
        )
    with pytest.raises(FileExistsError, match="match_001 already holds"):
        play_match(ElevensTeam("naive", "elevens"), ExternalTeam("false", "other"), match=1,
                   log_dir=tmp_path, rcssserver="/nonexistent/rcssserver")


def test_match_options_are_regulation() -> None:
    assert MATCH_OPTIONS["server::auto_mode"] == "true"
    assert MATCH_OPTIONS["server::half_time"] == "300"  # 3000 cycles a half
    assert MATCH_OPTIONS["server::coach_w_referee"] == "false"  # no trainer in a match


# -- with rcssserver ----------------------------------------------------------------------------


@needs_rcssserver
@pytest.mark.parametrize("real_time", [False, True])
def test_match_against_a_fake_external_team(tmp_path: Path, real_time: bool) -> None:
    results = play_matches(
        ElevensTeam("naive", "elevens"), _fake_team(real_time=real_time), matches=1,
        half_time=3, synch=not real_time, log_dir=tmp_path, results_path=tmp_path / "r.jsonl",
        print_fn=lambda _: None,
    )
    result = results[0]
    assert result.names == ("elevens", "fake") and result.server_cycles == 60
    report = result.teams[0]
    assert report is not None and report["ended"] == "time_over" and report["side"] == 0
    assert (report["goals_for"], report["goals_against"]) == result.score
    assert report["server_time"] == 60 and report["missed"] == 0
    if real_time:
        # Late cycles depend on the machine's load (counted, never doubled: see
        # test_client's real-time test); the match itself must not suffer from them.
        assert 0 <= report["late_player_cycles"] <= 11 * report["cycles"]
    else:
        assert result.missed_cycles == 0 and report["late_player_cycles"] == 0
    logs = sorted(p.suffix for p in (tmp_path / "match_000").iterdir())
    assert ".rcg" in logs and ".rcl" in logs
    line = json.loads((tmp_path / "r.jsonl").read_text().splitlines()[0])
    assert tuple(line["score"]) == result.score


@needs_rcssserver
def test_real_server_clock_and_team_stay_in_lockstep_despite_a_slow_first_call(
    tmp_path: Path,
) -> None:
    """A slow first policy call (2 s, longer than the server's 1.25 s wait) is paid before
    connecting: the match runs every cycle with every (done) in time."""
    options = dict(MATCH_OPTIONS, **{"server::half_time": "3"})
    with ServerProcess(options=options) as server:
        team = RoboCupTeam("naive", players_per_team=11, team_name="mine")
        calls = _slow_first_call(team, 2.0)
        box = _play_in_thread(team, server.address)
        hang_guard = time.monotonic() + 600  # only for a start that never ends
        while "mine 11" not in (server.log_path.read_text() if server.log_path else ""):
            if not box["thread"].is_alive():  # the team ended without connecting all 11
                pytest.fail(f"the team stopped before it connected: {box.get('error')!r}")
            if time.monotonic() > hang_guard:
                pytest.fail("the team neither connected nor stopped")
            time.sleep(0.05)
        proc = start_team(_fake_team().cmd, server.address, "fake", tmp_path / "fake.log")
        try:
            box["thread"].join(120)
            assert "error" not in box, box.get("error")
            log = server.log_path.read_text() if server.log_path else ""
        finally:
            stop_team(proc)
    result: TeamResult = box["result"]
    assert len(calls) > 1  # the slow call, then the match's (not one of them missed a cycle)
    assert result.ended == "time_over" and result.server_time == 60 and result.missed == 0
    assert "missed a cycle" not in log


@needs_rcssserver
@needs_proxy
def test_skills_naive_plays_a_short_match_through_the_proxy(tmp_path: Path) -> None:
    """The proxy's eleven players, started by ``elevens robocup skills-team``, ask the
    decision server every cycle of a synch-mode match: every cycle played, the round trips
    in the team's report."""
    result = play_match(SkillsTeam("skills_naive", "skills"), _fake_team(), half_time=3,
                        log_dir=tmp_path)
    assert result.names == ("skills", "fake") and result.lost_cycles == 0
    report = result.teams[0]
    assert report is not None and report["ended"] == "players left"
    stats = report["stats"]
    assert stats["errors"] == 0 and stats["requests"] >= 11 * 60  # 60 cycles, 11 players
    assert 0.0 < stats["roundtrip_ms_p50"] <= stats["roundtrip_ms_p99"]
    # skills_naive's rows are independent: each request is decided as it comes, no gather
    # (a trained team's batching is checked in test_skills_learned.py).
    assert stats["requests"] == stats["batches"] and stats["defaults"] == 0


@needs_helios
def test_helios_base_plays_a_short_match_against_naive(tmp_path: Path) -> None:
    helios = ExternalTeam(f"{HELIOS} -p {{port}} -P {{coach_port}} -t {{team}}", "HELIOS_base")
    result = play_match(ElevensTeam("naive", "elevens"), helios, half_time=10)
    assert result.names == ("elevens", "HELIOS_base") and result.missed_cycles == 0
    assert result.teams[0] is not None and result.teams[0]["ended"] == "time_over"
    assert result.score[1] >= result.score[0]  # helios-base outplays the naive team


def test_a_sampling_team_draws_its_actions_and_a_mean_team_does_not() -> None:
    """``elevens robocup team --sample`` plays the policy as PPO trained it: two keys, two
    actions; without it the mean action, whatever the key."""
    import jax

    from elevens.robocup.observe import PLAYER_DECAY, PerceptMemory

    spec = "rcss-gpu"
    for deterministic in (True, False):
        team = RoboCupTeam(spec, players_per_team=2, deterministic=deterministic)
        memory = PerceptMemory(team.params, team.config.team_names, PLAYER_DECAY)
        obs = team._observation(memory, 0, 0, np.zeros((2, 2), np.float32))
        carry = team.player.init_carry(2)
        drawn = [np.asarray(team.player.act(carry, obs, jax.random.key(k))[1]) for k in (1, 2)]
        assert drawn[0].shape == (2, 12)
        assert np.array_equal(drawn[0], drawn[1]) == deterministic
