#!/usr/bin/env bash
# Build every rob6 image offline, in one go: the base image (deploy/build-base.sh, reused
# when present), the wheelhouse (deploy/wheelhouse.sh, offline when it is complete), then
# `compose build` of docker-compose.yml with every profile: the router, the six services
# and the three stand-in controllers, tagged rob6/<name>:$ROB6_TAG.
#
# Usage: deploy/build-images.sh      (or `make images`)
# Env:   ROB6_TAG (default latest), ROB6_BASE_IMAGE (default rob6/base:bookworm), UV
#
# A cold build (no rob6 image, no wheelhouse) on a 2-core machine took 4.5 minutes (base
# 57 s, wheelhouse 12 s, compose build 193 s; deploy/README.md); with Docker's layer cache
# warm it takes seconds. Each step
# prints one line with its time; a failing step stops the script with its exit code.
# The tests build through this script once per run, before the first test (tests/conftest.py).
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
tag="${ROB6_TAG:-latest}"

step_start=$(date +%s)
done_step() {
    echo "build-images: $1 in $(( $(date +%s) - step_start )) s"
    step_start=$(date +%s)
}

bash "$here/build-base.sh"
done_step "base image ${ROB6_BASE_IMAGE:-rob6/base:bookworm}"

if ! bash "$here/wheelhouse.sh" --offline >/dev/null 2>&1; then
    bash "$here/wheelhouse.sh"  # a pinned wheel is missing: download what is missing
fi
done_step "wheelhouse"

# an empty env file: a developer's .env must not change what is built
env_file="$(mktemp)"
trap 'rm -f "$env_file"' EXIT
ROB6_TAG="$tag" "$here/compose" -p rob6build -f docker-compose.yml --env-file "$env_file" \
    --profile rsi --profile adept --profile kawasaki build
done_step "compose build of rob6/*:$tag (router, services, stand-in controllers)"
