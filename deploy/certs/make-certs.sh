#!/usr/bin/env bash
# Make the rob6 PKI for Zenoh mutual TLS: one CA, one certificate per participant.
# The certificate's common name (CN) is the participant's identity in the router's
# access control (deploy/zenoh/router-secure.json5, subjects/cert_common_names).
#
# Usage: deploy/certs/make-certs.sh [options] [NAME...]
#   NAME...            participants (default: router gateway kinematics planner driver gripper recorder ros ros2);
#                      extra names make extra certificates (e.g. a second kinematics host reuses
#                      "kinematics": replicas of one service share its identity)
#   --out DIR          output directory (default deploy/certs/out, gitignored)
#   --router-san SANS  extra subjectAltNames of the router certificate, comma-separated, e.g.
#                      "DNS:robot-pc,IP:192.168.10.5" (clients check the name they connect to;
#                      router, localhost and 127.0.0.1 are always included)
#   --days N           validity of participant certificates (default 825; the CA: 3650)
#   --owner UID:GID    owner of the private keys (default 10001:10001, the images' rob6 user, so
#                      containers can read their bind-mounted key; only applied when run as root)
#   --ca-dir DIR       take ca.crt/ca.key from DIR instead of making/reusing one in --out
#   --force            remake existing certificates (the CA too, unless --ca-dir)
#
# Output: ca.crt, ca.key (keep ca.key off the robot PC once done), NAME.crt, NAME.key (0600).
# Existing files are kept unless --force, so the script can be re-run to add a participant.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
out="$here/out"
router_san=""
days=825
owner="10001:10001"
ca_dir=""
force=0
names=()
while [ $# -gt 0 ]; do
    case "$1" in
        --out) out="$2"; shift ;;
        --router-san) router_san="$2"; shift ;;
        --days) days="$2"; shift ;;
        --owner) owner="$2"; shift ;;
        --ca-dir) ca_dir="$2"; shift ;;
        --force) force=1 ;;
        -h|--help) sed -n '2,24p' "$0"; exit 0 ;;
        -*) echo "unknown option: $1" >&2; exit 2 ;;
        *) names+=("$1") ;;
    esac
    shift
done
[ ${#names[@]} -gt 0 ] || names=(router gateway kinematics planner driver gripper recorder ros ros2)
command -v openssl >/dev/null || { echo "make-certs: openssl not found" >&2; exit 1; }
mkdir -p "$out"
umask 077
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

key() {  # ECDSA P-256 in PKCS#8 (what rustls, hence Zenoh, reads)
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null
}

# ---------------------------------------------------------------- CA
if [ -n "$ca_dir" ]; then
    cp "$ca_dir/ca.crt" "$out/ca.crt" 2>/dev/null || true
    ca_crt="$ca_dir/ca.crt"; ca_key="$ca_dir/ca.key"
else
    ca_crt="$out/ca.crt"; ca_key="$out/ca.key"
    if [ "$force" = 1 ] || [ ! -s "$ca_crt" ] || [ ! -s "$ca_key" ]; then
        key "$ca_key"
        openssl req -x509 -new -key "$ca_key" -sha256 -days 3650 -subj "/O=rob6/CN=rob6 lab CA" \
            -addext "basicConstraints=critical,CA:TRUE,pathlen:0" \
            -addext "keyUsage=critical,keyCertSign,cRLSign" \
            -addext "subjectKeyIdentifier=hash" -out "$ca_crt"
        chmod 0644 "$ca_crt"
        echo "make-certs: new CA $ca_crt"
        force=1  # certificates of an old CA are useless now
    fi
fi

# ---------------------------------------------------------------- participants
for name in "${names[@]}"; do
    [[ "$name" =~ ^[A-Za-z0-9][A-Za-z0-9_.-]*$ ]] || { echo "make-certs: bad name '$name'" >&2; exit 2; }
    crt="$out/$name.crt"; k="$out/$name.key"
    if [ "$force" = 0 ] && [ -s "$crt" ] && [ -s "$k" ]; then
        echo "make-certs: keeping $crt"
        continue
    fi
    san="DNS:$name"
    [ "$name" = router ] && san="DNS:router,DNS:localhost,IP:127.0.0.1${router_san:+,$router_san}"
    key "$k"
    openssl req -new -key "$k" -subj "/O=rob6/CN=$name" -out "$tmp/$name.csr"
    cat >"$tmp/$name.ext" <<EOF
basicConstraints=critical,CA:FALSE
keyUsage=critical,digitalSignature,keyEncipherment
extendedKeyUsage=serverAuth,clientAuth
subjectAltName=$san
subjectKeyIdentifier=hash
authorityKeyIdentifier=keyid
EOF
    openssl x509 -req -in "$tmp/$name.csr" -CA "$ca_crt" -CAkey "$ca_key" -CAcreateserial \
        -CAserial "$tmp/ca.srl" -days "$days" -sha256 -extfile "$tmp/$name.ext" -out "$crt" 2>/dev/null
    chmod 0644 "$crt"
    chmod 0600 "$k"
    if [ "$(id -u)" = 0 ] && [ -n "$owner" ]; then
        chown "$owner" "$k"
    fi
    openssl verify -CAfile "$ca_crt" "$crt" >/dev/null
    echo "make-certs: $crt (CN=$name, $san)"
done
