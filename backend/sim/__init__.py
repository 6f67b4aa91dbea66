"""Simulation adapter: the only code that imports mujoco or viser.

Importing this package imports neither: physics lives in `tableteach.sim.physics`, the browser view
in `tableteach.sim.view` and the per-participant runner in `tableteach.sim.session` (see docs/sim.md).
"""

from .trace_world import TraceWorld
from .world import OBJECTS, PlacementError, TableWorld

__all__ = ["OBJECTS", "PlacementError", "TableWorld", "TraceWorld"]
