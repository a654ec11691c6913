"""Controllers, one module each, all run every 1 ms on measured channels (see base.Controller)."""
from .base import Controller
from .cascade_p import CascadeP
from .open_loop import OpenLoop
from .pd_joint import PDJoint
from .pd_tip import PDTip
from .pi_velocity import PIVelocity

# controller.type in a scenario or sidecar -> class taking the table's other keys as arguments
CONTROLLERS = {"pd_tip": PDTip, "pd_joint": PDJoint, "cascade_p": CascadeP}
CONTROLLERS["pi_velocity"] = PIVelocity  # thesis 4.5.4 friction map (gain-scheduled PI velocity)
from .fuzzy_pd import FuzzyPD  # noqa: E402
CONTROLLERS["fuzzy_pd"] = FuzzyPD  # laser_arm_paper 2.4 fuzzy PD on the tip sensor
from .observer import Observer, make_observer  # noqa: E402
from .passivity import Passivity, make_passivity  # noqa: E402
CONTROLLERS["observer"] = make_observer  # thesis 5.2 observer-based recursive joint control
CONTROLLERS["passivity"] = make_passivity  # thesis 5.1 passivity-based Cartesian PD
from .pid import PID  # noqa: E402
from .state_feedback import StateFeedback  # noqa: E402
CONTROLLERS["state_feedback"] = StateFeedback  # u = K (x_ref - x) on any named channels (issue 15)
CONTROLLERS["pid"] = PID  # PID on any named channels (issue 15)
from .linear import Linear  # noqa: E402
CONTROLLERS["linear"] = Linear  # a discrete state space or transfer functions on named channels (a lab's LQG, H-inf)

__all__ = ["CascadeP", "Controller", "FuzzyPD", "Observer", "OpenLoop", "Passivity", "PDJoint", "PDTip", "PIVelocity", "PID",
           "StateFeedback", "Linear", "CONTROLLERS"]
