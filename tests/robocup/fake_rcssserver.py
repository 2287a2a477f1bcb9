"""A stand-in for the rcssserver binary in match tests: what ``robocup.match`` reads of a
server, and nothing of the game.

    python fake_rcssserver.py --players N --cycles T --score L-R [--missed T1,T2] \\
        server::port=P server::game_logging=true server::game_log_dir=DIR ...

Binds the player port, answers each ``(init TEAM ...)`` as rcssserver does and logs "A new
(v19) player (TEAM UNUM) connected."; once both teams are in, writes a game log whose last
show is at cycle T (a server that ended early stops short of its two halves), a "Someone
missed a cycle at T" line per --missed, the "Game Results" with the score, and exits.
"""

from __future__ import annotations

import argparse
import re
import socket
import sys
from pathlib import Path

_INIT = re.compile(rb"\(init (\S+) ")


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--players", type=int, required=True)
    parser.add_argument("--cycles", type=int, required=True)
    parser.add_argument("--score", required=True)
    parser.add_argument("--missed", default="")
    args, rest = parser.parse_known_args()
    options = dict(option.split("=", 1) for option in rest)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", int(options["server::port"])))
    print("rcssserver (fake)", flush=True)
    teams: dict[bytes, int] = {}
    while sum(teams.values()) < 2 * args.players:
        data, address = sock.recvfrom(8192)
        init = _INIT.match(data)
        if init is None:
            continue
        name = init.group(1)
        side = "l" if not teams or name == next(iter(teams)) else "r"
        teams[name] = teams.get(name, 0) + 1
        sock.sendto(b"(init %s %d before_kick_off)\0" % (side.encode(), teams[name]), address)
        print(f"A new (v19) player ({name.decode()} {teams[name]}) connected.", flush=True)
    if options.get("server::game_logging") == "true":
        log = Path(options["server::game_log_dir"]) / "20260101000000-fake.rcg"
        shows = "".join(f"(show {t} ((b) 0 0 0 0))\n" for t in range(1, args.cycles + 1))
        log.write_text("ULG6\n(playmode 0 before_kick_off)\n" + shows)
    for t in filter(None, args.missed.split(",")):
        print(f"Someone missed a cycle at {t}", file=sys.stderr, flush=True)
    left, right = args.score.split("-")
    print(f"\nGame Results:\n\tScore: {left} - {right}\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
