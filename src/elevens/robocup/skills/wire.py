"""The proxy's wire format, from elevens' own definition (``proxy.thrift`` beside this module).

:func:`protocol` loads it with thriftpy2 once per process; its structs are plain Python classes
(``protocol().State``, ``protocol().PlayerActions``, ...). :func:`protocol_factory` is the
binary protocol, the Cython one when thriftpy2 was built with it (the same bytes, about ten
times faster on a 20 KB State); :func:`transport_factory` is the buffered (unframed) socket
transport the proxy's Thrift client uses.
"""

from __future__ import annotations

import functools
from pathlib import Path
from types import ModuleType
from typing import Any

import thriftpy2
from thriftpy2 import protocol as _protocol
from thriftpy2 import transport as _transport
from thriftpy2.thrift import TType

__all__ = [
    "DEFINITION",
    "accelerated",
    "protocol",
    "protocol_factory",
    "spec_mismatches",
    "transport_factory",
]

#: elevens' definition of the messages, shipped with the package.
DEFINITION = Path(__file__).with_name("proxy.thrift")


@functools.cache
def protocol() -> ModuleType:
    """The loaded definition (structs, enums and the ``Game`` service)."""
    return thriftpy2.load(str(DEFINITION), module_name="elevens_proxy_thrift")


def accelerated() -> bool:
    """Whether thriftpy2's Cython binary protocol is in use."""
    return _protocol.TBinaryProtocolFactory is not _protocol.binary.TBinaryProtocolFactory


def protocol_factory() -> Any:
    # thriftpy2 exports the Cython factory under the plain name when it has it.
    return _protocol.TBinaryProtocolFactory()


#: Bytes a connection asks its socket for at once: a whole State (the proxy's are 15 to 30 KB)
#: in one read instead of thriftpy2's 4 KB steps, each a system call that gives the GIL up
#: and waits to take it back from the threads deciding.
READ_BUFFER = 1 << 16


class _BufferedTransportFactory:
    def get_transport(self, trans: Any) -> Any:
        return _transport.TBufferedTransport(trans, READ_BUFFER)


def transport_factory() -> Any:
    return _BufferedTransportFactory()


def _type_name(ttype: int, arg: Any) -> str:
    """A field's wire type as text: the Thrift type, with the struct's name and the element
    types of containers (enums are i32 on the wire)."""
    names = {v: k for k, v in vars(TType).items() if not k.startswith("_") and isinstance(v, int)}
    name = names.get(ttype, str(ttype)).lower()
    if ttype == TType.STRUCT:
        return f"struct {arg.__name__}"
    if ttype in (TType.LIST, TType.SET):
        elem = arg if isinstance(arg, tuple) else (arg, None)
        return f"{name}<{_type_name(elem[0], elem[1])}>"
    if ttype == TType.MAP:
        key, value = arg
        key = key if isinstance(key, tuple) else (key, None)
        value = value if isinstance(value, tuple) else (value, None)
        return f"map<{_type_name(*key)},{_type_name(*value)}>"
    return name


def _fields(struct: Any) -> dict[int, tuple[str, str]]:
    out = {}
    for fid, spec in struct.thrift_spec.items():
        ttype, name = spec[0], spec[1]
        arg = spec[2] if len(spec) == 4 else None
        out[fid] = (name, _type_name(ttype, arg))
    return out


def spec_mismatches(ours: ModuleType, theirs: ModuleType) -> list[str]:
    """Every struct, field, enum value and service method of ``ours`` that ``theirs`` lacks or
    declares with another id, name, wire type or value (an empty list: ours is a subset of
    theirs). Structs and enums are matched by name, fields by id, enum members by name (an
    enum is an i32 on the wire: its numbers are the protocol); a method's arguments and result
    are compared as structs."""
    problems: list[str] = []
    seen: set[str] = set()

    def compare(ours_struct: type, theirs_struct: type | None, label: str) -> None:
        if label in seen:
            return
        seen.add(label)
        if theirs_struct is None:
            problems.append(f"{label}: not in the proxy's definition")
            return
        theirs_fields = _fields(theirs_struct)
        for fid, (name, type_name) in sorted(_fields(ours_struct).items()):
            if fid not in theirs_fields:
                problems.append(f"{label}.{name}: id {fid} not in the proxy's definition")
            elif theirs_fields[fid] != (name, type_name):
                other = theirs_fields[fid]
                problems.append(
                    f"{label}.{name}: ours is {fid}: {type_name} {name}, "
                    f"the proxy's is {fid}: {other[1]} {other[0]}"
                )

    for name, value in sorted(vars(ours).items()):
        if isinstance(value, type) and hasattr(value, "thrift_spec") and name != "Game":
            compare(value, getattr(theirs, name, None), name)
        elif isinstance(value, type) and hasattr(value, "_NAMES_TO_VALUES"):
            other = getattr(getattr(theirs, name, None), "_NAMES_TO_VALUES", None)
            if other is None:
                problems.append(f"enum {name}: not in the proxy's definition")
                continue
            for member, number in sorted(value._NAMES_TO_VALUES.items()):
                if other.get(member) != number:
                    found = "absent" if member not in other else f"= {other[member]}"
                    problems.append(
                        f"enum {name}.{member}: ours is = {number}, the proxy's is {found}"
                    )
    ours_service, theirs_service = ours.Game, getattr(theirs, "Game", None)
    for method in ours_service.thrift_services:
        if theirs_service is None or method not in theirs_service.thrift_services:
            problems.append(f"Game.{method}: not in the proxy's service")
            continue
        for part in ("_args", "_result"):
            compare(
                getattr(ours_service, method + part),
                getattr(theirs_service, method + part),
                f"Game.{method}{part}",
            )
    return problems
