"""runtime.row_shifts: floor rows scored under every shift, against the sums written out one by one."""

from __future__ import annotations

import numpy as np
import pytest

from vtr.runtime.row_shifts import RMS_TO_MEAN_ABS, RowShifts


def rows(rng: np.random.Generator, *shape: int) -> np.ndarray:
    return (rng.random(shape) * 1000).astype(np.float32)  # pooled sums of 2 x 2 pixels: 0-1020


def written_out(shifts: RowShifts, cur: np.ndarray, taught: np.ndarray, power: int) -> np.ndarray:
    """(D, shifts, rows) from (3, rows, width) current and (D, 3, rows, width) taught rows, in float64: the
    mean over colours and middle columns of |difference| ** power, a taught row shifted s right at s + s_max."""
    s_max, m = shifts.shifts, shifts.cols
    cur = shifts.normalised(cur.copy()).astype(np.float64)[:, :, s_max : s_max + m]
    ref = shifts.normalised(taught.copy()).astype(np.float64)
    out = np.empty((len(taught), 2 * s_max + 1, cur.shape[1]))
    for q in range(2 * s_max + 1):  # shift q - s_max: current column j against taught column j - shift
        start = s_max - (q - s_max)
        diff = np.abs(ref[..., start : start + m] - cur[None])
        out[:, q] = (diff**power).sum(axis=(1, 3)) / (3 * m)
    return out


@pytest.mark.parametrize(("width", "s_max", "d"), [(64, 12, 9), (64, 12, 1), (32, 6, 13), (20, 2, 3)])
def test_the_squares_are_the_root_mean_square_difference_under_each_shift(width, s_max, d):
    rng = np.random.default_rng(width + d)
    shifts = RowShifts(width, s_max, 16.0)
    cur, taught = rows(rng, 3, 7, width), rows(rng, d, 3, 7, width)
    got = shifts.squares(
        shifts.current(cur.copy()), np.ascontiguousarray(taught.copy().transpose(1, 2, 0, 3))
    )
    want = np.sqrt(written_out(shifts, cur, taught, 2)) * RMS_TO_MEAN_ABS
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4)


def test_a_taught_row_that_is_the_current_one_shifted_scores_zero_at_that_shift_only():
    rng = np.random.default_rng(1)
    shifts = RowShifts(64, 12, 16.0)
    cur = rows(rng, 3, 5, 64)
    # the taught rows 4 pixels right of the current ones: current column c is taught column c + 4, a shift of
    # -4 (current c against taught c - s), at index s_max - 4
    taught = np.roll(cur, 4, axis=-1)[None]
    table = shifts.squares(shifts.current(cur.copy()), np.ascontiguousarray(taught.transpose(1, 2, 0, 3)))[0]
    assert (table.argmin(axis=0) == 12 - 4).all()
    assert table[8] == pytest.approx(0.0, abs=1e-3) and (np.delete(table, 8, axis=0) > 0.1).all()


def test_the_mean_absolute_difference_is_written_out_one_by_one():
    rng = np.random.default_rng(2)
    shifts = RowShifts(64, 12, 16.0)
    cur, taught = rows(rng, 3, 7, 64), rows(rng, 4, 3, 7, 64)
    got = shifts.mean_abs(shifts.current(cur.copy()), taught.copy())
    np.testing.assert_allclose(got, written_out(shifts, cur, taught, 1), rtol=1e-4, atol=1e-5)
