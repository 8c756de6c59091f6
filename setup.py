"""The one compiled part: slamrun.core._tumparse, the fast reader of plain numeric tables (TUM trajectory files).

Optional: where it cannot be built (no C compiler), slamrun installs without it and reads those files with
Arrow's CSV reader instead (about half as fast, the same numbers)."""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension("slamrun.core._tumparse", ["slamrun/core/_tumparse.c"], extra_compile_args=["-O3"], optional=True)
    ]
)
