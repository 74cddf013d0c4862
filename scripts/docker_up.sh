#!/usr/bin/env bash
# Make sure a Docker engine answers (the coding benchmark's sandboxes and their tests need one).
#   bash scripts/docker_up.sh      exit 0 once `docker info` answers; else one line on stderr, exit 1
# On a machine where we are root with apt-get (these CI machines), a missing engine is installed
# (Debian's docker.io) and dockerd is started in the background (log: /tmp/recap-dockerd.log).
# Elsewhere it says what to do. No registry is needed: the sandbox image is built locally
# (scripts/build_sandbox_image.sh).
set -uo pipefail
if docker info >/dev/null 2>&1; then exit 0; fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "error: no Docker engine answers, and it cannot be started here (needs root and apt-get): start dockerd, or set RECAP_SKIP_DOCKER=1 to skip the Docker sandbox tests" >&2
  exit 1
fi
if ! command -v dockerd >/dev/null 2>&1; then
  echo "installing docker.io (apt) for the coding sandbox tests"
  log=$(mktemp)
  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker.io; } >"$log" 2>&1; then
    tail -n 20 "$log" >&2
    echo "error: apt-get could not install docker.io (output above); set RECAP_SKIP_DOCKER=1 to skip the Docker sandbox tests" >&2
    rm -f "$log"
    exit 1
  fi
  rm -f "$log"
fi
nohup dockerd >/tmp/recap-dockerd.log 2>&1 &
for _ in $(seq 1 60); do
  if docker info >/dev/null 2>&1; then exit 0; fi
  sleep 1
done
tail -n 20 /tmp/recap-dockerd.log >&2
echo "error: dockerd did not answer within 60 s (its log above); set RECAP_SKIP_DOCKER=1 to skip the Docker sandbox tests" >&2
exit 1
