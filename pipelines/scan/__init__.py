"""Read an RGB-D scan directory (DESIGN.md, "Inputs"); the layout is detected.

The nerfstudio layout (primary):

    scan_dir/
      transforms.json   fl_x fl_y cx cy w h, optional k1 k2 p1 p2,
                        depth_unit_scale_factor [m per depth unit, default 0.001],
                        frames: [{file_path, depth_file_path, mask_path?, transform_matrix}]
      images/...  depth/... (16-bit PNG)  masks/... (optional, 8-bit, object > 0)
      object.json       optional: {"name", "material", "notes"}

The 7-Scenes / tsdf-fusion layout (Kinect-style frames in one folder):

    scan_dir/
      camera-intrinsics.txt          3x3 K [pixels] (of the depth camera)
      frame-XXXXXX.depth.png         16-bit depth [mm unless told otherwise]; 0 and 65535 invalid
      frame-XXXXXX.color.jpg|.png    colour, the depth image's size (not necessarily registered)
      frame-XXXXXX.pose.txt          4x4 camera-to-world [m], OpenCV camera axes (optional, see below)
      frame-XXXXXX.mask.png          optional object mask (8-bit, object > 0)
      object.json                    optional, as above

Frames without poses (no `transform_matrix` in any nerfstudio frame, no
`.pose.txt` in the 7-Scenes layout) are posed by `pipelines.posing` (RGB-D
odometry refined by ICP); their world frame is then the first camera's. A scan
whose poses are given can be re-posed the same way (`poses="estimate"`) to
measure the estimator against the given poses, which are kept in
`Scan.given_T_world_camera`.

`transform_matrix` is camera-to-world in nerfstudio's OpenGL camera axes (x
right, y up, looking along -z); the reader converts it to the OpenCV axes of
`Frame.T_world_camera`. The data types it returns, and the conventions it
settles for everything downstream (axes, depth, pixel centres), are in
`pipelines.rgbd`. Modules: `read` (`read_scan`), `nerfstudio`, `seven_scenes`,
and `files` (the checked reading of one file).

Everything is checked on reading; anything malformed raises `ScanError`, whose
message starts with the path of the offending file. Image headers are checked
against the camera's size before any pixel is decoded, so a file whose header
claims a huge image allocates nothing. A scan whose views leave a side of the
object unseen reads with a warning (see `read_scan`).
"""

from .read import PoseSource, read_scan

__all__ = ["PoseSource", "read_scan"]
