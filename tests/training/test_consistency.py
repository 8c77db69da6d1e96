"""The floor-consistency term: the command on a pair whose current floor was laid again equals the matched one's."""

from __future__ import annotations

import torch

from vtr.training.consistency import consistency_error, consistency_pairs, recolour_changed


def test_recolouring_touches_only_the_pixels_the_other_appearance_changed() -> None:
    recorded = torch.full((64, 3, 4, 4), 0.5)
    other = recorded.clone()
    other[:, :, 2:] = torch.tensor([0.9, 0.2, 0.4]).view(1, 3, 1, 1)  # the floor rows laid again
    out = recolour_changed(recorded, other, torch.Generator().manual_seed(0))
    assert torch.equal(out[:, :, :2], other[:, :, :2])  # the walls (unchanged) stay as they are
    recoloured = (out[:, :, 2:] - other[:, :, 2:]).abs().flatten(1).amax(1) > 1e-6
    assert 16 < int(recoloured.sum()) < 48  # about half of the images get a floor colour no house drew
    assert out.min() >= 0 and out.max() <= 1


def test_the_pairs_put_the_other_appearance_first_against_the_recorded_subgoal() -> None:
    frames, other = torch.rand(6, 3, 3, 4, 4), torch.rand(6, 3, 3, 4, 4)
    views, goals = consistency_pairs(frames, other, 2, 2, torch.Generator().manual_seed(0))
    assert views.shape == goals.shape == (4, 3, 4, 4)
    assert torch.equal(views[2:], frames[:2, 0]) and torch.equal(goals[:2], frames[:2, 2])
    assert torch.equal(goals[2:], frames[:2, 2])
    assert not torch.equal(views[:2], frames[:2, 0])


def test_the_error_trains_the_changed_pair_towards_the_matched_one_only() -> None:
    u = torch.tensor([[[1.0], [0.0]], [[0.0], [0.0]]], requires_grad=True)  # changed (1, 0), matched (0, 0)
    err = consistency_error(u)
    assert float(err.detach()) == 1.0
    err.backward()
    assert u.grad[0].abs().sum() > 0 and u.grad[1].abs().sum() == 0  # the matched output is the fixed target
    same = torch.ones(4, 2, 2)
    assert float(consistency_error(same)) == 0.0
