"""One MCAP file, read once in file order: its channels, their undecoded messages and log-time spans, and
the decoding of a channel's payloads (ROS 2 CDR or JSON)."""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from .checks import LogError

__all__ = ["DecodedTopic", "RawChannel", "TopicSummary", "decode_topic", "inspect_recording", "resolve_file",
           "scan_file"]


@dataclass(frozen=True)
class TopicSummary:
    """One topic of an MCAP file, for `twin inspect`.

    Attributes:
        topic: the topic name.
        type: the schema name (e.g. "geometry_msgs/msg/WrenchStamped"), "" if none.
        count: number of messages.
        rate_hz: mean rate (count − 1) / (t_end_s − t_start_s) [Hz], 0 if undefined.
        t_start_s, t_end_s: first and last log time [s].
    """

    topic: str
    type: str
    count: int
    rate_hz: float
    t_start_s: float
    t_end_s: float


@dataclass
class RawChannel:
    """Messages of one channel, undecoded: log times [ns] and payloads."""

    topic: str
    type: str
    message_encoding: str
    schema: Any
    log_ns: list
    data: list


def resolve_file(path: Path) -> Path:
    path = Path(path)
    if path.is_dir():  # a rosbag2 directory: metadata.yaml + one .mcap
        found = sorted(path.glob("*.mcap"))
        if len(found) != 1:
            raise LogError(f"{path}: a directory, expected exactly one .mcap inside, found {len(found)}")
        return found[0]
    if not path.exists():
        raise LogError(f"{path}: file not found")
    return path


def scan_file(path: Path, want: Callable[[str, str], bool] | None) -> tuple[dict[int, RawChannel], dict[int, list]]:
    """Read every record of `path` once, in file order.

    Returns the channels (id → RawChannel) and, for each channel, [count, first_ns,
    last_ns]. Payloads are kept only for channels where want(topic, type) holds.
    Raises LogError for anything but a complete, valid MCAP file.
    """
    from mcap.exceptions import InvalidMagic
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Any] = {}
    channels: dict[int, RawChannel] = {}
    stats: dict[int, list] = {}
    pending: list = []  # messages seen before their channel (not expected, but harmless)
    size = path.stat().st_size
    try:
        with open(path, "rb") as f:
            reader = StreamReader(f, validate_crcs=True, record_size_limit=max(size, 1024))
            for rec in reader.records:
                if isinstance(rec, Message):
                    s = stats.setdefault(rec.channel_id, [0, rec.log_time, rec.log_time])
                    s[0] += 1
                    s[1] = min(s[1], rec.log_time)
                    s[2] = max(s[2], rec.log_time)
                    ch = channels.get(rec.channel_id)
                    if ch is None:
                        pending.append(rec)
                    elif want is not None and want(ch.topic, ch.type):
                        ch.log_ns.append(rec.log_time)
                        ch.data.append(rec.data)
                elif isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel) and rec.id not in channels:
                    schema = schemas.get(rec.schema_id)
                    channels[rec.id] = RawChannel(
                        rec.topic, schema.name if schema else "", rec.message_encoding, schema, [], []
                    )
    except InvalidMagic:
        raise LogError(f"{path}: not an MCAP file (bad magic bytes)") from None
    except LogError:
        raise
    except Exception as e:  # EndOfFile, struct.error, CRC mismatch, zstd errors, ...
        detail = f"{type(e).__name__}: {e}".strip().rstrip(":")
        raise LogError(f"{path}: truncated or corrupt MCAP file ({detail})") from None
    for rec in pending:
        ch = channels.get(rec.channel_id)
        if ch is None:
            raise LogError(f"{path}: corrupt MCAP file (message on undeclared channel {rec.channel_id})")
        if want is not None and want(ch.topic, ch.type):
            ch.log_ns.append(rec.log_time)
            ch.data.append(rec.data)
    return channels, stats


def inspect_recording(path: Path) -> list[TopicSummary]:
    """Every topic of an MCAP file with its type, count, rate and log-time span.

    Times are log times (no message is decoded), so topics with undecodable
    schemas are listed too. Sorted by topic name. Raises LogError for a missing
    or damaged file.
    """
    path = resolve_file(Path(path))
    channels, stats = scan_file(path, None)
    out = []
    for cid, ch in channels.items():
        count, t0, t1 = stats.get(cid, [0, 0, 0])
        t0_s, t1_s = t0 * 1e-9, t1 * 1e-9
        rate = (count - 1) / (t1_s - t0_s) if count > 1 and t1 > t0 else 0.0
        out.append(TopicSummary(ch.topic, ch.type, int(count), float(rate), t0_s, t1_s))
    return sorted(out, key=lambda s: s.topic)


def _decoder(path: Path, raw: RawChannel, ros2_factory) -> Callable[[bytes], Any] | None:
    """A payload decoder for the channel, or None (with a warning) if it has none."""
    enc = raw.message_encoding
    if enc == "json":
        return lambda data: json.loads(data)
    if enc == "cdr" and raw.schema is not None and raw.schema.encoding == "ros2msg":
        try:
            return ros2_factory.decoder_for(enc, raw.schema)
        except Exception as e:
            warnings.warn(
                f"{path}: skipping topic {raw.topic} ({raw.type}): its schema cannot be decoded "
                f"({type(e).__name__}: {e})",
                stacklevel=3,
            )
            return None
    warnings.warn(
        f"{path}: skipping topic {raw.topic} ({raw.type}): no decoder for message encoding "
        f"{enc!r} with schema encoding {getattr(raw.schema, 'encoding', None)!r}",
        stacklevel=3,
    )
    return None


class DecodedTopic:
    """Decoded messages of one topic: (log_ns, message) in file order."""

    def __init__(self, raw: RawChannel, items: list):
        self.topic = raw.topic
        self.type = raw.type
        self.items = items


def decode_topic(path: Path, raw: RawChannel, ros2_factory) -> DecodedTopic | None:
    dec = _decoder(path, raw, ros2_factory)
    if dec is None:
        return None
    items, failed = [], 0
    for log_ns, data in zip(raw.log_ns, raw.data):
        try:
            items.append((log_ns, dec(data)))
        except Exception:
            failed += 1
    if failed:
        warnings.warn(f"{path}: {raw.topic}: skipped {failed} messages that could not be decoded", stacklevel=3)
    return DecodedTopic(raw, items)
