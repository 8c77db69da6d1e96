"""Whether the floor was laid again since the teach: the floor registration (``runtime.side_offset``) read none
of the robot's last views, where the taught floor registers against itself.

The camera stop (``runtime.obstruction``) stops for floor ahead that no longer matches the taught floor. A
re-coloured or re-laid floor matches nowhere, and on development routes the floor beside the path, which is to
tell that apart from a box, matched at these false stops as often as beside real boxes (52-63% of its tiles,
53-100% beside boxes). The floor rows the side registration reads tell it apart: beside a box on the path it read
the floor in 2-12 of the last 12 views it was asked (most 12 of 12); at the false stops on the re-coloured floor
in none of 6-12 (13 of 15 stops; 2 of 3 and 2 of 5 in the other two). A floor that registers nowhere, even
against its own taught view (plain, or a pattern that repeats), tells nothing either way, so only views whose
taught floor registers against itself count.
"""

from __future__ import annotations

from collections import deque

from vtr.runtime.floor_view import taught_offset
from vtr.runtime.side_offset import SideEstimate, SideOffset

#: The last views asked whose taught floor registers that are remembered, and how many of them must be asked
#: before none registering says the floor was laid again.
RELAID_VIEWS, RELAID_MIN = 12, 3


class FloorRelaid:
    """The floor registration's outcomes on the last views (see the module docstring)."""

    def __init__(self, registration: SideOffset | None) -> None:
        """``registration``: the route's floor registration (None: none, and the floor is never judged re-laid)."""
        self.registration = registration
        self._tells: dict[int, bool] = {}  # per taught view: whether it registers against itself
        self.recent: deque[bool] = deque(maxlen=RELAID_VIEWS)

    def tells(self, k: int) -> bool:
        """Whether taught view ``k``'s floor registers against itself (made once per view)."""
        if k not in self._tells:
            reg = self.registration
            assert reg is not None  # seen() asks only with one
            self._tells[k] = reg.estimate(reg.subgoals[k], float(k)) is not None
        return self._tells[k]

    def seen(self, position: float, found: SideEstimate | None) -> None:
        """A view at route ``position`` (subgoal units) was registered: ``found`` (None: the floor did not tell)."""
        if self.registration is not None and self.tells(taught_offset(self.registration.poses, position)[0]):
            self.recent.append(found is not None)

    @property
    def relaid(self) -> bool:
        """None of the last views registered, and at least ``RELAID_MIN`` were asked."""
        return len(self.recent) >= RELAID_MIN and not any(self.recent)

    def reset(self) -> None:
        self.recent.clear()


__all__ = ["RELAID_MIN", "RELAID_VIEWS", "FloorRelaid"]
