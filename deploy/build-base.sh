#!/usr/bin/env bash
# Build the rob6 base image without any image registry:
#   debootstrap a minimal Debian bookworm root fs (python3 3.11, python3-venv),
#   then `tar | docker import` it as rob6/base:bookworm.
#
# Usage: sudo deploy/build-base.sh [--force] [--tag rob6/base:bookworm] [--mirror URL] [--no-upgrade]
#   --force       rebuild even if the tag already exists (default: reuse it, exit 0)
#   --tag         image tag (env ROB6_BASE_IMAGE, default rob6/base:bookworm)
#   --mirror      Debian mirror (env DEBIAN_MIRROR; default: the first Debian URI in
#                 /etc/apt/sources.list*, else http://deb.debian.org/debian)
#   --no-upgrade  skip applying bookworm-updates / bookworm-security on top of the release
#
# Needs root (debootstrap, chroot) and the debootstrap package; no docker pull.
# The image has no pip, no compiler, no package lists: services install from the
# wheelhouse (deploy/wheelhouse.sh) in the builder stages of deploy/Dockerfile.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
tag="${ROB6_BASE_IMAGE:-rob6/base:bookworm}"
mirror="${DEBIAN_MIRROR:-}"
force=0
upgrade=1
suite=bookworm

while [ $# -gt 0 ]; do
    case "$1" in
        --force) force=1 ;;
        --tag) tag="$2"; shift ;;
        --mirror) mirror="$2"; shift ;;
        --no-upgrade) upgrade=0 ;;
        -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
        *) echo "unknown argument: $1" >&2; exit 2 ;;
    esac
    shift
done

if [ "$force" = 0 ] && docker image inspect "$tag" >/dev/null 2>&1; then
    echo "build-base: $tag already present (use --force to rebuild)"
    exit 0
fi
[ "$(id -u)" = 0 ] || { echo "build-base: needs root (debootstrap/chroot)" >&2; exit 1; }
command -v debootstrap >/dev/null || { echo "build-base: apt-get install debootstrap" >&2; exit 1; }

# mirror: the machine's configured Debian mirror (deb822 'URIs:' or one-line 'deb URL suite')
if [ -z "$mirror" ]; then
    mirror="$(cat /etc/apt/sources.list /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list 2>/dev/null \
        | awk '/^URIs:/ {print $2} /^deb / {print ($2 ~ /^\[/ ? $3 : $2)}' \
        | grep -E '/debian/?$' | grep -v security | head -n1 || true)"
    mirror="${mirror:-http://deb.debian.org/debian}"
fi
security_mirror="${DEBIAN_SECURITY_MIRROR:-${mirror%/debian*}/debian-security}"

work="$(mktemp -d "$here/base/rootfs.XXXXXX" 2>/dev/null || { mkdir -p "$here/base"; mktemp -d "$here/base/rootfs.XXXXXX"; })"
rootfs="$work/rootfs"
cleanup() {
    for m in proc dev/pts dev sys; do umount "$rootfs/$m" 2>/dev/null || true; done
    rm -rf "$work"
}
trap cleanup EXIT

start=$(date +%s)
echo "build-base: debootstrap $suite from $mirror into $rootfs"
debootstrap --variant=minbase --arch=amd64 --include=python3,python3-venv \
    "$suite" "$rootfs" "$mirror"

# later dpkg runs (if anyone apt-gets in a derived image) skip docs too
mkdir -p "$rootfs/etc/dpkg/dpkg.cfg.d"
cat >"$rootfs/etc/dpkg/dpkg.cfg.d/01-rob6-nodoc" <<'EOF'
path-exclude /usr/share/doc/*
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
EOF
cat >"$rootfs/etc/apt/sources.list" <<EOF
deb $mirror $suite main
deb $mirror $suite-updates main
deb $security_mirror $suite-security main
EOF

if [ "$upgrade" = 1 ]; then
    echo "build-base: applying $suite-updates and $suite-security"
    mount -t proc proc "$rootfs/proc"
    cp /etc/resolv.conf "$rootfs/etc/resolv.conf"
    chroot "$rootfs" /usr/bin/env DEBIAN_FRONTEND=noninteractive sh -c \
        'apt-get update -qq && apt-get -y -qq -o Dpkg::Options::=--force-confold dist-upgrade'
    umount "$rootfs/proc"
fi

# slim down: nothing here is needed at run time
chroot "$rootfs" apt-get clean
rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/* "$rootfs"/var/cache/debconf/*-old \
       "$rootfs"/usr/share/doc/* "$rootfs"/usr/share/man/* "$rootfs"/usr/share/info/* \
       "$rootfs"/usr/share/lintian "$rootfs"/var/log/* "$rootfs"/tmp/* "$rootfs"/root/.cache \
       "$rootfs"/etc/resolv.conf "$rootfs"/etc/hostname
find "$rootfs/usr/share/locale" -mindepth 1 -maxdepth 1 ! -name locale.alias -exec rm -rf {} +
find "$rootfs/usr/lib/python3.11" -name __pycache__ -prune -exec rm -rf {} +
: >"$rootfs/etc/machine-id"

py="$(chroot "$rootfs" /usr/bin/python3 -c 'import sys; print("%d.%d.%d" % sys.version_info[:3])')"
echo "build-base: python $py; importing as $tag"
tar --numeric-owner -C "$rootfs" -c . | docker import \
    --change 'ENV LANG=C.UTF-8 PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["/bin/bash"]' \
    --message "rob6 base: debootstrap $suite minbase + python3 $py ($(date -u +%Y-%m-%d))" \
    - "$tag" >/dev/null
docker tag "$tag" "${tag%%:*}:$suite-$(date -u +%Y%m%d)"
echo "build-base: $tag ($(docker image inspect -f '{{.Size}}' "$tag" | awk '{printf "%.0f MB", $1/1e6}')) in $(( $(date +%s) - start )) s"
