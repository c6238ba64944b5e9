"""Carousel (rotation-modulation) demodulation for a turning MEMS IMU; pure numpy, no ROS.

See docs/carousel.md. Entry point: `CarouselDemodulator(CarouselConfig()).update(chunk)`.
"""
from .config import CarouselConfig, FlipConfig
from .demodulator import (CarouselDemodulator, DemodulatedOutput, GyroBiasMeasurement, HighRateSamples,
                          RevolutionRecord, records_as_arrays)
from .flip import FlipEvent, flip_rotation
from .lockin import LockInEstimator, LockInSolution, RevolutionStats
from .revolutions import Crossing, RevolutionLadder

__all__ = ['CarouselConfig', 'FlipConfig', 'CarouselDemodulator', 'DemodulatedOutput', 'GyroBiasMeasurement',
           'HighRateSamples', 'RevolutionRecord', 'records_as_arrays', 'FlipEvent', 'flip_rotation',
           'LockInEstimator', 'LockInSolution', 'RevolutionStats', 'Crossing', 'RevolutionLadder']
