"""A stand-in for another team's binaries (helios-base's start.sh) in tests: a small program
that speaks the player protocol and nothing of elevens.

    python fake_team.py --port P --team NAME [--players N] [--real-time] [--leave]

Connects N players (the first as goalie), moves them into their own half before kick-off,
then each cycle turns and dashes towards the ball when it sees it. In synch mode it answers
every (think) with its command and (done); in real time it sends one command per sense_body.
It leaves at time_over or when the server has been silent for 5 s (with --leave: as soon as
its players are in).
"""

from __future__ import annotations

import argparse
import re
import select
import socket
import sys

_BALL = re.compile(rb"\(\(b\) ([-\d.]+) ([-\d.]+)")


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--team", required=True)
    parser.add_argument("--players", type=int, default=11)
    parser.add_argument("--real-time", action="store_true")
    parser.add_argument("--leave", action="store_true", help="connect, then leave at once")
    args = parser.parse_args()
    socks = []
    for unum in range(1, args.players + 1):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        goalie = b" (goalie)" if unum == 1 else b""
        sock.sendto(b"(init %s (version 19)%s)\0" % (args.team.encode(), goalie),
                    (args.host, args.port))
        data, address = sock.recvfrom(8192)
        if not data.startswith(b"(init "):
            print(f"refused: {data!r}", file=sys.stderr)
            return 1
        sock.connect(address)
        socks.append(sock)
    if args.leave:
        return 0
    marker = b"(sense_body " if args.real_time else b"(think)"
    ball: list[tuple[float, float] | None] = [None] * len(socks)
    mode = b"before_kick_off"
    while True:
        ready, _, _ = select.select(socks, [], [], 5.0)
        if not ready:
            return 0
        for sock in ready:
            i = socks.index(sock)
            data = sock.recv(8192)
            if b"referee" in data:
                mode = data.rstrip(b"\0)").split()[-1]
                if mode == b"time_over":
                    for s in socks:
                        s.send(b"(bye)\0")
                    return 0
            seen = _BALL.search(data)
            if data.startswith(b"(see "):
                ball[i] = (float(seen.group(1)), float(seen.group(2))) if seen else None
            if not data.startswith(marker):
                continue
            if mode == b"before_kick_off" or mode.startswith(b"goal_"):
                command = b"(move -%d %d)" % (5 + 4 * i, -20 + 4 * i)
            elif ball[i] is None:
                command = b"(turn 60)"
            elif abs(ball[i][1]) > 15:
                command = b"(turn %.0f)" % ball[i][1]
            elif ball[i][0] < 0.9:
                command = b"(kick 60 0)"
            else:
                command = b"(dash 60)"
            sock.send(command + (b"" if args.real_time else b"(done)") + b"\0")


if __name__ == "__main__":
    sys.exit(main())
