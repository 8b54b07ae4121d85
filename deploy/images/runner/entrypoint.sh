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
#   own /dev/shm is not the host's), of at most 31 characters (fbksd-ci
#   says so at start otherwise).
# - Cores: FBKSD_CI_CPUS defaults to the cores this container may use (a
#   Kubernetes pod's own cores under the static CPU manager), not to
#   0..N-1 as fbksd-ci alone would.
set -eu
. /usr/local/lib/fbksd/secrets.sh
if [ -z "${FBKSD_CI_WORK_DIR:-}" ]; then
    FBKSD_CI_WORK_DIR=${FBKSD_CI_WORK_ROOT:?set FBKSD_CI_WORK_ROOT (a host directory at the same path) or FBKSD_CI_WORK_DIR}/$(hostname)
    export FBKSD_CI_WORK_DIR
fi
mkdir -p "$FBKSD_CI_WORK_DIR"
if [ -n "${FBKSD_RUNTIME_DIR:-}" ]; then
    # fbksd-ci refuses one too long for a run's control socket.
    mkdir -p "$FBKSD_RUNTIME_DIR"
fi
if [ -z "${FBKSD_CI_CPUS:-}" ]; then
    FBKSD_CI_CPUS=$(sed -n 's/^Cpus_allowed_list:[[:space:]]*//p' /proc/self/status)
    export FBKSD_CI_CPUS
fi
exec "$@"
