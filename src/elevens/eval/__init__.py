"""Evaluation: matches between any two TeamPolicies with one compiled match function."""

from elevens.eval.match import (
    MatchRecord,
    MatchResult,
    home_sides,
    outcome_from_score,
    play_match,
    summary,
)

__all__ = ["MatchRecord", "MatchResult", "home_sides", "outcome_from_score", "play_match",
           "summary"]
