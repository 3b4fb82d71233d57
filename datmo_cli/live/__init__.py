"""The live view: a log's channels served to Foxglove over its WebSocket protocol (foxglove-sdk), as they are
made.

`datmo play` publishes a log at its own rate (scans segmented, their features extracted and tracked on the
fly when the log has no /datmo/tracks); `datmo record --live` publishes each scan as it arrives from the
scanner. Every channel goes out with its ROS 2 schema (ros2msg) and CDR payloads, as in the log files, so
Foxglove decodes them as it decodes a datmo log. Transforms: the log's own /tf and /tf_static when it has
them; else, with odometry, odom -> base_link at every scan stamp on /tf (and base_link -> the scan's frame,
identity, on /tf_static when the frames differ). Static transforms are sent again every second, so a client
that subscribes late still places the scan.

Times are the log's (header stamps, ns): the server advertises the time capability and broadcasts each
scan's stamp, so Foxglove's clock follows the log (and restarts with it when `play --loop` starts over).
`datmo play` also offers Foxglove's playback control over the log's span (control: pause, seek, speed).

Clients: foxglove-sdk's server accepts only the subprotocol `foxglove.sdk.v1` (Foxglove's app today), while
the public protocol (github.com/foxglove/ws-protocol) and the clients written to it (`@foxglove/ws-protocol`,
Lichtblick, older apps) ask for `foxglove.websocket.v1`: the same protocol under its older name. So the SDK's
server listens on a loopback port of its own, and a small front (`_Front`, on `websockets`) takes the
clients on the port asked for, accepts either name, and relays each client's frames to and from the SDK's
server unchanged.

The modules: messages (Message, the transforms a log lacks, the stages' messages of scans as they come), server
(LiveServer and its front), control (PlaybackControl: the clients' requests and the state reported), playback
(`datmo play`: LogSource, play) and feed (`datmo record --live`, `datmo node`: LiveFeed, PoseBuffer).
"""

from .control import PlaybackControl
from .feed import LiveFeed, PoseBuffer
from .messages import STATIC_EVERY_NS, TF_MESSAGE, TOPIC_TF, TOPIC_TF_STATIC, Message, Stages, Transforms, tf_payload
from .playback import MIN_LOOP_PASS_S, DrawnMarkers, LogSource, Pace, play
from .server import PUBLIC_SUBPROTOCOL, SUBPROTOCOL, SUBPROTOCOLS, LiveServer, app_url, require_foxglove, ws_url

__all__ = [
    "MIN_LOOP_PASS_S",
    "PUBLIC_SUBPROTOCOL",
    "STATIC_EVERY_NS",
    "SUBPROTOCOL",
    "SUBPROTOCOLS",
    "TF_MESSAGE",
    "TOPIC_TF",
    "TOPIC_TF_STATIC",
    "DrawnMarkers",
    "LiveFeed",
    "LiveServer",
    "LogSource",
    "Message",
    "Pace",
    "PlaybackControl",
    "PoseBuffer",
    "Stages",
    "Transforms",
    "app_url",
    "play",
    "require_foxglove",
    "tf_payload",
    "ws_url",
]
