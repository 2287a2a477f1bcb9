"""Flax networks of the learner: the attention + LSTM policy with a tanh-squashed Gaussian (or
the parametrised head: a kind, a pointer at a player slot, a target), the attention critic and
their feedforward ablations (config switches). ``elevens.teams.network`` plays a policy through
the TeamPolicy interface."""

from elevens.nets.attention import FF2, AttentionPool, MaskedMultiHeadAttention, masked_softmax
from elevens.nets.critic import AttentionCritic
from elevens.nets.distributions import (
    LOG_STD_MAX,
    LOG_STD_MIN,
    ParametrisedDistribution,
    TanhGaussian,
    TanhSample,
    clamp_log_std,
)
from elevens.nets.policy import (
    AttentionPolicy,
    LSTMState,
    ParametrisedOutput,
    PolicyCarry,
    PolicyOutput,
    RecurrentCore,
    reset_carry,
)

__all__ = [
    "FF2",
    "LOG_STD_MAX",
    "LOG_STD_MIN",
    "AttentionCritic",
    "AttentionPolicy",
    "AttentionPool",
    "LSTMState",
    "MaskedMultiHeadAttention",
    "ParametrisedDistribution",
    "ParametrisedOutput",
    "PolicyCarry",
    "PolicyOutput",
    "RecurrentCore",
    "TanhGaussian",
    "TanhSample",
    "clamp_log_std",
    "masked_softmax",
    "reset_carry",
]
