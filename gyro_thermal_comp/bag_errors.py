"""The errors and warnings of bag reading (bag_reader.py) and writing (bag_writer.py)."""


class BagError(ValueError):
    """A bag that cannot be read or written; the message is one line meant for the user.

    Raised for: not a bag / unreadable, no readable message on the streams asked for, a known
    stream topic (topics.BAG_STREAMS, or the reader's topic_map) carrying another message type, and
    output bags that cannot be written."""


class BagWarning(UserWarning):
    """A bag that is read only in part (truncated, damaged, undecodable messages). The message is
    one line meant for the user; it is issued once per bag and message text (the default warning
    filter deduplicates it), and the CLI prints it as `gyro-thermal-comp: warning: <message>`."""
