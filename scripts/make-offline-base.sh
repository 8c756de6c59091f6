#!/usr/bin/env bash
# Build the `debian:bookworm-slim` base image without a registry: debootstrap a minimal Debian into a
# folder and `docker import` it. Reused when the tag already exists (FORCE=1 rebuilds).
# The Debian mirror is the one this machine's apt uses (override with MIRROR=...).
set -euo pipefail
TAG=${TAG:-debian:bookworm-slim}
SUITE=${SUITE:-bookworm}
if [ "${FORCE:-0}" != 1 ] && docker image inspect "$TAG" >/dev/null 2>&1; then
  echo "make-offline-base: $TAG exists"; exit 0
fi
command -v debootstrap >/dev/null || { apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap; }
if [ -z "${MIRROR:-}" ]; then
  MIRROR=$( (grep -hE '^URIs:' /etc/apt/sources.list.d/*.sources 2>/dev/null; grep -hE '^deb ' /etc/apt/sources.list 2>/dev/null) \
    | grep -v -- '-security' | grep -i debian | head -1 | awk '{print $2}') || true
fi
[ -n "$MIRROR" ] || { echo "make-offline-base: no Debian mirror found in apt's sources; set MIRROR=" >&2; exit 1; }
root=$(mktemp -d)
trap 'rm -rf "$root"' EXIT
echo "make-offline-base: debootstrap $SUITE from $MIRROR (about a minute)"
debootstrap --variant=minbase "$SUITE" "$root" "$MIRROR" >/tmp/slamrun-debootstrap.log 2>&1 || {
  echo "make-offline-base: debootstrap failed; see /tmp/slamrun-debootstrap.log" >&2; tail -5 /tmp/slamrun-debootstrap.log >&2; exit 1; }
# apt inside the image uses the same mirror; slim: no docs, no caches
printf 'deb %s %s main\n' "$MIRROR" "$SUITE" > "$root/etc/apt/sources.list"
rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/* "$root"/usr/share/doc/* "$root"/usr/share/man/*
tar -C "$root" -c . | docker import -c 'CMD ["bash"]' - "$TAG" >/dev/null
echo "make-offline-base: built $TAG"
