#!/bin/sh
# A method's runtime stage, after `COPY --from=build /opt/runtime/ /`: install the Debian packages its binary needs
# (/opt/runtime-packages.txt), register the libraries copied to /usr/local/lib and fail if the binary
# (/opt/runtime-binary.txt) still misses a library.
set -eu
apt-get update
DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $(cat /opt/runtime-packages.txt)
rm -rf /var/lib/apt/lists/*
ldconfig
binary=$(cat /opt/runtime-binary.txt)
if ldd "$binary" | grep 'not found'; then
  echo "install-runtime: $binary misses the libraries above" >&2
  exit 1
fi
