"""The plan optimiser: an open-loop (or closed-loop) plan of grasp moves for one contour, optimised through
the simulator, and the ``grad`` method that plays it; the teacher of gps and of a generalist's dataset.

- :mod:`~agents.plan_optimizer.config`: its settings (:class:`~agents.plan_optimizer.config.GradConfig`, the
  ``grad`` section of a job; torch-free) and each estimator's defaults;
- :mod:`~agents.plan_optimizer.plan`: what a plan is (:class:`~agents.plan_optimizer.plan.PlanResult`) and
  how it is played (:class:`~agents.plan_optimizer.plan.PlanPolicy`, the ``grad`` tensioner);
- :mod:`~agents.plan_optimizer.estimators`: how a step's gradient is estimated, ``GradConfig.estimator``:
  ``tape`` (:class:`~agents.plan_optimizer.estimators.TapeGradient`) or ``es``
  (:class:`~agents.plan_optimizer.estimators.SmoothedGradient`);
- :mod:`~agents.plan_optimizer.optimizer`: the optimisation
  (:func:`~agents.plan_optimizer.optimizer.optimize_plan`), a plan kept in a folder
  (:func:`~agents.plan_optimizer.optimizer.cached_plan`) and the ``grad`` method on a suite.
"""
