"""rosbag2 (mcap) reading and writing: the package's bag API, in one import.

The modules below are the only ones that parse or build bag messages:

- bag_reader.py: `BagReader` (a bag as a stream of time-ordered SensorChunks, damaged bags read as
  far as they go), `read_chunks`, `TopicInfo` and `RawRecords` (records as stored, for copying);
- bag_writer.py: `BagWriter` (SensorChunks, ROS messages and raw records into a rosbag2 folder);
- bag_messages.py: the message builders, CDR encoders and decoders between samples and messages,
  `Covariances`, `stamp_to_ns`, and the per-stream decoding used by readers of other bag formats
  (`stream_msgtypes`, `message_row`, `samples_from_rows`);
- bag_errors.py: `BagError` and `BagWarning`;
- bag_storage.py: the rosbag2 folder and mcap file as rosbag2 Jazzy writes them.
"""
from .bag_errors import BagError, BagWarning
from .bag_messages import NO_ORIENTATION_COV, Covariances, message_row, samples_from_rows, stamp_to_ns, stream_msgtypes
from .bag_reader import BagReader, RawRecords, TopicInfo, read_chunks
from .bag_writer import BagWriter
from .cdr import TYPESTORE

__all__ = ['BagError', 'BagReader', 'BagWarning', 'BagWriter', 'Covariances', 'NO_ORIENTATION_COV', 'RawRecords',
           'TYPESTORE', 'TopicInfo', 'message_row', 'read_chunks', 'samples_from_rows', 'stamp_to_ns',
           'stream_msgtypes']
