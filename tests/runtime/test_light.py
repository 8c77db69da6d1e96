"""Repeat-time light compensation: the current image recoloured to the subgoal's light."""

from __future__ import annotations

import numpy as np
import pytest
from texture_views import lit, view

from vtr.runtime.light import LightMatchedPolicy, match_statistics


@pytest.mark.parametrize("gain, offset", [(0.7, 0.0), (1.3, 0.0), ((1.2, 1.0, 0.75), 0.0), (0.8, 25.0)])
def test_a_global_light_change_is_undone(gain, offset):
    taught = lit(view(40), 0.6, 40)  # mid-range: the changed light does not clip
    changed = lit(taught, gain, offset)
    restored = match_statistics(changed, taught)
    assert np.abs(restored.astype(int) - taught.astype(int)).mean() < 1.5
    assert np.abs(changed.astype(int) - taught.astype(int)).mean() > 8


def test_geometry_is_left_alone():
    a, b = view(0), view(30)
    out = match_statistics(b, a)
    # recolouring b cannot make it look like a: the pattern stays b's
    corr = np.corrcoef(out[..., 0].ravel(), b[..., 0].ravel())[0, 1]
    assert corr > 0.99
    with pytest.raises(ValueError, match="uint8"):
        match_statistics(b.astype(np.float32), a)


class Recorder:
    image_shape = (64, 64)
    nonfinite_count = 3

    def __init__(self) -> None:
        self.seen: list[np.ndarray] = []

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        self.seen.append(current)
        return np.zeros((2, 2), np.float32)


def test_the_wrapper_recolours_the_current_image_only_and_passes_the_rest_through():
    inner = Recorder()
    policy = LightMatchedPolicy(inner)
    taught = lit(view(10), 0.6, 40)
    policy.predict(lit(taught, 0.7), taught)
    assert np.abs(inner.seen[0].astype(int) - taught.astype(int)).mean() < 1.5
    assert policy.image_shape == (64, 64) and policy.nonfinite_count == 3


def test_one_side_darker_is_evened_out_before_the_statistics_are_matched():
    from vtr.runtime.light import remove_side_ramp

    taught = lit(view(70), 0.6, 40)
    ramp = np.linspace(0.45, 1.0, 64, dtype=np.float32)[None, :, None]
    darker = lit(taught, ramp)
    only_stats = match_statistics(darker, taught)
    both = match_statistics(remove_side_ramp(darker, taught), taught)
    err = lambda a: np.abs(a.astype(int) - taught.astype(int)).mean()  # noqa: E731
    assert err(both) < 0.5 * err(only_stats) and err(both) < 4
