"""Robot interaction logs (MCAP) into time-stamped tracks in the world frame.

`read_recording` reads one MCAP file (ROS 2 CDR messages, or JSON-encoded
Foxglove poses), finds its topics by message type (see DESIGN.md, "Logs:
MCAP") and returns a `Recording`:

- `pose`: the tracked frame (object, gripper or mocap markers) in world [m];
- `wrench`: the wrench the robot applies TO the object, converted to WORLD
  axes with its torque taken about the TRACKED FRAME's origin, so downstream
  code needs no frames;
- `wrench_raw`: the same samples as in the messages (message frame, torque
  about that frame's origin, or the contact point for world wrenches);
- `contact` and `joints` when the file has them.

World is the tracked pose's parent frame (`PoseTrack.frame_id`, e.g. "world";
the name "world" always means it too). A wrench in world acts at the contact
point when a contact topic exists, else at the tracked frame's origin. A wrench
in any other frame is resolved through the tracked pose itself and the
`/tf_static` + `/tf` tree (transforms interpolated at the wrench stamp: linear
in translation, slerp in rotation; held at the ends outside their range), and
acts at that frame's origin: τ_track = τ + (p_frame − p_track) × F.

Times are header stamps in seconds (as recorded, e.g. UNIX time); a zero stamp
falls back to the message's log time. Frame ids are compared without a leading
"/" (as tf2 does). Undecodable topics (e.g. the `robot_comm/*` schemas of the
MIT pushing bags) are skipped with a warning; a damaged file raises `LogError`.

What a file holds is checked before anything downstream sees it: samples with
non-finite values and stamps far outside the rest of their stream (one message
stamped at 2^31 s among stamps near 0) are dropped with a warning naming the file
and topic; a pose or wrench stream mostly non-finite, a force beyond 1e5 N, a
torque beyond 1e4 N m, a position beyond 1000 km, and pose and wrench streams
whose stamps do not overlap raise `LogError`.

The recorded data types (`PoseTrack`, `WrenchTrack`, `Recording`, ...) live in
`assets.recording`. Here: `checks` (LogError, the clean-up of a stream),
`mcap_file` (the file's channels and decoders), `messages` (decoded messages into
tracks), `frames` (the frame tree) and `read` (`read_recording`, step by step).
"""

from .checks import LogError
from .mcap_file import TopicSummary, inspect_recording
from .messages import JOINT_TYPE, POINT_TYPE, POSE_TYPES, ROLES, TF_TYPE, WRENCH_TYPE
from .read import read_recording

__all__ = [
    "LogError",
    "TopicSummary",
    "inspect_recording",
    "read_recording",
    "POSE_TYPES",
    "WRENCH_TYPE",
    "POINT_TYPE",
    "JOINT_TYPE",
    "TF_TYPE",
    "ROLES",
]
