"""Inside the DROID-SLAM image: only slamrun's DROID-SLAM process, without the runner's method registry."""
