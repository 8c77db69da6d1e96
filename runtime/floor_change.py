"""A floor that changed since the teach, kept out of VelocityNet's view where the teach drove straight on.

VelocityNet was trained on floors that stay as they were taught, and it steers by them: on a re-coloured floor
(every tile laid again) it steers away from the path (issue 20: 12 of 14 hidden routes stopped), and the floor
registration that brings the robot back (``runtime.side_offset``) reads nothing there. The registration also
says when the floor changed: the median floor row of the view matches the taught floor at the estimate under
no shift better than ``SideConfig.match`` (the score a row must beat to count: 0 the same floor, about 1.1
unrelated rows). On development routes gen_100-119 (seed 0, scored every commanded step) that held on 99.2% of
the steps on a re-coloured floor against none under noise, light, a colour cast or a repainted wall, 1% from a
start 10 cm / 10 deg off and 4% under moved furniture (furniture standing on the rows).

There, VelocityNet is shown the camera's view down to the row where the registered floor starts
(``SideOffset.floor_row``: the floor ``far_m`` ahead) and the subgoal's view below it: the walls and what stands
on the floor tell it where the robot is, a floor that agrees with the subgoal's tells it nothing, and nothing
of the new floor steers it away (dev gen_100-139, seeds 0 1, re-coloured floor: 62 -> 71/80 completed).
Only where the teach drove straight on (``RouteLocaliser.straight``): in a taught arc VelocityNet turned the
robot by what the floor showed it, and with the taught floor below the walls it turned too little (dev gen_131,
0.10 against 0.26 rad/s taught) and left the arc until it touched furniture (2 contacts; straight on only: 69/80,
no contact). The camera stop and the floor registration still judge the camera's own view.
"""

from __future__ import annotations

import numpy as np

from vtr.runtime.frame import Frame
from vtr.runtime.side_offset import SideOffset


class FloorChange:
    """The view VelocityNet is shown where the floor changed since the teach (see the module docstring)."""

    def __init__(self, registration: SideOffset | None, straight: np.ndarray) -> None:
        """``registration``: the route's floor registration (None: no taught poses, nothing hidden);
        ``straight``: (L,) per subgoal whether the teach drove on there without turning much either side."""
        self.registration, self.straight = registration, np.asarray(straight, dtype=bool)
        #: whether the floor of the last view asked was not the teach's
        self.changed = False

    def shown(self, image: Frame, position: float, subgoal: np.ndarray) -> Frame | None:
        """The view VelocityNet is shown for ``image`` at route ``position`` (subgoal units) steering to
        ``subgoal`` (its (H, W, 3) image): the camera's above the floor and the subgoal's floor, where the
        floor changed and the teach drove straight on; None elsewhere (the camera's view as it is)."""
        self.changed = False
        if self.registration is None or len(self.straight) == 0:
            return None
        if not self.straight[min(max(int(round(position)), 0), len(self.straight) - 1)]:
            return None
        reg = self.registration
        self.changed = reg.floor_match(image, position) > reg.cfg.match
        if not self.changed:
            return None
        row = reg.floor_row
        return Frame.decoded(np.concatenate([image.image[:row], subgoal[row:]], axis=0))


__all__ = ["FloorChange"]
