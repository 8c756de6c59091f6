"""Inside the DPVO image: only slamrun's DPVO process, without the runner's method registry."""
