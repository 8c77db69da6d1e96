"""What the controller decides on an image (runtime.controller): an action, and the events before it."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class Action(str, enum.Enum):
    COMMAND = "command"  # run the policy on (image, subgoal) and apply its first (v, w)
    ADVANCE = "advance"  # the subgoal was reached: move on to the next (same image, decide again)
    JUMP = "jump"  # stall guard or localisation moved the subgoal index (decide again)
    FINISHED = "finished"  # past the last subgoal
    STALLED = "stalled"  # stall guard found nothing close: stop
    LOST = "lost"  # no subgoal near the current one matches the view: stop
    COLLIDED = "collided"  # the robot reported a contact: stop
    BLOCKED = "blocked"  # something is in the way: hold still and wait for it to clear (not terminal)


TERMINAL = (Action.FINISHED, Action.STALLED, Action.LOST, Action.COLLIDED)


@dataclass(frozen=True)
class Decision:
    action: Action
    #: Subgoal index the decision is about (for COMMAND: the one to steer to; for ADVANCE/JUMP: the new one).
    index: int
    #: Distance (matcher units; 0..255 for raw) of the image to the subgoal it was judged against.
    error: float
    #: COMMAND only: send a zero command after the control step (False in continuous mode).
    then_stop: bool = True
    note: str = ""
    #: COMMAND only: |v| the robot may drive at (0 during a taught turn in place, see ``hold_turns``).
    v_limit: float = math.inf
    #: COMMAND only: (weight of v, weight of w, v, w): blend the taught command with the policy's.
    prior: tuple[float, float, float, float] | None = None
    #: COMMAND only: rad/s added to the turn after the blend (the follower's correction toward the taught path).
    turn: float = 0.0


#: Decisions the controller takes without moving the robot: it acts on them itself and judges again.
SWITCHES = (Action.ADVANCE, Action.JUMP)


@dataclass(frozen=True)
class Verdict:
    """Everything the controller decided on one image (:meth:`Controller.judge`).

    ``decision`` is the one the repeat loop acts on: COMMAND, FINISHED or STALLED. ``events`` are the
    ADVANCE and JUMP decisions the controller took and acted on before it, in order (empty when the
    subgoal did not change); ``from_index`` is the subgoal index before this image was judged.
    """

    decision: Decision
    events: tuple[Decision, ...]
    from_index: int
