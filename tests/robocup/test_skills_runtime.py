"""The skills decision server against a fake proxy team: eleven Thrift clients on threads, as
the proxy's players connect. One batched decision per cycle, the right skills for the scene,
a default within the deadline when the decision is slow or fails, and the process wiring of
a team (start.sh, the players, the latency report) with a stand-in for the proxy."""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from elevens.robocup.skills import skills_policy
from elevens.robocup.skills.naive import skills_naive
from elevens.robocup.skills.proxy import ProxyNotFound, find_proxy, proxy_command
from elevens.robocup.skills.runtime import DecisionServer, rowwise
from tests.robocup.fake_proxy import OURS, FakeTeam, Scene


class Counting:
    """``skills_naive``, recording each call's batch (shirt numbers), optionally slow or
    failing."""

    def __init__(self, block: bool = False, fail: bool = False) -> None:
        self.batches: list[list[int]] = []
        self.fail = fail
        # A blocked decision runs until the test releases it: "slow" without a wall clock.
        self.release, self.finished = threading.Event(), threading.Event()
        if not block:
            self.release.set()

    def __call__(self, states: Sequence[Any]) -> list[Any]:
        self.batches.append(sorted(s.world_model.myself.uniform_number for s in states))
        self.release.wait(30)
        self.finished.set()
        if self.fail:
            raise RuntimeError("the policy failed")
        return skills_naive(states)


@pytest.fixture
def served() -> Iterator[tuple[DecisionServer, Counting, FakeTeam]]:
    decide = Counting()
    server = DecisionServer(decide, deadline_s=0.5, gather_s=0.2).start()
    team = FakeTeam(server.port)
    try:
        yield server, decide, team
    finally:
        team.close()
        server.close()


def _body(answer: Any) -> str:
    """The first action's field name (the body skill the proxy tries first)."""
    first = answer.actions[0]
    return next(k for k, v in vars(first).items() if v is not None)


def _flags(answer: Any) -> tuple[bool, ...]:
    return (answer.ignore_preprocess, answer.ignore_doforcekick,
            answer.ignore_doHeardPassRecieve, answer.ignore_doIntention,
            answer.ignore_shootInPreprocess)


def test_kick_off_places_everyone_in_our_half(served: Any) -> None:
    server, decide, team = served
    answers, _ = team.cycle(Scene(mode=0))
    assert sorted(answers) == list(range(1, 12))
    for unum, answer in answers.items():
        assert _body(answer) == "move", unum
        assert answer.actions[0].move.x <= -1.0
        assert _flags(answer) == (True,) * 5  # the proxy's own kick-off positions are off
    assert decide.batches == [list(range(1, 12))]


def test_the_holder_near_goal_shoots_and_the_rest_take_their_slots(served: Any) -> None:
    _, decide, team = served
    ours = OURS.copy()
    ours[8] = (38.5, 4.0)
    answers, _ = team.cycle(Scene(ours=ours, ball=(38.0, 4.0), kickable=9))
    shot = answers[9].actions[0].body_smart_kick
    assert shot is not None and shot.target_point.x == 52.5 and abs(shot.target_point.y) < 7.0
    assert shot.first_speed == 3.0
    assert _body(answers[1]) == "helios_goalie"
    assert _flags(answers[1]) == (False,) * 5  # the ready goalie keeps the proxy's reflexes
    for unum in range(2, 12):
        assert _flags(answers[unum])[1:] == (True,) * 4, unum  # open play: our choice only
        if unum != 9:
            assert _body(answers[unum]) == "body_go_to_point", unum
    assert decide.batches == [list(range(1, 12))]


def test_on_a_loose_ball_the_first_to_reach_it_intercepts(served: Any) -> None:
    _, _, team = served
    answers, _ = team.cycle(Scene(ball=(-20.0, 12.0)))
    reach = np.linalg.norm(OURS - np.array([-20.0, 12.0]), axis=1)
    fastest = int(np.argmin(reach[1:])) + 2  # the goalie plays its own behaviour
    interceptors = [u for u, a in answers.items() if _body(a) == "body_intercept"]
    assert interceptors == [fastest]


def test_one_batched_decision_per_cycle_with_latency_recorded(served: Any) -> None:
    server, decide, team = served
    client_trips: list[float] = []
    for cycle in range(1, 11):
        answers, trips = team.cycle(Scene(ball=(cycle - 5.0, 0.0), cycle=cycle))
        assert len(answers) == 11 and len(trips) == 11
        client_trips += trips
    assert decide.batches == [list(range(1, 12))] * 10
    stats = server.stats()
    assert (stats.requests, stats.batches, stats.defaults, stats.errors) == (110, 10, 0, 0)
    assert stats.mean_batch == 11.0 and stats.connected_players == 11
    assert 0.0 < stats.latency_ms_p50 <= stats.latency_ms_p99 <= stats.latency_ms_max
    # The server's round trip holds the decoded request's wait and sits inside the client's.
    assert stats.latency_ms_p50 <= stats.roundtrip_ms_p50 <= stats.roundtrip_ms_p99
    assert stats.roundtrip_ms_max <= max(client_trips) * 1e3


def test_a_player_that_does_not_ask_delays_the_batch_only_by_the_gather_time() -> None:
    decide = Counting()
    with DecisionServer(decide, deadline_s=2.0, gather_s=0.5) as server:
        team = FakeTeam(server.port)
        try:
            answers, _ = team.cycle(Scene(cycle=3), skip=[7])
            assert sorted(answers) == [u for u in range(1, 12) if u != 7]  # it went on
            late, _ = team.cycle(Scene(cycle=3), skip=[u for u in range(1, 12) if u != 7])
            assert sorted(late) == [7]
        finally:
            team.close()
    # Player 7 was decided alone and at once: the others of its cycle were decided already.
    assert decide.batches == [[u for u in range(1, 12) if u != 7], [7]]


def test_a_rowwise_decision_answers_each_player_alone_without_the_gather() -> None:
    """A rowwise decide (skills_naive's) is called for each request on its own as it comes:
    a player that does not ask holds nobody back."""
    decide = rowwise(Counting())
    with DecisionServer(decide, deadline_s=10.0, gather_s=5.0) as server:
        team = FakeTeam(server.port)
        try:
            start = time.perf_counter()
            answers, _ = team.cycle(Scene(ball=(-20.0, 12.0), cycle=3), skip=[2])
            elapsed = time.perf_counter() - start
        finally:
            team.close()
        stats = server.stats()
    assert sorted(answers) == [u for u in range(1, 12) if u != 2]
    assert elapsed < 2.5  # not the 5 s gather
    assert sorted(decide.batches) == [[u] for u in range(1, 12) if u != 2]
    assert (stats.requests, stats.batches, stats.defaults, stats.errors) == (10, 10, 0, 0)
    assert 0.0 < stats.decide_ms_p50 <= stats.latency_ms_max <= stats.roundtrip_ms_max
    interceptors = [u for u, a in answers.items() if _body(a) == "body_intercept"]
    reach = np.linalg.norm(OURS - np.array([-20.0, 12.0]), axis=1)
    assert interceptors == [int(np.argmin(reach[1:])) + 2]  # as one batch decides


def test_a_failing_rowwise_decision_gets_the_default() -> None:
    told: list[Any] = []
    decide = rowwise(Counting(fail=True))
    with DecisionServer(decide, on_default=told.append) as server:
        team = FakeTeam(server.port, players=2)
        try:
            answers, _ = team.cycle(Scene(ball=(10.0, 0.0)))
        finally:
            team.close()
        stats = server.stats()
    assert sorted(answers) == [1, 2]
    assert all(_body(a) == "body_turn_to_ball" for a in answers.values())
    assert (stats.defaults, stats.errors) == (2, 2)
    assert sorted(s.world_model.myself.uniform_number for s in told) == [1, 2]


@pytest.mark.parametrize("fail", [False, True])
def test_a_slow_or_failing_decision_gets_the_default_in_time(fail: bool) -> None:
    decide = Counting(block=not fail, fail=fail)
    with DecisionServer(decide, deadline_s=0.15, gather_s=0.1) as server:
        team = FakeTeam(server.port)
        try:
            answers, _ = team.cycle(Scene(ball=(10.0, 0.0)))
            # Every player has its answer while the slow decision still runs.
            assert fail or not decide.finished.is_set()
        finally:
            decide.release.set()
            team.close()
        stats = server.stats()
    assert len(answers) == 11
    for answer in answers.values():
        assert _body(answer) == "body_turn_to_ball"  # nobody has the ball
        assert _flags(answer) == (False,) * 5  # the proxy's reflexes fill in
    assert stats.defaults == 11
    assert stats.errors == (len(decide.batches) if fail else 0) and stats.errors >= int(fail)


def test_requests_answered_by_the_default_are_not_decided_late() -> None:
    """A decision that overruns does not pile up: the next cycle's requests, answered by the
    default while it ran, are dropped instead of decided after their time."""
    decide = Counting(block=True)
    with DecisionServer(decide, deadline_s=0.1, gather_s=0.05) as server:
        team = FakeTeam(server.port)
        try:
            for cycle in (1, 2):
                answers, _ = team.cycle(Scene(cycle=cycle))
                assert all(_body(a) == "body_turn_to_ball" for a in answers.values())
            decide.release.set()  # the first decision ends; the second cycle is already answered
            assert decide.finished.wait(30)
        finally:
            team.close()
        stats = server.stats()
    assert len(decide.batches) == 1 and stats.defaults == 22


def test_real_time_requests_spread_over_a_cycle_make_one_batch() -> None:
    decide = Counting()
    with DecisionServer(decide, deadline_s=0.6, gather_s=0.3) as server:
        team = FakeTeam(server.port)
        try:
            from tests.robocup.fake_proxy import state

            answers: dict[int, Any] = {}

            def ask(player: Any, delay: float) -> None:
                time.sleep(delay)
                answers[player.unum], _ = player.ask(state(Scene(cycle=5), player.unum))

            threads = [threading.Thread(target=ask, args=(p, 0.002 * p.unum))
                       for p in team.players]
            for t in threads:
                t.start()
            for t in threads:
                t.join(10)
        finally:
            team.close()
    assert len(answers) == 11 and decide.batches == [list(range(1, 12))]


def test_a_proxy_that_resets_its_connection_is_not_an_error(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A proxy process ending mid-call resets its socket: the connection closes quietly and
    the others play on."""
    import socket
    import struct

    with DecisionServer(skills_naive) as server:
        team = FakeTeam(server.port, players=2)
        sock = socket.create_connection(("127.0.0.1", server.port))
        sock.sendall(b"\x80\x01")  # the start of a call, then a reset (linger 0)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        sock.close()
        time.sleep(0.2)
        answers, _ = team.cycle(Scene(ball=(0.0, 0.0), cycle=1))
        team.close()
        assert len(answers) == 2
    assert not [r for r in caplog.records if r.levelname == "ERROR"]


def test_constructor_refuses_a_gather_time_past_the_deadline() -> None:
    with pytest.raises(ValueError, match=r"gather_s 0.05 and deadline_s 0.04"):
        DecisionServer(skills_naive, deadline_s=0.04, gather_s=0.05)
    with pytest.raises(ValueError, match=r"skills team 'bogus' is unknown \(allowed: "):
        skills_policy("bogus")


def test_a_missing_proxy_is_one_line_naming_how_to_build_it(tmp_path: Path) -> None:
    with pytest.raises(ProxyNotFound) as error:
        find_proxy(tmp_path)
    message = str(error.value)
    assert "\n" not in message and str(tmp_path) in message
    assert "soccer-simulation-proxy" in message and "ELEVENS_SKILLS_PROXY" in message
    assert proxy_command(tmp_path, 5000).endswith("--rpc-port 5000 --rpc-type thrift -C")
    assert " -C" not in proxy_command(tmp_path, 5000, coach=True)


def _stand_in_proxy(folder: Path, cycles: int) -> Path:
    """A proxy folder whose start.sh runs the fake team (in its own process) instead of the
    eleven C++ players, recording the arguments elevens gives the real one."""
    script = Path(__file__).with_name("fake_proxy.py")
    start = folder / "start.sh"
    start.write_text(
        "#!/bin/sh\n"
        f'echo "$@" > "{folder}/args"\n'
        f'exec "{sys.executable}" "{script}" --cycles {cycles} "$@" > "{folder}/out"\n'
    )
    player = folder / "sample_player"
    player.write_text("#!/bin/sh\n")
    for path in (start, player):
        path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return folder


def test_the_command_plays_the_team_and_prints_its_report(tmp_path: Path) -> None:
    """elevens robocup skills-team starts the decision server and the players (start.sh with
    the server's and the decision server's addresses), plays until they leave, and prints
    the latency report as JSON (the line elevens robocup match reads)."""
    import json
    import os
    import subprocess

    folder = _stand_in_proxy(tmp_path, cycles=5)
    src = str(Path(__file__).resolve().parents[2] / "src")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, "-m", "elevens", "robocup", "skills-team", "--proxy", str(folder),
         "--port", "6200", "--team-name", "skills", "--json",
         # Windows a busy host cannot miss (skills_naive is decided request by request).
         "--gather-ms", "4000", "--deadline-ms", "8000"],
        capture_output=True, text=True, env=env, timeout=120,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["team"] == "skills" and report["ended"] == "players left"
    stats = report["stats"]
    assert (stats["requests"], stats["batches"], stats["defaults"]) == (55, 55, 0)
    assert stats["mean_batch"] == 1.0 and stats["latency_ms_p99"] > 0.0
    args = (folder / "args").read_text().split()
    assert args[:6] == ["-h", "127.0.0.1", "-p", "6200", "-P", "6202"]
    assert args[args.index("-t") + 1] == "skills" and "-C" in args
    assert args[args.index("--rpc-type") + 1] == "thrift"
    assert args[args.index("-n") + 1] == "11"  # every player of the team starts
    assert '"requests": 55' in (folder / "out").read_text()  # the fake team's own count


def test_the_latency_script_times_every_stage_of_a_cycle() -> None:
    # scripts/skills_latency.py is how the docs' latency figures are taken apart; keep it working.
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, str(root / "scripts" / "skills_latency.py"), "stages", "3"],
        cwd=root, env={**os.environ, "PYTHONPATH": f"{root / 'src'}{os.pathsep}{root}"},
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("3 cycles of 11 States")
    for stage in ("decode", "observe", "decide", "actions", "encode", "all"):
        line = next(x for x in done.stdout.splitlines() if f"a cycle's {stage} " in x)
        p50, p99 = (float(x) for x in re.findall(r"p(?:50|99) ([0-9.]+)", line))
        assert 0 < p50 <= p99, line
