"""Bridge to the official RoboCup Soccer Simulator 2D server (rcssserver 19).

* :mod:`elevens.robocup.protocol` -- strict parser of server messages and serialiser of
  player/trainer commands.
* :mod:`elevens.robocup.localize` -- self-localisation of a player from one ``see``.
* :mod:`elevens.robocup.actions` -- the thesis' 12-value continuous action mapped to one
  server command per cycle.
"""

from elevens.robocup.actions import (
    ACTION_SIZE,
    ActionIndex,
    ActionScaling,
    action_to_command,
    actions_to_commands,
)
from elevens.robocup.localize import LANDMARKS, PoseEstimate, localize
from elevens.robocup.protocol import (
    Command,
    FullState,
    GlobalView,
    Hear,
    Init,
    Message,
    ProtocolError,
    SafeParser,
    SeeMessage,
    SeenObject,
    SenseBody,
    ServerParams,
    datagram,
    parse_message,
    parse_sexp,
)

__all__ = [
    "ACTION_SIZE",
    "LANDMARKS",
    "ActionIndex",
    "ActionScaling",
    "Command",
    "FullState",
    "GlobalView",
    "Hear",
    "Init",
    "Message",
    "PoseEstimate",
    "ProtocolError",
    "SafeParser",
    "SeeMessage",
    "SeenObject",
    "SenseBody",
    "ServerParams",
    "action_to_command",
    "actions_to_commands",
    "datagram",
    "localize",
    "parse_message",
    "parse_sexp",
]
