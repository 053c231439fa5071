"""CARLA: coordinate frames, camera poses and JSON Lines recordings (:mod:`.bridge`)."""
