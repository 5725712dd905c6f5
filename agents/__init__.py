"""Tensioning agents: the paper's baselines, PPO training on rsl-rl, evaluation protocols, the pipelines
(:mod:`agents.pipeline`) and the command line (:mod:`agents.cli`). The map is in docs/architecture.md."""
