"""AprilTag detection and sub-pixel corners (OpenCV and pupil-apriltags, no MuJoCo)."""
