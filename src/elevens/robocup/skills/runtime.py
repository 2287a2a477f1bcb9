"""The decision server of a skills team: one Thrift server that the team's proxy players all
call, deciding each cycle's requests in one batched policy call.

Every connection is served by a thread of its own (a proxy player keeps one connection open
for the whole match). A player's ``GetPlayerActions`` request waits while the cycle's batch
gathers: the batch is decided as soon as every connected player of the cycle has asked, or
``gather_s`` after its first request (in real time a slow player must not hold the others
back), by ONE call of ``decide(states) -> actions`` over all the waiting requests. A request
whose answer is not ready ``deadline_s`` after it arrived gets :func:`default_actions` (the
proxy stalls without an answer: it has no timeout of its own); the late decision is then
dropped. Works the same in synch mode and in real time: batches are formed by arrival, and a
cycle is only used to know when everyone has asked.

A ``decide`` marked :func:`rowwise` (each answer depends on its own request alone, as
``skills_naive``'s) is neither gathered nor handed to the decide thread: each connection's
thread decides its own request as soon as it is decoded, ``decide([state])``, and answers it
(the same answer one call over the cycle gives). On a busy host the first players of a cycle
no longer wait up to ``gather_s`` for its last, and a request takes one thread wake-up
instead of three; a whole cycle costs more CPU (eleven calls instead of one or two). Its
answer is sent however late it is: the thread that would send the default is the one
deciding (a ``decide`` that raises still gets the default).

``DecisionServer.stats()`` reports the requests, the batches, the defaults sent, the latency
from a decoded request to its answer (p50, p99, max) and the round trip the proxy waits for:
from the request's first bytes on the socket to its answer handed to it (decoding, the wait
for the batch, the decision and encoding; p50, p99, max).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import socket
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np
from thriftpy2.thrift import TProcessor
from thriftpy2.transport import TSocket, TTransportException

from elevens.robocup.skills.planner import Candidates, Choose, helios_best
from elevens.robocup.skills.space import default_actions
from elevens.robocup.skills.wire import protocol, protocol_factory, transport_factory

__all__ = ["Decide", "DecisionServer", "RuntimeStats", "is_rowwise", "rowwise"]

#: The batched policy: the States of the players that asked, to their PlayerActions.
Decide = Callable[[Sequence[Any]], Sequence[Any]]
_ROWWISE = "elevens_rowwise"
_D = TypeVar("_D", bound=Decide)


def rowwise(decide: _D) -> _D:
    """Mark ``decide`` as deciding each request on its own (any split of a cycle's requests
    into calls gives the same answers) and safe to call from several threads at once: the
    server calls it once per request, in the request's connection thread (module
    docstring). Returns ``decide``."""
    setattr(decide, _ROWWISE, True)
    return decide


def is_rowwise(decide: Decide) -> bool:
    return bool(getattr(decide, _ROWWISE, False))

_log = logging.getLogger(__name__)
_PLAYER = 0  # the proxy's AgentType of a player (the coach and trainer are 1 and 2)


@dataclasses.dataclass(frozen=True)
class RuntimeStats:
    requests: int
    batches: int
    defaults: int  # answers that missed the deadline (or whose decision failed)
    errors: int  # batches whose decide raised
    mean_batch: float
    latency_ms_p50: float
    latency_ms_p99: float
    latency_ms_max: float
    roundtrip_ms_p50: float
    roundtrip_ms_p99: float
    roundtrip_ms_max: float
    decide_ms_p50: float
    decide_ms_p99: float
    connected_players: int
    chosen: int = 0  # planner chains chosen (GetBestPlannerAction)
    choice_errors: int = 0  # of which helios-base's choice stood in for a failed chooser

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class _Request:
    __slots__ = ("state", "key", "unum", "arrived", "answer", "done")

    def __init__(self, state: Any) -> None:
        wm = state.world_model
        self.state = state
        self.key = (int(wm.cycle or 0), int(wm.stoped_cycle or 0)) if wm is not None else (0, 0)
        me = None if wm is None else wm.myself
        self.unum = 0 if me is None else int(me.uniform_number or 0)
        self.arrived = time.perf_counter()
        self.answer: Any = None
        self.done = threading.Event()


class _TimedSocket(TSocket):
    """A socket that notes when the first bytes of a call arrive: a blocking ``recv``
    returns as they do."""

    first_read: float | None = None
    last_write: float | None = None

    def read(self, sz: int) -> bytes:
        data: bytes = super().read(sz)
        if self.first_read is None:
            self.first_read = time.perf_counter()
        return data

    def write(self, buff: bytes) -> None:
        # Stamped as the answer is handed to the socket: after a blocking send the thread
        # may wait for the GIL while the proxy already has the answer.
        self.last_write = time.perf_counter()
        super().write(buff)


class _Connection:
    """The handler of one proxy's connection (the Thrift service's methods)."""

    def __init__(self, server: DecisionServer) -> None:
        self.server = server
        self.kind: int | None = None
        self.asked = False  # the call being served is a GetPlayerActions

    def Register(self, request: Any) -> Any:  # noqa: N802 - the protocol's method names
        m = protocol()
        self.kind = int(request.agent_type or 0)
        client_id = self.server._register(self.kind)
        return m.RegisterResponse(
            client_id=client_id, agent_type=request.agent_type, team_name=request.team_name,
            uniform_number=request.uniform_number,
        )

    def SendServerParams(self, _: Any) -> Any:  # noqa: N802
        return protocol().Empty()

    def SendPlayerParams(self, _: Any) -> Any:  # noqa: N802
        return protocol().Empty()

    def SendPlayerType(self, _: Any) -> Any:  # noqa: N802
        return protocol().Empty()

    def SendInitMessage(self, _: Any) -> Any:  # noqa: N802
        return protocol().Empty()

    def SendByeCommand(self, _: Any) -> Any:  # noqa: N802
        self.close()
        return protocol().Empty()

    def GetPlayerActions(self, state: Any) -> Any:  # noqa: N802
        self.asked = True
        return self.server._ask(state)

    def GetBestPlannerAction(self, request: Any) -> Any:  # noqa: N802
        return protocol().BestPlannerActionResponse(index=self.server._choose(request))

    def GetCoachActions(self, _: Any) -> Any:  # noqa: N802
        m = protocol()
        actions = [m.CoachAction(do_helios_substitute=m.DoHeliosSubstitute())]
        return m.CoachActions(actions=actions if self.server.coach_substitutes else [])

    def close(self) -> None:
        if self.kind is not None:
            self.server._unregister(self.kind)
            self.kind = None


class DecisionServer:
    """Serve ``decide`` to a team's proxy players on ``host:port`` (port 0: a free one, see
    :attr:`port`). ``players``: how many players of a cycle to wait for at most (the
    connected players, when fewer are connected; a :func:`rowwise` ``decide`` waits for
    none and has no deadline). ``on_default(state)``: told of every
    request answered by the default instead of ``decide`` (a recorder masks those cycles).
    A player that leaves its kick to helios-base's planner with the choice on our side
    (``planner``) asks which searched chain to play: ``decide.choose_chain`` chooses when
    ``decide`` has one, else :func:`planner.helios_best` (also the answer when it fails).
    Start with :meth:`start`, stop with :meth:`close`, or use it as a context manager."""

    def __init__(
        self,
        decide: Decide,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        players: int = 11,
        deadline_s: float = 0.040,
        gather_s: float = 0.015,
        coach_substitutes: bool = True,
        on_default: Callable[[Any], None] | None = None,
    ) -> None:
        if not 0.0 < gather_s < deadline_s:
            raise ValueError(
                f"gather_s {gather_s} and deadline_s {deadline_s} "
                f"(allowed: 0 < gather_s < deadline_s)"
            )
        if not 1 <= players <= 11:
            raise ValueError(f"players {players} (allowed: 1..11)")
        self.decide = decide
        self.gathers = not is_rowwise(decide)
        self.players = players
        self.deadline_s = deadline_s
        self.gather_s = gather_s
        self.coach_substitutes = coach_substitutes
        self.on_default = on_default
        self.choose: Choose = getattr(decide, "choose_chain", helios_best)
        self._listener = socket.create_server((host, port), backlog=32)
        self.host, self.port = self._listener.getsockname()[:2]
        self._lock = threading.Condition()
        self._pending: list[_Request] = []
        self._decided: dict[tuple[int, int], set[int]] = {}
        self._connected = [0, 0]  # players, others (the coach)
        self._next_id = 0
        self._closed = False
        self._threads: list[threading.Thread] = []
        self._socks: set[socket.socket] = set()
        self._latency: list[float] = []
        self._roundtrip: list[float] = []
        self._decide_s: list[float] = []
        self._batches = 0
        self._batch_sizes = 0
        self._defaults = 0
        self._errors = 0
        self._chosen = 0
        self._choice_errors = 0

    # ---- lifecycle ----

    def start(self) -> DecisionServer:
        loops = [(self._accept_loop, "accept")]
        if self.gathers:
            loops.append((self._decide_loop, "decide"))
        for target, name in loops:
            t = threading.Thread(target=target, name=f"skills-{name}", daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._lock.notify_all()
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        with self._lock:
            socks = list(self._socks)
        for sock in socks:  # wakes the connection threads blocked in a read
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
        for t in self._threads:
            t.join(timeout=2.0)

    def __enter__(self) -> DecisionServer:
        return self.start()

    def __exit__(self, *_: object) -> None:
        self.close()

    # ---- connections ----

    def _accept_loop(self) -> None:
        while not self._closed:
            try:
                sock, _ = self._listener.accept()
            except OSError:
                return
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._socks.add(sock)
            t = threading.Thread(target=self._serve, args=(sock,), daemon=True,
                                 name="skills-connection")
            t.start()

    def _serve(self, sock: socket.socket) -> None:
        client = _TimedSocket()
        client.set_handle(sock)
        trans = transport_factory().get_transport(client)
        prot = protocol_factory().get_protocol(trans)
        connection = _Connection(self)
        processor = TProcessor(protocol().Game, connection)
        try:
            while not self._closed:
                client.first_read, client.last_write, connection.asked = None, None, False
                processor.process(prot, prot)  # reads a call, answers it, flushes
                # A call already buffered by the previous read has no arrival time: skipped.
                if (connection.asked and client.first_read is not None
                        and client.last_write is not None):
                    elapsed = client.last_write - client.first_read
                    with self._lock:
                        self._roundtrip.append(elapsed)
        except (TTransportException, ConnectionError):
            pass  # the proxy went away (closed, or reset as its process ended)
        except Exception:  # one bad connection must not take the team down
            _log.exception("a proxy connection failed")
        finally:
            connection.close()
            trans.close()
            with self._lock:
                self._socks.discard(sock)

    def _register(self, kind: int) -> int:
        with self._lock:
            self._connected[0 if kind == _PLAYER else 1] += 1
            self._next_id += 1
            self._lock.notify_all()
            return self._next_id

    def _unregister(self, kind: int) -> None:
        with self._lock:
            self._connected[0 if kind == _PLAYER else 1] -= 1
            self._lock.notify_all()

    # ---- batching ----

    def _ask(self, state: Any) -> Any:
        if not self.gathers:
            return self._decide_alone(state, time.perf_counter())
        request = _Request(state)
        with self._lock:
            self._pending.append(request)
            self._lock.notify_all()
        if not request.done.wait(self.deadline_s - (time.perf_counter() - request.arrived)):
            with self._lock:
                if not request.done.is_set():  # the decision may land while we take the lock
                    request.answer = default_actions(state)
                    request.done.set()
                    self._defaults += 1
                    self._defaulted(state)
        with self._lock:
            self._latency.append(time.perf_counter() - request.arrived)
        return request.answer

    def _decide_alone(self, state: Any, arrived: float) -> Any:
        """A :func:`rowwise` decide of one request, in its connection's thread."""
        answers = self._call([state])
        failed = answers is None
        answer = default_actions(state) if answers is None else answers[0]
        done = time.perf_counter()
        with self._lock:
            self._batches += 1
            self._batch_sizes += 1
            self._decide_s.append(done - arrived)
            self._latency.append(done - arrived)
            self._defaults += failed
        if failed:
            self._defaulted(state)
        return answer

    def _batch_ready(self, now: float) -> bool:
        if not self._pending:
            return False
        if now - self._pending[0].arrived >= self.gather_s:
            return True
        key = max(r.key for r in self._pending)
        asked = self._decided.get(key, set()) | {r.unum for r in self._pending if r.key == key}
        expected = min(self.players, max(self._connected[0], 1))
        return len(asked) >= expected

    def _decide_loop(self) -> None:
        while True:
            with self._lock:
                while not self._closed and not self._batch_ready(time.perf_counter()):
                    wait = None
                    if self._pending:
                        wait = max(self.gather_s - (time.perf_counter()
                                                    - self._pending[0].arrived), 0.0)
                    self._lock.wait(wait)
                if self._closed:
                    return
                for r in self._pending:
                    self._decided.setdefault(r.key, set()).add(r.unum)
                # Requests answered by the default while an earlier decision ran are dropped.
                batch = [r for r in self._pending if not r.done.is_set()]
                self._pending = []
                if len(self._decided) > 8:  # only the latest cycles matter
                    for key in sorted(self._decided)[:-8]:
                        del self._decided[key]
            if batch:
                self._run(batch)

    def _run(self, batch: list[_Request]) -> None:
        start = time.perf_counter()
        answers = self._call([r.state for r in batch])
        if answers is None:
            answers = [None] * len(batch)
        elapsed = time.perf_counter() - start
        with self._lock:
            self._batches += 1
            self._batch_sizes += len(batch)
            self._decide_s.append(elapsed)
            for r, answer in zip(batch, answers, strict=True):
                if r.done.is_set():
                    continue  # it got the default already
                if answer is None:
                    answer = default_actions(r.state)
                    self._defaults += 1
                    self._defaulted(r.state)
                r.answer = answer
                r.done.set()

    def _call(self, states: list[Any]) -> list[Any] | None:
        """``decide`` over ``states``; None (logged, counted as an error) when it raises or
        answers another number of requests: its requests then get the default actions."""
        try:
            answers = list(self.decide(states))
            if len(answers) != len(states):
                raise ValueError(f"decide answered {len(answers)} of {len(states)} requests")
            return answers
        except Exception:
            _log.exception("decide failed; its requests get the default actions")
            with self._lock:
                self._errors += 1
            return None

    def _choose(self, request: Any) -> int:
        """The node of the planner's search the asking player plays: ``choose``'s, or
        helios-base's own when it fails or names a node that was not searched."""
        candidates = Candidates.of(request.pairs, getattr(request, "state", None))
        unum = int(getattr(request.register_response, "uniform_number", 0) or 0)
        try:
            index = int(self.choose(unum, candidates))
            if index not in set(candidates.index.tolist()):
                raise ValueError(f"chose node {index}, not among the {len(candidates)} searched")
        except Exception:
            _log.exception("choose failed; the player plays helios-base's choice")
            index = helios_best(unum, candidates)
            with self._lock:
                self._choice_errors += 1
        with self._lock:
            self._chosen += 1
        return index

    def _defaulted(self, state: Any) -> None:
        if self.on_default is not None:
            try:
                self.on_default(state)
            except Exception:  # a recorder's failure must not take the team down
                _log.exception("on_default failed")

    # ---- reports ----

    def stats(self) -> RuntimeStats:
        with self._lock:
            lat = np.asarray(self._latency) * 1e3
            trip = np.asarray(self._roundtrip) * 1e3
            dec = np.asarray(self._decide_s) * 1e3
            requests, batches = len(self._latency), self._batches

            def pct(a: np.ndarray, q: float) -> float:
                return float(np.percentile(a, q)) if a.size else float("nan")

            return RuntimeStats(
                requests=requests, batches=batches, defaults=self._defaults,
                errors=self._errors,
                mean_batch=self._batch_sizes / batches if batches else 0.0,
                latency_ms_p50=pct(lat, 50), latency_ms_p99=pct(lat, 99),
                latency_ms_max=float(lat.max()) if lat.size else float("nan"),
                roundtrip_ms_p50=pct(trip, 50), roundtrip_ms_p99=pct(trip, 99),
                roundtrip_ms_max=float(trip.max()) if trip.size else float("nan"),
                decide_ms_p50=pct(dec, 50), decide_ms_p99=pct(dec, 99),
                connected_players=self._connected[0],
                chosen=self._chosen, choice_errors=self._choice_errors,
            )
