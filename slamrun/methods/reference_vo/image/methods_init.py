"""Inside the reference VO image: only the VO itself, without the runner's method registry."""
