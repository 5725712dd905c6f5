"""gps: guided policy search from the contour's own optimised plan.

The teacher is the open-loop plan that :func:`agents.plan_optimizer.optimizer.optimize_plan` finds with the es
estimator (a move per step, found by perturbing the moves themselves). The student is a closed-loop policy
that plays the teacher's plan as its feed-forward (:class:`agents.gps.model.PlanFeedbackModel`: the plan is a
table inside the network, indexed by the observation's time index, so the student imitates the teacher exactly
from the start) and learns a correction on top from what it observes: an MLP and linear feedback gains on the
tracking error, centred on the observations the plan itself meets, trained by evolution strategies on whole
cuts of its own rollouts (:class:`agents.gps.algorithm.GPS`) on sheets that differ from the nominal one
(:attr:`agents.gps.config.GpsConfig.randomize`). Model selection (:class:`agents.gps.runner.GpsRunner`) scores
the still grasp, the plan played open loop and the student on the same held-out episodes, of the nominal
sheet and of randomised ones, and keeps the best.
"""
