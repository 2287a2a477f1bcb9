"""Bridge to the official RoboCup Soccer Simulator 2D server (rcssserver 19).

* :mod:`elevens.robocup.protocol` -- strict parser of server messages and serialiser of
  player/trainer commands.
* :mod:`elevens.robocup.localize` -- self-localisation of a player from one ``see``.
* :mod:`elevens.robocup.actions` -- the thesis' 12-value continuous action mapped to one
  server command per cycle.
* :mod:`elevens.robocup.server` -- finding and running rcssserver processes on free ports.
* :mod:`elevens.robocup.client` -- 22 players and the trainer in synch mode over UDP.
* :mod:`elevens.robocup.observe` / :mod:`elevens.robocup.env` -- :class:`RoboCupEnv`, the
  simulator's reset/step contract and containers on top of the server.
* :mod:`elevens.robocup.naive` -- the RoboCup naive team of thesis section 6.7.
* :mod:`elevens.robocup.bodies` / :mod:`elevens.robocup.sim` /
  :mod:`elevens.robocup.rcss_naive` -- the simulator with rcssserver's bodies and the 12-value
  action, a game to train in (``elevens train rcss-11v11``) with its handcrafted team; importing
  this package registers them with the core.
* :mod:`elevens.robocup.train` / :mod:`elevens.robocup.play` -- PPO training and matches in the
  server (``elevens robocup ...``).
* :mod:`elevens.robocup.skills` -- a team that decides in librcsc's skills through the skills
  proxy (``elevens robocup skills-team``), and the same decisions as a game of the simulator
  (:mod:`elevens.robocup.skills.game`, ``elevens train skills-11v11``).
"""

from elevens.robocup.actions import (
    ACTION_SIZE,
    ActionIndex,
    ActionScaling,
    action_to_command,
    actions_to_commands,
)
from elevens.robocup.client import (
    ClientStats,
    Cycle,
    PlayerCycle,
    RoboCupClient,
    ServerDied,
    measure_cycles,
)
from elevens.robocup.env import RoboCupConfig, RoboCupEnv, sim_actions_to_commands
from elevens.robocup.localize import LANDMARKS, PoseEstimate, localize
from elevens.robocup.naive import RoboCupNaiveTeam
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
from elevens.robocup.server import (
    INSTALL_HINT,
    TRAINING_OPTIONS,
    RcssserverNotFound,
    ServerAddress,
    ServerProcess,
    find_rcssserver,
    free_port_triple,
)

__all__ = [
    "ACTION_SIZE",
    "INSTALL_HINT",
    "TRAINING_OPTIONS",
    "ClientStats",
    "Cycle",
    "PlayerCycle",
    "RcssserverNotFound",
    "RoboCupClient",
    "RoboCupConfig",
    "RoboCupEnv",
    "RoboCupNaiveTeam",
    "ServerAddress",
    "ServerDied",
    "ServerProcess",
    "find_rcssserver",
    "free_port_triple",
    "measure_cycles",
    "sim_actions_to_commands",
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

from elevens.robocup.sim import register as _register_sim_game  # noqa: E402
from elevens.robocup.skills.game import register as _register_skills_game  # noqa: E402

_register_sim_game()
_register_skills_game()
