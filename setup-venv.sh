# Sourced by demo.sh and test.sh: create ./.venv and install trackcli into it when needed.
# Re-installs only when pyproject.toml has changed since the last install.
PYTHON_BIN=${PYTHON:-python3}
if ! "$PYTHON_BIN" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    echo "trackcli needs Python >= 3.11 (set PYTHON=/path/to/python3.11 or newer)" >&2
    exit 1
fi
if [ ! -x .venv/bin/python ]; then
    echo "Creating .venv ..." >&2
    "$PYTHON_BIN" -m venv .venv
fi
stamp=.venv/.trackcli-installed
want=$(cat pyproject.toml | cksum)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    echo "Installing trackcli and its dependencies into .venv (first run takes a minute) ..." >&2
    .venv/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
    .venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".[test]" >&2
    echo "$want" > "$stamp"
fi
