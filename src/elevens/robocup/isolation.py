"""Keep rcssserver off the network: run the command that starts it in a private network
namespace.

rcssserver binds its UDP ports on every interface and has no option to choose the address, so a
server started on a machine with a network is reachable from it. ``elevens robocup
play|train|bench`` therefore re-execute themselves, at their start, under ``unshare --user
--map-root-user --net``: the process (and every server and client it starts) then has a network
of its own that holds only the loopback interface, which this module brings up. No privilege is
needed where unprivileged user namespaces are allowed (most Linux distributions). Where they
are not, or ``unshare`` is missing, the command runs as before with a warning: its clients talk
over 127.0.0.1 only, but the server's ports are open.

``elevens robocup serve`` is not isolated: its servers are there for other programs to use.
``ELEVENS_NETWORK_ISOLATION=0`` turns the isolation off (for example to watch a match with a
monitor from outside).
"""

from __future__ import annotations

import fcntl
import os
import shutil
import socket
import struct
import subprocess
import sys
import warnings
from collections.abc import Sequence

MARKER = "ELEVENS_PRIVATE_NETWORK"
"""Set in the re-executed command: it is inside its private namespace."""
SWITCH = "ELEVENS_NETWORK_ISOLATION"
"""``0`` turns the isolation off."""

_UNSHARE_ARGS = ("--user", "--map-root-user", "--net")
_SIOCGIFFLAGS = 0x8913
_SIOCSIFFLAGS = 0x8914
_IFF_UP = 0x1


class IsolationUnavailableError(RuntimeError):
    """This platform cannot give the command a private network namespace."""


def isolated_command(argv: Sequence[str]) -> list[str]:
    """``argv`` run in a new user and network namespace (``unshare``), or
    ``IsolationUnavailableError`` saying why that is not possible here."""
    unshare = shutil.which("unshare")
    if unshare is None:
        raise IsolationUnavailableError("the unshare program (util-linux) is not installed")
    probe = subprocess.run(
        [unshare, *_UNSHARE_ARGS, "true"], capture_output=True, text=True, timeout=30
    )
    if probe.returncode != 0:
        reason = probe.stderr.strip().splitlines()[-1] if probe.stderr.strip() else ""
        raise IsolationUnavailableError(
            f"unshare {' '.join(_UNSHARE_ARGS)} failed ({reason or probe.returncode}): "
            "unprivileged user namespaces are not allowed here"
        )
    return [unshare, *_UNSHARE_ARGS, *argv]


def loopback_up() -> None:
    """Bring up ``lo`` (a new network namespace starts with it down)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        request = struct.pack("16sh", b"lo", 0)
        flags = struct.unpack("16sh", fcntl.ioctl(sock, _SIOCGIFFLAGS, request))[1]
        if not flags & _IFF_UP:
            fcntl.ioctl(sock, _SIOCSIFFLAGS, struct.pack("16sh", b"lo", flags | _IFF_UP))


def enter_private_network(command: str) -> None:
    """Re-execute this process (the same interpreter and arguments) in a private network
    namespace, once; inside it, bring up the loopback interface. Where that is not possible,
    warn and go on. ``command`` names the command in the warning."""
    if os.environ.get(MARKER) == "1":
        loopback_up()
        return
    if os.environ.get(SWITCH, "1") == "0":
        return
    argv = [sys.executable, *sys.orig_argv[1:]]
    try:
        isolated = isolated_command(argv)
    except (IsolationUnavailableError, OSError, subprocess.SubprocessError) as error:
        warnings.warn(
            f"{command}: rcssserver runs without a private network namespace ({error}); it "
            "listens on every interface, so its ports are reachable from the network while it "
            "runs (the clients use 127.0.0.1 only); run it in a container without a network "
            "to keep it private",
            stacklevel=2,
        )
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os.environ[MARKER] = "1"
    # exec: the same process (pid, signals, exit status) goes on inside the namespace.
    os.execv(isolated[0], isolated)
