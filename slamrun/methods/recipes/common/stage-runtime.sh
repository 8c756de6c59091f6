#!/bin/sh
# Put together, under /opt/runtime, what a method's runtime stage copies to / (`COPY --from=build /opt/runtime/ /`):
# the BINARY and each further FILE or folder at its own path, /usr/local/lib (the libraries built into it, Pangolin's
# or g2o's), the Debian packages owning the libraries BINARY loads (opt/runtime-packages.txt) and the binary's path
# (opt/runtime-binary.txt), both read by install-runtime.sh.
# usage: stage-runtime.sh BINARY [FILE...]
set -eu
out=/opt/runtime
mkdir -p "$out/opt"
python3 "$(dirname "$0")/runtime_packages.py" "$1" > "$out/opt/runtime-packages.txt"
echo "$1" > "$out/opt/runtime-binary.txt"
for path in /usr/local/lib "$@"; do
  cp -a --parents "$path" "$out/"
done
echo "stage-runtime: $1, $# path(s), packages: $(tr '\n' ' ' < "$out/opt/runtime-packages.txt")"
