"""Light matching's in-place arithmetic on planar (3, H, W) float32 must equal, bit for bit, the broadcast
arithmetic on (H, W, 3) it replaced (kept here as the reference): same operations on the same values, only
numpy's memory layout and loops differ."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vtr.runtime.light import _column_means, channel_stats, match_statistics, remove_side_ramp

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def reference_match_statistics(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    mean, std = channel_stats(image)
    ref_mean, ref_std = channel_stats(reference)
    gain = ref_std / std
    out = image.astype(np.float32)
    out *= gain
    out += ref_mean - mean * gain + np.float32(0.5)
    return np.clip(out, 0, 255, out=out).astype(np.uint8)


def reference_remove_side_ramp(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    cols = _column_means(image) + 1.0
    ref_cols = _column_means(reference) + 1.0
    x = np.linspace(-1.0, 1.0, image.shape[1], dtype=np.float32)
    log_ratio = np.log(ref_cols / cols)
    slope = float((x * (log_ratio - log_ratio.mean())).sum() / (x * x).sum())
    out = image.astype(np.float32)
    out *= np.exp(slope * x)[None, :, None]
    out += np.float32(0.5)
    return np.clip(out, 0, 255, out=out).astype(np.uint8)


@FAST
@given(
    seed=st.integers(0, 2**32 - 1),
    height=st.integers(1, 24),
    width=st.integers(2, 24),
    gain=st.floats(0.2, 3.0),
    offset=st.integers(-80, 80),
)
def test_light_matching_equals_the_broadcast_reference(seed, height, width, gain, offset):
    rng = np.random.default_rng(seed)
    taught = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    ramp = np.linspace(0.5, 1.5, width)[None, :, None]
    changed = np.clip(taught * gain * ramp + offset, 0, 255).astype(np.uint8)
    assert np.array_equal(match_statistics(changed, taught), reference_match_statistics(changed, taught))
    assert np.array_equal(remove_side_ramp(changed, taught), reference_remove_side_ramp(changed, taught))
