"""PyBullet simulation: the six-direction grasp evaluator (canonical and original hands)."""

from ohra.sim.pybullet_import import import_pybullet

import_pybullet()  # first, so that no submodule's `import pybullet` prints the build-time line

from ohra.sim.controller import closes_positive, squeeze_targets
from ohra.sim.evaluator import PHASES, EvalReport, GraspEvaluator, GraspResult, evaluate_grasps, run_grasp
from ohra.sim.hands import SimHand
from ohra.sim.protocol import DIRECTION_NAMES, DIRECTIONS, Protocol, ProtocolError

__all__ = [
    "GraspEvaluator", "Protocol", "ProtocolError", "EvalReport", "GraspResult", "SimHand", "DIRECTIONS", "DIRECTION_NAMES", "PHASES",
    "evaluate_grasps", "run_grasp", "closes_positive", "squeeze_targets",
]
