"""A local web viewer for replays (`elevens view`): a small HTTP server and a canvas page.

The server binds to the loopback interface only (127.0.0.1) and serves a fixed set of paths:

* ``/`` (``index.html``), ``/viewer.js``, ``/viewer.css``: the page, from the package's
  ``viewer_static/`` folder (no build step, nothing from the network);
* ``/replays/index.json``: ``{"replays": [{"index", "name", "team_names", "final_score",
  "steps", "players_per_team"}, ...]}``;
* ``/replays/<i>.json``: replay ``i`` as JSON (``elevens.eval.replay.replay_to_json``).

Everything served is built in memory when the server starts, so a request only copies bytes.
Request handling is bounded: HTTP/1.0 (one request per connection), GET and HEAD only, a socket
timeout per connection, at most ``MAX_CONNECTIONS`` served at once (more are closed at once), and
requests whose ``Host`` is not the loopback address are refused (DNS-rebinding guard).
``ReplayServer.stop`` shuts the server down and joins its thread.
"""

from __future__ import annotations

import http.server
import json
import threading
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

from elevens.eval.replay import Replay, ReplayError, load_replay, replay_to_json

HOST = "127.0.0.1"
STATIC_FILES = {
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
    "/viewer.css": ("viewer.css", "text/css; charset=utf-8"),
}
MAX_CONNECTIONS = 16
REQUEST_TIMEOUT_S = 10.0
_LOOPBACK_HOSTS = ("127.0.0.1", "localhost")


def static_bytes(name: str) -> bytes:
    """A file of the page (``index.html``, ``viewer.js``, ``viewer.css``) from the package."""
    return resources.files("elevens.eval").joinpath("viewer_static", name).read_bytes()


def build_routes(replays: Sequence[Replay], names: Sequence[str]) -> dict[str, tuple[bytes, str]]:
    """``{path: (body, content type)}`` of everything the server answers."""
    routes: dict[str, tuple[bytes, str]] = {}
    for path, (filename, content_type) in STATIC_FILES.items():
        routes[path] = (static_bytes(filename), content_type)
    routes["/"] = routes["/index.html"]
    listing = []
    for index, (replay, name) in enumerate(zip(replays, names, strict=True)):
        body = json.dumps(replay_to_json(replay, actions=False), separators=(",", ":"))
        routes[f"/replays/{index}.json"] = (body.encode("utf-8"), "application/json")
        listing.append({
            "index": index,
            "name": name,
            "team_names": list(replay.team_names),
            "final_score": list(replay.final_score),
            "steps": replay.num_steps,
            "players_per_team": replay.players_per_team,
        })
    routes["/replays/index.json"] = (
        json.dumps({"replays": listing}).encode("utf-8"), "application/json"
    )
    return routes


class _Handler(http.server.BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.0"  # one request per connection: nothing lingers
    timeout = REQUEST_TIMEOUT_S  # socket timeout: a slow or silent client cannot hold a thread
    server_version = "elevens-viewer"
    sys_version = ""

    def _host_allowed(self) -> bool:
        host = (self.headers.get("Host") or "").strip()
        if not host:
            return True  # HTTP/1.0 clients may omit it
        name = host.rsplit(":", 1)[0] if not host.startswith("[") else host
        return name in _LOOPBACK_HOSTS

    def _answer(self, send_body: bool) -> None:
        if not self._host_allowed():
            self.send_error(403, "only loopback hosts are served")
            return
        path = self.path.split("?", 1)[0].split("#", 1)[0]
        route = self.server.routes.get(path)
        if route is None:
            self.send_error(404, "not found")
            return
        body, content_type = route
        self.send_response(200)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if send_body:
            self.wfile.write(body)

    def do_GET(self) -> None:  # noqa: N802 - the name http.server dispatches to
        self._answer(send_body=True)

    def do_HEAD(self) -> None:  # noqa: N802
        self._answer(send_body=False)

    def log_message(self, format: str, *args: Any) -> None:
        if self.server.verbose:
            super().log_message(format, *args)


class _Server(http.server.ThreadingHTTPServer):
    daemon_threads = True  # a stuck client never keeps the process alive

    def __init__(self, address: tuple[str, int], routes: dict[str, tuple[bytes, str]],
                 verbose: bool) -> None:
        self.routes = routes
        self.verbose = verbose
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)
        super().__init__(address, _Handler)

    def process_request(self, request: Any, client_address: Any) -> None:
        if not self._slots.acquire(blocking=False):
            self.shutdown_request(request)  # too many at once: close, do not queue
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._slots.release()


class ReplayServer:
    """Serves the viewer page and replays on ``http://127.0.0.1:<port>/``.

    Example::

        with ReplayServer([load_replay("game.npz")], port=0) as server:
            print(server.url)   # the port is chosen by the OS when port=0
            ...

    ``start`` runs the server in a daemon thread; ``stop`` (or leaving the ``with``) shuts it
    down, closes the socket and joins the thread. ``serve_forever`` blocks instead (Ctrl-C ends).
    """

    def __init__(self, replays: Sequence[Replay], names: Sequence[str] | None = None, *,
                 port: int = 0, verbose: bool = False) -> None:
        if not 0 <= port <= 65535:
            raise ValueError(f"port={port} is invalid: it must be in 0..65535 (0: any free port)")
        labels = list(names) if names is not None else [f"replay {i}" for i in
                                                          range(len(replays))]
        if len(labels) != len(replays):
            raise ValueError("names and replays must have the same length")
        self._server = _Server((HOST, port), build_routes(replays, labels), verbose)
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return int(self._server.server_address[1])

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}/"

    def start(self) -> ReplayServer:
        if self._thread is not None:
            raise RuntimeError("the server is already running")
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.1},
            name="elevens-viewer", daemon=True,
        )
        self._thread.start()
        return self

    def serve_forever(self) -> None:
        try:
            self._server.serve_forever(poll_interval=0.2)
        finally:
            self._server.server_close()

    def stop(self) -> None:
        """Stop serving and release the port; safe to call twice."""
        if self._thread is not None:
            self._server.shutdown()
            self._thread.join(timeout=5)
            self._thread = None
        self._server.server_close()

    def __enter__(self) -> ReplayServer:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()


def replay_files(paths: Sequence[str | Path]) -> list[Path]:
    """The replay files ``paths`` name: files as they are, and for a folder (a run, an
    ``analyze --out`` folder) every ``*.npz`` under it that is a replay, sorted. A folder with
    none is a ``ReplayError``."""
    from elevens.eval.replay import SUFFIX

    files: list[Path] = []
    for path in map(Path, paths):
        if not path.is_dir():
            files.append(path)
            continue
        found = sorted(
            candidate for candidate in path.rglob(f"*{SUFFIX}")
            if candidate.is_file() and _is_replay(candidate)
        )
        if not found:
            raise ReplayError(
                f"{path}: no replay (.npz) under this folder; write some with elevens analyze "
                "--replays N or elevens play --replay FILE"
            )
        files.extend(found)
    if not files:
        raise ReplayError("no replay given: elevens view REPLAY.npz ... or a folder of them")
    return files


def _is_replay(path: Path) -> bool:
    """An .npz with a header array (a shipped team's networks.npz is not a replay)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as archive:
            return "header.npy" in archive.namelist()
    except (OSError, zipfile.BadZipFile):
        return True  # let load_replay name the problem


def _short_name(path: Path, given: Sequence[str | Path]) -> str:
    """The name shown for a replay: relative to the folder it was found under."""
    for root in map(Path, given):
        if root.is_dir() and path.is_relative_to(root):
            return str(path.relative_to(root))
    return path.name


def view(paths: Sequence[str | Path], port: int = 0, open_browser: bool = False) -> None:
    """`elevens view`: load the replays (a clear ``ReplayError`` if one is bad), print the URL
    and serve until Ctrl-C."""
    files = replay_files(paths)
    replays = [load_replay(path) for path in files]
    server = ReplayServer(replays, [_short_name(path, paths) for path in files], port=port)
    print(f"elevens viewer: {server.url}  ({len(replays)} replay(s); Ctrl-C stops)", flush=True)
    if open_browser:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped")
        raise  # the command exits 130, as every interrupted command does
