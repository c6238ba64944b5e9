"""Evaluation layer: scoring heading methods against ground truth (docs/design.md section 5).

No ROS imports: everything here works on SensorChunk streams.
"""
from .peers import FusionPeer, MahonyPeer, attitude_from_accel_mag, default_peers
from .report import EvaluationReport, NotApplicable, chunks_from_list, evaluate
from .scoring import ORACLE, RAW, HeadingScorer, RunningStats, ScoreResult, ScoringError

__all__ = ['FusionPeer', 'MahonyPeer', 'attitude_from_accel_mag', 'default_peers',
           'EvaluationReport', 'NotApplicable', 'chunks_from_list', 'evaluate',
           'ORACLE', 'RAW', 'HeadingScorer', 'RunningStats', 'ScoreResult', 'ScoringError']
