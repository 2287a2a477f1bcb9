"""Find, start and stop rcssserver processes for training.

Each :class:`ServerProcess` runs one ``rcssserver`` (19.x) on its own triple of UDP ports
with :data:`TRAINING_OPTIONS` (synchronous mode, trainer plus referees, no logs, no half
time, no fouls, no drop-ball timer). It writes its configuration files into a private
temporary directory (``RCSS_CONF_DIR``, never ``~/.rcssserver``), runs there (so any
file the server creates stays there) and sends its stdout/stderr to a log file whose
last lines are quoted when the server dies.

The server binds its ports on all interfaces (rcssserver has no option to choose the
address). ``elevens robocup play|train|bench`` therefore run in a private network namespace
where the platform allows it (``elevens.robocup.isolation``); code that starts servers itself
should run inside a network namespace or a container without a network.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

__all__ = [
    "ENV_VAR",
    "INSTALL_HINT",
    "TRAINING_OPTIONS",
    "RcssserverNotFound",
    "ServerAddress",
    "ServerProcess",
    "find_rcssserver",
    "free_port_triple",
]

#: Environment variable that names the rcssserver binary.
ENV_VAR = "ELEVENS_RCSSSERVER"

INSTALL_HINT = (
    "Install rcssserver 19 from the RoboCup Soccer Simulator project, "
    "https://github.com/rcsoccersim/rcssserver:\n"
    "  sudo apt-get install build-essential cmake flex bison libboost-system-dev zlib1g-dev\n"
    "  git clone https://github.com/rcsoccersim/rcssserver && cd rcssserver\n"
    "  cmake -B build && cmake --build build && sudo cmake --install build\n"
    f"then put `rcssserver` on PATH, set {ENV_VAR}=/path/to/rcssserver, or pass the path "
    "explicitly (--rcssserver; --server.rcssserver for elevens robocup train)."
)

#: Server options for training (rcssserver 19.0.0 names, each checked against the
#: ``server.conf`` it writes; an unknown name makes the server exit with a usage text).
#: Why each is needed is said beside it.
TRAINING_OPTIONS: dict[str, str] = {
    # One simulation step per round of (done)s instead of 100 ms wall-clock cycles.
    "server::synch_mode": "true",
    # The offline trainer AND the referees (coach=true alone deletes all referees:
    # no goals, no out-of-bounds).
    "server::coach_w_referee": "true",
    "server::coach": "false",
    # auto_mode kicks off by itself and exits the server after the game ends.
    "server::auto_mode": "false",
    # No log files (they grow by MBs a minute and cost server CPU).
    "server::game_logging": "false",
    "server::text_logging": "false",
    "server::keepaway_logging": "false",
    "server::record_messages": "false",
    "server::profile": "false",
    "server::log_times": "false",
    # Negative half_time disables time keeping: no half time, no time_over.
    "server::half_time": "-1",
    "server::nr_extra_halfs": "0",
    "server::penalty_shoot_outs": "false",
    "server::golden_goal": "false",
    # No fouls, so no cards: a red card disables a player for the rest of the run.
    "server::foul_detect_probability": "0",
    "server::red_card_probability": "0",
    # No drop ball for a stuck ball or an untaken set piece.
    "server::drop_ball_time": "0",
    # No results saved to a CSV database.
    "CSVSaver::save": "false",
}

# Ports for servers come from below Linux's ephemeral range (32768-60999), so they never
# collide with the clients' own sockets.
_PORT_LOW, _PORT_HIGH = 20000, 32000
_handed_out: set[int] = set()


class RcssserverNotFound(FileNotFoundError):  # noqa: N818 - the name the interface promises
    """The rcssserver binary was not found; the message says where we looked and how to
    install it."""


def _executable(path: str) -> bool:
    return os.path.isfile(path) and os.access(path, os.X_OK)


def find_rcssserver(path: str | os.PathLike[str] | None = None) -> str:
    """Return the absolute path of the rcssserver binary.

    Looks at ``path`` (a file path or a command name) if given, else at
    ``$ELEVENS_RCSSSERVER``, else for ``rcssserver`` on ``PATH``. A given path or
    environment value that is not an executable raises instead of falling back, so a
    typo is not silently replaced by another binary. Raises :class:`RcssserverNotFound`.
    """
    looked: list[str] = []
    if path is not None:
        candidate = os.fspath(path)
        source = f"the given path {candidate!r}"
    elif os.environ.get(ENV_VAR):
        candidate = os.environ[ENV_VAR]
        source = f"${ENV_VAR}={candidate!r}"
    else:
        candidate = None
        source = ""
    if candidate is not None:
        if os.sep in candidate or (os.altsep and os.altsep in candidate):
            if _executable(candidate):
                return os.path.abspath(candidate)
            looked.append(f"{source} (not an executable file)")
        else:
            found = shutil.which(candidate)
            if found:
                return os.path.abspath(found)
            looked.append(f"{source} (no such command on PATH)")
    else:
        found = shutil.which("rcssserver")
        if found:
            return os.path.abspath(found)
        looked.append(f"`rcssserver` on PATH ({os.environ.get('PATH', '')!r})")
        looked.append(f"${ENV_VAR} (not set)")
    raise RcssserverNotFound(
        "rcssserver was not found: looked at " + "; ".join(looked) + ".\n" + INSTALL_HINT
    )


@dataclass(frozen=True)
class ServerAddress:
    """Where one rcssserver listens: players on ``port``, the offline trainer on
    ``coach_port``, online coaches on ``olcoach_port`` (defaults 6000/6001/6002)."""

    port: int
    coach_port: int
    olcoach_port: int
    host: str = "127.0.0.1"

    def __post_init__(self) -> None:
        for name in ("port", "coach_port", "olcoach_port"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 65535:
                raise ValueError(f"{name} {value!r} must be an int in [1, 65535]")

    @classmethod
    def from_port(cls, port: int, host: str = "127.0.0.1") -> ServerAddress:
        """The server's convention: players on ``port``, coaches on the next two."""
        return cls(port, port + 1, port + 2, host)


def _port_free(port: int) -> bool:
    # The server binds INADDR_ANY, so test that (it also fails if 127.0.0.1:port is taken).
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def free_port_triple(attempts: int = 200) -> ServerAddress:
    """Three free consecutive UDP ports on 127.0.0.1 (players, trainer, online coach).

    Ports are drawn at random below the ephemeral range and never handed out twice by
    this process, so servers started side by side do not collide. There is a short
    race with other processes until the server binds them; :class:`ServerProcess`
    retries with a new triple if its server cannot bind.
    """
    rng = random.Random()
    for _ in range(attempts):
        base = rng.randrange(_PORT_LOW, _PORT_HIGH - 3)
        ports = (base, base + 1, base + 2)
        if any(p in _handed_out for p in ports):
            continue
        if all(_port_free(p) for p in ports):
            _handed_out.update(ports)
            return ServerAddress(*ports)
    raise RuntimeError(
        f"found no 3 free consecutive UDP ports in [{_PORT_LOW}, {_PORT_HIGH}) "
        f"after {attempts} attempts"
    )


def _udp_port_bound(port: int) -> bool | None:
    """Whether some socket is bound to UDP ``port`` (from /proc; None if unknown).

    Read-only on purpose: a bind probe could steal the port from a server starting up.
    """
    suffix = f":{port:04X}"
    seen_file = False
    for name in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(name) as f:
                seen_file = True
                next(f, None)
                for line in f:
                    fields = line.split(None, 2)
                    if len(fields) > 1 and fields[1].endswith(suffix):
                        return True
        except OSError:
            continue
    return False if seen_file else None


def _option_text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    text = str(value)
    if any(c.isspace() for c in text):
        raise ValueError(f"server option value {value!r} must not contain whitespace")
    return text


def _option_name(name: str) -> str:
    full = name if "::" in name else f"server::{name}"
    module, _, key = full.partition("::")
    if not module.isidentifier() or not key or not all(c.isalnum() or c == "_" for c in key):
        raise ValueError(
            f"server option name {name!r} must look like NAME or MODULE::NAME "
            "(e.g. 'half_time', 'server::half_time', 'player::random_seed')"
        )
    return full


def _kill(proc: subprocess.Popen[bytes], workdir: str | None) -> None:
    """Stop ``proc`` (SIGTERM, then SIGKILL) and remove its work directory."""
    if proc.poll() is None:
        with contextlib.suppress(OSError):
            proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=3.0)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(OSError):
                proc.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=3.0)
    if workdir is not None:
        shutil.rmtree(workdir, ignore_errors=True)


class ServerProcess:
    """One rcssserver process on a private port triple, as a context manager.

    ``options`` override :data:`TRAINING_OPTIONS` (names with or without ``server::``;
    ``player::`` and ``CSVSaver::`` names must be given in full); the ports always come
    from ``address`` (a free triple when None). ``log_path`` None puts the log in the
    server's temporary directory (removed by :meth:`stop`); give a path to keep it
    (appended to across restarts). :meth:`restart` keeps the address, so clients can
    reconnect to the same ports.
    """

    def __init__(
        self,
        binary: str | os.PathLike[str] | None = None,
        *,
        address: ServerAddress | None = None,
        options: Mapping[str, object] | None = None,
        log_path: str | os.PathLike[str] | None = None,
        startup_timeout_s: float = 10.0,
    ) -> None:
        self.binary = find_rcssserver(binary)
        self._fixed_address = address is not None
        self._address = address
        self._overrides = {_option_name(k): _option_text(v) for k, v in (options or {}).items()}
        for port_name in ("server::port", "server::coach_port", "server::olcoach_port"):
            if port_name in self._overrides:
                raise ValueError(f"give ports through address=ServerAddress(...), not {port_name}")
        self._log_path = Path(log_path) if log_path is not None else None
        if startup_timeout_s <= 0:
            raise ValueError(f"startup_timeout_s {startup_timeout_s!r} must be > 0")
        self.startup_timeout_s = float(startup_timeout_s)
        self._proc: subprocess.Popen[bytes] | None = None
        self._workdir: str | None = None
        self._finalizer: weakref.finalize | None = None
        self.starts = 0
        self.last_log_tail = ""

    # -- properties ---------------------------------------------------------------

    @property
    def address(self) -> ServerAddress:
        """The ports this server uses (chosen at the first start when not given)."""
        if self._address is None:
            raise RuntimeError("the server has no address yet: call start() first")
        return self._address

    @property
    def options(self) -> dict[str, str]:
        """Every ``MODULE::NAME -> value`` passed on the command line (ports included
        once an address is known)."""
        opts = dict(TRAINING_OPTIONS)
        opts.update(self._overrides)
        if self._address is not None:
            opts["server::port"] = str(self._address.port)
            opts["server::coach_port"] = str(self._address.coach_port)
            opts["server::olcoach_port"] = str(self._address.olcoach_port)
        return opts

    @property
    def alive(self) -> bool:
        """True while the process runs."""
        return self._proc is not None and self._proc.poll() is None

    @property
    def pid(self) -> int | None:
        """The process to signal: the guard that runs the server, passes SIGTERM, SIGINT and
        SIGHUP on to it, and takes it along when it dies (``server_guard``)."""
        return self._proc.pid if self._proc is not None else None

    @property
    def returncode(self) -> int | None:
        """Exit status once the process has ended (negative: killed by that signal)."""
        return self._proc.poll() if self._proc is not None else None

    @property
    def log_path(self) -> Path | None:
        """The file holding the server's stdout and stderr (None before start)."""
        if self._log_path is not None:
            return self._log_path
        if self._workdir is not None:
            return Path(self._workdir) / "rcssserver.log"
        return None

    @property
    def workdir(self) -> Path | None:
        """The temporary directory the server runs in (its RCSS_CONF_DIR is inside)."""
        return Path(self._workdir) if self._workdir is not None else None

    # -- lifecycle ----------------------------------------------------------------

    def start(self) -> ServerProcess:
        """Start the server and wait until its player port is bound.

        Raises RuntimeError with the log's last lines if it exits or does not bind
        within ``startup_timeout_s`` (e.g. an unknown option or a port in use).
        """
        if self.alive:
            raise RuntimeError(f"rcssserver (pid {self.pid}) is already running")
        attempts = 1 if self._fixed_address else 3
        for attempt in range(attempts):
            if self._address is None or (attempt > 0 and not self._fixed_address):
                self._address = free_port_triple()
            try:
                self._start_once()
                return self
            except _BindError:
                if attempt == attempts - 1:
                    raise RuntimeError(
                        f"rcssserver could not bind ports {self._address}:\n{self.last_log_tail}"
                    ) from None
        return self  # unreachable

    def _start_once(self) -> None:
        self._cleanup()
        self._workdir = tempfile.mkdtemp(prefix="elevens-rcss-")
        conf_dir = Path(self._workdir) / "conf"
        conf_dir.mkdir()
        log_path = self.log_path
        assert log_path is not None
        log_path.parent.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        env["RCSS_CONF_DIR"] = str(conf_dir)
        # The server expands "~" from $USER (a literal ./~ directory when unset); keep
        # whatever it does inside the work directory.
        env.setdefault("USER", "elevens")
        # Through the guard (server_guard.py): the server stops when this process dies, even
        # by SIGKILL. ``pid`` and signals then go to the guard, which passes them on.
        guard = [sys.executable, "-I", "-S", str(Path(__file__).with_name("server_guard.py"))]
        args = [*guard, str(os.getpid()), self.binary]
        args += [f"{k}={v}" for k, v in self.options.items()]
        with open(log_path, "ab") as log:
            self._proc = subprocess.Popen(
                args,
                cwd=self._workdir,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        self._finalizer = weakref.finalize(self, _kill, self._proc, self._workdir)
        self.starts += 1
        self._wait_ready()

    def _wait_ready(self) -> None:
        assert self._proc is not None and self._address is not None
        deadline = time.monotonic() + self.startup_timeout_s
        port = self._address.port
        while True:
            if self._proc.poll() is not None:
                self.last_log_tail = self.log_problems()
                code = self._proc.returncode
                self._cleanup()
                if "address already in use" in self.last_log_tail.lower():
                    raise _BindError
                raise RuntimeError(
                    f"rcssserver exited with status {code} while starting "
                    f"({self.binary}):\n{self.last_log_tail}"
                )
            bound = _udp_port_bound(port)
            if bound is None:  # no /proc: give it a moment
                time.sleep(0.3)
                if self._proc.poll() is None:
                    return
                continue
            if bound:
                # Bound; give it a moment to reach its loop, then confirm it still runs.
                time.sleep(0.02)
                if self._proc.poll() is None:
                    return
                continue
            if time.monotonic() > deadline:
                self.last_log_tail = self.log_problems()
                self._cleanup()
                raise RuntimeError(
                    f"rcssserver did not bind UDP port {port} within "
                    f"{self.startup_timeout_s:g} s:\n{self.last_log_tail}"
                )
            time.sleep(0.01)

    def stop(self) -> None:
        """Stop the process (SIGTERM, then SIGKILL) and remove its temporary directory.
        Idempotent."""
        if self._proc is not None:
            self.last_log_tail = self.log_problems()
        self._cleanup()

    def _cleanup(self) -> None:
        if self._finalizer is not None:
            self._finalizer()  # kills the process and removes the work directory
            self._finalizer = None
        elif self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
        self._proc = None
        self._workdir = None

    def restart(self) -> ServerProcess:
        """Stop (if running) and start again on the same ports."""
        self.stop()
        self._fixed_address = self._address is not None or self._fixed_address
        return self.start()

    def log_problems(self, tail: int = 10) -> str:
        """The log's error lines (first 5) followed by its last ``tail`` lines: what a
        failure message should quote (rcssserver prints option errors before a long
        usage text)."""
        path = self.log_path
        errors: list[str] = []
        if path is not None and path.exists():
            with contextlib.suppress(OSError), open(path, "rb") as f:
                for raw in f:
                    line = raw.decode("utf-8", "replace").rstrip()
                    low = line.lower()
                    if "error" in low or "exiting" in low or "missed a cycle" in low:
                        errors.append(line)
        head = "\n".join(errors[:5])
        rest = self.log_tail(tail)
        return f"{head}\n...\n{rest}" if head else rest

    def log_tail(self, lines: int = 20) -> str:
        """The last ``lines`` lines of the server log ('' if there is none)."""
        path = self.log_path
        if path is None or not path.exists():
            return self.last_log_tail
        try:
            with open(path, "rb") as f:
                f.seek(0, os.SEEK_END)
                size = f.tell()
                f.seek(max(0, size - 16384))
                text = f.read().decode("utf-8", "replace")
        except OSError:
            return self.last_log_tail
        return "\n".join(text.splitlines()[-lines:])

    def __enter__(self) -> ServerProcess:
        if not self.alive:
            self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = f"pid {self.pid}" if self.alive else "stopped"
        return f"ServerProcess({self._address}, {state})"


class _BindError(Exception):
    """The server exited because it could not bind its ports (retry with others)."""
