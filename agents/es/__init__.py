"""es: evolution strategies on the policy's weights, the learner of one contour's policy and of a generalist.

Its settings are the ``train.es`` section (:class:`agents.es.config.EsConfig`); the learner is an rsl-rl
algorithm (:class:`agents.es.algorithm.ES`) that warpcut's rsl-rl runner (:class:`agents.runner.Runner`)
drives, one whole cut per env an iteration.
"""
