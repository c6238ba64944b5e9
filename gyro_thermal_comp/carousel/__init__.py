"""Carousel (rotation-modulation) demodulation for a turning MEMS IMU; pure numpy, no ROS.

See docs/carousel.md (its "Modules" table maps the pipeline onto the files here). Entry point:
`CarouselDemodulator(CarouselConfig()).update(chunk)`.
"""
from .bias_book import SensorBiasBook
from .config import CarouselConfig, FlipConfig
from .demodulator import CarouselDemodulator
from .flip import FlipEvent, flip_rotation
from .lockin import LockInEstimator, LockInSolution, RevolutionStats
from .records import DemodulatedOutput, GyroBiasMeasurement, HighRateSamples, RevolutionRecord, records_as_arrays
from .revolutions import Crossing, RevolutionLadder

__all__ = ['CarouselConfig', 'FlipConfig', 'CarouselDemodulator', 'DemodulatedOutput', 'GyroBiasMeasurement',
           'HighRateSamples', 'RevolutionRecord', 'records_as_arrays', 'FlipEvent', 'flip_rotation',
           'LockInEstimator', 'LockInSolution', 'RevolutionStats', 'Crossing', 'RevolutionLadder',
           'SensorBiasBook']
