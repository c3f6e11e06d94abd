"""The frame path's own labelling, filters and assignment equal scipy's, their reference."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage
from scipy.optimize import linear_sum_assignment as scipy_assignment

from vehicles.assignment import linear_sum_assignment
from vehicles.detections import Detections
from vehicles.heatmap import label_regions, max_filter, mean_filter

masks = st.tuples(st.integers(1, 40), st.integers(1, 40)).flatmap(
    lambda shape: arrays(np.bool_, shape)
)


@settings(max_examples=200, deadline=None)
@given(masks)
def test_labels_and_boxes_equal_scipy(mask: np.ndarray) -> None:
    expected, n = ndimage.label(mask)
    labels, windows = label_regions(mask)
    assert len(windows) == n
    assert (labels == expected).all()
    assert windows == ndimage.find_objects(expected)


@settings(max_examples=200, deadline=None)
@given(
    st.tuples(st.integers(1, 30), st.integers(1, 30)).flatmap(
        lambda shape: arrays(np.float32, shape, elements=st.floats(0, 8, width=32))
    )
)
def test_filters_equal_scipy(heat: np.ndarray) -> None:
    assert np.allclose(mean_filter(heat, 3), ndimage.uniform_filter(heat, 3), atol=1e-5)
    assert (max_filter(heat, 5) == ndimage.maximum_filter(heat, 5)).all()


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(st.integers(0, 7), st.integers(0, 7)).flatmap(
        lambda shape: arrays(np.float64, shape, elements=st.floats(-1, 1))
    )
)
def test_assignment_is_as_cheap_as_scipys(cost: np.ndarray) -> None:
    rows, cols = linear_sum_assignment(cost)
    ref_rows, ref_cols = scipy_assignment(cost)
    assert len(rows) == len(ref_rows) == min(cost.shape)
    assert len(set(rows)) == len(rows) and len(set(cols)) == len(cols)
    assert np.isclose(cost[rows, cols].sum(), cost[ref_rows, ref_cols].sum())


def test_assignment_of_tie_free_matrices_is_scipys() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        cost = rng.random(tuple(rng.integers(1, 9, 2)))
        rows, cols = linear_sum_assignment(cost)
        ref_rows, ref_cols = scipy_assignment(cost)
        assert (rows == ref_rows).all() and (cols == ref_cols).all()


def test_clipped_boxes_stay_in_the_frame() -> None:
    dets = Detections.from_boxes(
        np.array([[-5.0, 10, 50, 60], [1200, 600, 1290, 730]]), np.array([0.9, 0.8])
    )
    boxes = dets.clipped((0, 0, 1280, 720)).boxes
    assert boxes.tolist() == [[0, 10, 50, 60], [1200, 600, 1280, 720]]
