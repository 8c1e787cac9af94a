"""Grasp synthesis for any canonical hand: CasADi/IPOPT force-closure NLP + PyBullet filter."""

from ohra.synth.nlp import GraspNLP, NLPSettings
from ohra.synth.pipeline import SynthSettings, synthesize, synthesize_shard

__all__ = ["GraspNLP", "NLPSettings", "SynthSettings", "synthesize", "synthesize_shard"]
