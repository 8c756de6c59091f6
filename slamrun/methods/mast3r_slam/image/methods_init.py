"""Inside the MASt3R-SLAM image: only slamrun's MASt3R-SLAM process, without the runner's method registry."""
