"""The progress gate: the controller switches past a subgoal only after the robot was told to travel
toward it (or after its patience), so its index cannot run ahead of the robot."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from texture_views import view

from vtr.runtime.controller import Action, Controller, ControllerConfig
from vtr.runtime.progress_gate import ProgressGate

ROUTE = np.stack([view(100 + 2 * k) for k in range(6)])
#: taught poses: 5 cm along x per subgoal, then a 10 deg turn in place into the last one
POSES = np.array([[0.05 * k, 0.0, 0.0] for k in range(5)] + [[0.2, 0.0, math.radians(10)]])


def gated(**changes) -> ControllerConfig:
    return replace(ControllerConfig(progress_gate=0.8, gate_patience=2, settle_steps=0), **changes)


def test_taught_travel_into_each_subgoal_and_the_carry_over():
    g = ProgressGate(POSES, len(POSES), 0.8, 2)
    np.testing.assert_allclose(g.distance, [0, 0.05, 0.05, 0.05, 0.05, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.turn, [0, 0, 0, 0, 0, math.radians(10)], atol=1e-12)
    assert g.passes(0)  # the start is never gated
    g.reset(1)
    g.commanded(0.2, 0.0, 0.1)  # 2 cm of the 5
    assert g.progress == pytest.approx(0.4) and not g.passes(1)
    g.commanded(-0.5, 0.0, 0.1)  # backing up is travel too: 7 cm of 5
    assert g.passes(1)
    g.reset(2)  # the next subgoal: the 2 cm beyond subgoal 1 count toward it
    assert g.progress == pytest.approx(0.4)
    g.reset(5)  # a jump: nothing carries over
    assert g.progress == 0.0
    g.commanded(0.0, 0.2, 0.1)  # a turn in place is measured in heading: 0.02 of 0.175 rad
    assert not g.passes(5)
    g.commanded(0.0, 1.5, 0.1)
    assert g.passes(5)
    with pytest.raises(ValueError, match="taught poses"):
        ProgressGate(POSES[:, :2], len(POSES), 0.8, 2)


def test_a_matching_view_waits_for_travel_then_switches():
    c = Controller(ROUTE, gated(), poses=POSES)
    assert c.decide(ROUTE[0]).action is Action.ADVANCE  # subgoal 0: not gated
    # the view already matches subgoal 1 (low parallax), but the robot was told to move nowhere yet
    d = c.decide(ROUTE[1])
    assert d.action is Action.COMMAND and d.note == "waiting for travel" and c.index == 1
    c.commanded(0.3, 0.0, 0.1)  # 3 cm of the taught 5: not yet 80%
    assert c.decide(ROUTE[1]).note == "waiting for travel"
    c.commanded(0.2, 0.0, 0.1)  # 5 cm
    assert c.decide(ROUTE[1]).action is Action.ADVANCE and c.index == 2


def test_patience_counts_only_commands_that_hardly_move_the_robot():
    c = Controller(ROUTE, gated(), poses=POSES)
    c.decide(ROUTE[0])
    assert c.decide(ROUTE[1]).note == "waiting for travel"
    c.commanded(0.1, 0.0, 0.1)  # the policy still drives toward subgoal 1 (1 cm): not idle
    assert c.decide(ROUTE[1]).note == "waiting for travel"
    c.commanded(0.001, 0.0, 0.1)  # idle
    assert c.decide(ROUTE[1]).note == "waiting for travel"
    c.commanded(0.0, 0.0, 0.1)  # idle: patience 2 reached
    assert c.decide(ROUTE[1]).action is Action.ADVANCE and c.index == 2


def test_the_gate_holds_the_relative_rule_too():
    cfg = gated(e_m_mode="fixed", e_m=1e-3, pass_ratio=1.0, stall_steps=0, gate_patience=5)
    c = Controller(ROUTE, cfg, poses=POSES)
    c._set_index(1)
    d = c.decide(view(100 + 2 + 1 + 1))  # past halfway to subgoal 2: the relative rule would switch
    assert d.action is Action.COMMAND and c.index == 1 and c.early_switches == 0
    c.commanded(0.5, 0.0, 0.1)
    assert c.decide(view(100 + 2 + 1 + 1)).action is Action.ADVANCE and c.early_switches == 1


def test_on_by_default_off_without_poses_and_for_the_paper_and_before():
    assert Controller(ROUTE, ControllerConfig(), poses=POSES).gate is not None
    assert ControllerConfig.paper().progress_gate == 0.0 and ControllerConfig.before().progress_gate == 0.0
    off = ControllerConfig(settle_steps=0, progress_gate=0.0)
    for c in (Controller(ROUTE, gated()), Controller(ROUTE, off, poses=POSES)):
        assert c.gate is None
        c.decide(ROUTE[0])
        assert c.decide(ROUTE[1]).action is Action.ADVANCE
    with pytest.raises(ValueError, match="progress_gate"):
        ControllerConfig(progress_gate=-0.1)


def test_what_fell_short_is_owed_so_the_lag_cannot_grow():
    g = ProgressGate(POSES, len(POSES), 0.5, 1)
    g.reset(1)
    g.commanded(0.3, 0.0, 0.1)  # 3 cm of 5: past the fraction, 2 cm short
    assert g.passes(1)
    g.reset(2)
    assert g.progress == pytest.approx(-0.4)
    g.commanded(0.3, 0.0, 0.1)  # 3 cm more: 6 of the 10 taught so far
    assert g.progress == pytest.approx(0.2) and not g.passes(2)
    g.commanded(0.0, 0.0, 0.1)  # idle: the patience (1) lets it through and forgets the debt
    assert g.passes(2)
    g.reset(3)
    assert g.progress == 0.0
