#!/bin/sh
# Download a build input (weights, vocabulary) and check its SHA-256.
# usage: fetch.sh URL SHA256 DEST
# An empty SHA256 fails the build, printing the file's actual hash, unless ALLOW_UNVERIFIED=1:
# pin the hash once (--build-arg) and every later build is verified.
set -eu
url=$1; sum=$2; dest=$3
mkdir -p "$(dirname "$dest")"
if ! wget -q -O "$dest" "$url" && ! curl -fsSL -o "$dest" "$url"; then
  echo "fetch: cannot download $url (needed for $dest); set the URL build argument to a mirror" >&2
  exit 1
fi
actual=$(sha256sum "$dest" | cut -d' ' -f1)
if [ -z "$sum" ]; then
  if [ "${ALLOW_UNVERIFIED:-0}" = 1 ]; then
    echo "fetch: WARNING $dest is unverified; its sha256 is $actual (pass it as a build argument to pin it)"
    exit 0
  fi
  echo "fetch: no checksum given for $url; its sha256 is $actual. Pass it as a build argument (or ALLOW_UNVERIFIED=1)." >&2
  exit 1
fi
if [ "$actual" != "$sum" ]; then
  echo "fetch: $url has sha256 $actual, expected $sum: refusing it" >&2
  exit 1
fi
echo "fetch: $dest verified"
