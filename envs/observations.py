"""What a pattern-cutting policy observes: time, grasp displacement, fiducials and (by default) the contour
features.

The layout of one env's observation (float32, ``D = 4 + 3 * num_fiducials [+ 7]``; 47 with the defaults):

=================  =====  =====================================================================  ==========
slice              size   quantity                                                               bounds
=================  =====  =====================================================================  ==========
``[0]``            1      time index ``step / num_steps`` (progress of the whole cut; with      [0, 1]
                          ``lookahead``, of this env's own trajectory)
``[1:4]``          3      grasp displacement / ``max_displacement_mm``                          [-1, 1]
``[4:4+3K]``       3K     fiducial ``k`` at ``[4+3k : 7+3k]``: world position, normalised       [-2, 2]
``[4+3K:7+3K]``    3      (``contour_features``) scissor tip position, normalised               [-2, 2]
``[7+3K]``         1      (``contour_features``) 1 while the tip cuts, 0 while it travels       [0, 1]
``[8+3K:11+3K]``   3      (``contour_features``) tracking error / ``max_displacement_mm``       [-5, 5]
then               2      (``lookahead``) the grasp (pinch point + displacement) from the tip    [-2, 2]
                   6L     (``lookahead``) per look-ahead point ``j`` (below)
=================  =====  =====================================================================  ==========

With ``lookahead = L`` the policy also sees what lies ahead of the scissors, L points ``j = 1..L`` at
:data:`LOOKAHEAD_STEPS` ``* j`` steps past the next update along the planned trajectory: the planned tip's
move from the tip now (x, y, normalised as positions without the centre: [-2, 2]), the look-ahead tracking
error (where the sheet holds the material point that tip means to cut, from that tip, /
``max_displacement_mm``: [-5, 5]; 0 where the tip will travel) and whether the tip will cut there ([0, 1]).
Together they give the contour's direction and curvature ahead, where the segment ends, and how far the sheet
has already carried what is to come: what a policy that tensions contours it never trained on needs to know
(the time index alone means nothing across contours of different lengths). With a look-ahead the time index is
the env's own progress along its trajectory, not the batch's clock (the longest trajectory of the batch), so
that a policy sees the same whether its contour is cut alone or in a batch of others.

*Normalised* positions are ``(p - (W/2, H/2, 0)) / (max(W, H) / 2)``: the sheet at rest spans [-1, 1] in
x and y, and its ~15 mm sag is about -0.3 in z. The tracking error is ``target_world() - tip``, the vector
from the next scissor position to where the sheet has carried the contour point it is about to cut (what
:class:`agents.baselines.AnalyticTension` opposes); zero while the tip travels or once the cut is done.

Every entry is clipped to its bounds, so observations always lie in the observation space (only a
piece that has been cut free and falls ever reaches the position bounds, 100 mm from the sheet centre).

Fiducials are material points, drawn at random, that a camera tracks on the gauze; a hidden one reports its
last visible position (:mod:`warpcut.fiducials`, which recordings share).
"""

from __future__ import annotations

import numpy as np

from warpcut.fiducials import Fiducials, sample_fiducials
from warpcut.sim.config import SimConfig

__all__ = [
    "LOOKAHEAD_STEPS",
    "POSITION_LIMIT",
    "observation_names",
    "TRACKING_ERROR",
    "TRACKING_LIMIT",
    "Fiducials",
    "normalise_positions",
    "observation_bounds",
    "sample_fiducials",
]

POSITION_LIMIT = 2.0
"""Bound on normalised positions (fiducials, tip): 100 mm from the sheet centre on a 100 mm sheet."""

TRACKING_ERROR = ("tracking_dx", "tracking_dy", "tracking_dz")
"""The names (:func:`observation_names`) of the tracking error's entries (``contour_features``)."""

TRACKING_LIMIT = 5.0
"""Bound on the normalised tracking error: 50 mm at the default ``max_displacement_mm`` of 10 mm."""

LOOKAHEAD_STEPS = 2
"""Env steps between look-ahead points (``lookahead``): 4 mm of trajectory at the default 2 updates of
1 mm a step, so 8 points see 32 mm ahead."""

LOOKAHEAD_POINT = (
    "ahead_{j}_dx",
    "ahead_{j}_dy",
    "ahead_{j}_ex",
    "ahead_{j}_ey",
    "ahead_{j}_ez",
    "ahead_{j}_cut",
)
"""The names of look-ahead point ``j``'s entries: the planned tip's move, the tracking error there, and
whether it cuts."""


def observation_bounds(
    num_fiducials: int, contour_features: bool, lookahead: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` float32 bounds of one env's observation, in the layout of the module docstring."""
    low = [0.0, -1.0, -1.0, -1.0] + [-POSITION_LIMIT] * (3 * num_fiducials)
    high = [1.0, 1.0, 1.0, 1.0] + [POSITION_LIMIT] * (3 * num_fiducials)
    if contour_features:
        low += [-POSITION_LIMIT] * 3 + [0.0] + [-TRACKING_LIMIT] * 3
        high += [POSITION_LIMIT] * 3 + [1.0] + [TRACKING_LIMIT] * 3
    if lookahead:
        point_low = [-POSITION_LIMIT] * 2 + [-TRACKING_LIMIT] * 3 + [0.0]
        point_high = [POSITION_LIMIT] * 2 + [TRACKING_LIMIT] * 3 + [1.0]
        low += [-POSITION_LIMIT] * 2 + point_low * lookahead
        high += [POSITION_LIMIT] * 2 + point_high * lookahead
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def normalise_positions(points: np.ndarray, config: SimConfig) -> np.ndarray:
    """World positions (..., 3) in mm to the observation's unit scale (see the module docstring)."""
    centre = np.array([config.width_mm / 2, config.height_mm / 2, 0.0])
    return (points - centre) / (max(config.width_mm, config.height_mm) / 2)


def observation_names(num_fiducials: int, contour_features: bool, lookahead: int = 0) -> list[str]:
    """The name of each entry of one env's observation, in the layout of the module docstring (e.g. for an
    exported policy's metadata)."""
    names = ["time", "grasp_dx", "grasp_dy", "grasp_dz"]
    names += [f"fiducial_{k}_{axis}" for k in range(num_fiducials) for axis in "xyz"]
    if contour_features:
        names += ["tip_x", "tip_y", "tip_z", "tip_cutting", *TRACKING_ERROR]
    if lookahead:
        names += ["pinch_dx", "pinch_dy"]
        names += [name.format(j=j) for j in range(1, lookahead + 1) for name in LOOKAHEAD_POINT]
    return names
