"""Data preparation: the embedded synthetic sets, real pairs from drives and scans,
cross-sensor pairs, KITTI odometry."""
