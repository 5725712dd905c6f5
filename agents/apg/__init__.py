"""apg: analytic policy gradients through the differentiable simulator.

Its settings are the ``train.apg`` section (:class:`agents.apg.config.ApgConfig`). Its episodes run under
``wp.Tape``, not through the env's step, so it has no rsl-rl algorithm: it is a runner of its own
(:class:`agents.apg.runner.ApgRunner`, warpcut's rsl-rl runner with its learning loop replaced).
"""
