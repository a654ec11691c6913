"""Controllers, one module each, all run every 1 ms on measured channels (see base.Controller)."""
from .base import Controller
from .open_loop import OpenLoop
from .pd_joint import PDJoint
from .pd_tip import PDTip

# controller.type in a scenario or sidecar -> class taking the table's other keys as arguments
CONTROLLERS = {"pd_tip": PDTip, "pd_joint": PDJoint}

__all__ = ["Controller", "OpenLoop", "PDJoint", "PDTip", "CONTROLLERS"]
