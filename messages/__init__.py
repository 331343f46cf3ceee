"""Topic message schemas and the shared msgpack codec."""
from messages.codec import DecodeError, decode, encode, json_schemas
from messages.schemas import (
    ALL_MESSAGES, BY_SCHEMA, Cpu, FLAG_INTERPOLATED, FLAG_MEASURED, FLAG_MISSING, Header, Heartbeat, Latency,
    LimbSolution, MarkerFrame, MarkerSet, Message, RigPose, SkeletonFrame,
)

__all__ = [
    "ALL_MESSAGES", "BY_SCHEMA", "Cpu", "DecodeError", "FLAG_INTERPOLATED", "FLAG_MEASURED", "FLAG_MISSING", "Header",
    "Heartbeat", "Latency", "LimbSolution", "MarkerFrame", "MarkerSet", "Message", "RigPose", "SkeletonFrame",
    "decode", "encode", "json_schemas",
]
