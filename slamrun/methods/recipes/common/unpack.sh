#!/bin/sh
# Unpack a GitHub source archive (one top folder <repo>-<commit>/) into DEST, without the top folder.
# usage: unpack.sh ARCHIVE DEST
set -eu
mkdir -p "$2"
tar -xzf "$1" -C "$2" --strip-components=1 --no-same-owner
[ -n "$(ls -A "$2")" ] || { echo "unpack: $1 held nothing" >&2; exit 1; }
echo "unpack: $1 -> $2"
