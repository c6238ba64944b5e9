"""Bags are written as rosbag2 Jazzy writes them (gyro_thermal_comp/bag_storage.py).

Chunk, data and summary CRCs that readers validate, the offered QoS of each topic in metadata.yaml
and in the mcap channel, the RIHS01 type hash in both, and stamps from the simulator's epoch.
"""
import json
import shutil
import sys
import warnings
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Header
from mcap.stream_reader import CRCValidationError, StreamReader
from rosbags.rosbag2.metadata import parse_qos

from conftest import BAGS
from gyro_thermal_comp.bag_io import BagReader, BagWarning
from gyro_thermal_comp.bag_storage import LATCHED, RELIABLE, SENSOR_DATA
from gyro_thermal_comp.sim import EPOCH_NS

BAG = BAGS / 'carousel_vertical'   # the smallest bundled bag; every topic kind
OFFERED = {'/imu/data_raw': SENSOR_DATA, '/imu/mag': SENSOR_DATA, '/imu/temperature': SENSOR_DATA,
           '/carousel/joint_states': SENSOR_DATA, '/ground_truth/odom': RELIABLE,
           '/ground_truth/gyro_bias': RELIABLE, '/ground_truth/mag_disturbance': RELIABLE, '/sim/config': LATCHED}


def _records(mcap_file, **kw):
    with open(mcap_file, 'rb') as f:
        return list(StreamReader(f, emit_chunks=True, **kw).records)


def _jazzy_hash(msgtype: str) -> str | None:
    """The type hash of the installed Jazzy interface (share/<pkg>/msg/<Type>.json), if there."""
    pkg, _, name = msgtype.split('/')
    path = Path(sys.prefix) / 'share' / pkg / 'msg' / f'{name}.json'
    if not path.is_file():
        return None
    hashes = json.loads(path.read_text())['type_hashes']
    return next(h['hash_string'] for h in hashes if h['type_name'] == msgtype)


def test_chunks_carry_crcs_that_validate():
    (mcap_file,) = BAG.glob('*.mcap')
    records = _records(mcap_file, validate_crcs=True)   # raises on a wrong chunk or data CRC
    chunks = [r for r in records if isinstance(r, Chunk)]
    assert len(chunks) > 1 and all(c.uncompressed_crc != 0 and c.compression == 'zstd' for c in chunks)
    assert next(r for r in records if isinstance(r, DataEnd)).data_section_crc != 0
    assert next(r for r in records if isinstance(r, Footer)).summary_crc != 0
    header = next(r for r in records if isinstance(r, Header))
    assert header.profile == 'ros2'
    with BagReader(BAG) as reader:
        total = sum(t.count for t in reader.topics)
    with open(mcap_file, 'rb') as f:    # the indexed reader validates them too
        assert sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages()) == total


def test_a_wrong_chunk_crc_is_detected(tmp_path):
    """The CRC of a chunk halfway through changed (data intact): mcap refuses it, and BagReader
    (through rosbags, which checks chunk CRCs) reads up to it and says the bag is damaged."""
    bag = tmp_path / BAG.name
    shutil.copytree(BAG, bag)
    (mcap_file,) = bag.glob('*.mcap')
    with open(mcap_file, 'rb') as f:
        indexes = make_reader(f).get_summary().chunk_indexes
        start = indexes[len(indexes) // 2].chunk_start_offset
    data = bytearray(mcap_file.read_bytes())
    crc_at = start + 1 + 8 + 3 * 8      # opcode, record length, start/end time, uncompressed size
    data[crc_at] ^= 0xFF
    mcap_file.write_bytes(bytes(data))
    with pytest.raises(CRCValidationError):
        _records(mcap_file, validate_crcs=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        with BagReader(bag) as reader:
            n = sum(len(c.imu.t) for c in reader.chunks(60.0, streams=['imu']))
            assert reader.truncated
    assert 0 < n < 30000 and any(issubclass(w.category, BagWarning) and 'damaged' in str(w.message) for w in caught)


def test_metadata_and_channels_offer_qos_and_type_hashes():
    info = yaml.safe_load((BAG / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['starting_time']['nanoseconds_since_epoch'] == EPOCH_NS
    topics = {t['topic_metadata']['name']: t['topic_metadata'] for t in info['topics_with_message_count']}
    assert topics.keys() == OFFERED.keys()
    (mcap_file,) = BAG.glob('*.mcap')
    channels = {r.topic: r for r in _records(mcap_file) if isinstance(r, Channel)}
    assert channels.keys() == OFFERED.keys()
    for topic, meta in topics.items():
        assert parse_qos(meta['offered_qos_profiles']) == [OFFERED[topic]], topic
        assert parse_qos(channels[topic].metadata['offered_qos_profiles']) == [OFFERED[topic]], topic
        digest = meta['type_description_hash']
        assert digest.startswith('RIHS01_') and channels[topic].metadata['topic_type_hash'] == digest, topic
        assert _jazzy_hash(meta['type']) in (None, digest), f'{topic}: not the Jazzy hash of {meta["type"]}'


def test_stamps_start_at_the_simulator_epoch():
    """Header stamps and log times both: simulator time t is stamped EPOCH_NS + t."""
    with BagReader(BAG) as reader:
        assert reader.time_origin_ns == EPOCH_NS
        for topic in ('/sim/config', '/imu/data_raw', '/ground_truth/odom'):
            _, _, log_ns, msg = next(reader.messages([topic]))
            assert log_ns == EPOCH_NS, topic
            if hasattr(msg, 'header'):
                assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (EPOCH_NS // 10**9, 0), topic
        chunk = next(reader.chunks(10.0, streams=['imu']))
    assert chunk.imu.t[0] == 0.0 and chunk.imu.t[1] == 0.01    # simulator time, full precision
