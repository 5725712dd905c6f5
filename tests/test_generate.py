"""Generated contours: seeded, split into streams that never mix, and every one resolvable and plannable."""

import numpy as np
import pytest

from warpcut.contours import check_resolution
from warpcut.planning import ORDER_LIMIT, default_pinch, plan_cut, segment_contour
from warpcut.planning.generate import KINDS, MARGIN_MM, SPLITS, generate_contours
from warpcut.sim.config import SimConfig

CONFIG = SimConfig()


@pytest.fixture(scope="module")
def drawn():
    return {split: generate_contours(8, split, seed=3) for split in SPLITS}


def test_the_same_seed_gives_the_same_contours_and_more_keeps_the_first(drawn):
    again = generate_contours(10, "train", seed=3)
    for a, b in zip(drawn["train"], again[:8], strict=True):
        assert a.name == b.name and np.array_equal(a.points, b.points)
    other = generate_contours(8, "train", seed=4)
    assert not any(np.array_equal(a.points, b.points) for a, b in zip(drawn["train"], other, strict=True))


def test_the_splits_never_share_a_contour(drawn):
    shapes = [c.points.tobytes() for split in SPLITS for c in drawn[split]]
    assert len(set(shapes)) == len(shapes)
    assert all(c.name.startswith(f"gen-{split}-3-") for split in SPLITS for c in drawn[split])


def test_every_kind_is_drawn_and_each_contour_is_resolvable_and_plannable(drawn):
    contours = [c for split in SPLITS for c in drawn[split]]
    assert {c.name.rsplit("-", 1)[1] for c in contours} == set(KINDS)
    width, height = CONFIG.width_mm, CONFIG.height_mm
    for c in contours:
        check_resolution(c, CONFIG.spacing_mm)
        assert 1 <= len(segment_contour(c)) <= ORDER_LIMIT
        default_pinch(c, CONFIG)  # a feasible pinch point
        x, y = c.points.T
        if c.closed:
            assert x.min() >= MARGIN_MM - 1e-6 and x.max() <= width - MARGIN_MM + 1e-6
            assert y.min() >= MARGIN_MM - 1e-6 and y.max() <= height - MARGIN_MM + 1e-6
            assert c.intended_region().is_valid and c.area_mm2 > 100
        else:  # from edge to edge
            for end in (c.points[0], c.points[-1]):
                assert min(end[0], width - end[0], end[1], height - end[1]) < 1e-6


def test_a_generated_contour_is_planned_like_a_built_in_one(drawn):
    plan = plan_cut(drawn["test"][3], CONFIG, num_candidates=2, seed=0)
    assert np.isfinite(plan.chosen["error_vertices"]) and plan.segments


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"count": -1}, "count: an integer >= 0"),
        ({"count": 2.0}, "count: an integer >= 0"),
        ({"count": 1, "split": "dev"}, "split: one of train, validation, test"),
        ({"count": 1, "seed": True}, "seed: an integer >= 0"),
        ({"count": 1, "kinds": ["star"]}, "kinds: a non-empty list of blob, polygon, notched, open"),
    ],
)
def test_bad_arguments_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        generate_contours(**kwargs)
