"""Runs one rcssserver and makes sure it does not outlive the Python process that wanted it.

``ServerProcess`` starts this file as a script (``python server_guard.py PARENT_PID BINARY
ARGS...``; standard library only, so it starts in milliseconds without importing elevens):

* the guard starts the server as its child, which is sent SIGKILL by the kernel the moment the
  guard dies (Linux ``PR_SET_PDEATHSIG``), however the guard dies;
* the guard checks twice a second that PARENT_PID is still its parent; once that process is
  gone (killed with SIGKILL, say, which no handler can catch), it stops the server and exits;
* SIGTERM, SIGINT and SIGHUP sent to the guard are passed on to the server;
* the guard exits as the server did: with its exit status, or killed by the same signal.

Without it, a training run killed by SIGKILL (the OOM killer, a scheduler's hard limit) left
its servers running. Where ``prctl`` is missing (not Linux), the parent check still applies,
but a SIGKILL sent to the guard itself leaves the server running.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys

PARENT_CHECK_S = 0.5
STOP_GRACE_S = 3.0
PR_SET_PDEATHSIG = 1
FORWARDED = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)


def _die_with_guard() -> None:
    """In the server's process, before exec: SIGKILL when the guard dies."""
    with contextlib.suppress(AttributeError, OSError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def _stop(server: subprocess.Popen[bytes]) -> int:
    server.terminate()
    try:
        return server.wait(timeout=STOP_GRACE_S)
    except subprocess.TimeoutExpired:
        server.kill()
        return server.wait()


def main(argv: list[str]) -> int:
    if len(argv) < 2 or not argv[0].isdigit():
        print("usage: server_guard.py PARENT_PID BINARY [ARGS...]", file=sys.stderr)
        return 2
    parent = int(argv[0])
    # The guard is single-threaded, so preexec_fn is safe here.
    server = subprocess.Popen(argv[1:], preexec_fn=_die_with_guard)  # noqa: PLW1509

    def forward(signum: int, _frame: object) -> None:
        server.send_signal(signum)

    for signum in FORWARDED:
        signal.signal(signum, forward)
    while True:
        if os.getppid() != parent:  # checked first too: it may have died before the handlers
            code = _stop(server)
            break
        try:
            code = server.wait(timeout=PARENT_CHECK_S)
            break
        except subprocess.TimeoutExpired:
            pass
    if code < 0:  # killed by a signal: end the same way, so the parent sees that signal
        if -code in FORWARDED:
            signal.signal(-code, signal.SIG_DFL)
        os.kill(os.getpid(), -code)
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
