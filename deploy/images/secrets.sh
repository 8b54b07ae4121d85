# Sourced by the server's and the runner's entrypoints: each file named
# FBKSD_* in $FBKSD_SECRETS_DIR (default /run/secrets) becomes the variable
# of its name (e.g. FBKSD_SERVER_DATABASE_URL, FBKSD_REGISTRATION_TOKEN),
# since the programs read their secrets from the environment or a flag,
# not from files of their own. A command line is readable by every user
# of the machine; this is not.
for file in "${FBKSD_SECRETS_DIR:-/run/secrets}"/FBKSD_*; do
    [ -f "$file" ] || continue
    name=${file##*/}
    case "$name" in *[!A-Z0-9_]*) echo "fbksd-entrypoint: $file: not a variable name" >&2; exit 1 ;; esac
    value=$(cat "$file")
    export "$name=$value"
done
