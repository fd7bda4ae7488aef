"""Reading rosbag2 recordings (directory or .mcap) with the ``rosbags`` library, for the tools."""
from pathlib import Path


def open_bag(bag):
    """Open a bag for reading (caller closes it); ``ValueError`` when it cannot be read."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = Path(bag)
    if not path.exists():
        raise ValueError('no such bag: %s' % path)
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as error:  # rosbags raises several reader errors (and OSError)
        raise ValueError('cannot read bag %s: %s' % (path, error)) from None
    return reader


def pick_connections(connections, suffix, msgtype):
    """Return the connections of the busiest ``.../suffix`` topic of type ``msgtype``.

    ``suffix`` is the exact topic or its last name parts ('tip' matches '/a/tip').
    """
    matching = [c for c in connections
                if c.msgtype == msgtype and (c.topic == suffix or c.topic.endswith('/' + suffix))]
    if not matching:
        return []
    counts = {}
    for c in matching:
        counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
    topic = max(sorted(counts), key=counts.get)
    return [c for c in matching if c.topic == topic]
