"""The reference VO: `vo.py` (the algorithm) and `__main__.py` (the process) need only OpenCV, NumPy and
SciPy, so a container image can hold them alone; `adapter.py` is the method class the runner uses."""
