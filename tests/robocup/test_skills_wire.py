"""elevens' definition of the skills proxy's messages: it loads, it reads what the proxy writes
(skipping what it does not use), and every message and field it declares is the proxy's own
(checked against the proxy's IDL when that is beside the project)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import thriftpy2
from thriftpy2.protocol import TBinaryProtocol
from thriftpy2.transport import TMemoryBuffer

from elevens.robocup.skills import wire
from tests.robocup.fake_proxy import FAKE, Scene, state

_IDL_BESIDE = (
    Path(__file__).resolve().parents[2].parent
    / "ext/soccer-simulation-proxy/idl/thrift/soccer_service.thrift"
)


def _proxy_idl() -> Path | None:
    given = os.environ.get("ELEVENS_PROXY_IDL")
    path = Path(given) if given else _IDL_BESIDE
    return path if path.is_file() else None


def _encode(message: object) -> bytes:
    buf = TMemoryBuffer()
    message.write(TBinaryProtocol(buf))  # type: ignore[attr-defined]
    return buf.getvalue()


def test_reads_what_the_proxy_writes_and_skips_the_rest() -> None:
    m = wire.protocol()
    sent = state(Scene(ball=(38.0, 4.0), kickable=9, cycle=17), 9)
    data = _encode(sent)
    got = m.State()
    got.read(TBinaryProtocol(TMemoryBuffer(data)))
    wm = got.world_model
    assert wm.cycle == 17 and wm.game_mode_type == m.GameModeType.PlayOn
    assert wm.myself.uniform_number == 9 and wm.myself.is_kickable
    assert (wm.ball.position.x, wm.ball.position.y) == (38.0, 4.0)
    assert sorted(p.uniform_number for p in wm.teammates) == [k for k in range(1, 12) if k != 9]
    assert len(wm.opponents) == 11 and wm.opponents[0].side == m.Side.RIGHT
    # What elevens does not declare was skipped, not kept: re-encoding is much smaller.
    assert not hasattr(got, "full_world_model")
    assert len(_encode(got)) < len(data) / 2


def test_accelerated_protocol_when_available() -> None:
    try:
        from thriftpy2.protocol import cybin  # noqa: F401
    except ImportError:
        pytest.skip("thriftpy2 was built without its Cython extensions")
    assert wire.accelerated()


def test_a_changed_field_is_reported(tmp_path: Path) -> None:
    """The check against the proxy's IDL can fail: a definition whose field differs in type,
    a field the other lacks and a method it lacks are each named."""
    text = wire.DEFINITION.read_text()
    edited = (
        text.replace("29: double stamina,", "29: i32 stamina,")
        .replace("struct Empty {}", "struct Empty {\n  7: bool extra\n}")
        .replace("service Game {", "service Game {\n  Empty Unknown(1: Empty e),")
        .replace("PlayOn = 2,", "PlayOn = 3,")
    )
    assert edited != text
    path = tmp_path / "edited_thrift.thrift"
    path.write_text(edited)
    ours = thriftpy2.load(str(path), module_name="edited_thrift")
    problems = wire.spec_mismatches(ours, wire.protocol())
    joined = "\n".join(problems)
    assert "Self.stamina: ours is 29: i32 stamina, the proxy's is 29: double stamina" in joined
    assert "Empty.extra: id 7 not in the proxy's definition" in joined
    assert "Game.Unknown: not in the proxy's service" in joined
    assert "enum GameModeType.PlayOn: ours is = 3, the proxy's is = 2" in joined
    assert wire.spec_mismatches(wire.protocol(), wire.protocol()) == []


@pytest.mark.skipif(
    _proxy_idl() is None,
    reason="the proxy's IDL is not beside the project: clone CLSFramework/soccer-simulation-"
    "proxy into ../ext/ or set ELEVENS_PROXY_IDL to its idl/thrift/soccer_service.thrift",
)
def test_every_message_is_the_proxys_own() -> None:
    theirs = thriftpy2.load(str(_proxy_idl()), module_name="proxy_idl_thrift")
    assert wire.spec_mismatches(wire.protocol(), theirs) == []
    # The fake proxy's richer States (what the tests send) are the proxy's too.
    assert wire.spec_mismatches(FAKE, theirs) == []
