#!/usr/bin/env bash
# Build the container image's Python environment the way docker/Dockerfile does, without Docker:
# copy what the Dockerfile copies into an empty folder, `pip install -c constraints.txt ".[all]"`
# there (a real install, not an editable one, so package data must be in the wheel), then run the
# demo from it with its history database in a data folder, and check what the containers rely on:
# /api/health answers, /metrics serves bevflow_ series, `bevflow healthcheck` finds every service.
# First the same folder is installed without extras, as a library user would: the core imports,
# `bevflow evaluate` runs, and a service names the extra it needs.
#
#   scripts/check_image_env.sh            # prints each check; exit 1 on the first that fails
#   PYTHON=python3.11 KEEP=1 scripts/check_image_env.sh   # keep the folder for a look afterwards
#
# What it cannot check: the base image, apt packages, the bevflow user and the volume's owner,
# and Docker's own health scheduling (docs/INSTALL.md, "Containers").
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
work=$(mktemp -d)
demo_pid=""
cleanup() {
  [ -n "$demo_pid" ] && kill "$demo_pid" 2>/dev/null && wait "$demo_pid" 2>/dev/null || true
  [ -n "${KEEP:-}" ] && echo "kept $work" || rm -rf "$work"
}
trap cleanup EXIT

# The Dockerfile's COPY lines, then its RUN pip line.
mkdir -p "$work/opt" "$work/data"
cp pyproject.toml README.md LICENSE NOTICE constraints.txt "$work/opt/"
cp -r shared services dashboard "$work/opt/"
find "$work/opt" -name __pycache__ -prune -exec rm -rf {} +
"$PYTHON" -m venv "$work/venv"
install() {  # install WHAT: pip install -c constraints.txt WHAT in the copied folder
  echo "installing with pip install -c constraints.txt $1"
  (cd "$work/opt" && "$work/venv/bin/python" -m pip install --quiet -c constraints.txt "$1" > "$work/pip.log" 2>&1) \
    || { grep -v '^WARNING: Location' "$work/pip.log"; echo "FAIL: pip install $1"; exit 1; }
}
bevflow="$work/venv/bin/bevflow"

install .
(cd "$work" && "$work/venv/bin/python" -c "import bevflow, bevflow.camera, bevflow.live") \
  || { echo "FAIL: the core does not import without extras"; exit 1; }
(cd "$work" && "$bevflow" evaluate --suite paper --frames-scale 0.01 --jobs 1 > "$work/evaluate.out" 2>&1) \
  || { cat "$work/evaluate.out"; echo "FAIL: bevflow evaluate without extras"; exit 1; }
echo "ok: without extras the core imports and bevflow evaluate runs"
said=$(cd "$work" && "$bevflow" serve gateway --site demo-hall 2>&1) && status=0 || status=$?
[ "$status" = 2 ] && [ "$said" = "bevflow serve gateway needs the 'services' extra: pip install 'bevflow[services]'" ] \
  || { echo "FAIL: bevflow serve gateway without extras exited $status saying: $said"; exit 1; }
echo "ok: without extras bevflow serve gateway names the extra it needs"

install ".[all]"  # as the image does; on top of the core, to the same versions

port=$("$work/venv/bin/python" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
(cd "$work" && exec "$bevflow" demo --boxes simulated --port "$port" --duration 120 \
    --history-db "sqlite:///$work/data/history.db" --log-dir "$work/logs") > "$work/demo.out" 2>&1 &
demo_pid=$!

for _ in $(seq 1 120); do
  code=$(curl -s -o /dev/null -w '%{http_code}' "http://127.0.0.1:$port/api/health" || true)
  [ "$code" = 200 ] && break
  sleep 1
done
[ "$code" = 200 ] || { echo "FAIL: /api/health answered '$code'"; cat "$work/demo.out"; exit 1; }
echo "ok: /api/health 200 from the installed package"
metrics=$(curl -s -w '\nHTTP %{http_code}' "http://127.0.0.1:$port/metrics")
grep -q '^bevflow_site_ok ' <<< "$metrics" && grep -q '^bevflow_camera_frames_received_total{' <<< "$metrics" \
  || { echo "FAIL: /metrics:"; head -c 2000 <<< "$metrics"; exit 1; }
echo "ok: /metrics serves bevflow_ series"
# What the extras of the image add beyond the services: the 3D view and the PDF report.
for path in /view3d/ "/api/reports/daily?format=pdf"; do
  code=$(curl -s -o /dev/null -w '%{http_code}' "http://127.0.0.1:$port$path" || true)
  [ "$code" = 200 ] || { echo "FAIL: $path answered '$code'"; exit 1; }
done
echo "ok: the 3D view and the PDF report are served"
[ -s "$work/data/history.db" ] || { echo "FAIL: no history database in the data folder"; exit 1; }
echo "ok: the recorder writes its database into the data folder"
# The demo's first service listens on the hub the others join; ask the bus from there.
hub=$(ps -o args= --ppid "$demo_pid" | grep -o -- '--listen tcp/127.0.0.1:[1-9][0-9]*' | head -1 | cut -d' ' -f2)
"$bevflow" healthcheck gateway --url "http://127.0.0.1:$port/api/health"
for service in tracker projector recorder ingest; do
  "$bevflow" healthcheck "$service" --site demo-hall --connect "$hub"
done
echo "all checks passed"
