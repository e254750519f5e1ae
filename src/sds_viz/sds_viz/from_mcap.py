"""A recording (MCAP) into a Rerun .rrd file: the same scene the viewer node shows live.

The camera's recorded packets (foxglove_msgs/CompressedVideo) are decoded here and shown as
the frames are, the region downscaled under the spots: Rerun's VideoStream cannot play a
stream with B-frames (rerun-io/rerun#10090), which GoPro's and x264's have."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import rerun as rr
from mcap.exceptions import McapError
from sds_camera.compressed_video import PacketDecoder, VideoPacket
from sds_camera.frame_source import Frame, Region
from sds_model.errors import InputError
from sds_model.rig import Rig
from sds_model.staging import staged_file
from sds_record.mcap_files import decoded_messages, require_mcap
from sds_ros.image_msg import PACKET_TYPES, packet_fields

from sds_viz.messages import log_message
from sds_viz.scene import RerunScene


@dataclass(frozen=True)
class Conversion:
    """How many messages were shown and how many of a type the scene does not show."""

    shown: int
    skipped: int


def mcap_to_rrd(recording: str | Path, output: str | Path, rig: Rig | None = None,
                image_scale: float = 0.25, image_every: int = 1) -> Conversion:
    """Log every message of `recording` to a new .rrd file, in log-time order (the file
    appears only when complete). InputError for an image scale outside (0, 1] or a step
    below 1, a file that is not MCAP and a recording without a message."""
    if not 0 < image_scale <= 1 or image_every < 1:
        raise InputError(f"image scale {image_scale:g} and step {image_every}: the scale is in "
                         "(0, 1] (e.g. 0.25), the step 1 or more")
    require_mcap(Path(recording))
    with staged_file(Path(output)) as staging:
        stream = rr.RecordingStream("sds", recording_id=Path(recording).stem)
        stream.save(str(staging))
        scene = RerunScene(stream, rig, image_scale)
        shown = skipped = 0
        images: dict[str, int] = {}   # per camera (frame_id): each is thinned on its own
        decoders: dict[str, PacketDecoder] = {}
        try:
            for recorded, msg in decoded_messages(recording):
                type_name = recorded.type_name
                if type_name in PACKET_TYPES:
                    frame_id, frames = _decoded(decoders, scene, msg)
                    for frame in frames:
                        count = images[frame_id] = images.get(frame_id, 0) + 1
                        if not (count - 1) % image_every:
                            scene.set_time(frame.time_ns * 1e-9)
                            scene.log_image(frame.image, tuple(scene.roi_offset.astype(int)))
                    shown += 1
                    continue
                if type_name == "sensor_msgs/msg/Image":
                    count = images[msg.header.frame_id] = images.get(msg.header.frame_id, 0) + 1
                    if (count - 1) % image_every:
                        continue
                if log_message(scene, type_name, msg):
                    shown += 1
                else:
                    skipped += 1
            for decoder in decoders.values():
                for frame in decoder.flush():
                    scene.set_time(frame.time_ns * 1e-9)
                    scene.log_image(frame.image, tuple(scene.roi_offset.astype(int)))
        except McapError as error:
            raise InputError(f"{recording}: {error}") from None
        else:
            if shown + skipped == 0:   # an empty scene would look like a viewer's fault
                raise InputError(f"{recording} holds no message: nothing to show")
        finally:
            stream.flush()
            stream.disconnect()
    return Conversion(shown, skipped)


def _decoded(decoders: dict[str, PacketDecoder], scene: RerunScene, msg
             ) -> tuple[str, list[Frame]]:
    """The camera (frame_id) of a recorded packet and the frames (time: stamp [ns]) it
    completes; each camera's decoder is made at its first packet, cut to the camera model's
    region known then (else whole)."""
    frame_id, stamp_ns, packet_format, data = packet_fields(msg)
    if frame_id not in decoders:
        width, height = scene.roi_size
        region = Region(int(scene.roi_offset[0]), int(scene.roi_offset[1]), width, height) \
            if width > 0 else None
        decoders[frame_id] = PacketDecoder(packet_format, region)
    return frame_id, decoders[frame_id].decode(VideoPacket(0, stamp_ns, False, data))
