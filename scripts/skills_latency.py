"""The skills runtime's decision latency without rcssserver or the proxy, on the fake proxy's
varied States (tests/robocup/fake_proxy.py), from the repository root:

    PYTHONPATH=src:. python scripts/skills_latency.py stages [CYCLES]
    PYTHONPATH=src:. python scripts/skills_latency.py burst [CYCLES]

``stages``: a cycle's eleven serialized States through the decision path, each stage timed
(decode, observe, skills_naive's decisions, the proxy's actions, encode; p50 and p99 in ms),
and one player's whole decision in play on (``skills_naive([state])``, as the server calls
it).

``burst``: a synch-mode match's bursts on this host: the DecisionServer serving
``skills_naive`` to eleven proxy processes (each spins about 0.6 ms, sends its State in the
proxy's 512 B writes, waits for the answer, spins 0.2 ms), eleven opponent processes (spin
0.8 ms), the next cycle when all 22 are done, and two busy loops at nice 10. Prints the
server's stats (round trip, decoded request to answer) and the players' own round trip.
Compare versions with PYTHONPATH=OTHER/src:. in turn on the same host; its tail is harsher
than a real match's. docs/robocup_skills.md has the match figures.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import sys
import time
from typing import Any

import numpy as np

CHUNK = 512  # the proxy's Thrift TBufferedTransport writes


def _spin(ms: float) -> None:
    end = time.perf_counter() + ms / 1e3
    while time.perf_counter() < end:
        pass


def _serialize(obj: Any, call: bool = False) -> bytes:
    from thriftpy2.thrift import TMessageType
    from thriftpy2.transport import TMemoryBuffer

    from elevens.robocup.skills.wire import protocol_factory
    from tests.robocup.fake_proxy import FAKE

    buf = TMemoryBuffer()
    proto = protocol_factory().get_protocol(buf)
    if call:
        proto.write_message_begin("GetPlayerActions", TMessageType.CALL, 0)
        FAKE.Game.GetPlayerActions_args(state=obj).write(proto)
        proto.write_message_end()
    else:
        obj.write(proto)
    return bytes(buf.getvalue())


def _cycles(count: int, play_on: bool = False) -> list[list[Any]]:
    from tests.robocup.fake_proxy import FAKE, varied_cycle

    rng = np.random.default_rng(1)
    cycles = [varied_cycle(rng, c + 1) for c in range(count)]
    for states in cycles:
        for s in states:
            s.full_world_model = FAKE.WorldModel()  # the proxy sends it empty
            if play_on:
                s.world_model.game_mode_type = 2
    return cycles


def _pct(values: list[float]) -> str:
    return f"p50 {np.percentile(values, 50):.3f} p99 {np.percentile(values, 99):.3f} ms"


def stages(count: int) -> None:
    from thriftpy2.transport import TMemoryBuffer

    from elevens.robocup.skills.naive import skills_naive, skills_naive_decisions
    from elevens.robocup.skills.observe import observe
    from elevens.robocup.skills.space import to_player_actions
    from elevens.robocup.skills.wire import protocol, protocol_factory

    m = protocol()
    raw = [[_serialize(s) for s in states] for states in _cycles(count)]
    play_on = _cycles(count, play_on=True)

    def decode(b: bytes) -> Any:
        state = m.State()
        state.read(protocol_factory().get_protocol(TMemoryBuffer(b)))
        return state

    times: dict[str, list[float]] = {k: [] for k in
                                     ("decode", "observe", "decide", "actions", "encode", "all")}
    single: list[float] = []
    for _ in range(3):
        for cycle in raw:
            t0 = time.perf_counter()
            states = [decode(b) for b in cycle]
            t1 = time.perf_counter()
            obs = observe(states)
            t2 = time.perf_counter()
            decisions = skills_naive_decisions(obs)
            t3 = time.perf_counter()
            answers = to_player_actions(decisions, obs)
            t4 = time.perf_counter()
            for a in answers:
                _serialize(a)
            t5 = time.perf_counter()
            for key, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t5 - t0),
                               strict=True):
                times[key].append(dt * 1e3)
    for _ in range(3):
        for states in play_on:
            for s in states:
                t = time.perf_counter()
                skills_naive([s])
                single.append((time.perf_counter() - t) * 1e3)
    print(f"{len(raw)} cycles of 11 States, {np.mean([len(b) for b in raw[0]]):.0f} B each")
    for key, values in times.items():
        print(f"  a cycle's {key:8s} {_pct(values)}")
    print(f"  one player's skills_naive([state]) in play on {_pct(single)}")


def _proxy(unum: int, port: int, raws: list[bytes], trigger: Any, done: Any, seed: int) -> None:
    from tests.robocup.fake_proxy import FakePlayer

    rng = np.random.default_rng(seed)
    player = FakePlayer(port, unum)
    client = player.client
    done.put(0.0)
    while (k := trigger.get()) is not None:
        _spin(rng.exponential(0.6))
        start = time.perf_counter()
        raw = raws[k % len(raws)]
        for at in range(0, len(raw), CHUNK):
            client._oprot.trans.write(raw[at:at + CHUNK])
            client._oprot.trans.flush()
        client._recv("GetPlayerActions")
        trip = time.perf_counter() - start
        _spin(rng.exponential(0.2))
        done.put(trip)
    player.close()


def _opponent(trigger: Any, done: Any, seed: int) -> None:
    rng = np.random.default_rng(seed)
    done.put(None)
    while trigger.get() is not None:
        _spin(rng.exponential(0.8))
        done.put(None)


def _busy() -> None:
    os.nice(10)
    while True:
        pass


def burst(count: int) -> None:
    from elevens.robocup.skills.naive import skills_naive
    from elevens.robocup.skills.runtime import DecisionServer

    raws = [[_serialize(s, call=True) for s in states] for states in _cycles(50, play_on=True)]
    ctx = mp.get_context("fork")
    done: Any = ctx.Queue()
    with DecisionServer(skills_naive) as server:
        triggers, procs = [], []
        for unum in range(1, 12):
            triggers.append(ctx.Queue())
            procs.append(ctx.Process(target=_proxy, args=(
                unum, server.port, [r[unum - 1] for r in raws], triggers[-1], done, unum)))
        for k in range(11):
            triggers.append(ctx.Queue())
            procs.append(ctx.Process(target=_opponent, args=(triggers[-1], done, 100 + k)))
        busy = [ctx.Process(target=_busy, daemon=True) for _ in range(2)]
        for p in procs + busy:
            p.start()
        for _ in procs:
            done.get()
        trips: list[float] = []
        start = time.perf_counter()
        for k in range(count):
            for q in triggers:
                q.put(k)
            for _ in procs:
                trip = done.get()
                if trip is not None:
                    trips.append(trip * 1e3)
        wall = time.perf_counter() - start
        for q in triggers:
            q.put(None)
        for p in procs:
            p.join(10)
        for p in busy:
            p.terminate()
        stats = server.stats().as_dict()
    print(json.dumps({"cycles": count, "wall_s": round(wall, 1),
                      "players_trip_ms_p50": round(float(np.percentile(trips, 50)), 2),
                      "players_trip_ms_p99": round(float(np.percentile(trips, 99)), 2),
                      **{k: round(v, 2) if isinstance(v, float) else v
                         for k, v in stats.items()}}))


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    if what not in ("stages", "burst"):
        raise SystemExit(f"usage: {sys.argv[0]} stages|burst [CYCLES] (got {what!r})")
    cycles = int(sys.argv[2]) if len(sys.argv) > 2 else (100 if what == "stages" else 600)
    (stages if what == "stages" else burst)(cycles)
