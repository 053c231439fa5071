"""ROS 2 bags out and in, and the Foxglove scene, without a ROS installation (docs/integrations.md, "ROS 2 bags
and Foxglove").

* :mod:`.types` -- the rosbags type store with vision_msgs registered from its ``.msg`` texts (``msg/``);
* :mod:`.messages` -- a frame's footprints as Detection3DArray and MarkerArray messages;
* :mod:`.foxglove_scene` -- the same frame (and the camera) as a Foxglove ``SceneUpdate``;
* :mod:`.bag_writer` -- footprint tables / frames -> a bag (one MCAP file or a rosbag2 folder);
* :mod:`.bag_reader` -- a bag's Detection2DArray topic -> the canonical detection table, its CameraInfo -> camera;
  ``BagFormat``, the format registry's ``ros2-bag`` (entered there by name: ``batch/`` does not import this layer);
* :mod:`.live` -- ``serve --output rosbag:PATH``.

The third-party packages (rosbags, mcap, foxglove-sdk: the optional extra ``ros``) are imported where used.
"""
