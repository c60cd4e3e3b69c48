#!/usr/bin/env bash
# Run the test suite. Creates ./.venv with trackcli and its test dependencies on first use.
set -euo pipefail
cd "$(dirname "$0")"
. ./setup-venv.sh
CI=true exec .venv/bin/python -m pytest "$@"
