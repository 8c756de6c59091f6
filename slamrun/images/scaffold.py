"""`slamrun new-method NAME`: a method of one's own, outside slamrun's repository.

Writes a Python package that registers the adapter through the `slamrun.methods` entry point, a Dockerfile on the
project's base with the method's source pinned by commit, and a test. Each file marks the few lines a person must
fill in with `FILL IN`; as written, the adapter runs a local executable given in the spec
(`params: {executable: ...}`) that takes the prepared view's frames folder, times, camera and output path.
"""

from __future__ import annotations

import re
from pathlib import Path

from slamrun.errors import SlamRunError


def pyproject(distribution: str, description: str, group: str, entry: str, package: str) -> str:
    """The pyproject.toml of a plug-in package: its distribution, one entry point (`entry` = "name = module:obj") in
    the entry-point `group` (slamrun.methods, slamrun.datasets) and its one package."""
    return f"""[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "{distribution}"
version = "0.1.0"
description = "{description}"
requires-python = ">=3.11"

[project.entry-points."{group}"]
{entry}

[tool.setuptools]
packages = ["{package}"]
"""


ADAPTER = '''"""{name}: a slamrun adapter (the contract of slamrun.methods.Method)."""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from slamrun.methods import Method, PreparedView, Profile


class {cls}Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    executable: str = Field("{name}", description="The method's program (a local build, or its path in the image).")
    # FILL IN: the method's own settings, each with a default and a description (they key the runs' results)


class {cls}(Method):
    name = "{name}"
    image = "slamrun/{name}:latest"  # built from docker/Dockerfile (`docker build -t slamrun/{name} docker`)
    native = True  # runs as a local process too (backend: local) when params.executable is a local build
    profile = Profile.rectified  # FILL IN: rectified (pinhole, undistorted) or native (TUM-Mono's FOV files)
    Params = {cls}Params
    output_file = "trajectory.txt"  # TUM rows `t tx ty tz qx qy qz qw` at the view's timestamps
    not_initialized_pattern = None  # FILL IN: a log line meaning "never initialised", if the method prints one
    lost_pattern = None  # FILL IN: a log line meaning "tracking lost"

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        # FILL IN: the method's command line: its frames, times and calibration, and where it writes its poses
        return [
            self.params.executable,
            str(view.path(view.images_dir)),
            str(view.path(view.times)),
            str(view.path(view.camera)),
            str(workdir / self.output_file),
        ]
'''

DOCKERFILE = """# {name} on slamrun's base (debian:bookworm-slim, made by scripts/make-offline-base.sh), built in one
# stage and run from a small one. The source is pinned by commit: GitHub serves the archive of any commit.
FROM debian:bookworm-slim AS build
RUN apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \\
        build-essential cmake ca-certificates curl libeigen3-dev libopencv-dev \\
    && rm -rf /var/lib/apt/lists/*
# FILL IN: the upstream repository and the full commit the results are made with
ARG REPO=owner/{name}
ARG COMMIT=0000000000000000000000000000000000000000
RUN curl -fsSL https://github.com/${{REPO}}/archive/${{COMMIT}}.tar.gz | tar -xz -C /opt \\
    && mv /opt/*-${{COMMIT}} /opt/{name}
# FILL IN: the build, ending with the program at /opt/{name}/bin/{name}
RUN cmake -S /opt/{name} -B /opt/{name}/build -DCMAKE_BUILD_TYPE=Release && cmake --build /opt/{name}/build -j

FROM debian:bookworm-slim
RUN apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends libopencv-core406 \\
    && rm -rf /var/lib/apt/lists/*
COPY --from=build /opt/{name}/bin /opt/{name}/bin
LABEL slamrun.sources="${{REPO}}@${{COMMIT}}"
"""

TEST = '''"""{name}'s adapter: its command and its output, without running the method (slamrun verify runs it)."""

from pathlib import Path

import numpy as np

from slamrun.methods import Direction, PreparedView, Profile
from slamrun_{module}.adapter import {cls}


def view(root: Path) -> PreparedView:
    (root / "original_times.txt").write_text("1.0\\n1.1\\n1.2\\n")
    return PreparedView(root, "s", Direction.forward, Profile.rectified, 3, 1.0, 1.2, 64, 48, (50.0, 50.0, 32.0, 24.0))


def test_command_names_the_views_files(tmp_path):
    argv = {cls}({{"executable": "/opt/{name}/bin/{name}"}}).command(view(tmp_path), tmp_path / "work")
    assert argv[0] == "/opt/{name}/bin/{name}" and str(tmp_path / "work" / "trajectory.txt") in argv


def test_output_is_read_at_the_original_times(tmp_path):
    out = tmp_path / "trajectory.txt"
    out.write_text("1.0 0 0 0 0 0 0 1\\n1.1 0.1 0 0 0 0 0 1\\n")  # FILL IN: a real output of the method
    traj = {cls}().read_trajectory(tmp_path, view(tmp_path))
    assert np.allclose(traj.timestamps, [1.0, 1.1])
'''


MAX_NAME = 64  # a package's folder, module and test file are named by it: well inside a file name's 255 bytes
# names the generated adapter and test import: a class of the same name would shadow one of them
IMPORTED = {"Path", "BaseModel", "ConfigDict", "Field", "Method", "PreparedView", "Profile", "Direction"}


def destination_problem(dest: Path) -> str | None:
    """Why a new package cannot be written at `dest` (a link, a path under a file, a folder that holds files), or
    None."""
    if dest.is_symlink():
        return f"{dest} is a symbolic link (to {dest.readlink()}); give a new folder (--dest)"
    for parent in dest.parents:
        if parent.exists() and not parent.is_dir():
            return f"{dest}: {parent} is a file, not a folder; give a new folder (--dest)"
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        return f"{dest} exists and is not empty; choose a new folder (--dest)"
    return None


def write_files(files: dict[Path, str]) -> list[Path]:
    """Write a new package's files; an OS error (no space, no permission) names the file."""
    for path, text in files.items():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
        except OSError as exc:
            raise SlamRunError(f"{path}: cannot be written ({exc.strerror or exc})") from None
    return list(files)


def new_method(name: str, dest: Path) -> list[Path]:
    """Write the package of method `name` into `dest` (which must not exist or be empty); returns the files."""
    if not re.fullmatch(r"[a-z][a-z0-9_]*", name):
        raise SlamRunError(f"{name!r}: a method name is lower-case letters, digits and _ (a Python identifier)")
    if len(name) > MAX_NAME:
        raise SlamRunError(f"{name[:20]}...: a method name of {len(name)} characters; at most {MAX_NAME}")
    import slamrun.methods

    if name in slamrun.methods.REGISTRY:
        raise SlamRunError(f"{name!r} is a method slamrun has already; choose another name")
    cls = "".join(part.capitalize() for part in name.split("_"))
    if cls in IMPORTED:
        raise SlamRunError(
            f"{name!r} would name the adapter's class {cls}, which its own code imports from slamrun (the class would "
            "shadow it and the package's tests fail); choose another name"
        )
    if problem := destination_problem(dest):
        raise SlamRunError(problem)
    fill = {"name": name, "module": name, "cls": cls}
    files = {
        dest / "pyproject.toml": pyproject(
            f"slamrun-{name}",
            f"{name} for slamrun",
            "slamrun.methods",
            f'{name} = "slamrun_{name}.adapter:{cls}"',
            f"slamrun_{name}",
        ),
        dest / f"slamrun_{name}" / "__init__.py": "",
        dest / f"slamrun_{name}" / "adapter.py": ADAPTER.format(**fill),
        dest / "docker" / "Dockerfile": DOCKERFILE.format(**fill),
        dest / "tests" / f"test_{name}.py": TEST.format(**fill),
    }
    return write_files(files)
