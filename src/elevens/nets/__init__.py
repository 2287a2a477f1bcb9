"""Flax networks of the learner: the attention + LSTM policy with a tanh-squashed Gaussian, the
attention critic, their feedforward ablations (config switches), and NetworkTeam, which plays a
policy through the TeamPolicy interface."""

from elevens.nets.attention import FF2, AttentionPool, MaskedMultiHeadAttention, masked_softmax
from elevens.nets.critic import AttentionCritic
from elevens.nets.distributions import (
    LOG_STD_MAX,
    LOG_STD_MIN,
    TanhGaussian,
    TanhSample,
    clamp_log_std,
)
from elevens.nets.policy import (
    AttentionPolicy,
    LSTMState,
    PolicyCarry,
    PolicyOutput,
    RecurrentCore,
    reset_carry,
)
from elevens.teams.network import NetworkTeam

__all__ = [
    "FF2",
    "LOG_STD_MAX",
    "LOG_STD_MIN",
    "AttentionCritic",
    "AttentionPolicy",
    "AttentionPool",
    "LSTMState",
    "MaskedMultiHeadAttention",
    "NetworkTeam",
    "PolicyCarry",
    "PolicyOutput",
    "RecurrentCore",
    "TanhGaussian",
    "TanhSample",
    "clamp_log_std",
    "masked_softmax",
    "reset_carry",
]
