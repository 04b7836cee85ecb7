"""What the ROS 2 test peers (tests/ros2_peer.py, ros2_ur_peer.py) share: a DDS participant.

Each peer is its own Cyclone participant on `ROS_DOMAIN_ID`; a thread takes the raw CDR bytes
of every reader's samples and hands them to the peer, which decodes them with rosbags. Nothing
from armfleet is imported, so what armfleet writes is judged by an independent implementation.
"""

from __future__ import annotations

import os
import threading
import time

from cyclonedds._clayer import ddspy_take
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader

ANY = SampleState.Any | ViewState.Any | InstanceState.Any


class Participant:
    """A participant whose readers (`topic` → reader and its ROS type) are polled for bytes."""

    def __init__(self) -> None:
        self.dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
        self.readers: dict[str, tuple[DataReader, str]] = {}
        self.lock = threading.Lock()
        threading.Thread(target=self._poll, daemon=True).start()

    def received(self, topic: str, ros_type: str, raw: bytes) -> None:
        """One valid sample's CDR bytes, as written (no cyclonedds decoding)."""
        raise NotImplementedError

    def _poll(self) -> None:
        while True:
            with self.lock:
                readers = list(self.readers.items())
            for topic, (reader, ros_type) in readers:
                for data, info in ddspy_take(reader._ref, ANY, 64):
                    if info.valid_data:
                        self.received(topic, ros_type, bytes(data))
            time.sleep(0.005)
