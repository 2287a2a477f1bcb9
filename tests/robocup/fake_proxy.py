"""A fake skills proxy: eleven Thrift clients that connect to a decision server the way the
proxy's players do (register, send the parameters, then one ``GetPlayerActions`` per cycle,
each from its own thread) and send synthetic but realistic States.

The States are written with a richer definition than elevens' own: elevens' messages plus
fields the real proxy also sends and elevens never reads (the full-state world model, the
players' seen / heard positions, the player dictionaries), so the server must skip them as
it skips the proxy's.
"""

from __future__ import annotations

import dataclasses
import io
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import thriftpy2
from thriftpy2.rpc import make_client

from elevens.robocup.skills.wire import DEFINITION, protocol_factory, transport_factory

# Fields the proxy sends that elevens' definition leaves out (ids and types as the proxy's).
_EXTRA = {
    "struct RpcVector2D {": ["3: double dist,", "4: double angle,"],
    "struct Player {": [
        "2: RpcVector2D seen_position,", "3: RpcVector2D heard_position,",
        "5: RpcVector2D seen_velocity,", "12: double dist_from_self,",
        "13: double angle_from_self,", "21: double face_direction,",
        "26: double dist_from_ball,", "27: double angle_from_ball,",
        "31: RpcVector2D inertia_final_point,",
    ],
    "struct WorldModel {": [
        "2: string our_team_name,", "3: string their_team_name,",
        "10: list<Player> unknowns,", "11: map<i32, Player> our_players_dict,",
        "12: map<i32, Player> their_players_dict,",
        "31: map<i32, RpcVector2D> helios_home_positions,",
    ],
    "struct State {": ["3: WorldModel full_world_model,"],
}


def sender_protocol() -> Any:
    """The richer definition the fake proxy writes with."""
    text = DEFINITION.read_text()
    for head, fields in _EXTRA.items():
        assert head in text, head
        text = text.replace(head, head + "\n  " + "\n  ".join(fields), 1)
    return thriftpy2.load_fp(io.StringIO(text), module_name="fake_proxy_thrift")


FAKE = sender_protocol()

#: Opponents (their 4-4-2, in our coordinates) and our players at a kick-off.
THEIRS = np.array([
    [50, 0], [30, -20], [32, -7], [32, 7], [30, 20], [14, -22], [16, -7], [16, 7],
    [14, 22], [3, -9], [3, 9],
], np.float32)
OURS = -THEIRS


@dataclasses.dataclass
class Scene:
    """A moment of a game, in our coordinates: positions by shirt number."""

    ours: np.ndarray = dataclasses.field(default_factory=lambda: OURS.copy())
    theirs: np.ndarray = dataclasses.field(default_factory=lambda: THEIRS.copy())
    ball: tuple[float, float] = (0.0, 0.0)
    mode: int = 2  # PlayOn
    cycle: int = 1
    kickable: int = 0  # our shirt number with the ball (0: none)
    kickable_opponent: bool = False
    score: tuple[int, int] = (0, 0)  # ours, theirs, as the referee announced them
    our_set_play: bool = False
    last_kicker: int = 0  # our shirt number that kicked last (0: one of theirs, or nobody)


def _v(m: Any, xy: Sequence[float], me: Sequence[float] | None = None) -> Any:
    x, y = float(xy[0]), float(xy[1])
    dx, dy = (x, y) if me is None else (x - me[0], y - me[1])
    return m.RpcVector2D(x=x, y=y, dist=float(np.hypot(dx, dy)),
                         angle=float(np.degrees(np.arctan2(dy, dx))))


def _player(m: Any, unum: int, xy: np.ndarray, side: int, ball: np.ndarray,
            me: np.ndarray) -> Any:
    d = float(np.linalg.norm(xy - ball))
    return m.Player(
        position=_v(m, xy, me), seen_position=_v(m, xy, me), heard_position=_v(m, xy, me),
        velocity=_v(m, (0.0, 0.0)), seen_velocity=_v(m, (0.0, 0.0)), pos_count=1,
        dist_from_self=float(np.linalg.norm(xy - me)), angle_from_self=0.0,
        id=unum + (0 if side == 1 else 100), side=side, uniform_number=unum,
        is_goalie=unum == 1, body_direction=0.0, face_direction=0.0,
        dist_from_ball=d, angle_from_ball=0.0, ball_reach_steps=int(d),
        inertia_final_point=_v(m, xy),
    )


def state(scene: Scene, unum: int) -> Any:
    """Player ``unum``'s State in ``scene``: a perfect world model, intercept steps of one
    per metre."""
    m = FAKE
    ball = np.asarray(scene.ball, np.float32)
    me = scene.ours[unum - 1]
    mates = [_player(m, k, scene.ours[k - 1], 1, ball, me) for k in range(1, 12) if k != unum]
    opps = [_player(m, k, scene.theirs[k - 1], 2, ball, me) for k in range(1, 12)]
    reach = np.linalg.norm(scene.ours - ball, axis=1).astype(int)
    other = np.delete(np.arange(1, 12), unum - 1)
    first_mate = other[np.argmin(reach[other - 1])]
    opp_reach = np.linalg.norm(scene.theirs - ball, axis=1).astype(int)
    table = m.InterceptTable(
        self_reach_steps=int(reach[unum - 1]),
        first_teammate_reach_steps=int(reach[first_mate - 1]),
        first_opponent_reach_steps=int(opp_reach.min()),
        first_teammate_id=int(first_mate), first_opponent_id=int(100 + opp_reach.argmin() + 1),
    )
    myself = m.Self(
        position=_v(m, me), velocity=_v(m, (0.0, 0.0)), uniform_number=unum,
        is_goalie=unum == 1, body_direction=0.0, stamina=8000.0,
        is_kickable=scene.kickable == unum, tackle_probability=0.0,
    )
    extra = dict(
        our_team_name="elevens", their_team_name="HELIOS_base", unknowns=[],
        our_players_dict={p.uniform_number: p for p in mates},
        their_players_dict={p.uniform_number: p for p in opps},
        helios_home_positions={k: _v(m, scene.ours[k - 1]) for k in range(1, 12)},
    )
    wm = m.WorldModel(
        intercept_table=table, our_side=1, myself=myself,
        ball=m.Ball(position=_v(m, ball, me), velocity=_v(m, (0.0, 0.0)), pos_count=0),
        teammates=mates, opponents=opps, their_goalie_uniform_number=1,
        offside_line_x=float(max(np.sort(scene.theirs[:, 0])[-2], ball[0], 0.0)),
        cycle=scene.cycle, game_mode_type=scene.mode, is_our_set_play=scene.our_set_play,
        last_kick_side=1 if scene.last_kicker else 2, last_kicker_uniform_number=scene.last_kicker,
        stoped_cycle=0,
        our_team_score=scene.score[0], their_team_score=scene.score[1],
        is_penalty_kick_mode=False,
        kickable_teammate_existance=scene.kickable not in (0, unum),
        kickable_opponent_existance=scene.kickable_opponent, **extra,
    )
    response = m.RegisterResponse(client_id=unum, agent_type=0, team_name="elevens",
                                  uniform_number=unum)
    return m.State(register_response=response, world_model=wm, full_world_model=wm,
                   need_preprocess=False)


def varied_cycle(rng: np.random.Generator, cycle: int = 1) -> list[Any]:
    """Eleven States of a random moment, each world model as partial as the proxy's can be:
    players missing or with an unknown shirt number (0), a lost ball, no intercept table,
    unset values; random modes, holders and stamina."""
    spread = rng.uniform(2.0, 20.0)
    holder = int(rng.integers(3))  # 0: loose ball, 1: one of ours has it, 2: one of them
    kickable = int(rng.integers(1, 12)) if holder == 1 else 0
    shift = np.array([rng.uniform(-45.0, 45.0), 0.0], np.float32)  # both teams, up or down
    ours = OURS + shift + rng.normal(0.0, spread, OURS.shape).astype(np.float32)
    theirs = THEIRS + shift + rng.normal(0.0, spread, THEIRS.shape).astype(np.float32)
    ball = rng.uniform([-50.0, -32.0], [50.0, 32.0])
    theirs_ball = holder == 2
    if kickable:
        ball = ours[kickable - 1] + rng.normal(0.0, 0.3, 2)
    elif theirs_ball:
        ball = theirs[int(rng.integers(0, 11))] + rng.normal(0.0, 0.3, 2)
    mode = int(rng.choice([2, 2, 2, 2, 0, 8, 3, 5, 10]))
    scene = Scene(
        ours=ours, theirs=theirs,
        ball=(float(ball[0]), float(ball[1])), mode=mode,
        cycle=cycle, kickable=kickable, kickable_opponent=theirs_ball,
        # Without a draw of their own, so that the moments stay what they were.
        our_set_play=mode in (3, 5, 10) and cycle % 2 == 0, last_kicker=kickable or cycle % 12,
    )
    states = []
    for unum in range(1, 12):
        s = state(scene, unum)
        wm = s.world_model
        for players in (wm.teammates, wm.opponents):
            keep = rng.random(len(players)) < rng.uniform(0.3, 1.0)
            players[:] = [p for p, k in zip(players, keep, strict=True) if k]
            for p in players:
                if rng.random() < 0.05:
                    p.uniform_number = 0
                if rng.random() < 0.05:
                    p.body_direction = None
                p.velocity = _v(FAKE, rng.normal(0.0, 0.5, 2))
        if rng.random() < 0.05:
            wm.ball = None
        if rng.random() < 0.05:
            wm.intercept_table = None
        else:
            wm.intercept_table.self_reach_steps = int(rng.integers(0, 30))
        wm.myself.stamina = float(rng.uniform(2000.0, 8000.0))
        wm.myself.tackle_probability = float(rng.random())
        wm.myself.body_direction = float(rng.uniform(-180.0, 180.0))
        wm.is_penalty_kick_mode = bool(rng.random() < 0.05)
        s.need_preprocess = bool(rng.random() < 0.2)
        states.append(s)
    return states


class FakePlayer:
    """One proxy player's connection."""

    def __init__(self, port: int, unum: int, timeout_ms: int = 5000) -> None:
        self.unum = unum
        self.client = make_client(
            FAKE.Game, "127.0.0.1", port, proto_factory=protocol_factory(),
            trans_factory=transport_factory(), timeout=timeout_ms,
        )
        request = FAKE.RegisterRequest(agent_type=0, team_name="elevens", uniform_number=unum,
                                       rpc_version=1)
        self.response = self.client.Register(request)
        self.client.SendServerParams(FAKE.ServerParam(register_response=self.response))
        self.client.SendPlayerParams(FAKE.PlayerParam(register_response=self.response))
        for _ in range(3):
            self.client.SendPlayerType(FAKE.PlayerType(register_response=self.response))
        self.client.SendInitMessage(FAKE.InitMessage(register_response=self.response))

    def ask(self, state: Any) -> tuple[Any, float]:
        """The answer and the round trip in seconds."""
        start = time.perf_counter()
        answer = self.client.GetPlayerActions(state)
        return answer, time.perf_counter() - start

    def close(self) -> None:
        self.client.SendByeCommand(self.response)
        self.client.close()


class FakeTeam:
    """Eleven players, each on its own thread; :meth:`cycle` sends one State each at once
    (as in synch mode) and returns the answers by shirt number and the round trips."""

    def __init__(self, port: int, players: int = 11, timeout_ms: int = 5000) -> None:
        self.players = [FakePlayer(port, unum, timeout_ms) for unum in range(1, players + 1)]

    def cycle(self, scene: Scene, skip: Sequence[int] = ()) -> tuple[dict[int, Any], list[float]]:
        answers: dict[int, Any] = {}
        trips: list[float] = []
        states = {p.unum: state(scene, p.unum) for p in self.players if p.unum not in skip}
        barrier = threading.Barrier(len(states))
        lock = threading.Lock()
        errors: list[BaseException] = []

        def run(player: FakePlayer) -> None:
            try:
                barrier.wait()
                answer, trip = player.ask(states[player.unum])
                with lock:
                    answers[player.unum] = answer
                    trips.append(trip)
            except BaseException as e:  # surfaces in the test, not in a thread's log
                errors.append(e)

        threads = [threading.Thread(target=run, args=(p,)) for p in self.players
                   if p.unum in states]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        if errors:
            raise errors[0]
        return answers, trips

    def close(self) -> None:
        for p in self.players:
            p.close()


def main() -> None:
    """A stand-in for the proxy's ``start.sh``: ``--rpc-port N`` connects eleven fake players,
    plays ``--cycles`` cycles of a scene that moves the ball, and prints one JSON line with
    the round trips."""
    import argparse
    import json

    parser = argparse.ArgumentParser(add_help=False)  # start.sh's -h is the host
    parser.add_argument("--rpc-port", type=int, required=True)
    parser.add_argument("--cycles", type=int, default=20)
    args, _ = parser.parse_known_args()
    team = FakeTeam(args.rpc_port)
    trips: list[float] = []
    for c in range(args.cycles):
        ball = (-30.0 + 60.0 * c / max(args.cycles - 1, 1), 5.0)
        _, t = team.cycle(Scene(ball=ball, cycle=c + 1))
        trips += t
    team.close()
    print(json.dumps({"requests": len(trips), "p50_ms": float(np.percentile(trips, 50)) * 1e3,
                      "p99_ms": float(np.percentile(trips, 99)) * 1e3}))


if __name__ == "__main__":
    main()
