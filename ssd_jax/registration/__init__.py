"""Registration pipeline, split as Open3D's: keypoints, features, correspondences,
estimation (RANSAC) and metrics."""
