#!/bin/sh
# Runs fbksd-ci in a container that drives the host's Docker engine.
# - Secrets: each file named FBKSD_* in $FBKSD_SECRETS_DIR (default
#   /run/secrets) becomes the variable of its name, e.g.
#   FBKSD_REGISTRATION_TOKEN (fbksd-ci reads it from the environment or a
#   flag only; a command line is readable by every user of the machine).
# - Work directory: the runner mounts its job directories into sibling
#   containers by path, so FBKSD_CI_WORK_ROOT must be a host directory
#   mounted at the same path here. Each replica works in its own
#   subdirectory, named by the container's host name, since a runner
#   empties its work directory at start (FBKSD_CI_WORK_DIR overrides it).
# - Rendezvous: FBKSD_RUNTIME_DIR, where runs share memory with their
#   containers, is a host directory at the same path too (the container's
#   own /dev/shm is not the host's), of at most 31 characters.
# - Cores: FBKSD_CI_CPUS defaults to the cores this container may use (a
#   Kubernetes pod's own cores under the static CPU manager), not to
#   0..N-1 as fbksd-ci alone would.
set -eu
for file in "${FBKSD_SECRETS_DIR:-/run/secrets}"/FBKSD_*; do
    [ -f "$file" ] || continue
    name=${file##*/}
    case "$name" in *[!A-Z0-9_]*) echo "fbksd-entrypoint: $file: not a variable name" >&2; exit 1 ;; esac
    value=$(cat "$file")
    export "$name=$value"
done
if [ -z "${FBKSD_CI_WORK_DIR:-}" ]; then
    FBKSD_CI_WORK_DIR=${FBKSD_CI_WORK_ROOT:?set FBKSD_CI_WORK_ROOT (a host directory at the same path) or FBKSD_CI_WORK_DIR}/$(hostname)
    export FBKSD_CI_WORK_DIR
fi
mkdir -p "$FBKSD_CI_WORK_DIR"
if [ -n "${FBKSD_RUNTIME_DIR:-}" ]; then
    # A run's control socket is fbksd-ci-<runner id>/fbksd-run-XXXXXX/control.sock
    # below it (76 characters), and a Unix socket's path has at most 107.
    if [ ${#FBKSD_RUNTIME_DIR} -gt 31 ]; then
        echo "fbksd-entrypoint: FBKSD_RUNTIME_DIR=$FBKSD_RUNTIME_DIR is longer than 31 characters: runs could not bind their control sockets" >&2
        exit 1
    fi
    mkdir -p "$FBKSD_RUNTIME_DIR"
fi
if [ -z "${FBKSD_CI_CPUS:-}" ]; then
    FBKSD_CI_CPUS=$(sed -n 's/^Cpus_allowed_list:[[:space:]]*//p' /proc/self/status)
    export FBKSD_CI_CPUS
fi
exec "$@"
