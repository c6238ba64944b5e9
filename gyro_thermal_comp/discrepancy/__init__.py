"""Model-discrepancy workflow: where the thermal drift model and a bag disagree, which named effect
is missing, and how much adding it closes the gap (docs/discrepancy.md). No ROS imports.

    from gyro_thermal_comp.discrepancy import discover
    result = discover(bag_path, reference='static', report_dir='report/')
    result.verdict, result.effects, result.to_dict()
"""
from .candidates import BY_NAME, LIBRARY, Candidate
from .data import BinnedData, DiscoveryInputError, bin_chunks, load_bins
from .selection import Criteria
from .workflow import VERDICTS, DiscoveryResult, discover

__all__ = ['BY_NAME', 'LIBRARY', 'Candidate', 'BinnedData', 'DiscoveryInputError', 'bin_chunks', 'load_bins',
           'Criteria', 'VERDICTS', 'DiscoveryResult', 'discover']
