"""dagger: a generalist learned from many teachers by supervised learning, corrected on its own states.

The teachers are a dataset of per-contour plans (``warpcut teachers``, :mod:`agents.teachers`): the open-loop
plan ``warpcut optimize --estimator es`` finds for each contour at its planned cut. The student is one
closed-loop network for every contour (:class:`agents.models.FeedbackMLPModel`, es's generalist network: it
observes what lies ahead of the scissors and the tracking error). It is trained by DAgger (Ross, Gordon &
Bagnell, AISTATS 2011; the supervised step of guided policy search, Levine & Koltun 2013): every iteration
the batch cuts each teacher's contour, the envs following either the teacher or the student (the teacher's
share decays), every visited state is labelled with the teacher's move there, the labels join an aggregated
dataset, and the student regresses onto it (:class:`agents.dagger.algorithm.DAgger`).
"""
