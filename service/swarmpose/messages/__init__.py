"""The protocol's messages: key expressions, schemas and validation (:mod:`.schema`), building
them from plain values (:mod:`.build`) and one-line descriptions (:mod:`.describe`).

Below the tracker and the publishers: both build and read messages through this package.
"""

from swarmpose.messages.build import POSE_NAMES, body_message, frame_message, info_message, json_vector
from swarmpose.messages.describe import format_status
from swarmpose.messages.schema import (
           MESSAGE_VERSIONS,
           PROTOCOL_VERSION,
           check_camera_id,
           decode,
           encode,
           keys,
           schema,
           validate,
)

__all__ = ["MESSAGE_VERSIONS", "POSE_NAMES", "PROTOCOL_VERSION", "body_message", "check_camera_id", "decode", "encode",
           "format_status", "frame_message", "info_message", "json_vector", "keys", "schema", "validate"]
