"""The optimised Matcher (float32 pooling, a 0/1 product for the columns, reductions without
ndarray.mean) must equal, bit for bit, the straightforward computation it replaced, kept here as the
reference: integer pooling sums, ndarray.mean, np.abs(...).mean."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vtr.runtime.matching import MatchConfig, Matcher

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def reference_features(batch: np.ndarray, cfg: MatchConfig) -> np.ndarray:
    b, h, w, c = batch.shape
    f, p = cfg.downsample, cfg.patch
    x = np.zeros((b, h // f, w // f, c), dtype=np.uint32)
    for dy in range(f):
        for dx in range(f):
            x += batch[:, dy::f, dx::f]
    hp, wp = h // (f * p), w // (f * p)
    tiles = (
        x.astype(np.float32)
        .reshape(b, hp, p, wp, p, c)
        .transpose(0, 1, 3, 5, 2, 4)
        .reshape(b, hp * wp, c, p * p)
    )
    tiles -= tiles.mean(axis=-1, keepdims=True)
    std = np.sqrt(np.einsum("...i,...i->...", tiles, tiles) / (p * p))[..., None]
    tiles /= np.maximum(std, np.float32(cfg.std_floor * f * f))
    return tiles.reshape(b, hp * wp, c * p * p)


def reference_distances(feature: np.ndarray, others: np.ndarray, trim: float) -> np.ndarray:
    per_tile = np.abs(others - feature).mean(axis=-1)
    keep = max(1, int(round(per_tile.shape[1] * (1.0 - trim))))
    if keep < per_tile.shape[1]:
        per_tile = np.partition(per_tile, keep - 1, axis=1)[:, :keep]
    return per_tile.mean(axis=1).astype(np.float64)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@FAST
@given(
    seed=st.integers(0, 2**32 - 1),
    downsample=st.sampled_from([1, 2, 3, 4]),
    patch=st.sampled_from([2, 4, 8]),
    trim=st.sampled_from([0.0, 0.5, 0.75]),
    count=st.integers(1, 4),
    flat=st.booleans(),
)
def test_features_and_distances_equal_the_reference_bit_for_bit(seed, downsample, patch, trim, count, flat):
    rng = np.random.default_rng(seed)
    side = downsample * patch * 2
    images = rng.integers(0, 256, (count, side, side, 3), dtype=np.uint8)
    if flat:  # textureless tiles: the std floor decides
        images[:] = rng.integers(0, 256)
    cfg = MatchConfig(downsample=downsample, patch=patch, trim=trim)
    matcher = Matcher(cfg)
    feats = matcher.features(images)
    assert _same_bits(feats, reference_features(images, cfg))
    assert _same_bits(matcher.features(images[0]), reference_features(images[:1], cfg)[0])
    assert _same_bits(matcher.distances(feats[0], feats), reference_distances(feats[0], feats, trim))
    assert matcher.distance(feats[0], feats[-1]) == float(reference_distances(feats[0], feats[-1:], trim)[0])
    # a distance is the same number alone or in a stack (the controller compares them across calls)
    stacked = matcher.distances(feats[-1], feats)
    assert all(matcher.distance(feats[-1], feats[k]) == stacked[k] for k in range(count))
