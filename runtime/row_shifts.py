"""Floor rows compared under sideways shifts (``runtime.side_offset``): every shift of every row scored at once.

The side registration compares each floor row of the current view with the same row of a taught view (warped to
a few offsets along the route) under every whole-pixel shift. Two scores, each the mean over colours and the
compared columns of the rows' normalised values:

- :meth:`RowShifts.squares`, every step: the root mean square difference, scaled to read as the mean absolute
  difference would on Gaussian differences (``RMS_TO_MEAN_ABS``). A sum of squared differences splits into the
  two rows' energies and their correlation, and the correlation under every shift is one small matrix product
  per row and colour with the current row laid at each shift (built once per view): on the 128 px camera (19
  rows, 25 shifts, 13 offsets along the route) a table costs about what the mean absolute difference cost for
  two offsets.
- :meth:`RowShifts.mean_abs`: the mean absolute difference, where a decision rests on how much better the best
  offset along the route scores than the others (the end's arrival, ``SideConfig.along_margin``, and whether a
  taught floor tells a distance along at all). Squares weigh a few large differences (a square's edge moved)
  more, and read a floor of squares laid along the path as telling a distance it does not.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import as_strided

#: sqrt(2 / pi): the mean absolute value of a zero-mean Gaussian over its root mean square, which puts the
#: squares on the scale the side registration's thresholds were chosen on. Measured on 2,400 views 0-8 cm
#: beside and +-3 cm along taught poses of development houses random:900-939 (``benchmarks/RESULTS.md``),
#: the estimate read a side offset as often and as accurately with either score.
RMS_TO_MEAN_ABS = math.sqrt(2 / math.pi)


class CurrentRows:
    """The current view's normalised floor rows, and (made when first asked) what :meth:`RowShifts.squares`
    needs of them."""

    def __init__(self, rows: np.ndarray, shifts: int, width: int) -> None:
        #: (3, rows, cols) normalised rows (zero mean, unit spread per row and colour)
        self.rows = rows
        self._shifts, self._width = shifts, width
        self._laid: tuple[np.ndarray, np.ndarray] | None = None

    def laid(self) -> tuple[np.ndarray, np.ndarray]:
        """(3, rows, cols, shifts): per colour and row, the middle columns laid at every shift, zero elsewhere,
        so that a taught row times it gives the correlation at each shift; and (rows,): the middle columns' sum
        of squares over colours."""
        if self._laid is None:
            rows, s_max, n_s = self.rows, self._shifts, 2 * self._shifts + 1
            n_rows, m = rows.shape[1], self._width - 2 * s_max
            middle = rows[:, :, s_max : s_max + m]
            # padded so that entry (taught column x, shift index q) of a row's matrix is padded[x + q]: the
            # current column j = x + q - (n_s - 1) against taught column x, a shift of q - s_max
            padded = np.zeros((3, n_rows, self._width + n_s - 1), np.float32)
            padded[:, :, n_s - 1 : n_s - 1 + m] = middle
            s0, s1, e = padded.strides
            view = as_strided(padded, (3, n_rows, self._width, n_s), (s0, s1, e, e), writeable=False)
            self._laid = np.ascontiguousarray(view), np.einsum("crj,crj->r", middle, middle)
        return self._laid


class RowShifts:
    """Scores of floor rows against taught rows under whole-pixel shifts of up to ``shifts`` each way; rows of
    ``width`` columns, of which the middle ``width - 2 * shifts`` are compared; ``spread_floor``: added to each
    row's spread before it is divided by it (noise on a plain floor is not blown up into a pattern)."""

    def __init__(self, width: int, shifts: int, spread_floor: float) -> None:
        self.width, self.shifts, self.spread_floor = width, shifts, spread_floor
        self.cols = width - 2 * shifts
        self.n_shifts = 2 * shifts + 1

    def normalised(self, rows: np.ndarray) -> np.ndarray:
        """(..., cols) float32 floor rows normalised in place (and returned): each row at zero mean and unit
        spread (floored)."""
        cols = rows.shape[-1]
        mean = np.add.reduce(rows, axis=-1, keepdims=True)
        mean /= cols
        rows -= mean
        spread = np.add.reduce(rows * rows, axis=-1, keepdims=True)
        spread /= cols
        np.sqrt(spread, out=spread)
        spread += self.spread_floor
        rows /= spread
        return rows

    def current(self, rows: np.ndarray) -> CurrentRows:
        """The current view's (3, rows, width) float32 floor rows, normalised here in place."""
        return CurrentRows(self.normalised(rows), self.shifts, self.width)

    def mean_abs(self, cur: CurrentRows, taught_rows: np.ndarray) -> np.ndarray:
        """(..., shifts, rows) mean absolute differences of the current rows and taught ones (..., 3, rows,
        width; normalised here in place) under each shift, from -``shifts``."""
        ref = self.normalised(taught_rows)
        s_max, m = self.shifts, self.cols
        # the current rows' middle columns against every window of the taught rows: window i is a shift of
        # s_max - i (the current column c against the taught c - s); the strided view is what
        # sliding_window_view makes, without its ~50 us of Python checks
        middle = cur.rows[:, :, s_max : s_max + m]
        step = ref.strides[-1]
        windows = as_strided(ref, (*ref.shape[:-1], 2 * s_max + 1, m), (*ref.strides[:-1], step, step), False)
        diff = np.subtract(windows, middle[:, :, None, :])
        # summed over colours and columns per (row, shift), in the order the rows' layout gives numpy: the same
        # bits with or without the leading offsets (tests/runtime/test_arrival.py holds them)
        table = np.abs(diff, out=diff).sum(axis=(-4, -1))[..., ::-1]
        return np.swapaxes(table, -1, -2) / (3 * m)

    def squares(self, cur: CurrentRows, taught: np.ndarray) -> np.ndarray:
        """(D, shifts, rows) root mean square differences (times ``RMS_TO_MEAN_ABS``) of the current rows and
        D taught versions of them (3, rows, D, width; float32, normalised here in place) under each shift, from
        -``shifts``."""
        ref = self.normalised(taught)
        m, n_s = self.cols, self.n_shifts
        n_rows, d, width = ref.shape[1:]
        laid, energy = cur.laid()
        per_colour = np.matmul(ref, laid)  # (3, rows, D, shifts): one small product per colour and row
        cross = np.add(per_colour[0], per_colour[1])
        cross += per_colour[2]
        # each window's sum of squares over colours, from a running sum along the row
        running = np.zeros((n_rows, d, width + 1), np.float32)
        np.cumsum(np.einsum("crdx,crdx->rdx", ref, ref), axis=-1, out=running[..., 1:])
        windows = running[..., m : m + n_s]
        windows -= running[..., :n_s]  # window i starts at taught column i: a shift of s_max - i
        cross *= -2
        cross += windows[..., ::-1]
        cross += energy[:, None, None]
        np.maximum(cross, 0, out=cross)  # rounding can take a perfect match a hair below zero
        cross *= np.float32(RMS_TO_MEAN_ABS**2 / (3 * m))
        np.sqrt(cross, out=cross)
        return cross.transpose(1, 2, 0)


__all__ = ["RMS_TO_MEAN_ABS", "CurrentRows", "RowShifts"]
