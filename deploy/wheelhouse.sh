#!/usr/bin/env bash
# Fill deploy/wheelhouse/ (gitignored) with every Python dependency of the rob6 images,
# for Linux x86_64 / CPython 3.11, so that `docker compose build` needs no network.
#
#   wheelhouse/*.whl             third-party wheels pinned by uv.lock (binary only) and pip itself
#                                (the image builder runs pip from its wheel)
#   wheelhouse/rob6/*.whl        the workspace packages as wheels (rob6_shared, rob6_<service>)
#   wheelhouse/req/common.txt    third-party requirements of rob6-shared (zenoh, msgspec, click)
#   wheelhouse/req/<svc>.txt     all third-party requirements of a service
#   wheelhouse/req/numeric.txt   what kinematics, planner and driver share beyond common (numpy)
#   wheelhouse/req/<svc>-extra.txt  the rest of <svc>.txt (the service's own image layer)
#   wheelhouse/req/<ctl>.txt     third-party requirements of a stand-in controller (controllers/*:
#                                kuka-rsi-sim, adept-sm-sim, kawasaki-as-sim), installed on the bare runtime,
#                                without rob6-shared
#   wheelhouse/debs/*.deb        Debian packages some wheels expect from the system (libgomp1)
#   wheelhouse/SHA256SUMS        checksums of all wheels and debs
#
# Usage: deploy/wheelhouse.sh [--clean] [--offline]
#   --clean    empty the wheelhouse first (default: keep downloaded wheels, prune unpinned ones)
#   --offline  do not download; only rebuild the workspace wheels and requirement files
#              (fails if a pinned wheel is missing)
# Env: UV (path of uv; default .tools/bin/uv or uv on PATH), PIP_VERSION (pip wheel to ship).
# Needs network access to PyPI (or UV_DEFAULT_INDEX / PIP_INDEX_URL) unless --offline.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
out="$here/wheelhouse"
uv="${UV:-$root/.tools/bin/uv}"
[ -x "$uv" ] || uv="$(command -v uv)" || { echo "wheelhouse: uv not found (set UV=)" >&2; exit 1; }
pip_version="${PIP_VERSION:-25.3}"
clean=0
offline=0
for arg in "$@"; do
    case "$arg" in
        --clean) clean=1 ;;
        --offline) offline=1 ;;
        -h|--help) sed -n '2,23p' "$0"; exit 0 ;;
        *) echo "unknown argument: $arg" >&2; exit 2 ;;
    esac
done

services="gateway kinematics planner driver gripper recorder ros"
controllers="kuka-rsi-sim adept-sm-sim kawasaki-as-sim"  # stand-in robot controllers with an image (profiles rsi, adept, kawasaki)
system_debs="libgomp1"
start=$(date +%s)
[ "$clean" = 1 ] && rm -rf "$out"
mkdir -p "$out/req"
cd "$root"

# 1. pinned third-party requirements per package, straight from uv.lock
export_req() {  # $1 = workspace package, $2 = output file
    "$uv" export --package "$1" --frozen --no-dev --no-hashes --no-emit-workspace \
        --no-header --no-annotate --format requirements.txt | grep -v '^\s*#' | grep -v '^\s*$' | sort >"$2"
}
export_req rob6-shared "$out/req/common.txt"
for svc in $services; do
    export_req "rob6-$svc" "$out/req/$svc.txt"
done
for ctl in $controllers; do
    export_req "rob6-$ctl" "$out/req/$ctl.txt"
done
# image layers: common (every image) < numeric (what kinematics, planner and driver share:
# numpy) < <svc>-extra (the rest of that service's closure)
comm -12 "$out/req/kinematics.txt" "$out/req/planner.txt" | comm -12 - "$out/req/driver.txt" \
    | comm -23 - "$out/req/common.txt" >"$out/req/numeric.txt"
for svc in $services; do
    case "$svc" in kinematics|planner|driver) base_layers="$out/req/numeric.txt" ;; *) base_layers=/dev/null ;; esac
    comm -23 "$out/req/$svc.txt" "$out/req/common.txt" | comm -23 - <(sort "$base_layers") >"$out/req/$svc-extra.txt"
done
sort -u "$out"/req/common.txt $(for s in $services $controllers; do echo "$out/req/$s.txt"; done) >"$out/req/all.txt"
echo "pip==$pip_version" >"$out/req/pip.txt"

# 2. third-party wheels for the target platform (not the build host's): binary only,
#    no dependency resolution (uv.lock already resolved everything)
if [ "$offline" = 0 ]; then
    platforms=""
    for p in manylinux_2_36_x86_64 manylinux_2_28_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64 \
             manylinux_2_5_x86_64 manylinux1_x86_64; do
        platforms="$platforms --platform $p"
    done
    # shellcheck disable=SC2086
    "$uv" tool run --quiet --from "pip==$pip_version" pip download --quiet --disable-pip-version-check \
        --dest "$out" --no-deps --only-binary=:all: --implementation cp --python-version 3.11 --abi cp311 \
        $platforms -r "$out/req/all.txt" -r "$out/req/pip.txt"
fi

# 3. the few Debian packages a wheel expects from the system (pinocchio: libgomp1), for
#    the images' Debian (bookworm, amd64); taken with the host's apt (a Debian/Ubuntu host)
mkdir -p "$out/debs"
if [ "$offline" = 0 ]; then
    for deb in $system_debs; do
        ls "$out/debs/${deb}"_*_amd64.deb >/dev/null 2>&1 \
            || (cd "$out/debs" && apt-get download -q "$deb:amd64" >/dev/null) \
            || { echo "wheelhouse: cannot download $deb with apt-get; put ${deb}_*_amd64.deb (bookworm) into $out/debs" >&2; exit 1; }
    done
fi
for deb in $system_debs; do
    ls "$out/debs/${deb}"_*_amd64.deb >/dev/null || exit 1
done

# 4. the workspace packages as wheels (always rebuilt: they are the code under development)
#    into their own folder: the image build copies them after the third-party layers, so a
#    code change rebuilds only the small rob6 layers. SOURCE_DATE_EPOCH makes the wheels
#    reproducible (unchanged code = identical wheel = docker cache hit).
rm -rf "$out/rob6" "$out"/rob6_*.whl
SOURCE_DATE_EPOCH="${SOURCE_DATE_EPOCH:-315532800}" \
    "$uv" build --quiet --all-packages --wheel --out-dir "$out/rob6" 2>&1 | grep -v '^Building\|^Successfully' || true
rm -f "$out/rob6/.gitignore"
ls "$out"/rob6/rob6_shared-*.whl >/dev/null

# 5. prune wheels that uv.lock no longer pins; fail if a pinned one is missing
python3 - "$out" <<'EOF'
import os, re, sys
out = sys.argv[1]
norm = lambda s: re.sub(r"[-_.]+", "-", s).lower()
pins = {}
for name in ("all.txt", "pip.txt"):
    for line in open(os.path.join(out, "req", name)):
        line = line.split(";")[0].strip()
        if "==" in line:
            pkg, ver = line.split("==", 1)
            pins[norm(pkg)] = ver.strip()
found = set()
for f in sorted(os.listdir(out)):
    if not f.endswith(".whl"):
        continue
    pkg, ver = f.split("-")[:2]
    if pins.get(norm(pkg)) == ver:
        found.add(norm(pkg))
    else:
        os.remove(os.path.join(out, f))
        print(f"wheelhouse: pruned {f}")
missing = sorted(set(pins) - found)
if missing:
    sys.exit(f"wheelhouse: missing wheels for {missing} (run without --offline, or no binary wheel exists)")
EOF

(cd "$out" && sha256sum ./*.whl ./rob6/*.whl ./debs/*.deb >SHA256SUMS)
echo "wheelhouse: $(ls "$out"/*.whl "$out"/rob6/*.whl | wc -l) wheels, $(du -sh "$out" | cut -f1) in $(( $(date +%s) - start )) s -> $out"
