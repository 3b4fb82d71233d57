#!/usr/bin/env bash
# Regenerate every log in sample_logs/ bit for bit (run by `make sample-logs` from the project root).
# The simulated logs need nothing but datmo; the real-data excerpt needs ../shared/data beside the clone.
set -euo pipefail
cd "$(dirname "$0")/.."
SHARED=../shared/data
if [ -d "$SHARED/carmen" ]; then
  datmo import "$SHARED/carmen/csail-corrected.log.gz" --max-scans 150 -o sample_logs/csail-excerpt.mcap --force
else
  echo "sample_logs/make.sh: $SHARED is absent; keeping the committed csail-excerpt.mcap" >&2
fi
bash sample_logs/make_simulated.sh
