"""`--topic STREAM=/name`: which topic of a bag feeds which stream, with the node's remap names.

A stream is a `SensorChunk` field (imu, mag, temperature, joint, imu_aux, odom, gyro_bias,
mag_disturbance). The key may also be the node's relative topic name, as in a remap
(`imu/data_raw:=/my_imu/data_raw` becomes `--topic imu/data_raw=/my_imu/data_raw`), so a robot's
remaps carry over unchanged.
"""
from __future__ import annotations

from typing import Iterable

from .. import topics
from .base import SourceError

STREAMS = tuple(topics.BAG_STREAMS)
# the node's relative topic names (topics.py) -> stream
NODE_TOPICS = {topic.lstrip('/'): name for name, (topic, _) in topics.BAG_STREAMS.items()}


def stream_name(key: str) -> str:
    """A stream name from a stream name or a node topic name (leading '/' optional)."""
    if key in STREAMS:
        return key
    name = NODE_TOPICS.get(key.lstrip('/'))
    if name is None:
        raise SourceError(f'--topic {key}=...: unknown stream {key!r}; streams: {", ".join(STREAMS)} '
                          f'(or the node topic names {", ".join(NODE_TOPICS)})')
    return name


def parse_topic_map(items: Iterable[str] | dict | None) -> dict[str, str]:
    """['imu=/my_imu/data_raw', 'imu/mag=/my_imu/mag'] (or a dict) -> {'imu': '/my_imu/data_raw',
    'mag': '/my_imu/mag'}; SourceError for a malformed item or a stream given twice."""
    if not items:
        return {}
    pairs = items.items() if isinstance(items, dict) else [_split(item) for item in items]
    out: dict[str, str] = {}
    for key, topic in pairs:
        name = stream_name(key)
        if name in out and out[name] != topic:
            raise SourceError(f'--topic: stream {name} given twice ({out[name]} and {topic})')
        out[name] = topic if topic.startswith('/') else '/' + topic
    return out


def _split(item: str) -> tuple[str, str]:
    key, sep, topic = item.partition('=')
    if key.endswith(':'):      # a remap written as imu/data_raw:=/x
        key = key[:-1]
    if not sep or not key or not topic.strip('/'):
        raise SourceError(f'--topic expects STREAM=/topic (e.g. imu=/my_imu/data_raw), got {item!r}')
    return key, topic
