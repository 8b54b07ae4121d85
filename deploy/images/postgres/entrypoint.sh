#!/bin/sh
# Starts PostgreSQL on $PGDATA, listening on every address with password
# (SCRAM) authentication. The first start makes the cluster, the role
# fbksd with the password in $FBKSD_SECRETS_DIR/POSTGRES_PASSWORD (default
# /run/secrets) and the database fbksd it owns; the password goes to
# PostgreSQL on its standard input, never on a command line.
set -eu
bin=$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)
if [ ! -s "$PGDATA/PG_VERSION" ]; then
    password_file=${FBKSD_SECRETS_DIR:-/run/secrets}/POSTGRES_PASSWORD
    [ -s "$password_file" ] || { echo "fbksd-postgres: $password_file is missing or empty" >&2; exit 1; }
    mkdir -p "$PGDATA"
    chmod 0700 "$PGDATA"
    "$bin/initdb" -D "$PGDATA" -U postgres --auth-local=peer --auth-host=scram-sha-256 \
        --encoding=UTF8 --locale=C.UTF-8 >/dev/null
    printf 'host all all all scram-sha-256\n' >>"$PGDATA/pg_hba.conf"
    # Single-user mode: no connection is possible until the role exists.
    { printf "CREATE ROLE fbksd LOGIN PASSWORD '"
      sed "s/'/''/g" "$password_file" | tr -d '\n'
      printf "';\nCREATE DATABASE fbksd OWNER fbksd;\n"
    } | "$bin/postgres" --single -D "$PGDATA" postgres >/dev/null
    echo "fbksd-postgres: made the cluster in $PGDATA with the role and database fbksd" >&2
fi
exec "$bin/postgres" -D "$PGDATA" -c listen_addresses='*' -c unix_socket_directories=/run/postgresql
