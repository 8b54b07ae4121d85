#!/bin/sh
# Runs its arguments (fbksd-server, or `fbksd-server backup DIR`) with the
# secrets of $FBKSD_SECRETS_DIR (default /run/secrets) in the environment:
# each file there named FBKSD_* becomes the variable of its name (e.g.
# FBKSD_SERVER_DATABASE_URL), since the server reads its secrets from the
# environment or a configuration file, not from files of their own. A
# command line is readable by every user of the machine; this is not.
set -eu
. /usr/local/lib/fbksd/secrets.sh
exec "$@"
