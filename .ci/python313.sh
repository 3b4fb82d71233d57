#!/usr/bin/env bash
# make py313: a plain install of datmo-cli on Python 3.13 (Debian 13's), then `datmo info` and `datmo run` on
# the hall sample log. The interpreter comes from Debian's packages alone: a minimal Debian 13 (trixie) root made
# with debootstrap in $PY313_ROOT (kept for the next run), entered with chroot; needs root (as CI runs). The wheel
# is built there from the committed tree (git archive HEAD), its dependencies from the package index. The first
# run takes over 10 minutes on 2 cores (the root, the install, and above all the kernels' compile on the first
# datmo run: 686 s on a busy machine).
set -euo pipefail
ROOT=${PY313_ROOT:-/var/tmp/datmo-py313}
MIRROR=${PY313_MIRROR:-http://deb.debian.org/debian}
cd "$(dirname "$0")/.."

if ! command -v debootstrap >/dev/null; then
    apt-get update -qq && apt-get install -y -qq debootstrap >/dev/null
fi
if [ ! -x "$ROOT/usr/bin/python3.13" ]; then
    debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates trixie "$ROOT" "$MIRROR"
fi
cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
# the host's trust store: where the index is reached through a proxy with its own certificate authority
cp /etc/ssl/certs/ca-certificates.crt "$ROOT/etc/ssl/certs/ca-certificates.crt"
mounted=()
for fs in proc dev; do
    if ! mountpoint -q "$ROOT/$fs"; then
        if [ "$fs" = proc ]; then mount -t proc proc "$ROOT/proc"; else mount --bind /dev "$ROOT/dev"; fi
        mounted+=("$ROOT/$fs")
    fi
done
cleanup() { for m in "${mounted[@]}"; do umount "$m" || true; done; }
trap cleanup EXIT

rm -rf "$ROOT/src" "$ROOT/out" && mkdir -p "$ROOT/src"
git archive HEAD | tar -x -C "$ROOT/src"
chroot "$ROOT" /usr/bin/env -i PATH=/usr/bin:/bin HOME=/root /bin/bash -euo pipefail -c '
    rm -rf /opt/datmo && python3.13 -m venv /opt/datmo
    /opt/datmo/bin/pip install --quiet --disable-pip-version-check /src
    /opt/datmo/bin/python --version
    /opt/datmo/bin/datmo --version
    /opt/datmo/bin/datmo info /src/sample_logs/hall.mcap > /tmp/info.txt && head -3 /tmp/info.txt
    /opt/datmo/bin/datmo run /src/sample_logs/hall.mcap -o /out
    /opt/datmo/bin/datmo info /out/hall.mcap > /tmp/info.txt && head -10 /tmp/info.txt
'
echo "make py313: a plain install on $(chroot "$ROOT" /opt/datmo/bin/python --version) ran datmo info and datmo run"
