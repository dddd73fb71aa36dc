#!/usr/bin/env bash
# A throwaway PostgreSQL server for the results-store tests: a cluster in a
# temporary directory, listening on loopback only, with a user and a
# database `gyrobench` (password `gyrobench`).
#
#   tests/conformance/postgres.sh start DIR PORT   # prints the URL; again after a stop: the same cluster
#   tests/conformance/postgres.sh stop DIR
#
# Needs Debian's `postgresql` package. Run as root it runs the server as
# the `postgres` user (the server refuses to run as root).
set -euo pipefail
cmd=$1 dir=$2
bin=$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)
as_pg() {
    if [ "$(id -u)" = 0 ]; then runuser -u postgres -- "$@"; else "$@"; fi
}
case "$cmd" in
start)
    port=$3
    fresh=false
    if [ ! -d "$dir/data" ]; then
        fresh=true
        mkdir -p "$dir"
        if [ "$(id -u)" = 0 ]; then chown postgres: "$dir"; fi
        as_pg "$bin/initdb" -D "$dir/data" -U postgres -A trust --no-sync > "$dir/initdb.log"
    fi
    as_pg "$bin/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w \
        -o "-c listen_addresses=127.0.0.1 -p $port -k $dir -c fsync=off -c max_connections=100" start > /dev/null
    if $fresh; then
        as_pg "$bin/psql" -h 127.0.0.1 -p "$port" -U postgres -q -v ON_ERROR_STOP=1 <<SQL
CREATE USER gyrobench PASSWORD 'gyrobench';
CREATE DATABASE gyrobench OWNER gyrobench;
SQL
        # Passwords from here on: the tests check a wrong one is refused.
        sed -i 's/ trust$/ scram-sha-256/' "$dir/data/pg_hba.conf"
        as_pg "$bin/pg_ctl" -D "$dir/data" reload > /dev/null
    fi
    echo "postgres://gyrobench:gyrobench@127.0.0.1:$port/gyrobench"
    ;;
stop)
    if [ -f "$dir/data/postmaster.pid" ]; then
        as_pg "$bin/pg_ctl" -D "$dir/data" -m fast -w stop > /dev/null || true
    fi
    ;;
*)
    echo "usage: $0 start DIR PORT | stop DIR" >&2
    exit 2
    ;;
esac
