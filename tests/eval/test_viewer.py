"""The web viewer: the server's routes and limits, and the page in a real headless browser.

The browser test drives Debian's chromium with Playwright (``pip install playwright``,
``apt-get install chromium``; ``playwright install`` is not needed). Without either it is skipped
with a message saying what is missing.
"""

from __future__ import annotations

import http.client
import importlib.util
import json
import shutil
import socket
from pathlib import Path

import jax
import numpy as np
import pytest
from PIL import Image

import elevens
from elevens.env.observe import observe
from elevens.env.render import visible_entities
from elevens.eval.match import play_match
from elevens.eval.replay import replay_from_match, replay_to_json
from elevens.eval.viewer import HOST, ReplayServer, static_bytes
from elevens.teams.scripted import NaiveTeam, TeamworkTeam

CHROMIUM_PATHS = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run",
]


@pytest.fixture(scope="module")
def replays():
    env, params = elevens.make("3v3", episode_length=60)
    result = jax.device_get(play_match(env, params, NaiveTeam(), TeamworkTeam(),
                                       jax.random.key(2), 2, record=True))
    return [replay_from_match(result, params, game, "naive", "teamwork") for game in (0, 1)]


def _get(port: int, path: str, method: str = "GET", host: str | None = None):
    connection = http.client.HTTPConnection(HOST, port, timeout=5)
    try:
        headers = {} if host is None else {"Host": host}
        connection.request(method, path, headers=headers)
        response = connection.getresponse()
        return response.status, dict(response.getheaders()), response.read()
    finally:
        connection.close()


def test_server_routes_limits_and_clean_stop(replays) -> None:
    server = ReplayServer(replays, ["a.npz", "b.npz"], port=0)
    assert server._server.server_address[0] == "127.0.0.1"  # loopback only
    with server:
        port = server.port
        assert server.url == f"http://127.0.0.1:{port}/"
        status, headers, body = _get(port, "/")
        assert status == 200 and headers["Content-Type"].startswith("text/html")
        assert body == static_bytes("index.html") and b"<canvas" in body
        assert _get(port, "/viewer.js")[2] == static_bytes("viewer.js")
        assert _get(port, "/viewer.css")[0] == 200
        listing = json.loads(_get(port, "/replays/index.json")[2])
        assert [item["name"] for item in listing["replays"]] == ["a.npz", "b.npz"]
        assert listing["replays"][1]["team_names"] == list(replays[1].team_names)
        served = json.loads(_get(port, "/replays/1.json?x=1")[2])
        assert served == json.loads(json.dumps(replay_to_json(replays[1], actions=False)))
        status, headers, body = _get(port, "/replays/0.json", method="HEAD")
        assert status == 200 and body == b"" and int(headers["Content-Length"]) > 1000
        for path in ("/replays/2.json", "/../../etc/passwd", "/viewer.py", "/replays/"):
            assert _get(port, path)[0] == 404
        assert _get(port, "/", method="POST")[0] == 501
        assert _get(port, "/", host="evil.example:80")[0] == 403  # DNS-rebinding guard
        assert _get(port, "/", host=f"localhost:{port}")[0] == 200
    # Stopped: the port is released and nothing answers.
    with pytest.raises(OSError), socket.create_connection((HOST, port), timeout=1):
        pass
    server.stop()  # twice is fine


def _browser_or_skip():
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("playwright is not installed (pip install playwright); browser test skipped")
    executable = next((p for p in CHROMIUM_PATHS if Path(p).exists()), None)
    executable = executable or shutil.which("chromium")
    if executable is None:
        pytest.skip("no chromium found (apt-get install chromium); browser test skipped")
    return executable


def test_page_plays_a_replay_and_selects_a_player(replays) -> None:
    executable = _browser_or_skip()
    from playwright.sync_api import sync_playwright

    replay = replays[1]
    errors: list[str] = []
    with ReplayServer(replays, ["a.npz", "b.npz"]) as server, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1100, "height": 850})
            page.on("pageerror", lambda error: errors.append(str(error)))
            page.goto(server.url + "#replay=1")
            page.wait_for_function("window.viewerState && window.viewerState.ready",
                                   timeout=15_000)
            assert page.evaluate("viewerState.replayIndex") == 1
            assert page.evaluate("viewerState.numFrames") == 60
            assert page.inner_text("#team0") == replay.team_names[0]

            # It plays by itself: the frame, the canvas attribute and the clock advance.
            page.wait_for_function("viewerState.frame >= 10", timeout=15_000)
            assert page.evaluate("viewerState.playing") is True
            assert int(page.get_attribute("#pitch", "data-frame")) >= 10
            assert "step" in page.inner_text("#clock")

            # Pause with the button, go to a frame with the scrubber.
            page.click("#play")
            assert page.evaluate("viewerState.playing") is False
            page.locator("#scrubber").fill("30")
            assert page.evaluate("viewerState.frame") == 30
            frame_30 = page.evaluate("viewerState.frame")

            # A real mouse click on player 4 (team 1, player 1) selects it.
            point = page.evaluate("viewerApi.playerClientPosition(4)")
            page.mouse.click(point["x"], point["y"])
            assert page.evaluate("viewerState.selected") == 4
            assert page.get_attribute("#pitch", "data-selected") == "4"
            assert "row 4" in page.inner_text("#info")

            # What the page says each player sees is what the env's observation masks say.
            state = jax.tree.map(lambda leaf: leaf[frame_30], replay.states())
            mask = np.asarray(observe(state, replay.params).entity_mask)
            for row in range(6):
                page.evaluate(f"viewerApi.select({row})")
                seen = visible_entities(mask, replay.params, row)
                assert page.evaluate("viewerState.visible") == [
                    int(j) for j in np.flatnonzero(seen[:-1])
                ], f"player {row}"
                assert page.evaluate("viewerState.ballVisible") == bool(seen[-1])

            # Clicking the grass far from everyone deselects; the last frame shows full time.
            gaps = np.linalg.norm(replay.positions[frame_30] - [-49.5, 34.5], axis=-1)
            assert gaps.min() > 3.0
            corner = page.evaluate("viewerApi.worldToClient(-49.5, 34.5)")
            page.mouse.click(corner["x"], corner["y"])
            assert page.evaluate("viewerState.selected") is None
            page.evaluate("viewerApi.seek(59)")
            assert "full time" in page.inner_text("#clock")
            assert page.inner_text("#score") == "{} : {}".format(*replay.final_score)
        finally:
            browser.close()
    assert errors == []


def test_a_folder_lists_every_replay_under_it(replays, tmp_path) -> None:
    from elevens.eval.replay import ReplayError, save_replay
    from elevens.eval.viewer import replay_files

    save_replay(replays[0], tmp_path / "replays" / "naive" / "game_0000.npz")
    save_replay(replays[1], tmp_path / "replays" / "teamwork" / "game_0001.npz")
    np.savez(tmp_path / "networks.npz", w=np.zeros(3))  # an .npz that is not a replay
    single = tmp_path / "single.npz"
    save_replay(replays[0], single)
    found = replay_files([tmp_path / "replays", single])
    assert [p.relative_to(tmp_path).as_posix() for p in found] == [
        "replays/naive/game_0000.npz", "replays/teamwork/game_0001.npz", "single.npz"
    ]
    assert len(replay_files([tmp_path])) == 3  # networks.npz is left out
    (tmp_path / "empty").mkdir()
    with pytest.raises(ReplayError, match="no replay .* under this folder"):
        replay_files([tmp_path / "empty"])


@pytest.mark.parametrize("size", [(1280, 720), (1366, 768), (1920, 1080)])
def test_page_fits_the_window_and_the_keyboard_works_after_a_drag(
    replays, size, tmp_path
) -> None:
    executable = _browser_or_skip()
    from playwright.sync_api import sync_playwright

    width, height = size
    replay = replays[0]
    errors: list[str] = []
    with ReplayServer(replays, ["a.npz", "b.npz"]) as server, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.on("pageerror", lambda error: errors.append(str(error)))
            page.goto(server.url + "#replay=0")
            page.wait_for_function("window.viewerState && window.viewerState.ready",
                                   timeout=15_000)
            # Everything is in view at once: nothing below the fold, nothing scrolled away.
            for selector in ("#scoreboard", "#clock", "#pitch", "#controls", "#play"):
                box = page.locator(selector).bounding_box()
                assert box is not None, selector
                assert box["y"] >= 0 and box["y"] + box["height"] <= height + 0.5, selector
                assert box["x"] >= 0 and box["x"] + box["width"] <= width + 0.5, selector
            assert page.evaluate("document.scrollingElement.scrollHeight") <= height
            shot = tmp_path / f"viewer_{width}x{height}.png"
            page.screenshot(path=str(shot))
            with Image.open(shot) as image:
                assert image.size == (width, height)
            # A drag on the scrubber pauses; afterwards Space plays again, Home and End jump.
            box = page.locator("#scrubber").bounding_box()
            middle = box["y"] + box["height"] / 2
            page.mouse.move(box["x"] + 5, middle)
            page.mouse.down()
            page.mouse.move(box["x"] + box["width"] / 2, middle, steps=5)
            page.mouse.up()
            assert page.evaluate("viewerState.playing") is False
            dragged = page.evaluate("viewerState.frame")
            assert 15 <= dragged <= 45
            page.keyboard.press("Space")
            assert page.evaluate("viewerState.playing") is True
            page.keyboard.press("End")
            assert page.evaluate("viewerState.frame") == 59
            assert page.evaluate("viewerState.playing") is False
            page.keyboard.press("Home")
            assert page.evaluate("viewerState.frame") == 0
            # The frame box jumps to a frame.
            page.fill("#frame-box", "42")
            page.press("#frame-box", "Enter")
            assert page.evaluate("viewerState.frame") == 42
            # One mark on the timeline per goal, at the frame the score changes.
            goals = int(sum(replay.final_score))
            assert page.locator("#goal-marks span").count() == goals
            marked = page.evaluate("viewerState.goalFrames.map((g) => g.frame)")
            changes = np.flatnonzero(np.diff(np.vstack([replay.score, [replay.final_score]]),
                                             axis=0).sum(axis=1)) + 1
            assert marked == [min(int(f), 59) for f in changes]
        finally:
            browser.close()
    assert errors == []
