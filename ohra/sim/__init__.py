"""PyBullet simulation: the six-direction grasp evaluator."""

from .evaluator import DIRECTIONS, EvalReport, GraspEvaluator, GraspResult, Protocol

__all__ = ["GraspEvaluator", "Protocol", "EvalReport", "GraspResult", "DIRECTIONS"]
