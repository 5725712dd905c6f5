"""Tensioning agents: the paper's baselines, PPO training on rsl-rl, evaluation protocols."""

from agents.baselines import AnalyticTension, FixedTension, NoTension, make_policy
from agents.evaluation import compare_policies, evaluate_suite

__all__ = [
    "AnalyticTension",
    "FixedTension",
    "NoTension",
    "compare_policies",
    "evaluate_suite",
    "make_policy",
]
