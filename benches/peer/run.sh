#!/usr/bin/env bash
# Side-by-side benchmark of this drive against motulator 0.5.0 on motulator's 2.2 kW machine.
#
#   bash benches/peer/run.sh              # both sides; writes docs/peer-benchmark.md and
#                                         # docs/figures/peer/*.png (about 20 min, most of it motulator)
#   bash benches/peer/run.sh --ours-only  # this drive only: no venv, no motulator, nothing written
#                                         # under docs/ (for CI: the scenarios run and are consistent)
#
# Our side runs the simulator CLI: $ACIM_SIM, default target/release/acim-sim (build it with
# `cargo build --release -p acim-sim`). The peer side runs in a venv in benches/peer/.venv
# (Python 3.11: motulator 0.5.0 is its last release for 3.11), made on first use.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
cd "$root"

export ACIM_SIM="${ACIM_SIM:-target/release/acim-sim}"
if [[ ! -x "$ACIM_SIM" ]]; then
    echo "run.sh: no simulator at $ACIM_SIM: build it with 'cargo build --release -p acim-sim'" \
        "or point ACIM_SIM at one" >&2
    exit 1
fi

py=python3.11
command -v "$py" >/dev/null || py=python3

if [[ "${1:-}" == "--ours-only" ]]; then
    shift
    exec "$py" "$here/peer.py" --ours-only "$@"
fi

venv="$here/.venv"
want="$here/requirements.txt"
stamp="$venv/.requirements"
if [[ ! -x "$venv/bin/python" ]] || ! cmp -s "$want" "$stamp"; then
    echo "run.sh: making the venv $venv (motulator 0.5.0)" >&2
    rm -rf "$venv"
    "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$want"
    cp "$want" "$stamp"
fi
"$venv/bin/python" -c 'import importlib.metadata as m, sys; v = m.version("motulator"); sys.exit(0 if v == "0.5.0" else "motulator " + v + " in the venv, 0.5.0 wanted")'

exec "$venv/bin/python" "$here/peer.py" "$@"
