"""Grasp synthesis for any canonical hand: CasADi/IPOPT force-closure NLP + PyBullet filter."""

from .nlp import GraspNLP, NLPSettings
from .pipeline import SynthSettings, synthesize, synthesize_shard

__all__ = ["GraspNLP", "NLPSettings", "SynthSettings", "synthesize", "synthesize_shard"]
