#!/usr/bin/env bash
# Start a Docker engine if none answers (CI and fresh machines): installs docker.io when absent.
set -euo pipefail
if docker info >/dev/null 2>&1; then exit 0; fi
if ! command -v dockerd >/dev/null; then
  apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q docker.io
fi
log=${DOCKERD_LOG:-/tmp/slamrun-dockerd.log}
nohup dockerd >"$log" 2>&1 &
for _ in $(seq 1 60); do
  if docker info >/dev/null 2>&1; then exit 0; fi
  sleep 0.5
done
echo "start-dockerd: dockerd did not answer within 30 s; its log ($log) ends with:" >&2
tail -20 "$log" >&2
exit 1
