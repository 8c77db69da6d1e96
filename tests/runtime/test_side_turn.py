"""runtime.side_turn: the pursuit's turn toward the taught path from the floor's side estimates."""

from __future__ import annotations

import math

import pytest

from vtr.runtime.side_offset import SideEstimate
from vtr.runtime.side_turn import SIDE_TURN_MAX, SIDE_VIEWS, SideTurn


def told(dy: float) -> SideEstimate:
    return SideEstimate(dy, 0.0, 10)


def test_the_turn_pursues_the_median_of_the_last_views_and_starts_afresh_where_the_floor_does_not_tell():
    pursuit = SideTurn(gain=3.6, lookahead=0.2)
    turns = [pursuit.turn(told(dy)) for dy in (0.04, 0.10, 0.04)]
    assert turns[: SIDE_VIEWS - 1] == [0.0] * (SIDE_VIEWS - 1)  # not before SIDE_VIEWS views in a row
    assert turns[-1] == pytest.approx(-3.6 * math.atan(0.04 / 0.2))  # the 10 cm one is outvoted
    assert pursuit.beside is not None and pursuit.beside.dy == 0.04
    assert pursuit.turn(None) == 0.0 and pursuit.run == [] and pursuit.beside is None
    assert pursuit.turn(told(0.04)) == 0.0  # counting afresh


def test_the_turn_is_at_most_side_turn_max_either_way():
    pursuit = SideTurn(gain=3.6, lookahead=0.2)
    for dy in (0.5,) * SIDE_VIEWS:
        turn = pursuit.turn(told(dy))
    assert turn == -SIDE_TURN_MAX
    for dy in (-0.5,) * SIDE_VIEWS:
        turn = pursuit.turn(told(dy))
    assert turn == SIDE_TURN_MAX
