"""Record ROS topics to MCAP with ROS 2 (CDR) serialization, and read them back.

The files are what rosbag2's MCAP storage writes: one ``ros2msg`` schema per type (the full
definition with nested types), one ``cdr`` channel per topic, message log times in nanoseconds,
plus metadata records. rosbag2 (``ros2 bag info``), Foxglove and ``mcap-ros2-support`` read them.
Messages are taken raw (serialized) from the subscription, so recording costs no (de)serialization.
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from ppod_nodes.common.events import quiet_subscription
from ppod_nodes.common.msgdict import type_from_name
from ppod_nodes.record.msgdef import full_definition
from ppod_ros.errors import ConfigError

PROFILE = "ros2"
#: Types recorded under another, wire-identical name: no tf2_msgs wheel exists, so TF travels as
#: ppod_msgs/msg/TFMessage (same definition) and is written as the type every ROS tool draws.
RECORDED_AS = {"ppod_msgs/msg/TFMessage": "tf2_msgs/msg/TFMessage"}
_RECORDED_FROM = {v: k for k, v in RECORDED_AS.items()}
#: rosbag2's QoS enumerations as it writes them in ``offered_qos_profiles`` (rmw_qos_*_policy_e).
_INFINITE = {"sec": 2147483647, "nsec": 4294967295}


def qos_profiles_yaml(infos) -> str:
    """rosbag2's ``offered_qos_profiles`` channel metadata: the publishers' QoS as a YAML list."""
    import yaml

    out = []
    for i in infos:
        q = i.qos_profile
        out.append({"history": int(q.history), "depth": int(q.depth), "reliability": int(q.reliability),
                    "durability": int(q.durability), "deadline": dict(_INFINITE), "lifespan": dict(_INFINITE),
                    "liveliness": int(q.liveliness), "liveliness_lease_duration": dict(_INFINITE),
                    "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions)})
    return yaml.safe_dump(out, sort_keys=False)


@dataclass
class RecordedMessage:
    topic: str
    type_name: str
    log_time_ns: int
    data: bytes

    def decode(self) -> Any:
        return deserialize_message(self.data, type_from_name(self.type_name))


class McapRecorder:
    """Subscribe (raw) to topics of a running system and write them to an MCAP file.

    Parameters
    ----------
    node : rclpy Node
        The node that subscribes (its executor must spin elsewhere).
    path : Path
        Output file (overwritten).
    include : callable(topic, type_name) -> bool
        Which discovered topics to record.
    metadata : dict of str -> dict of str
        MCAP metadata records written at the start (e.g. the configuration of the session).
    """

    def __init__(self, node, path: Path, include, metadata: dict[str, dict[str, str]] | None = None,
                 discovery_period_s: float = 0.5):
        self.node = node
        self.path = Path(path)
        self.include = include
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="ppod record")
        for name, data in (metadata or {}).items():
            self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._subs: dict[str, Any] = {}
        self._types: dict[str, str] = {}
        self._qos: dict[str, str] = {}
        self._first_ns: int | None = None
        self._last_ns = 0
        self.counts: dict[str, int] = {}
        self._closed = False
        self._timer = node.create_timer(discovery_period_s, self.discover)

    def discover(self) -> None:
        """Subscribe to newly appeared topics that ``include`` accepts."""
        if self._closed:
            return
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subs or not types or not self.include(topic, types[0]):
                continue
            type_name = types[0]
            try:
                msg_type = type_from_name(type_name)
                definition = full_definition(type_name)
            except (ImportError, ValueError, FileNotFoundError) as exc:
                self.node.get_logger().warning(f"not recording {topic}: {exc}")
                self._subs[topic] = None
                continue
            infos = self.node.get_publishers_info_by_topic(topic)
            qos = QoSProfile(
                depth=100,
                durability=(DurabilityPolicy.TRANSIENT_LOCAL
                            if any(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
                            else DurabilityPolicy.VOLATILE),
                reliability=(ReliabilityPolicy.BEST_EFFORT
                             if any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
                             else ReliabilityPolicy.RELIABLE),
            )
            schema_name = RECORDED_AS.get(type_name, type_name)
            with self._lock:
                if schema_name not in self._schemas:
                    self._schemas[schema_name] = self._writer.register_schema(schema_name, "ros2msg",
                                                                              definition.encode())
                self._qos[topic] = qos_profiles_yaml(infos)
                self._channels[topic] = self._writer.register_channel(
                    topic, "cdr", self._schemas[schema_name], metadata={"offered_qos_profiles": self._qos[topic]})
                self._types[topic] = schema_name
            self.counts[topic] = 0
            self._subs[topic] = self.node.create_subscription(
                msg_type, topic, lambda data, t=topic: self._write(t, data), qos, raw=True,
                event_callbacks=quiet_subscription())

    def _write(self, topic: str, data: bytes) -> None:
        now = time.time_ns()
        with self._lock:
            if self._closed:
                return
            self._writer.add_message(self._channels[topic], log_time=now, data=data, publish_time=now,
                                     sequence=self.counts[topic])
            self.counts[topic] += 1
            self._first_ns = now if self._first_ns is None else self._first_ns
            self._last_ns = now

    def _rosbag2_metadata(self) -> str:
        return _rosbag2_metadata_text(self.counts, self._types, self._first_ns, self._last_ns, self.path, self._qos)

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.add_metadata("rosbag2", {"serialized_metadata": self._rosbag2_metadata()})
            # The subscriptions and the timer stay until the node is destroyed: destroying them here,
            # from another thread while the executor waits on them, is the rclpy teardown race of
            # ROS_NOTES.md. Callbacks see _closed and drop what still arrives.
            self._writer.finish()
            self._file.close()


def _rosbag2_metadata_text(counts: dict[str, int], types: dict[str, str], first_ns: int | None,
                           last_ns: int, path: Path, qos: dict[str, str] | None = None) -> str:
    """rosbag2's metadata.yaml content (``rosbag_bagfile_information``) for the MCAP ``rosbag2`` record."""
    import yaml

    start = first_ns or 0
    info = {"version": 9, "storage_identifier": "mcap", "relative_file_paths": [path.name],
            "duration": {"nanoseconds": max(0, last_ns - start)}, "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(counts.values()),
            "topics_with_message_count": [
                {"topic_metadata": {"name": t, "type": types[t], "serialization_format": "cdr",
                                    "offered_qos_profiles": (qos or {}).get(t, ""), "type_description_hash": ""},
                 "message_count": n} for t, n in sorted(counts.items()) if t in types],
            "compression_format": "", "compression_mode": "", "files": [
                {"path": path.name, "starting_time": {"nanoseconds_since_epoch": start},
                 "duration": {"nanoseconds": max(0, last_ns - start)}, "message_count": sum(counts.values())}],
            "custom_data": {}, "ros_distro": "jazzy"}
    return yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)


#: What a corrupt, truncated or foreign file raises inside the mcap reader (its own errors, and
#: lower-level ones from records cut short); every one becomes a one-line ConfigError.
_CORRUPT = (McapError, EOFError, struct.error, ValueError, IndexError, KeyError, UnicodeDecodeError,
            MemoryError, OverflowError)


def _corrupt(path: Path, exc: BaseException) -> ConfigError:
    detail = " ".join(str(exc).split())[:160] or type(exc).__name__
    return ConfigError(f"recording {path}: not a readable MCAP file (empty, truncated or corrupt): {detail}")


def read_mcap(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
    """Messages of an MCAP recording in log-time order (optionally only ``topics``).

    Raises ConfigError (one line) for a missing, empty, truncated, corrupt or non-MCAP file.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"recording {path}: no such file")
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            for schema, channel, message in reader.iter_messages(topics=list(topics) if topics else None,
                                                                 log_time_order=True):
                if channel.message_encoding != "cdr" or schema is None:
                    continue
                type_name = _RECORDED_FROM.get(schema.name, schema.name)  # decodable with the installed types
                yield RecordedMessage(channel.topic, type_name, message.log_time, message.data)
    except OSError as exc:
        raise ConfigError(f"recording {path}: {exc.strerror or exc}") from exc
    except _CORRUPT as exc:
        raise _corrupt(path, exc) from exc


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    path = Path(path)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            return {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except OSError as exc:
        raise ConfigError(f"recording {path}: {exc.strerror or exc}") from exc
    except _CORRUPT as exc:
        raise _corrupt(path, exc) from exc
