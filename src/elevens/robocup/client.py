"""One-process UDP client for rcssserver: 2n players and the offline trainer in synch mode.

Why it is built this way (rcssserver 19 as measured against the live server):

* **One socket per player**, each with a large receive buffer. After ``(init ...)`` the
  server answers from a per-client port; the socket is ``connect()``-ed to it, so later
  datagrams go there and nothing else is read.
* **Synch mode.** Each server cycle ends with a ``(think)`` to every player (and to the
  trainer when its eye is on); the server steps once it has a ``(done)`` from all of
  them. :meth:`RoboCupClient.step` sends each player's commands and ``(done)`` in one
  datagram, then reads every socket until its next ``(think)``: everything before it
  belongs to the new cycle.
* **Exactly one (done) per (think).** A client gets a ``(done)`` only when a ``(think)``
  arrived since its last ``(done)``. An early or duplicate ``(done)`` would release the
  next cycle before the real actions arrive and shift every later action by a cycle.
* **Missing data is flagged, not invented.** A player whose ``(think)`` does not arrive
  within ``think_timeout_s`` gets ``thought=False`` (no see/sense_body this cycle) and
  is counted. It is then read without waiting (a disabled player never thinks again)
  until a ``(think)`` shows up. When nobody thinks for two timeouts, or the process has
  exited, :class:`ServerDied` is raised.
* **Stale cycles are skipped.** If the caller pauses for more than a second between
  steps, the server may have stepped without our ``(done)`` (it waits 1.25 s): the next
  step first reads what is queued, answers only the newest ``(think)`` and keeps the
  observations of the newest cycle.
* **A cheap hot path.** Receiving only appends raw datagrams and compares their first
  bytes with ``(think)``. Classifying (``see``, ``sense_body``, ``hear``) happens after
  all sockets are read, and the s-expression parser
  (:class:`elevens.robocup.protocol.SafeParser`, which counts, logs and drops malformed
  messages) runs on ``see``/``sense_body``/``see_global`` only when ``parse=True``.
  Referee messages (play modes, goals) are always parsed: they are rare.

Server frame throughout: x towards the right goal, y down, degrees.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import random
import selectors
import socket
import struct
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import TracebackType

import numpy as np

from elevens.robocup.protocol import (
    PLAY_MODES,
    ChangeMode,
    CoachInit,
    Command,
    Dash,
    ErrorReply,
    GlobalView,
    Hear,
    Init,
    InitPlayer,
    InitTrainer,
    Kick,
    MoveBall,
    MovePlayer,
    PlayerType,
    ProtocolError,
    Recover,
    SafeParser,
    SeeMessage,
    SenseBody,
    ServerParams,
    Turn,
    datagram,
    parse_message,
)
from elevens.robocup.server import ServerAddress, ServerProcess

__all__ = ["ClientStats", "Cycle", "PlayerCycle", "RoboCupClient", "ServerDied", "measure_cycles"]

logger = logging.getLogger(__name__)

_THINK = b"(think)"
_SENSE_BODY = b"(sense_body "
_SEE = b"(see "
_HEAR = b"(hear "
_SEE_GLOBAL = b"(see_global "
_DONE = b"(done)"
_NUL = b"\x00"
# The server's messages are at most 8192 bytes (MaxMesg); room to spare.
_BUFSIZE = 16384
# Requested SO_RCVBUF (the kernel caps it at net.core.rmem_max and doubles it).
_RCVBUF = 1 << 20
# Blocking receives wake up this often to check the deadline and the server process.
_POLL_S = 0.1
# The server waits 1.25 s for (done)s; after a pause this long it may have moved on.
_STALE_AFTER_S = 1.0
# Messages kept for a player that does not think (a disabled player hears the referee).
_MAX_INBOX = 256
# Per-kind warnings before server error replies are logged at DEBUG only.
_LOG_LIMIT = 20
# Setup messages that need no handling.
_IGNORED = (
    b"(ok ",
    b"(player_param ",
    b"(player_type ",
    b"(change_player_type ",
    b"(init ",
    b"(score ",
)


class ServerDied(RuntimeError):  # noqa: N818 - the name the interface promises
    """The rcssserver process exited or stopped answering. Restart the
    :class:`~elevens.robocup.server.ServerProcess` and call
    :meth:`RoboCupClient.reconnect` (or build a new client)."""


@dataclass(frozen=True, slots=True)
class PlayerCycle:
    """What one player received during one cycle, up to its ``(think)``."""

    side: int  # 0 left, 1 right
    unum: int  # 1..n
    see: SeeMessage | None  # the cycle's see (None when none arrived: normal in synch-see)
    sense_body: SenseBody | None  # None when not thought, malformed, or parse=False
    hears: tuple[Hear, ...]  # referee and other hear messages, in order
    thought: bool  # False: its (think) did not arrive before the timeout (missing data)
    raw_see: bytes | None = None  # the see datagram as received (kept also with parse=False)
    raw_sense_body: bytes | None = None  # the sense_body datagram as received


@dataclass(frozen=True, slots=True)
class Cycle:
    """One synchronous server cycle as seen by all players and the trainer."""

    players: tuple[PlayerCycle, ...]  # left unum 1..n, then right unum 1..n (one_team: n)
    world: GlobalView | None  # trainer's see_global of this cycle (only with eye on, parse)
    play_mode: str  # current referee play mode (tracked from hear referee / trainer)
    score: tuple[int, int]  # left, right goals since the client connected / last reset_score
    goals: tuple[int, int]  # goals scored during this cycle (0/1 each)
    server_time: int  # the server's clock (frozen in stoppages: count steps yourself)
    missed: int  # players whose (think) did not arrive
    malformed: int  # messages that failed to parse this cycle (counted, logged, dropped)
    raw_world: bytes | None = None  # the see_global datagram (eye on), also with parse=False
    trainer_thought: bool = True  # False: eye on and the trainer's (think) did not arrive


@dataclass
class ClientStats:
    """Counters and where the time goes (seconds, summed over calls)."""

    cycles: int = 0  # cycles returned by step/reset/connect
    missed_thinks: int = 0  # player-cycles without a (think) before the timeout
    trainer_missed: int = 0  # cycles whose trainer (think) was missing (eye on)
    malformed: int = 0  # messages dropped as malformed
    timeouts: int = 0  # cycles in which a read waited the full think timeout
    stale_thinks: int = 0  # (think)s skipped because a newer one was queued
    restarts: int = 0  # reconnects after a server restart
    server_errors: int = 0  # (error ...) replies to our commands (players and trainer)
    send_s: float = 0.0  # encoding and sending commands and (done)s
    wait_s: float = 0.0  # waiting for and receiving datagrams (includes the server's step)
    parse_s: float = 0.0  # classifying and parsing the received datagrams
    errors: Counter[str] = field(default_factory=Counter)  # error replies by reason

    def as_dict(self) -> dict[str, float]:
        """Numbers only, for logging (``errors`` left out)."""
        return {
            "cycles": self.cycles,
            "missed_thinks": self.missed_thinks,
            "trainer_missed": self.trainer_missed,
            "malformed": self.malformed,
            "timeouts": self.timeouts,
            "stale_thinks": self.stale_thinks,
            "restarts": self.restarts,
            "server_errors": self.server_errors,
            "send_s": self.send_s,
            "wait_s": self.wait_s,
            "parse_s": self.parse_s,
        }


class _Conn:
    """One UDP endpoint (a player or the trainer) and its synch bookkeeping."""

    __slots__ = ("sock", "name", "inbox", "pending", "absent", "thought")

    def __init__(self, name: str) -> None:
        self.name = name
        self.sock = _udp_socket()
        self.inbox: list[bytes] = []  # raw datagrams not yet handed out in a cycle
        self.pending = False  # a (think) arrived that no (done) has answered yet
        self.absent = False  # missed a (think): read without waiting until it thinks again
        self.thought = False  # a new (think) arrived during this cycle's read


def _udp_socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF)
    # A kernel receive timeout (struct timeval) keeps recv() to one system call; a
    # Python-level timeout would add a poll() before every recv, and would make the
    # MSG_DONTWAIT drains wait. The socket itself stays in blocking mode.
    usec = int(_POLL_S * 1e6)
    sock.setsockopt(
        socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", usec // 10**6, usec % 10**6)
    )
    sock.bind(("127.0.0.1", 0))
    return sock


def _wrap_deg(angle: float) -> float:
    """Angle in degrees wrapped to [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


class RoboCupClient:
    """Drives ``players_per_team`` players per side and the offline trainer of one
    rcssserver in synch mode from one Python process.

    ``one_team=True`` connects only the players of ``team_names[0]``, on the side the server
    gives (``sides``); the other side is another program's (``team_names[1]``: its name, for
    the trainer's moves and for telling opponents in ``see``; "" if unknown). ``trainer=False``
    connects no trainer (a match: the referee runs the game). ``synch=False`` plays a real-time
    server: a cycle starts with its ``sense_body``, no ``(done)`` is sent, and a cycle that
    began before our command went out is counted in ``stats.stale_thinks`` (late; the command
    acts one cycle later, never two at once).

    ``address`` is a :class:`ServerAddress` or a running :class:`ServerProcess` (then its
    process state and log are used for :class:`ServerDied`; ``server=`` does the same
    with an address). ``eye`` turns the trainer's ``see_global`` on (ground truth each
    cycle, at the price of one more client the server waits for). ``parse=False`` skips
    parsing ``see``/``sense_body``/``see_global`` (raw bytes stay in ``raw_*``).

    Usage::

        with ServerProcess() as server, RoboCupClient(server, 11) as client:
            cycle = client.connect()
            cycle = client.reset(positions_srv, body_deg)
            cycle = client.step([Dash(80.0)] * 22)

    After :class:`ServerDied`: ``server.restart()`` then ``client.reconnect()``.
    """

    def __init__(
        self,
        address: ServerAddress | ServerProcess,
        players_per_team: int,
        *,
        team_names: tuple[str, str] = ("elevens_l", "elevens_r"),
        version: int = 19,
        one_team: bool = False,
        trainer: bool = True,
        synch: bool = True,
        eye: bool = True,
        think_timeout_s: float = 2.0,
        parse: bool = True,
        server: ServerProcess | None = None,
        connect_timeout_s: float = 10.0,
    ) -> None:
        if isinstance(address, ServerProcess):
            server = address if server is None else server
            address = address.address
        if not isinstance(address, ServerAddress):
            raise TypeError(f"address must be a ServerAddress or ServerProcess, got {address!r}")
        if (
            isinstance(players_per_team, bool)
            or not isinstance(players_per_team, int)
            or not 1 <= players_per_team <= 11
        ):
            raise ValueError(f"players_per_team {players_per_team!r} must be an int in [1, 11]")
        if isinstance(version, bool) or not isinstance(version, int) or not 18 <= version <= 19:
            raise ValueError(
                f"protocol version {version!r} must be 18 or 19 (the synch-see format "
                "the parser expects)"
            )
        if len(team_names) != 2 or team_names[0] == team_names[1]:
            raise ValueError(f"team_names {team_names!r} must be two different names")
        for name in team_names[: 1 if one_team else 2]:
            InitPlayer(name, version)  # validates the name (<= 15 chars of [A-Za-z0-9_+-])
        if eye and not (trainer and synch):
            raise ValueError(
                "eye=True needs the trainer (trainer=True) and synch mode (synch=True): in real "
                "time the trainer gets no (think) to pace its see_global by"
            )
        if not (think_timeout_s > 0 and math.isfinite(think_timeout_s)):
            raise ValueError(f"think_timeout_s {think_timeout_s!r} must be a finite number > 0")
        if not (connect_timeout_s > 0 and math.isfinite(connect_timeout_s)):
            raise ValueError(f"connect_timeout_s {connect_timeout_s!r} must be a finite number > 0")
        self.address = address
        self.server = server
        self.n = players_per_team
        #: (own, other) with ``one_team`` until connected, then (left, right) as always.
        self.team_names = (str(team_names[0]), str(team_names[1]))
        self.version = version
        self.one_team = bool(one_team)
        self.trainer = bool(trainer)
        self.synch = bool(synch)
        #: The sides this client plays: (0, 1), or the one the server gave ``one_team``.
        self.sides: tuple[int, ...] = () if one_team else (0, 1)
        self._own_name = str(team_names[0])
        self._other_name = str(team_names[1])
        # A cycle ends with (think) in synch mode; in real time every cycle starts with a
        # sense_body, so that is where a cycle is cut.
        self._marker = _THINK if self.synch else _SENSE_BODY
        self.eye = bool(eye)
        self.think_timeout_s = float(think_timeout_s)
        self.connect_timeout_s = float(connect_timeout_s)
        self.parse = bool(parse)
        #: Pause between steps after which the server may have stepped without our
        #: (done)s, so step() first reads what is queued. Below the server's 1.25 s wait.
        self.stale_after_s = _STALE_AFTER_S
        self.stats = ClientStats()
        self.parser = SafeParser(logger)
        #: The server's parameters (from its server_param message; defaults before connect).
        self.server_params: ServerParams = ServerParams.defaults()
        #: The heterogeneous player types (from player_type messages; empty before connect).
        self.player_types: tuple[PlayerType, ...] = ()
        self._players: list[_Conn] = []
        self._trainer: _Conn | None = None
        self._think_conns: list[_Conn] = []
        self._connected = False
        self._reset_tracking()

    # -- state ----------------------------------------------------------------------

    def _reset_tracking(self) -> None:
        self._play_mode = "before_kick_off"
        self._totals = [0, 0]  # goals per side since the server started (goal_X_N)
        self._score_base = [0, 0]
        self._server_time = 0
        self._last_think_t = time.perf_counter()
        self._error_log_counts: Counter[str] = Counter()

    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def play_mode(self) -> str:
        """The last known play mode."""
        return self._play_mode

    @property
    def score(self) -> tuple[int, int]:
        """Left, right goals since connect / the last :meth:`reset_score`."""
        return (
            self._totals[0] - self._score_base[0],
            self._totals[1] - self._score_base[1],
        )

    def reset_score(self) -> None:
        """Count goals from zero again (the server's own totals keep running)."""
        self._score_base = list(self._totals)

    # -- connecting -----------------------------------------------------------------

    def connect(self) -> Cycle:
        """Connect 2n players (unum 1 of each side as goalie) and the trainer, turn the
        trainer's ear (and eye, if ``eye``) on, answer the ``(think)``s queued during
        setup, and return the first cycle.

        The server stays in ``before_kick_off`` (where its clock does not run and it
        sleeps 50 ms per cycle) until :meth:`reset` or :meth:`change_mode` starts play.
        """
        if self._connected:
            raise RuntimeError("already connected: call close() first, or reconnect()")
        self._reset_tracking()
        count = (1 if self.one_team else 2) * self.n
        try:
            self._players = [
                _Conn(f"{'LR'[i // self.n] if not self.one_team else 'P'}{i % self.n + 1}")
                for i in range(count)
            ]
            self._trainer = _Conn("trainer") if self.trainer else None
            self._think_conns = self._players + (
                [self._trainer] if self.eye and self._trainer is not None else []
            )
            self._init_players()
            if self._trainer is not None:
                self._init_trainer()
            self._synchronise()
            self._connected = True
            return self._read_cycle()
        except BaseException:
            self._connected = False
            self._close_sockets()
            raise

    def reconnect(self, address: ServerAddress | ServerProcess | None = None) -> Cycle:
        """Close the old connection and connect again, e.g. after
        :meth:`ServerProcess.restart` (same ports) or to another server. Counts a
        restart in ``stats.restarts`` and returns the first cycle."""
        self.close()
        if isinstance(address, ServerProcess):
            self.server = address
            address = address.address
        if address is not None:
            self.address = address
        elif self.server is not None and self.server.alive:
            self.address = self.server.address
        self.stats.restarts += 1
        return self.connect()

    def _deadline(self) -> float:
        return time.perf_counter() + self.connect_timeout_s

    def _recv_reply(self, conn: _Conn, deadline: float, what: str) -> tuple[bytes, tuple[str, int]]:
        while True:
            try:
                return conn.sock.recvfrom(_BUFSIZE)
            except (BlockingIOError, TimeoutError):
                self._check_process()
                if time.perf_counter() > deadline:
                    raise self._died(
                        f"did not answer the {what} within {self.connect_timeout_s:g} s "
                        "(is it running on this address?)"
                    ) from None
            except ConnectionRefusedError:
                raise self._died(f"refused the {what} (nothing listens there)") from None

    def _init_players(self) -> None:
        host, port = self.address.host, self.address.port
        names = (self._own_name,) if self.one_team else self.team_names
        for i, conn in enumerate(self._players):
            unum = i % self.n + 1
            init = InitPlayer(names[i // self.n], self.version, goalie=unum == 1)
            # Sent back to back: the server handles them in arrival order, so side l and
            # unums 1..n go to the first team name (checked below).
            conn.sock.sendto(init.encode() + _NUL, (host, port))
        deadline = self._deadline()
        own_side: str | None = None
        for i, conn in enumerate(self._players):
            side, unum = "lr"[i // self.n], i % self.n + 1
            what = f"(init {names[i // self.n]} ...) of player {unum}"
            data, addr = self._recv_reply(conn, deadline, what)
            try:
                msg = parse_message(data)
            except ProtocolError as err:
                raise ConnectionError(f"unexpected reply to {what}: {err}") from None
            if isinstance(msg, ErrorReply):
                raise ConnectionError(
                    f"rcssserver refused {what}: {msg.reason} (is another team or an old "
                    "client still connected?)"
                )
            if self.one_team and isinstance(msg, Init):
                side = own_side = own_side or msg.side  # the server chooses; all the same
            if not isinstance(msg, Init) or (msg.side, msg.unum) != (side, unum):
                raise ConnectionError(
                    f"expected (init {side} {unum} ...) in reply to {what}, got {data[:80]!r}"
                )
            conn.sock.connect(addr)
            self._play_mode = msg.play_mode
        if self.one_team:
            index = "lr".index(own_side or "l")
            self.sides = (index,)
            pair = (self._own_name, self._other_name)
            self.team_names = pair if index == 0 else (pair[1], pair[0])
            for i, conn in enumerate(self._players):
                conn.name = f"{'LR'[index]}{i + 1}"

    def _init_trainer(self) -> None:
        trainer = self._trainer
        assert trainer is not None
        what = "trainer's (init (version ...))"
        trainer.sock.sendto(
            InitTrainer(self.version).encode() + _NUL,
            (self.address.host, self.address.coach_port),
        )
        data, addr = self._recv_reply(trainer, self._deadline(), what)
        try:
            msg = parse_message(data)
        except ProtocolError as err:
            raise ConnectionError(f"unexpected reply to the {what}: {err}") from None
        if isinstance(msg, ErrorReply):
            hint = (
                " (start the server with server::coach_w_referee=true, see TRAINING_OPTIONS)"
                if "coach_mode" in msg.reason
                else ""
            )
            raise ConnectionError(f"rcssserver refused the {what}: {msg.reason}{hint}")
        if not isinstance(msg, CoachInit) or msg.side is not None:
            raise ConnectionError(f"expected (init ok) in reply to the {what}, got {data[:80]!r}")
        trainer.sock.connect(addr)
        self._send(trainer, b"(ear on)" + _NUL)
        if self.eye:
            self._send(trainer, b"(eye on)" + _NUL)

    def _synchronise(self) -> None:
        """Answer the (think)s queued while connecting until every client got one in the
        same round, so the next read starts a clean cycle."""
        conns = [*self._players, *([self._trainer] if self._trainer is not None else [])]
        selector = selectors.DefaultSelector()
        for conn in conns:
            selector.register(conn.sock, selectors.EVENT_READ)
        deadline = self._deadline()
        stale_before = self.stats.stale_thinks  # (think)s queued during setup are expected
        thought: set[_Conn] = set()
        try:
            while True:
                remaining = deadline - time.perf_counter()
                if remaining <= 0:
                    missing = [c.name for c in self._think_conns if c not in thought]
                    raise self._died(
                        f"did not send every client a (think) within {self.connect_timeout_s:g}"
                        f" s while connecting (still waiting for {', '.join(missing)})"
                    )
                if not selector.select(min(remaining, _POLL_S)):
                    self._check_process()
                    continue
                time.sleep(0.002)  # let the server finish sending this cycle's burst
                for conn in conns:
                    assert conn is not None
                    self._drain(conn)
                everyone = all(c.pending for c in self._think_conns)
                thought.update(c for c in self._think_conns if c.pending)
                for conn in self._think_conns:
                    if conn.pending:
                        if self.synch:
                            self._send(conn, _DONE + _NUL)
                        conn.pending = False
                self._absorb_setup(conns)
                if everyone:
                    return
        finally:
            self.stats.stale_thinks = stale_before
            selector.close()

    def _absorb_setup(self, conns: Sequence[_Conn | None]) -> None:
        """Take the parameters and referee messages out of setup traffic; drop the rest."""
        first = self._players[0]
        listener = self._trainer if self._trainer is not None else first
        for conn in conns:
            assert conn is not None
            for data in conn.inbox:
                if conn is first and data.startswith(b"(server_param "):
                    msg = self.parser.parse(data)
                    if isinstance(msg, ServerParams):
                        self.server_params = msg
                elif conn is first and data.startswith(b"(player_type "):
                    ptype = self.parser.parse(data)
                    if isinstance(ptype, PlayerType):
                        self.player_types = (*self.player_types, ptype)
                elif data.startswith(_HEAR):
                    hear = self.parser.parse(data)
                    if isinstance(hear, Hear) and conn is listener:
                        self._referee([hear])
                elif data.startswith(b"(error ") or data.startswith(b"(warning "):
                    self._server_error(conn, data)
            conn.inbox.clear()

    # -- stepping -------------------------------------------------------------------

    def step(self, commands: Sequence[Command | Sequence[Command] | None]) -> Cycle:
        """Send one entry per player (2n: left unum 1..n, then right): a command, a
        sequence of commands (one body command, plus e.g. turn_neck) or None, each with
        ``(done)`` in one datagram; the trainer's ``(done)`` if its eye is on. Then read
        every socket until its next ``(think)`` and return that cycle.

        Raises :class:`ServerDied` when the server has exited or nobody thinks within two
        ``think_timeout_s``; ValueError for a wrong number of entries or a command
        outside the server's ranges.
        """
        if not self._connected:
            raise RuntimeError("not connected: call connect() first")
        count = len(self._players)
        if len(commands) != count:
            raise ValueError(
                f"step needs one entry per player ({count} = {len(self.sides)} x {self.n}), "
                f"got {len(commands)}"
            )
        t0 = time.perf_counter()
        payloads = [self._encode(entry) for entry in commands]
        if not self.synch:
            # Cycles that began while the caller thought: counted as late (stale_thinks), and
            # the command goes out once, for the newest.
            for conn in self._players:
                self._drain(conn)
        elif t0 - self._last_think_t > self.stale_after_s:
            # The server may have stepped without us: answer only the newest (think).
            for conn in self._players:
                self._drain(conn)
            if self._trainer is not None:
                self._drain(self._trainer)
        else:
            # A late (think) of a client that missed the last cycle is answered now, or the
            # server would wait 1.25 s for it.
            for conn in self._think_conns:
                if conn.absent:
                    self._drain(conn)
        try:
            for conn, payload in zip(self._players, payloads, strict=True):
                if conn.pending and self.synch:
                    conn.sock.send(payload + _DONE + _NUL)
                    conn.pending = False
                elif payload:
                    conn.sock.send(payload + _NUL)
                if not self.synch:
                    conn.pending = False  # one command per cycle seen; a newer one is late
            trainer = self._trainer
            if self.eye and trainer is not None and trainer.pending:
                trainer.sock.send(_DONE + _NUL)
                trainer.pending = False
        except ConnectionRefusedError:
            raise self._died("refused our datagrams (its ports are closed)") from None
        self.stats.send_s += time.perf_counter() - t0
        return self._read_cycle()

    def _encode(self, entry: Command | Sequence[Command] | None) -> bytes:
        if entry is None:
            return b""
        if isinstance(entry, Command):
            return entry.encode(self.server_params)
        if isinstance(entry, (str, bytes)):
            raise TypeError(
                f"commands must be Command objects (see elevens.robocup.protocol), got {entry!r}"
            )
        params = self.server_params
        return b"".join(cmd.encode(params) for cmd in entry)

    def _read_cycle(self) -> Cycle:
        t0 = time.perf_counter()
        try:
            self._collect()
        except ConnectionRefusedError:
            raise self._died("refused our datagrams (its ports are closed)") from None
        t1 = time.perf_counter()
        self.stats.wait_s += t1 - t0
        cycle = self._build_cycle()
        self.stats.parse_s += time.perf_counter() - t1
        return cycle

    def _collect(self) -> None:
        """Read every waiting client until its next (think), within the timeout."""
        conns = self._think_conns
        for conn in conns:
            conn.thought = False
        deadline = time.perf_counter() + self.think_timeout_s
        timed_out = False
        first = True
        for conn in conns:
            if conn.absent:
                continue
            if timed_out:
                self._drain(conn)
            elif self._read_until_think(conn, deadline):
                if first:
                    self._last_think_t = time.perf_counter()
                    first = False
                # Normal case: nothing queued after the think; only an absent client
                # or a long pause can leave a newer (think) behind it.
            else:
                timed_out = True
        for conn in conns:
            if conn.absent:
                self._drain(conn)
        if not self.eye and self._trainer is not None:
            self._drain(self._trainer)
        if not self.synch:
            time.sleep(0.003)  # the cycle's see follows its sense_body
            for conn in conns:
                self._drain(conn)
        if not any(c.thought for c in conns):
            timed_out = True
            self._second_chance(conns)
        missing = [c for c in conns if not c.thought]
        for conn in missing:
            if not conn.absent:
                logger.warning(
                    "no (think) from %s within %.2f s; reading it without waiting until it "
                    "thinks again",
                    conn.name,
                    self.think_timeout_s,
                )
            conn.absent = True
        for conn in conns:
            if conn.thought:
                conn.absent = False
        if timed_out:
            self.stats.timeouts += 1

    def _second_chance(self, conns: Sequence[_Conn]) -> None:
        """Nobody thought within the timeout: wait once more, then declare it dead."""
        self._check_process()
        selector = selectors.DefaultSelector()
        try:
            for conn in conns:
                selector.register(conn.sock, selectors.EVENT_READ)
            deadline = time.perf_counter() + self.think_timeout_s
            while not any(c.thought for c in conns):
                remaining = deadline - time.perf_counter()
                if remaining <= 0:
                    raise self._died(
                        f"stopped answering: no (think) from any client for "
                        f"{2 * self.think_timeout_s:g} s"
                    )
                if selector.select(min(remaining, _POLL_S)):
                    time.sleep(0.002)  # let the burst finish
                    for conn in conns:
                        self._drain(conn)
                else:
                    self._check_process()
            self._last_think_t = time.perf_counter()
        finally:
            selector.close()

    def _read_until_think(self, conn: _Conn, deadline: float) -> bool:
        """Blocking reads until a (think) arrives (True) or the deadline passes (False)."""
        recv = conn.sock.recv
        inbox = conn.inbox
        marker = self._marker
        while True:
            try:
                data = recv(_BUFSIZE)
            except (BlockingIOError, TimeoutError):
                self._check_process()
                if time.perf_counter() >= deadline:
                    return False
                continue
            inbox.append(data)
            if data.startswith(marker):
                conn.pending = True
                conn.thought = True
                return True

    def _drain(self, conn: _Conn) -> bool:
        """Non-blocking: take everything queued; True if a (think) was among it."""
        recv = conn.sock.recv
        inbox = conn.inbox
        marker = self._marker
        found = False
        while True:
            try:
                data = recv(_BUFSIZE, socket.MSG_DONTWAIT)
            except (BlockingIOError, TimeoutError):
                break
            except ConnectionRefusedError:
                raise self._died("refused our datagrams (its ports are closed)") from None
            inbox.append(data)
            if data.startswith(marker):
                if conn.pending:
                    # A (think) nobody answered is superseded: one (done) answers the newest.
                    self.stats.stale_thinks += 1
                conn.pending = True
                conn.thought = True
                found = True
        return found

    def _send(self, conn: _Conn, data: bytes) -> None:
        try:
            conn.sock.send(data)
        except ConnectionRefusedError:
            raise self._died("refused our datagrams (its ports are closed)") from None

    # -- building the cycle ---------------------------------------------------------

    def _take(self, conn: _Conn) -> list[bytes]:
        """Hand out the inbox up to its last (think); keep what follows (next cycle). In real
        time a cycle starts with its sense_body: everything queued is handed out."""
        inbox = conn.inbox
        if not self.synch:
            conn.inbox = []
            return inbox
        last = len(inbox) - 1
        while last >= 0 and not inbox[last].startswith(_THINK):
            last -= 1
        taken = inbox[: last + 1]
        conn.inbox = inbox[last + 1 :]
        return taken

    def _build_cycle(self) -> Cycle:
        parser = self.parser
        errors_before = parser.stats.total_errors
        parse = self.parse
        players: list[PlayerCycle] = []
        referee_src: list[Hear] | None = None
        all_hears: list[Hear] = []
        server_time: int | None = None
        missed = 0
        n = self.n
        sides = self.sides
        for i, conn in enumerate(self._players):
            side, unum = sides[i // n], i % n + 1
            if not conn.thought:
                missed += 1
                if len(conn.inbox) > _MAX_INBOX:
                    del conn.inbox[:-_MAX_INBOX]
                players.append(PlayerCycle(side, unum, None, None, (), False))
                continue
            msgs = self._take(conn)
            raw_see: bytes | None = None
            raw_sb: bytes | None = None
            hears: list[Hear] = []
            last = len(msgs) - 1
            for j, data in enumerate(msgs):
                if data.startswith(_SENSE_BODY):
                    raw_sb = data
                elif data.startswith(_SEE):
                    raw_see = data
                elif data.startswith(_THINK):
                    if j != last:  # an older cycle's sensors: superseded
                        raw_see = raw_sb = None
                elif data.startswith(_HEAR):
                    hear = parser.parse(data)
                    if isinstance(hear, Hear):
                        hears.append(hear)
                else:
                    self._other(conn, data)
            see: SeeMessage | None = None
            sense: SenseBody | None = None
            if parse:
                if raw_sb is not None:
                    msg = parser.parse(raw_sb)
                    sense = msg if isinstance(msg, SenseBody) else None
                if raw_see is not None:
                    msg = parser.parse(raw_see)
                    see = msg if isinstance(msg, SeeMessage) else None
            if server_time is None:
                if sense is not None:
                    server_time = sense.time
                elif raw_sb is not None:
                    server_time = _time_of(raw_sb)
            if hears:
                all_hears.extend(hears)
                if referee_src is None and any(h.sender == "referee" for h in hears):
                    referee_src = hears
            players.append(PlayerCycle(side, unum, see, sense, tuple(hears), True, raw_see, raw_sb))

        world, raw_world, trainer_thought, trainer_hears = self._trainer_messages()
        if any(h.sender == "referee" for h in trainer_hears):
            referee_src = trainer_hears  # the trainer hears every referee message once
        old_totals = list(self._totals)
        self._referee(referee_src or [], all_hears)
        if world is not None and server_time is None:
            server_time = world.time
        if server_time is not None:
            self._server_time = server_time
        malformed = parser.stats.total_errors - errors_before
        stats = self.stats
        stats.cycles += 1
        stats.missed_thinks += missed
        stats.malformed += malformed
        if not trainer_thought:
            stats.trainer_missed += 1
        return Cycle(
            players=tuple(players),
            world=world,
            play_mode=self._play_mode,
            score=self.score,
            goals=(self._totals[0] - old_totals[0], self._totals[1] - old_totals[1]),
            server_time=self._server_time,
            missed=missed,
            malformed=malformed,
            raw_world=raw_world,
            trainer_thought=trainer_thought,
        )

    def _trainer_messages(self) -> tuple[GlobalView | None, bytes | None, bool, list[Hear]]:
        trainer = self._trainer
        if trainer is None:
            return None, None, True, []
        thought = True
        if self.eye:
            thought = trainer.thought
            msgs = self._take(trainer) if thought else []
        else:
            msgs, trainer.inbox = trainer.inbox, []
        raw_world: bytes | None = None
        hears: list[Hear] = []
        last = len(msgs) - 1
        for j, data in enumerate(msgs):
            if data.startswith(_SEE_GLOBAL):
                raw_world = data
            elif data.startswith(_HEAR):
                hear = self.parser.parse(data)
                if isinstance(hear, Hear):
                    hears.append(hear)
            elif data.startswith(_THINK):
                if j != last:
                    raw_world = None
            else:
                self._other(trainer, data)
        world: GlobalView | None = None
        if raw_world is not None and self.parse:
            msg = self.parser.parse(raw_world)
            world = msg if isinstance(msg, GlobalView) else None
        return world, raw_world, thought, hears

    def _referee(self, source: Sequence[Hear], extra: Sequence[Hear] = ()) -> None:
        """Track the play mode from ``source`` (one listener's messages, in order) and the
        goal totals from every referee message (``goal_l_N`` carries the new total, so
        hearing it twice never counts twice)."""
        for hear in source:
            if hear.sender != "referee":
                continue
            goal = hear.goal
            if goal is not None:
                side = 0 if goal[0] == "l" else 1
                self._totals[side] = max(self._totals[side], goal[1])
                self._play_mode = f"goal_{goal[0]}"  # the after-goal mode is not announced
            elif hear.play_mode is not None:
                self._play_mode = hear.play_mode
        for hear in extra:
            goal = hear.goal
            if goal is not None:
                side = 0 if goal[0] == "l" else 1
                self._totals[side] = max(self._totals[side], goal[1])

    def _other(self, conn: _Conn, data: bytes) -> None:
        """A datagram that is not a sensor message: replies, setup, or garbage."""
        if data.startswith(b"(error ") or data.startswith(b"(warning "):
            self._server_error(conn, data)
        elif data.startswith(_IGNORED):
            return
        elif data.startswith(b"(server_param "):
            msg = self.parser.parse(data)
            if isinstance(msg, ServerParams) and conn is self._players[0]:
                self.server_params = msg
        else:
            # Anything else goes through the parser, which counts and logs it if malformed.
            self.parser.parse(data)

    def _server_error(self, conn: _Conn, data: bytes) -> None:
        text = data.rstrip(b"\x00\n").decode("latin-1")
        key = text[:60]
        if text.startswith("(error"):
            self.stats.server_errors += 1
            self.stats.errors[key] += 1
        self._error_log_counts[key] += 1
        level = logging.WARNING if self._error_log_counts[key] <= _LOG_LIMIT else logging.DEBUG
        logger.log(level, "rcssserver replied to %s: %s", conn.name, text)

    # -- trainer --------------------------------------------------------------------

    def send_trainer(self, *commands: Command) -> None:
        """Send trainer commands, one datagram each (the trainer's parser reads one
        command per datagram). They act at once, before the next step."""
        trainer = self._trainer
        if not self._connected or trainer is None:
            raise RuntimeError("not connected: call connect() first")
        for cmd in commands:
            if isinstance(cmd, ChangeMode):
                self._play_mode = cmd.mode
            self._send(trainer, datagram(cmd, params=self.server_params))

    def move_ball(self, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> None:
        """Trainer: put the ball at (x, y) with velocity (vx, vy), server frame; acts
        before the next step."""
        self.send_trainer(MoveBall(x, y, vx, vy))

    def change_mode(self, mode: str) -> None:
        """Trainer: switch the play mode (one of protocol.PLAY_MODES)."""
        if mode not in PLAY_MODES:
            raise ValueError(f"play mode {mode!r} is not one of the server's play modes")
        self.send_trainer(ChangeMode(mode))

    def reset(
        self,
        positions_srv: np.ndarray,
        body_deg: np.ndarray,
        ball_srv: tuple[float, float] = (0.0, 0.0),
        ball_vel: tuple[float, float] = (0.0, 0.0),
        play_mode: str = "play_on",
        recover: bool = True,
    ) -> Cycle:
        """Trainer reset: ``before_kick_off``, move every player to ``positions_srv``
        (f[2, n, 2], server frame) facing ``body_deg`` (f[2, n], degrees) at rest, move
        the ball, ``(recover)`` stamina if ``recover``, switch to ``play_mode``; then one
        step with no commands, so the returned cycle observes the new state."""
        n = self.n
        pos = np.asarray(positions_srv, dtype=np.float64)
        body = np.asarray(body_deg, dtype=np.float64)
        if pos.shape != (2, n, 2):
            raise ValueError(f"positions_srv has shape {pos.shape}; expected (2, {n}, 2)")
        if body.shape != (2, n):
            raise ValueError(f"body_deg has shape {body.shape}; expected (2, {n})")
        ball = np.asarray(ball_srv, dtype=np.float64)
        vel = np.asarray(ball_vel, dtype=np.float64)
        if ball.shape != (2,) or vel.shape != (2,):
            raise ValueError(
                f"ball_srv {ball_srv!r} and ball_vel {ball_vel!r} must each be 2 numbers"
            )
        for name, arr in (
            ("positions_srv", pos),
            ("body_deg", body),
            ("ball", ball),
            ("ball_vel", vel),
        ):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} must be finite, got {arr.tolist()!r}")
        if play_mode not in PLAY_MODES:
            raise ValueError(f"play mode {play_mode!r} is not one of the server's play modes")
        commands: list[Command] = [ChangeMode("before_kick_off")]
        for side in range(2):
            team = self.team_names[side]
            if not team:  # another client's team whose name we were not told
                continue
            for k in range(n):
                x, y = float(pos[side, k, 0]), float(pos[side, k, 1])
                commands.append(
                    MovePlayer(team, k + 1, x, y, _wrap_deg(float(body[side, k])), 0.0, 0.0)
                )
        commands.append(MoveBall(float(ball[0]), float(ball[1]), float(vel[0]), float(vel[1])))
        if recover:
            commands.append(Recover())
        commands.append(ChangeMode(play_mode))
        self.send_trainer(*commands)
        return self.step([None] * len(self._players))

    # -- errors and shutdown -------------------------------------------------------

    def _check_process(self) -> None:
        server = self.server
        if server is not None and not server.alive:
            raise self._died(f"exited (status {server.returncode})")

    def _died(self, why: str) -> ServerDied:
        self._connected = False
        if self.server is not None and not self.server.alive:
            why = f"exited (status {self.server.returncode})"
        text = f"rcssserver at {self.address.host}:{self.address.port} {why}"
        if self.server is not None:
            tail = self.server.log_problems()
            if tail:
                text += f"\nlast lines of its log ({self.server.log_path}):\n{tail}"
        return ServerDied(text)

    def close(self) -> None:
        """Say ``(bye)`` for every player, turn the trainer's eye off and close the
        sockets. Idempotent; errors from a dead server are ignored."""
        if self._connected:
            for conn in self._players:
                try:
                    conn.sock.send(b"(bye)" + _NUL)
                except OSError:
                    break
            trainer = self._trainer
            if trainer is not None and self.eye:
                with contextlib.suppress(OSError):
                    trainer.sock.send(b"(eye off)" + _NUL)
                    if trainer.pending:  # else the server waits 1.25 s for it
                        trainer.sock.send(_DONE + _NUL)
                        trainer.pending = False
        self._connected = False
        self._close_sockets()

    def _close_sockets(self) -> None:
        for conn in [*self._players, self._trainer]:
            if conn is not None:
                conn.sock.close()
        self._players = []
        self._trainer = None
        self._think_conns = []

    def __enter__(self) -> RoboCupClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:
        if sys.is_finalizing():
            return
        with contextlib.suppress(Exception):  # best effort in a finaliser
            self._close_sockets()


def _time_of(raw_sense_body: bytes) -> int | None:
    """The time field of a raw ``(sense_body T ...)`` without parsing the rest."""
    start = len(_SENSE_BODY)
    end = raw_sense_body.find(b" ", start)
    try:
        return int(raw_sense_body[start:end])
    except ValueError:
        return None


def _random_commands(rng: random.Random, count: int) -> list[Command]:
    """Random dash (50 %), turn (30 %) or kick (20 %) commands, one per player."""
    out: list[Command] = []
    for _ in range(count):
        r = rng.random()
        if r < 0.5:
            out.append(Dash(rng.uniform(0.0, 100.0), rng.uniform(-180.0, 180.0)))
        elif r < 0.8:
            out.append(Turn(rng.uniform(-180.0, 180.0)))
        else:
            out.append(Kick(rng.uniform(0.0, 100.0), rng.uniform(-180.0, 180.0)))
    return out


def measure_cycles(
    address: ServerAddress | ServerProcess,
    players_per_team: int = 11,
    cycles: int = 2000,
    *,
    eye: bool = False,
    parse: bool = False,
    seed: int = 0,
    warmup: int = 20,
) -> dict[str, float]:
    """Connect a client to a fresh server, start play and step ``cycles`` synchronous
    cycles with random dash/turn/kick commands; return the rate and where the time goes.

    Keys: ``cycles_per_s``; ``send_ms``/``wait_ms``/``parse_ms`` per cycle (wait
    includes the server's own step), ``other_ms`` (the loop around them), ``missed``,
    ``malformed``, ``load_1min`` (the machine's load average, since other processes
    share the CPU). The command pool is drawn before timing; encoding is timed (send).
    """
    if cycles < 1:
        raise ValueError(f"cycles {cycles!r} must be >= 1")
    rng = random.Random(seed)
    pool = [_random_commands(rng, 2 * players_per_team) for _ in range(64)]
    with RoboCupClient(address, players_per_team, eye=eye, parse=parse) as client:
        client.connect()
        client.change_mode("play_on")
        for k in range(warmup):
            client.step(pool[k % len(pool)])
        before = client.stats.as_dict()
        start = time.perf_counter()
        for k in range(cycles):
            client.step(pool[k % len(pool)])
        seconds = time.perf_counter() - start
        after = client.stats.as_dict()
    per = {
        key: 1e3 * (after[key] - before[key]) / cycles for key in ("send_s", "wait_s", "parse_s")
    }
    total_ms = 1e3 * seconds / cycles
    return {
        "cycles": float(cycles),
        "seconds": seconds,
        "cycles_per_s": cycles / seconds,
        "send_ms": per["send_s"],
        "wait_ms": per["wait_s"],
        "parse_ms": per["parse_s"],
        "other_ms": total_ms - sum(per.values()),
        "missed": after["missed_thinks"] - before["missed_thinks"],
        "malformed": after["malformed"] - before["malformed"],
        "load_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"),
    }
