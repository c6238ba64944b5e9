"""The rosbag2 folder as rosbag2 Jazzy (`ros2 bag record -s mcap`) writes it, built on rosbags.

rosbags writes the metadata.yaml (version 9: offered QoS profiles as YAML lists, type description
hashes) but its mcap storage writes chunk CRCs of 0 and no `topic_type_hash` in the channel metadata.
`Rosbag2Writer` is rosbags' Writer with the mcap storage replaced by one built on the `mcap` library
that writes what rosbag2_storage_mcap writes: profile `ros2`, zstd chunks with CRCs (readers such as
rosbags and `mcap` validate them), a summary CRC, channel metadata `offered_qos_profiles` and
`topic_type_hash`, the `rosbag2` metadata record. A data section CRC is written too (rosbag2 leaves
it 0), so a stream reader can validate the whole file.

`offered_qos(topic)` is the QoS the recorded publisher offered, as rosbag2 records it from discovery.
"""
from __future__ import annotations

from importlib.metadata import version

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.interfaces import (MessageDefinitionFormat, Qos, QosDurability, QosHistory, QosLiveliness,
                                QosReliability, QosTime)
from rosbags.rosbag2 import CompressionMode, StoragePlugin, Writer

from . import topics

# rosbag2 records the offered QoS from DDS discovery, which carries neither history nor depth;
# unset durations are RMW_DURATION_INFINITE.
_INFINITE = QosTime(9223372036, 854775807)


def _offered(reliability: QosReliability, durability: QosDurability = QosDurability.VOLATILE) -> Qos:
    return Qos(QosHistory.UNKNOWN, 0, reliability, durability, _INFINITE, _INFINITE,
               QosLiveliness.AUTOMATIC, _INFINITE, False)


SENSOR_DATA = _offered(QosReliability.BEST_EFFORT)      # drivers: rclpy's qos_profile_sensor_data
RELIABLE = _offered(QosReliability.RELIABLE)            # node outputs, diagnostics, ground truth
LATCHED = _offered(QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)   # published once

_SENSOR_STREAMS = ('imu', 'imu_aux', 'mag', 'temperature', 'joint')
_OFFERED = {**{topics.BAG_STREAMS[s][0]: SENSOR_DATA for s in _SENSOR_STREAMS}, topics.SIM_CONFIG: LATCHED}


def offered_qos(topic: str) -> Qos:
    """The QoS a publisher of `topic` offers: sensor data (best effort) for the raw sensor topics,
    reliable + transient local for /sim/config (sent once), reliable for everything else."""
    return _OFFERED.get(topic, RELIABLE)


class _McapStorage:
    """rosbags' storage-writer interface over `mcap.writer.Writer` (chunk and summary CRCs on)."""

    def __init__(self, path, compression: CompressionMode):
        self.path = path / f'{path.name}.mcap'
        self._file = self.path.open('xb')
        kind = CompressionType.ZSTD if compression == CompressionMode.STORAGE else CompressionType.NONE
        self._mcap = McapWriter(self._file, chunk_size=1 << 20, compression=kind,
                                enable_crcs=True, enable_data_crcs=True)
        self._mcap.start(profile='ros2', library=f'rosbags-{version("rosbags")}; {LIBRARY_IDENTIFIER}')
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}   # rosbags connection id -> mcap channel id

    def add_msgtype(self, connection) -> None:
        encoding = 'ros2msg' if connection.msgdef.format == MessageDefinitionFormat.MSG else 'ros2idl'
        self._schemas[connection.msgtype] = self._mcap.register_schema(
            connection.msgtype, encoding, connection.msgdef.data.encode())

    def add_connection(self, connection, offered_qos_profiles: str) -> None:
        self._channels[connection.id] = self._mcap.register_channel(
            connection.topic, connection.ext.serialization_format, self._schemas[connection.msgtype],
            {'offered_qos_profiles': offered_qos_profiles, 'topic_type_hash': connection.digest})

    def write(self, connection, timestamp: int, data) -> None:
        # rosbag2 Jazzy sets publish time = log time when the transport gives no send time
        self._mcap.add_message(self._channels[connection.id], log_time=timestamp, data=bytes(data),
                               publish_time=timestamp)

    def close(self, version_: int, metadata: str) -> None:
        self._mcap.flush()   # the last chunk before the metadata record, as rosbag2 orders them
        self._mcap.add_metadata('rosbag2', {'serialized_metadata': metadata})
        self._mcap.finish()
        self._file.close()

    def abort(self) -> None:
        self._file.close()


class Rosbag2Writer(Writer):
    """rosbags' rosbag2 Writer whose mcap files carry CRCs and the channel metadata rosbag2 writes."""
    STORAGE_PLUGINS = {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _McapStorage}
