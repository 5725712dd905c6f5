"""ppo: rsl-rl's PPO with warpcut's speed-ups and a categorical policy that starts by holding still.

Its settings are the ``train.ppo`` section (:class:`agents.ppo.config.PpoConfig`); the learner is an rsl-rl
algorithm (:class:`agents.ppo.algorithm.PPO`, its categorical actions in :mod:`agents.ppo.distributions`)
that warpcut's rsl-rl runner (:class:`agents.runner.Runner`) drives.
"""
