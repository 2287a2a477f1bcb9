"""The s-expression reader of the rcssserver protocol: tokenizer, tree builder with a nesting
limit, and the scalar helpers the message decoders share."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import TypeAlias

#: Deepest nesting accepted. Server messages nest at most 4 deep (sense_body ->
#: arm -> target); the limit only guards against hostile or corrupt input.
MAX_DEPTH = 32
#: Longest text accepted (the UDP payload limit); longer input is rejected unread.
MAX_MESSAGE_CHARS = 65536

Sexp: TypeAlias = str | tuple["Sexp", ...]
"""A parsed s-expression: an atom (``str``; quoted strings keep their quotes) or a
tuple of s-expressions."""


class ProtocolError(ValueError):
    """A server message that does not follow the rcssserver protocol.

    The message quotes the offending part (an excerpt around the error position or
    the offending sub-expression) and says what was expected.
    """


# --------------------------------------------------------------------------------------
# Tokenizer and tree builder
# --------------------------------------------------------------------------------------

# Only printable ASCII and ordinary whitespace may appear; one search per message.
_BAD_CHAR = re.compile(r"[^\t\n\r\x20-\x7e]")
_EXCERPT = 30


def _excerpt_at(text: str, pos: int) -> str:
    """Return ``text`` around ``pos`` with a ``<HERE>`` marker, shortened to ~60 chars."""
    lo = max(0, pos - _EXCERPT)
    hi = min(len(text), pos + _EXCERPT)
    pre = ("..." if lo > 0 else "") + text[lo:pos]
    post = text[pos:hi] + ("..." if hi < len(text) else "")
    return repr(pre + "<HERE>" + post)


def _excerpt(node: Sexp) -> str:
    """Return a short quoted rendering of a sub-expression for error messages."""
    text = sexp_to_text(node)
    if len(text) > 2 * _EXCERPT:
        text = text[: 2 * _EXCERPT] + "..."
    return repr(text)


def _locate_structure_error(text: str) -> tuple[int, str]:
    """Slow character scan that finds where a structurally bad text goes wrong.

    Only called after the fast path has failed, to point at the exact position.
    """
    depth = 0
    quote_start = -1
    for i, ch in enumerate(text):
        if quote_start >= 0:
            if ch == '"':
                quote_start = -1
            continue
        if ch == '"':
            quote_start = i
        elif ch == "(":
            depth += 1
            if depth > MAX_DEPTH:
                return i, f"nesting deeper than the limit of {MAX_DEPTH} levels"
        elif ch == ")":
            if depth == 0:
                return i, "a ')' without a matching '('"
            depth -= 1
    if quote_start >= 0:
        return quote_start, "a string opened with '\"' but never closed"
    if depth:
        return len(text), f"truncated message: {depth} '(' never closed"
    return len(text), "malformed expression"


def _structure_error(text: str, expected: str) -> ProtocolError:
    pos, problem = _locate_structure_error(text)
    return ProtocolError(f"{problem} at {_excerpt_at(text, pos)}; expected {expected}")


def _tokenize(text: str) -> list[str]:
    """Split ``text`` into '(' / ')' / atom / quoted-string tokens."""
    if '"' not in text:
        return text.replace("(", " ( ").replace(")", " ) ").split()
    parts = text.split('"')
    if len(parts) % 2 == 0:
        raise _structure_error(text, "balanced double quotes")
    tokens: list[str] = []
    for i, part in enumerate(parts):
        if i % 2:
            tokens.append('"' + part + '"')
        elif part:
            tokens.extend(part.replace("(", " ( ").replace(")", " ) ").split())
    return tokens


def _build(tokens: list[str], text: str) -> list[Sexp]:
    """Assemble tokens into nested tuples without recursion, bounding the depth."""
    stack: list[list[Sexp]] = []
    cur: list[Sexp] = []
    for tok in tokens:
        if tok == "(":
            stack.append(cur)
            if len(stack) > MAX_DEPTH:
                raise _structure_error(text, f"at most {MAX_DEPTH} nested levels")
            cur = []
        elif tok == ")":
            if not stack:
                raise _structure_error(text, "balanced parentheses")
            done = tuple(cur)
            cur = stack.pop()
            cur.append(done)
        else:
            cur.append(tok)
    if stack:
        raise _structure_error(text, "a complete message (balanced parentheses)")
    return cur


def _check_chars(text: str) -> None:
    if len(text) > MAX_MESSAGE_CHARS:
        raise ProtocolError(
            f"message of {len(text)} characters is longer than the limit of "
            f"{MAX_MESSAGE_CHARS}: {_excerpt_at(text, 0)}"
        )
    bad = _BAD_CHAR.search(text)
    if bad is not None:
        raise ProtocolError(
            f"character {bad.group()!r} at {_excerpt_at(text, bad.start())}; expected "
            "printable ASCII and whitespace only"
        )


def parse_sexps(text: str) -> tuple[Sexp, ...]:
    """Parse zero or more top-level s-expressions (e.g. ``"(dash 50)(done)"``).

    Raises :class:`ProtocolError` on unbalanced parentheses or quotes, nesting deeper
    than :data:`MAX_DEPTH`, forbidden characters or input longer than
    :data:`MAX_MESSAGE_CHARS`. Top-level atoms are rejected too.
    """
    _check_chars(text)
    items = _build(_tokenize(text), text)
    for item in items:
        if not isinstance(item, tuple):
            raise ProtocolError(
                f"stray atom {item!r} outside any parentheses in {_excerpt_at(text, 0)}; "
                "expected only (...) expressions"
            )
    return tuple(items)


def parse_sexp(text: str) -> tuple[Sexp, ...]:
    """Parse exactly one parenthesised s-expression and return it as a tuple."""
    items = parse_sexps(text)
    if len(items) != 1:
        what = "an empty message" if not items else f"{len(items)} expressions"
        raise ProtocolError(f"got {what} in {_excerpt_at(text, 0)}; expected exactly one (...)")
    item = items[0]
    assert isinstance(item, tuple)
    return item


def sexp_to_text(node: Sexp) -> str:
    """Render a parsed s-expression back to text (single spaces, no trailing NUL)."""
    if isinstance(node, str):
        return node
    # Iterative to stay safe on deep trees.
    out: list[str] = []
    stack: list[Iterator[Sexp]] = [iter((node,))]
    need_space = False
    while stack:
        nxt = next(stack[-1], None)
        if nxt is None:
            stack.pop()
            if stack:
                out.append(")")
                need_space = True
            continue
        if need_space:
            out.append(" ")
        if isinstance(nxt, str):
            out.append(nxt)
            need_space = True
        else:
            out.append("(")
            need_space = False
            stack.append(iter(nxt))
    return "".join(out)


# --------------------------------------------------------------------------------------
# Scalar helpers
# --------------------------------------------------------------------------------------


def _bad(expected: str, node: Sexp, where: str) -> ProtocolError:
    return ProtocolError(f"in {where}: expected {expected}, got {_excerpt(node)}")


def _f(tok: Sexp, what: str, where: str) -> float:
    """Parse a finite float atom (no ``nan``/``inf``/``1_0``)."""
    if isinstance(tok, str) and "_" not in tok:
        try:
            v = float(tok)
        except ValueError:
            pass
        else:
            if v - v == 0.0:  # false for nan and +-inf
                return v
    raise _bad(f"a finite number for {what}", tok, where)


def _i(tok: Sexp, what: str, where: str) -> int:
    """Parse an integer atom (``"3"``, ``"-0"``; not ``"3.0"``)."""
    if isinstance(tok, str) and "_" not in tok:
        try:
            return int(tok)
        except ValueError:
            pass
    raise _bad(f"an integer for {what}", tok, where)


def _atom(tok: Sexp, what: str, where: str) -> str:
    if isinstance(tok, str) and not tok.startswith('"'):
        return tok
    raise _bad(f"a bare word for {what}", tok, where)


def _choice(tok: Sexp, choices: frozenset[str] | tuple[str, ...], what: str, where: str) -> str:
    if isinstance(tok, str) and tok in choices:
        return tok
    shown = "|".join(sorted(choices)) if len(choices) <= 8 else "a known name"
    raise _bad(f"{what} ({shown})", tok, where)


def _quoted(tok: Sexp, what: str, where: str) -> str:
    if isinstance(tok, str) and len(tok) >= 2 and tok[0] == '"' and tok[-1] == '"':
        return tok[1:-1]
    raise _bad(f"a quoted string for {what}", tok, where)


def _list(node: Sexp, what: str, where: str) -> tuple[Sexp, ...]:
    if isinstance(node, tuple):
        return node
    raise _bad(f"a (...) list for {what}", node, where)


def _arity(node: tuple[Sexp, ...], n: int | tuple[int, ...], where: str) -> None:
    ok = len(node) == n if isinstance(n, int) else len(node) in n
    if not ok:
        want = str(n) if isinstance(n, int) else " or ".join(str(k) for k in n)
        raise ProtocolError(
            f"in {where}: expected {want} elements in ({node[0] if node else ''} ...), "
            f"got {len(node)}: {_excerpt(node)}"
        )


_SIDES = ("l", "r")


