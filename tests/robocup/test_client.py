"""RoboCupClient: synchronisation, one (done) per (think), timeouts, malformed input,
goals and a dead server, against a small fake server (threads, real UDP on loopback);
then the same against a real rcssserver when one is installed."""

from __future__ import annotations

import os
import random
import select
import signal
import socket
import threading
import time
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest

from elevens.robocup.client import Cycle, PlayerCycle, RoboCupClient, ServerDied, measure_cycles
from elevens.robocup.protocol import Dash, Kick, SeeMessage, SenseBody, Turn, TurnNeck
from elevens.robocup.server import ServerAddress, ServerProcess
from tests.robocup.conftest import needs_rcssserver

DATA = Path(__file__).parents[1] / "data" / "rcss"


def _template(name: str, head: str) -> str:
    """The first recorded ``(head T ...)`` of a transcript, with T replaced by @T@."""
    for line in (DATA / name).read_text().splitlines():
        msg = line.partition("\t")[2]
        if msg.startswith(f"({head} "):
            rest = msg[len(head) + 2 :].split(" ", 1)[1]
            return f"({head} @T@ {rest}"
    raise AssertionError(f"no {head} in {name}")


SENSE = _template("sense_body.txt", "sense_body")
SEE = _template("see.txt", "see")
SEE_GLOBAL = _template("see_global.txt", "see_global")


class _Peer:
    """One client as the fake server sees it."""

    def __init__(self, name: str, addr: Any, trainer: bool = False) -> None:
        self.name = name
        self.addr = addr
        self.trainer = trainer
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.awaiting = False  # a (think) was sent and its (done) has not arrived
        self.done_ahead = False  # an early (done) that releases the next cycle
        self.thinks = 0
        self.dones = 0
        self.early_dones = 0
        self.eye = False
        self.gone = False
        self.received: list[bytes] = []

    def send(self, text: str | bytes) -> None:
        data = text.encode() if isinstance(text, str) else text
        self.sock.sendto(data + b"\x00", self.addr)


class FakeServer:
    """A tiny synch-mode stand-in for rcssserver on loopback.

    Like the real one it answers inits from a per-client port, sends every cycle a
    sense_body (and every ``see_every`` cycles a see) then ``(think)`` to each player (and
    see_global + think to the trainer with eye on), and steps once every awaited client
    sent ``(done)`` or ``wait_s`` passed. A ``(done)`` that arrives when none is awaited
    is an early done (counted, and it releases the next cycle, as in rcssserver).
    ``silent`` players never get a think; ``extra[time]`` injects raw datagrams.
    """

    def __init__(
        self,
        n: int,
        *,
        wait_s: float = 0.2,
        silent: tuple[int, ...] = (),
        see_every: int = 2,
        refuse: str | None = None,
        ports: tuple[int, int] | None = None,
        teams: int = 2,
        cycle_s: float | None = None,
    ) -> None:
        self.n = n
        self.first_side = "l"
        self.expected = teams * n  # players it waits for before its clock runs
        self.cycle_s = cycle_s  # real-time mode: a cycle every cycle_s, no (think)
        self.wait_s = wait_s
        self.silent = set(silent)
        self.see_every = see_every
        self.refuse = refuse
        self.main = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.coach = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.main.bind(("127.0.0.1", ports[0] if ports else 0))
        self.coach.bind(("127.0.0.1", ports[1] if ports else 0))
        port, coach_port = self.main.getsockname()[1], self.coach.getsockname()[1]
        self.address = ServerAddress(port, coach_port, coach_port)
        self.players: list[_Peer] = []
        self.trainer: _Peer | None = None
        self.trainer_commands: list[str] = []
        self.time = 0
        self.mode = "before_kick_off"
        self.timeouts = 0
        self.extra: dict[int, list[tuple[str, bytes]]] = {}
        self.received_by_cycle: list[list[list[bytes]]] = []  # real time: [cycle][player]
        self.frozen = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    # -- control ------------------------------------------------------------------

    def close(self) -> None:
        """Stop and close every socket (the client then gets 'connection refused')."""
        self._stop.set()
        self._thread.join(timeout=5)
        for sock in [self.main, self.coach] + [p.sock for p in self.peers]:
            sock.close()

    @property
    def peers(self) -> list[_Peer]:
        return self.players + ([self.trainer] if self.trainer else [])

    @property
    def early_dones(self) -> int:
        return sum(p.early_dones for p in self.peers)

    # -- loop ---------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                if self.frozen.is_set():
                    time.sleep(0.005)
                    continue
                if len(self.players) < self.expected:
                    time.sleep(0.005)  # rcssserver sleeps 50 ms per cycle while time is 0
                if self.cycle_s is not None:
                    self._real_time_cycle()
                else:
                    self._cycle()
        except OSError:
            if not self._stop.is_set():
                raise

    def _cycle(self) -> None:
        t = self.time
        stamp = str(t)
        for i, p in enumerate(self.players):
            if i in self.silent or p.gone:
                continue
            p.send(SENSE.replace("@T@", stamp))
            if t % self.see_every == 0:
                p.send(SEE.replace("@T@", stamp))
        for target, data in self.extra.pop(t, []):
            for p in self._targets(target):
                p.sock.sendto(data, p.addr)
        trainer = self.trainer
        if trainer is not None and trainer.eye:
            trainer.send(SEE_GLOBAL.replace("@T@", stamp))
        waiting = [p for i, p in enumerate(self.players) if i not in self.silent and not p.gone]
        if trainer is not None and trainer.eye:
            waiting.append(trainer)
        for p in waiting:
            p.send("(think)")
            p.thinks += 1
            p.awaiting = not p.done_ahead
            p.done_ahead = False
        deadline = time.monotonic() + self.wait_s
        while any(p.awaiting for p in waiting) or not waiting:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                if waiting:
                    self.timeouts += 1
                break
            socks = [self.main, self.coach] + [p.sock for p in self.peers]
            ready, _, _ = select.select(socks, [], [], min(remaining, 0.02))
            for sock in ready:
                self._receive(sock)
            if not waiting and len(self.players) == 2 * self.n:
                break
        for p in waiting:
            p.awaiting = False
        if len(self.players) == self.expected:
            self.time += 1

    def _real_time_cycle(self) -> None:
        """rcssserver without synch mode: sensors at the start of each cycle, then commands
        are taken until the next one begins (the first body command of a cycle counts)."""
        assert self.cycle_s is not None
        stamp = str(self.time)
        for p in self.players:
            if not p.gone:
                p.send(SENSE.replace("@T@", stamp))
                if self.time % self.see_every == 0:
                    p.send(SEE.replace("@T@", stamp))
        start = len(self.received_by_cycle)
        self.received_by_cycle.append([[] for _ in self.players])
        deadline = time.monotonic() + self.cycle_s
        while (remaining := deadline - time.monotonic()) > 0:
            socks = [self.main, self.coach] + [p.sock for p in self.peers]
            ready, _, _ = select.select(socks, [], [], remaining)
            for sock in ready:
                before = [len(p.received) for p in self.players]
                self._receive(sock)
                for i, p in enumerate(self.players):
                    if i < len(before) and len(p.received) > before[i]:
                        self.received_by_cycle[start][i].extend(p.received[before[i] :])
        if len(self.players) == self.expected:
            self.time += 1

    def _targets(self, target: str) -> list[_Peer]:
        if target == "players":
            return list(self.players)
        if target == "all":
            return self.peers
        if target == "trainer":
            return [self.trainer] if self.trainer else []
        return [self.players[int(target)]]

    def _receive(self, sock: socket.socket) -> None:
        data, addr = sock.recvfrom(16384)
        text = data.rstrip(b"\x00").decode()
        if sock is self.main:
            self._player_init(text, addr)
        elif sock is self.coach:
            self.trainer = _Peer("trainer", addr, trainer=True)
            self.trainer.send("(init ok)")
        else:
            peer = next(p for p in self.peers if p.sock is sock)
            peer.received.append(data)
            for _ in range(text.count("(done)")):
                if peer.awaiting:
                    peer.awaiting = False
                    peer.dones += 1
                else:
                    peer.early_dones += 1
                    peer.done_ahead = True
            if peer.trainer:
                self._trainer_command(peer, text)
            elif text.startswith("(bye)"):
                peer.gone = True
                peer.awaiting = False  # rcssserver stops waiting for a player that left

    def _player_init(self, text: str, addr: Any) -> None:
        if self.refuse is not None:
            self.main.sendto(f"(error {self.refuse})".encode() + b"\x00", addr)
            return
        team = text.split()[1]
        first_team = self.players[0].name.split()[0] if self.players else team
        side = "l" if team == first_team else "r"
        if self.first_side == "r":  # another program's team took the left side before us
            side = "r" if side == "l" else "l"
        unum = sum(1 for p in self.players if p.name.split()[0] == team) + 1
        peer = _Peer(f"{team} {unum}", addr)
        self.players.append(peer)
        peer.send(f"(init {side} {unum} {self.mode})")
        peer.send("(server_param (goal_width 14.02) (min_dash_power -100))")
        peer.send("(ok synch_see)")

    def _trainer_command(self, peer: _Peer, text: str) -> None:
        if text == "(done)":
            return
        self.trainer_commands.append(text)
        if text == "(eye on)":
            peer.eye = True
            peer.send("(ok eye on)")
        elif text == "(eye off)":
            peer.eye = False
        elif text == "(ear on)":
            peer.send("(ok ear on)")
        elif text.startswith("(change_mode "):
            self.mode = text[len("(change_mode ") : -1]
            peer.send("(ok change_mode)")
            peer.send(f"(hear referee {self.time} {self.mode})")
            for p in self.players:
                p.send(f"(hear {self.time} referee {self.mode})")
        elif text.startswith("(move ") or text == "(recover)":
            peer.send(f"(ok {text[1:].split()[0].rstrip(')')})")
        else:
            peer.send("(error illegal_command_form)")


@pytest.fixture
def fake() -> Any:
    servers: list[FakeServer] = []

    def make(n: int = 2, **kwargs: Any) -> FakeServer:
        server = FakeServer(n, **kwargs)
        servers.append(server)
        return server

    yield make
    for server in servers:
        server.close()


def _client(server: FakeServer, **kwargs: Any) -> RoboCupClient:
    kwargs.setdefault("think_timeout_s", 0.3)
    return RoboCupClient(server.address, server.n, **kwargs)


# -- connecting and stepping --------------------------------------------------------------


def test_connect_then_steps_stay_in_synch_with_one_done_per_think(fake: Any) -> None:
    server = fake(2)
    with _client(server, eye=True) as client:
        first = client.connect()
        assert len(first.players) == 4 and first.missed == 0 and first.trainer_thought
        assert [(p.side, p.unum) for p in first.players] == [(0, 1), (0, 2), (1, 1), (1, 2)]
        assert first.world is not None
        assert client.server_params.min_dash_power == -100  # taken from server_param
        t0 = first.server_time
        for k in range(1, 31):
            cycle = client.step([Dash(50.0), Turn(30.0), [Kick(20.0, 0.0), TurnNeck(5.0)], None])
            assert cycle.server_time == t0 + k
            assert cycle.missed == 0 and cycle.malformed == 0
            assert all(p.thought and isinstance(p.sense_body, SenseBody) for p in cycle.players)
            assert cycle.world is not None and cycle.world.time == cycle.server_time
            has_see = [p.see is not None for p in cycle.players]
            assert has_see == [cycle.server_time % 2 == 0] * 4  # see only on its cycles
        assert server.early_dones == 0 and server.timeouts == 0
        # Every datagram carries at most one (done); the actions went with it.
        p0 = server.players[0].received
        assert all(d.count(b"(done)") <= 1 for p in server.peers for d in p.received)
        assert p0[-1] == b"(dash 50)(done)\x00"
        assert server.players[2].received[-1] == b"(kick 20 0)(turn_neck 5)(done)\x00"
        assert server.players[3].received[-1] == b"(done)\x00"
        stats = client.stats
        assert stats.cycles == 31 and stats.missed_thinks == 0 and stats.stale_thinks == 0
        assert stats.send_s > 0 and stats.wait_s > 0 and stats.parse_s > 0


def test_eye_off_trainer_gets_no_think_and_cycles_have_no_world(fake: Any) -> None:
    server = fake(1)
    with _client(server, eye=False) as client:
        client.connect()
        for _ in range(5):
            cycle = client.step([None, None])
            assert cycle.world is None and cycle.raw_world is None and cycle.missed == 0
        assert server.trainer is not None and server.trainer.thinks == 0
        assert server.trainer.dones == 0 and server.early_dones == 0
        assert "(eye on)" not in server.trainer_commands and "(ear on)" in server.trainer_commands


def test_parse_false_keeps_raw_messages_only(fake: Any) -> None:
    server = fake(1)
    with _client(server, parse=False) as client:
        client.connect()
        cycle = client.step([None, None])
        player = cycle.players[0]
        assert player.see is None and player.sense_body is None and cycle.world is None
        assert player.raw_sense_body is not None and player.raw_sense_body.startswith(b"(sense_")
        assert cycle.raw_world is not None and cycle.server_time > 0


def test_connect_fails_clearly_when_a_player_never_gets_a_think(fake: Any) -> None:
    server = fake(2, silent=(1,))
    with _client(server, connect_timeout_s=0.5) as client:
        with pytest.raises(ServerDied, match="still waiting for L2"):
            client.connect()
        assert not client.connected


def test_player_that_stops_thinking_is_marked_missing_then_read_without_waiting(
    fake: Any,
) -> None:
    server = fake(2)
    with _client(server, think_timeout_s=0.3) as client:
        client.connect()
        client.step([None] * 4)
        server.silent.add(2)  # R1 stops getting thinks (like a red-carded player)
        cycle = client.step([None] * 4)
        assert [p.thought for p in cycle.players] == [True, True, False, True]
        assert cycle.players[2].see is None and cycle.players[2].sense_body is None
        assert cycle.missed == 1 and client.stats.timeouts == 1  # it waited for R1 once
        for _ in range(5):
            cycle = client.step([Dash(10.0)] * 4)
            assert cycle.missed == 1
        # No more waiting for it: no cycle since waited for a think.
        assert client.stats.missed_thinks == 6 and client.stats.timeouts == 1
        assert server.early_dones == 0
        # It comes back: thinks again, gets its done again.
        server.silent.discard(2)
        for _ in range(3):
            cycle = client.step([None] * 4)
        assert cycle.missed == 0 and all(p.thought for p in cycle.players)
        assert server.early_dones == 0


def test_malformed_datagrams_are_counted_not_raised(fake: Any) -> None:
    server = fake(1)
    with _client(server) as client:
        first = client.connect()
        t = first.server_time + 1
        server.extra[t] = [
            ("0", b"(see 5 ((f c) abc 0))\x00"),  # a see with a broken number
            ("0", b"\xff\xfe(garbage\x00"),
            ("1", b"(hear 5 referee)\x00"),  # a hear without a message
            ("trainer", b"(hear referee 5 goal_l_1\x00"),  # truncated
        ]
        cycle = client.step([None, None])
        assert cycle.server_time == t
        assert cycle.malformed >= 4 and client.stats.malformed == cycle.malformed
        assert all(p.thought for p in cycle.players)
        assert cycle.players[1].sense_body is not None
        assert cycle.goals == (0, 0)  # the truncated goal was dropped, not half-read
        cycle = client.step([None, None])
        assert cycle.malformed == 0


def test_referee_goals_count_once_and_track_the_play_mode(fake: Any) -> None:
    server = fake(2)
    with _client(server) as client:
        first = client.connect()
        assert first.score == (0, 0) and first.play_mode == "before_kick_off"
        client.change_mode("play_on")
        assert client.play_mode == "play_on"
        cycle = client.step([None] * 4)
        assert cycle.play_mode == "play_on" and cycle.goals == (0, 0)
        t = cycle.server_time + 1
        # Every player and the trainer hear the goal: it still counts once.
        server.extra[t] = [("players", f"(hear {t} referee goal_l_1)\x00".encode())]
        server.extra[t] += [("trainer", f"(hear referee {t} goal_l_1)\x00".encode())]
        cycle = client.step([None] * 4)
        assert cycle.goals == (1, 0) and cycle.score == (1, 0) and cycle.play_mode == "goal_l"
        assert any(h.goal == ("l", 1) for h in cycle.players[0].hears)
        cycle = client.step([None] * 4)
        assert cycle.goals == (0, 0) and cycle.score == (1, 0)
        t = cycle.server_time + 1
        server.extra[t] = [("players", f"(hear {t} referee goal_r_1)\x00".encode())]
        server.extra[t] += [("all", f"(hear {t} referee kick_off_l)\x00".encode())]
        cycle = client.step([None] * 4)
        assert cycle.goals == (0, 1) and cycle.score == (1, 1)
        assert cycle.play_mode == "kick_off_l"
        client.reset_score()
        assert client.step([None] * 4).score == (0, 0)


def test_reset_sends_the_trainer_recipe_and_observes_the_new_state(fake: Any) -> None:
    server = fake(2)
    with _client(server, team_names=("Alpha", "Beta")) as client:
        client.connect()
        pos = np.array([[[-10.0, 5.0], [-20.5, -3.25]], [[10.0, -5.0], [20.0, 3.0]]])
        body = np.array([[0.0, 90.0], [180.0, -190.0]])
        cycle = client.reset(pos, body, ball_srv=(1.0, -2.0), ball_vel=(0.5, 0.0))
        assert cycle.play_mode == "play_on" and isinstance(cycle, Cycle)
        expected = [
            "(change_mode before_kick_off)",
            "(move (player Alpha 1) -10 5 0 0 0)",
            "(move (player Alpha 2) -20.5 -3.25 90 0 0)",
            "(move (player Beta 1) 10 -5 -180 0 0)",
            "(move (player Beta 2) 20 3 170 0 0)",
            "(move (ball) 1 -2 0 0.5 0)",
            "(recover)",
            "(change_mode play_on)",
        ]
        commands = [c for c in server.trainer_commands if c not in ("(eye on)", "(ear on)")]
        assert commands == expected
        assert server.early_dones == 0
        with pytest.raises(ValueError, match=r"expected \(2, 2, 2\)"):
            client.reset(pos[:, :1], body)
        with pytest.raises(ValueError, match="finite"):
            client.reset(pos * np.nan, body)
        with pytest.raises(ValueError, match="play mode 'playon'"):
            client.reset(pos, body, play_mode="playon")


def test_step_checks_its_input(fake: Any) -> None:
    server = fake(1)
    client = _client(server)
    with pytest.raises(RuntimeError, match="not connected"):
        client.step([None, None])
    with client:
        client.connect()
        with pytest.raises(ValueError, match=r"one entry per player \(2 = 2 x 1\), got 3"):
            client.step([None] * 3)
        with pytest.raises(TypeError, match="Command objects"):
            client.step(["(dash 10)", None])  # type: ignore[list-item]
        with pytest.raises(ValueError, match="dash power"):
            client.step([Dash(500.0), None])
        with pytest.raises(RuntimeError, match="already connected"):
            client.connect()
        assert client.step([None, None]).missed == 0  # still in synch after the errors


def test_a_long_pause_answers_only_the_newest_think(fake: Any) -> None:
    server = fake(1, wait_s=0.15)
    with _client(server) as client:
        client.stale_after_s = 0.1  # below the fake server's wait, as 1.0 s is below 1.25 s
        client.connect()
        client.step([None, None])
        time.sleep(0.5)  # the server steps ~3 times without our (done)s
        behind = server.time
        cycle = client.step([Dash(10.0), None])
        assert cycle.server_time >= behind and cycle.missed == 0
        assert client.stats.stale_thinks >= 2
        for _ in range(5):
            last = client.step([None, None])
        assert last.server_time == server.time  # the server waits on exactly this cycle
        assert server.early_dones == 0


def test_measure_cycles_reports_the_rate_and_where_the_time_goes(fake: Any) -> None:
    server = fake(1)
    result = measure_cycles(server.address, 1, cycles=30, eye=True, parse=True, warmup=2)
    assert result["cycles"] == 30 and result["cycles_per_s"] > 0
    assert result["missed"] == 0 and result["malformed"] == 0
    assert min(result["send_ms"], result["wait_ms"], result["parse_ms"]) > 0
    assert server.early_dones == 0
    assert any(b"(dash " in d or b"(turn " in d for d in server.players[0].received)
    with pytest.raises(ValueError, match="cycles 0"):
        measure_cycles(server.address, 1, cycles=0)


# -- a dead server ------------------------------------------------------------------------


def test_server_that_stops_answering_raises_server_died(fake: Any) -> None:
    server = fake(1)
    with _client(server, think_timeout_s=0.2) as client:
        client.connect()
        client.step([None, None])
        server.frozen.set()
        # Two think timeouts (the second chance) without a think: dead.
        with pytest.raises(ServerDied, match=r"stopped answering: .* for 0.4 s"):
            client.step([None, None])
        assert not client.connected


def test_closed_ports_raise_server_died_at_once(fake: Any) -> None:
    server = fake(1)
    with _client(server, think_timeout_s=1.0) as client:
        client.connect()
        server.close()
        client._second_chance = _no_waiting  # type: ignore[method-assign]
        with pytest.raises(ServerDied):
            for _ in range(3):
                client.step([None, None])


def _no_waiting(*args: Any) -> None:
    raise AssertionError("the client waited a second think timeout")


class _DeadProcess:
    """Stands in for a ServerProcess whose process has exited."""

    alive = False
    returncode = -9
    log_path = Path("/tmp/rcssserver.log")

    def log_problems(self) -> str:
        return "Waiting too long for clients! Exiting"


def test_exited_process_raises_server_died_with_its_log(fake: Any) -> None:
    server = fake(1)
    client = RoboCupClient(server.address, 1, think_timeout_s=2.0)
    with client:
        client.connect()
        server.frozen.set()
        client.server = cast(ServerProcess, _DeadProcess())
        client._second_chance = _no_waiting  # type: ignore[method-assign]
        # No full timeout when the process is gone: it is noticed while waiting the first one.
        with pytest.raises(ServerDied, match=r"exited \(status -9\)[\s\S]*Waiting too long"):
            client.step([None, None])


def test_reconnect_after_the_server_comes_back(fake: Any) -> None:
    server = fake(1)
    client = _client(server)
    with client:
        client.connect()
        client.step([None, None])
        ports = (server.address.port, server.address.coach_port)
        server.close()
        with pytest.raises(ServerDied):
            for _ in range(3):
                client.step([None, None])
        fake(1, ports=ports)  # "restarted" on the same ports
        cycle = client.reconnect()
        assert cycle.missed == 0 and client.stats.restarts == 1 and client.connected
        assert client.step([None, None]).missed == 0


def test_refused_init_names_the_reason(fake: Any) -> None:
    server = fake(1, refuse="no_more_team")
    with pytest.raises(ConnectionError, match="refused .* no_more_team"), _client(server) as c:
        c.connect()


def test_no_server_at_all_raises_server_died() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        address = ServerAddress(port, port, port)  # bound but silent
        client = RoboCupClient(address, 1, connect_timeout_s=0.3)
        with pytest.raises(ServerDied, match="did not answer"):
            client.connect()
        assert not client.connected


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"players_per_team": 0}, "players_per_team 0"),
        ({"players_per_team": 12}, "players_per_team 12"),
        ({"version": 17}, "version 17"),
        ({"team_names": ("a", "a")}, "two different names"),
        ({"team_names": ("a b", "c")}, "team"),
        ({"think_timeout_s": 0.0}, "think_timeout_s"),
    ],
)
def test_constructor_rejects_bad_settings(kwargs: dict[str, Any], message: str) -> None:
    args: dict[str, Any] = {"players_per_team": 11}
    args.update(kwargs)
    n = args.pop("players_per_team")
    with pytest.raises(ValueError, match=message):
        RoboCupClient(ServerAddress(6000, 6001, 6002), n, **args)


@pytest.mark.parametrize("other_team_first", [False, True])
def test_one_team_takes_the_side_it_is_given_and_plays_without_a_trainer(
    fake: Any, other_team_first: bool
) -> None:
    server = fake(3, teams=1)
    if other_team_first:
        server.first_side = "r"
    client = _client(server, team_names=("mine", "theirs"), one_team=True, trainer=False,
                     eye=False)
    with client:
        first = client.connect()
        side = 1 if other_team_first else 0
        assert client.sides == (side,) and server.trainer is None
        assert client.team_names == (("theirs", "mine") if side else ("mine", "theirs"))
        assert [(p.side, p.unum) for p in first.players] == [(side, 1), (side, 2), (side, 3)]
        t0 = first.server_time
        for k in range(1, 6):
            cycle = client.step([Dash(50.0), None, Turn(10.0)])
            assert cycle.server_time == t0 + k and cycle.missed == 0
        with pytest.raises(ValueError, match="one entry per player \\(3 = 1 x 3\\)"):
            client.step([None] * 6)
        with pytest.raises(RuntimeError, match="not connected"):
            client.send_trainer()
    assert server.early_dones == 0 and server.timeouts == 0
    assert server.players[0].received[-2] == b"(dash 50)(done)\x00"


def test_real_time_cycles_start_at_sense_body_and_a_late_command_is_never_doubled(
    fake: Any,
) -> None:
    server = fake(2, teams=1, cycle_s=0.05)
    client = _client(server, one_team=True, trainer=False, eye=False, synch=False,
                     think_timeout_s=0.5)
    with client:
        cycle = client.connect()
        times = [cycle.server_time]
        for _ in range(8):
            cycle = client.step([Dash(60.0), Turn(5.0)])
            times.append(cycle.server_time)
            assert all(isinstance(p.sense_body, SenseBody) for p in cycle.players)
        # One cycle a step while we keep up.
        assert np.diff(times).tolist() == [1] * 8 and client.stats.stale_thinks == 0
        time.sleep(0.16)  # about three cycles late
        late = client.step([Dash(70.0), Turn(5.0)])
        assert late.server_time >= times[-1] + 3
        assert client.stats.stale_thinks >= 2  # the cycles we slept through, counted
        for _ in range(3):
            client.step([Dash(60.0), Turn(5.0)])
    assert all(b"(done)" not in d for p in server.players for d in p.received)
    # Never more than one body command from a player in one server cycle.
    for received in server.received_by_cycle:
        for datagrams in received:
            assert sum(d.count(b"(dash") + d.count(b"(turn ") for d in datagrams) <= 1


def test_eye_needs_the_trainer_and_synch_mode() -> None:
    address = ServerAddress(6000, 6001, 6002)
    with pytest.raises(ValueError, match="eye=True needs the trainer"):
        RoboCupClient(address, 2, trainer=False, eye=True)
    with pytest.raises(ValueError, match="synch mode"):
        RoboCupClient(address, 2, synch=False, eye=True)


def test_player_cycle_is_a_frozen_record() -> None:
    pc = PlayerCycle(0, 1, None, None, (), False)
    assert pc.raw_see is None and pc.thought is False
    with pytest.raises(AttributeError):
        pc.thought = True  # type: ignore[misc]


# -- with a real rcssserver ---------------------------------------------------------------


def _random_commands(rng: random.Random, n: int) -> list[Dash | Turn | Kick]:
    out: list[Dash | Turn | Kick] = []
    for _ in range(n):
        r = rng.random()
        if r < 0.5:
            out.append(Dash(rng.uniform(0, 100), rng.uniform(-180, 180)))
        elif r < 0.8:
            out.append(Turn(rng.uniform(-180, 180)))
        else:
            out.append(Kick(rng.uniform(0, 100), rng.uniform(-180, 180)))
    return out


@needs_rcssserver
def test_real_server_22_players_play_in_synch(rcss_server: ServerProcess) -> None:
    rng = random.Random(5)
    with RoboCupClient(rcss_server, 11, eye=True) as client:
        first = client.connect()
        assert len(first.players) == 22 and first.missed == 0
        assert first.players[0].unum == 1 and first.players[11].side == 1
        client.change_mode("play_on")
        previous = client.step(_random_commands(rng, 22)).server_time
        for _ in range(50):
            cycle = client.step(_random_commands(rng, 22))
            assert cycle.missed == 0 and cycle.malformed == 0 and cycle.trainer_thought
            assert all(p.thought and p.sense_body is not None for p in cycle.players)
            assert cycle.world is not None and len(cycle.world.players) == 22
            assert cycle.server_time == previous + 1
            previous = cycle.server_time
        assert any(p.see is not None for p in cycle.players)
        assert client.stats.server_errors == 0 and client.stats.stale_thinks == 0
        # The commands were executed: sense_body's dash counters grew.
        assert sum(p.sense_body.counts.dash or 0 for p in cycle.players if p.sense_body) > 0


@needs_rcssserver
def test_real_server_reset_places_players_and_ball(rcss_server: ServerProcess) -> None:
    with RoboCupClient(rcss_server, 11, eye=True) as client:
        client.connect()
        pos = np.zeros((2, 11, 2))
        pos[0, :, 0] = -5.0 - 3.0 * np.arange(11)
        pos[0, :, 1] = -10.0 + 2.0 * np.arange(11)
        pos[1] = -pos[0]
        body = np.zeros((2, 11))
        body[0] = -150.0 + 30.0 * np.arange(11)
        body[1] = 170.0
        cycle = client.reset(pos, body, ball_srv=(3.0, -4.0))
        assert cycle.play_mode == "play_on" and cycle.world is not None
        for p in cycle.world.players:
            side = 0 if p.team == "elevens_l" else 1
            assert (p.x, p.y) == pytest.approx(tuple(pos[side, p.unum - 1]), abs=1e-3)
            assert p.body == pytest.approx(body[side, p.unum - 1], abs=1e-3)
            assert (p.vx, p.vy) == (0.0, 0.0)
        assert cycle.world.ball is not None
        assert (cycle.world.ball.x, cycle.world.ball.y) == pytest.approx((3.0, -4.0), abs=1e-3)


@needs_rcssserver
def test_real_server_goal_set_up_by_the_trainer(rcss_server: ServerProcess) -> None:
    with RoboCupClient(rcss_server, 11, eye=False) as client:
        client.connect()
        pos = np.stack([np.stack([-10.0 - np.arange(11), np.zeros(11)], -1)] * 2)
        pos[1, :, 0] *= -1
        client.reset(pos, np.zeros((2, 11)))
        client.move_ball(50.0, 0.0, 3.0, 0.0)  # into the right goal: a goal for the left side
        goals = []
        for _ in range(5):
            cycle = client.step([None] * 22)
            goals.append(cycle.goals)
        assert (1, 0) in goals and cycle.score == (1, 0) and cycle.play_mode == "goal_l"
        heard = [h.goal for p in client.step([None] * 22).players for h in p.hears if h.goal]
        assert heard == []  # announced once, in the goal's cycle


@needs_rcssserver
def test_real_server_killed_raises_then_restart_and_reconnect(rcss_server: ServerProcess) -> None:
    with RoboCupClient(rcss_server, 11, eye=True, think_timeout_s=1.0) as client:
        client.connect()
        client.change_mode("play_on")
        client.step([None] * 22)
        assert rcss_server.pid is not None
        os.kill(rcss_server.pid, signal.SIGKILL)
        with pytest.raises(ServerDied, match="exited"):
            for _ in range(3):
                client.step([None] * 22)
        address = rcss_server.address
        rcss_server.restart()
        assert rcss_server.address == address and rcss_server.alive
        cycle = client.reconnect()
        assert cycle.missed == 0 and client.stats.restarts == 1
        client.change_mode("play_on")
        for _ in range(5):
            cycle = client.step([Dash(50.0)] * 22)
        assert cycle.missed == 0 and cycle.server_time >= 5
        assert isinstance(cycle.players[0].see, (SeeMessage, type(None)))


@needs_rcssserver
def test_real_server_pause_longer_than_its_wait_resynchronises(rcss_server: ServerProcess) -> None:
    with RoboCupClient(rcss_server, 11, eye=True) as client:
        client.connect()
        client.change_mode("play_on")
        for _ in range(3):
            client.step([Dash(50.0)] * 22)
        time.sleep(1.6)  # rcssserver steps without our (done)s after 1.25 s
        times: list[int] = []
        dashes: list[int] = []
        for _ in range(6):
            cycle = client.step([Dash(50.0)] * 22)
            sense = cycle.players[0].sense_body
            assert sense is not None and cycle.missed == 0
            times.append(cycle.server_time)
            dashes.append(sense.counts.dash or 0)
        # One server step per step, and each step's dash executed exactly once.
        assert times == list(range(times[0], times[0] + 6))
        assert dashes == list(range(dashes[0], dashes[0] + 6))
        assert client.stats.stale_thinks > 0
