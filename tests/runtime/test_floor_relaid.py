"""runtime.floor_relaid: a floor laid again since the teach is one the floor registration reads in none of the
last views, counted only where the taught floor registers against itself."""

from __future__ import annotations

import numpy as np

from vtr.runtime.floor_relaid import RELAID_MIN, RELAID_VIEWS, FloorRelaid
from vtr.runtime.obstruction import Growth
from vtr.runtime.obstruction_decision import ObstructionConfig
from vtr.runtime.side_offset import SideEstimate

READ = SideEstimate(0.0, 0.0, 10)


class _Registration:
    """Ten taught views 5 cm apart along x; ``tells``: the taught views whose floor registers against itself."""

    def __init__(self, tells: set[int]) -> None:
        self.subgoals = np.arange(10)  # stands in for the images: estimate() is given subgoals[k]
        self.poses = np.stack([np.arange(10) * 0.05, np.zeros(10), np.zeros(10)], axis=1)
        self.tells = tells

    def estimate(self, view: object, position: float) -> SideEstimate | None:
        return READ if int(view) in self.tells else None  # type: ignore[call-overload]


def test_a_floor_read_in_none_of_the_last_views_was_laid_again():
    relaid = FloorRelaid(_Registration(set(range(10))))  # type: ignore[arg-type]
    for i in range(RELAID_MIN):
        assert not relaid.relaid  # too few views asked yet
        relaid.seen(2.0 + 0.5 * i, None)
    assert relaid.relaid
    relaid.seen(4.0, READ)  # one view read: the floor is the taught one
    assert not relaid.relaid
    for _ in range(RELAID_VIEWS - 1):
        relaid.seen(4.5, None)
    assert not relaid.relaid  # the read view is still among the last RELAID_VIEWS
    relaid.seen(4.5, None)
    assert relaid.relaid
    relaid.reset()
    assert not relaid.relaid and not relaid.recent


def test_views_whose_taught_floor_tells_nothing_do_not_count():
    """A plain floor, or one that matches itself as well a step along, never registers: that is no evidence the
    floor was laid again, or the camera stop would never act on it."""
    relaid = FloorRelaid(_Registration({7, 8}))  # type: ignore[arg-type]
    for _ in range(2 * RELAID_VIEWS):
        relaid.seen(3.0, None)
    assert not relaid.relaid and not relaid.recent
    for _ in range(RELAID_MIN):
        relaid.seen(7.2, None)
    assert relaid.relaid
    assert not FloorRelaid(None).relaid  # no registration at all: never judged re-laid
    FloorRelaid(None).seen(3.0, None)


def test_a_relaid_floor_does_not_block_what_the_floor_beside_the_path_alone_would():
    """Dev re-coloured floor gen_107 s0 (session 26): the path region 100% unmatched up to its far end, growing,
    the floor beside it 40% unmatched (under ``max_elsewhere``): `blocked` with nothing there. The floor
    registration had read none of the last views; beside real boxes it read 2-12 of the last 12."""
    shares = [0.05, 0.15, 0.25, 0.35, 0.45]
    for relaid, blocks in ((False, True), (True, False)):
        growth = Growth(ObstructionConfig())
        verdicts = [growth.update(s, s, True, lambda: (8, 20), relaid) for s in shares]
        assert verdicts[-1].blocked is blocks
