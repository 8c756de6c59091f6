"""For the tests that look inside a built method image, without a GPU: the image or a skip saying why, and a command
run in a container of it."""

from __future__ import annotations

import pytest


def built_image(image: str, how: str):
    """The Docker API client and `image`'s labels, or a skip naming why (`how`: the command that builds it)."""
    from slamrun.backends.docker import DockerBackend
    from slamrun.errors import InfraError

    try:
        api = DockerBackend().client.api
    except InfraError as exc:
        pytest.skip(reason=f"no Docker engine: {exc}")
    if not api.images(name=image):
        pytest.skip(reason=f"{image} is not built ({how})")
    return api, (api.inspect_image(image).get("Config") or {}).get("Labels") or {}


def run_in_image(
    api, image: str, command: list[str], volumes: dict | None = None, timeout: int = 600
) -> tuple[int, str]:
    """`command` in a container of `image`, without a network or a GPU: (exit status, its stderr then its stdout).
    The engine reads stdout and stderr through two pipes and does not keep their order across them, so the two are
    read apart: the output's last line is the command's last line on stdout."""
    binds = {str(k): {"bind": v, "mode": "ro"} for k, v in (volumes or {}).items()}
    container = api.create_container(
        image,
        command=command,
        volumes=[b["bind"] for b in binds.values()],
        host_config=api.create_host_config(network_mode="none", binds=binds),
    )
    try:
        api.start(container)
        status = api.wait(container, timeout=timeout)["StatusCode"]
        err = api.logs(container, stdout=False, stderr=True).decode(errors="replace")
        out = api.logs(container, stdout=True, stderr=False).decode(errors="replace")
        return status, err + out
    finally:
        api.remove_container(container, force=True)
