"""Strict parser and command serialiser for the rcssserver 19 text protocol.

The RoboCup Soccer Simulator 2D server (rcssserver, github rcsoccersim/rcssserver,
tag rcssserver-19.0.0) talks to its clients in UDP datagrams that each hold one
s-expression terminated by a NUL byte. This module turns such datagrams into typed,
immutable Python objects and builds the commands a player or the offline trainer
sends back.

Layers:

* :func:`parse_sexp` / :func:`parse_sexps` -- a small tokenizer (one ``split`` pass
  per quoted/unquoted segment, no regex per token, no ``eval``) and an iterative
  tree builder with a nesting limit (:data:`MAX_DEPTH`); atoms are ``str``, lists are
  ``tuple``. Quoted strings keep their quotes, so ``'"LeftTeam"'`` and ``'LeftTeam'``
  stay distinguishable.
* :func:`parse_message` -- dispatches on the head of the expression and decodes it
  into one of the frozen dataclasses below (see :data:`Message`). The hot kinds (see,
  sense_body, see_global, hear, think) first go through fast paths that read the
  server's exact layout 3-5x faster and hand anything else, including every error,
  to this generic path, so results and errors are the same either way.
* :class:`SafeParser` -- wraps :func:`parse_message` for clients: a malformed datagram
  is counted per kind, logged and dropped (``None``) instead of raising.
* Commands (:class:`Dash`, :class:`Kick`, ..., :class:`MovePlayer`) -- frozen
  dataclasses with ``encode() -> bytes``; :func:`datagram` joins several of them and
  appends the NUL byte the server expects.

The package splits these by role: ``sexp`` (the reader and scalar helpers), ``messages``
(the message types and their generic decoders), ``fast`` (the fast paths), ``parse``
(dispatch and :class:`SafeParser`) and ``commands``; everything public is importable from
here.

Every malformed input raises :class:`ProtocolError` (a ``ValueError``) whose message
quotes the offending part and says what was expected; no other exception escapes
:func:`parse_message` for ``str``/``bytes`` input.

Coordinates are the server's: x towards the right goal, **y downward**, angles in
degrees, positive from +x towards +y. Message formats follow the v18 serializers of
rcssserver 19 (v19 clients get identical output): ``src/serializerplayerstdv8.cpp``,
``...v13.cpp``, ``...v14.cpp``, ``...v18.cpp``, ``src/serializercoachstdv14.cpp``,
``src/fullstatesender.cpp``, ``src/visualsenderplayer.cpp``.
"""


from __future__ import annotations

from elevens.robocup.protocol.commands import (
    Bye,
    Catch,
    ChangeMode,
    ChangeView,
    Command,
    Dash,
    Done,
    Ear,
    Eye,
    InitPlayer,
    InitTrainer,
    Kick,
    Look,
    Move,
    MoveBall,
    MovePlayer,
    NoOp,
    ReconnectPlayer,
    Recover,
    RequestTeamNames,
    Say,
    Start,
    SynchSee,
    Tackle,
    TrainerEar,
    Turn,
    TurnNeck,
    datagram,
)
from elevens.robocup.protocol.messages import (
    PLAY_MODES,
    ArmState,
    BallState,
    ChangePlayerType,
    CoachInit,
    CommandCounts,
    ErrorReply,
    FullState,
    GlobalView,
    Hear,
    Init,
    Message,
    OkReply,
    ParamMap,
    PlayerParams,
    PlayerState,
    PlayerType,
    Reconnect,
    Score,
    SeeMessage,
    SeenObject,
    SenseBody,
    ServerParams,
    TeamNames,
    Think,
    WarningReply,
)
from elevens.robocup.protocol.parse import (
    KNOWN_HEADS,
    MessageStats,
    SafeParser,
    parse_message,
)
from elevens.robocup.protocol.sexp import (
    MAX_DEPTH,
    MAX_MESSAGE_CHARS,
    ProtocolError,
    Sexp,
    parse_sexp,
    parse_sexps,
    sexp_to_text,
)

__all__ = [
    "KNOWN_HEADS",
    "MAX_DEPTH",
    "MAX_MESSAGE_CHARS",
    "PLAY_MODES",
    "ArmState",
    "BallState",
    "Bye",
    "Catch",
    "ChangeMode",
    "ChangePlayerType",
    "ChangeView",
    "CoachInit",
    "Command",
    "CommandCounts",
    "Dash",
    "Done",
    "Ear",
    "ErrorReply",
    "Eye",
    "FullState",
    "GlobalView",
    "Hear",
    "Init",
    "InitPlayer",
    "InitTrainer",
    "Kick",
    "Look",
    "Message",
    "MessageStats",
    "Move",
    "MoveBall",
    "MovePlayer",
    "NoOp",
    "OkReply",
    "ParamMap",
    "PlayerParams",
    "PlayerState",
    "PlayerType",
    "ProtocolError",
    "Reconnect",
    "ReconnectPlayer",
    "Recover",
    "RequestTeamNames",
    "SafeParser",
    "Say",
    "Score",
    "SeeMessage",
    "SeenObject",
    "SenseBody",
    "ServerParams",
    "Sexp",
    "Start",
    "SynchSee",
    "Tackle",
    "TeamNames",
    "Think",
    "TrainerEar",
    "Turn",
    "TurnNeck",
    "WarningReply",
    "datagram",
    "parse_message",
    "parse_sexp",
    "parse_sexps",
    "sexp_to_text",
]
