#!/usr/bin/env bash
# Makes /dev/null the null device again where a machine has a regular file there (seen
# on CI runners). With a file, whatever one program discards into /dev/null the next
# one reads back: cargo's rustc target probe, whose source comes from /dev/null, read a
# build script's feature-probe error text and failed the build after clippy.
# Without the rights to create the device, the file is at least emptied; callers run
# this before each cargo command.
# No redirection to /dev/null here: while it is missing, that would create the file.
set -u
[ -c /dev/null ] && exit 0
if rm -f /dev/null && mknod -m 666 /dev/null c 1 3; then
    echo "note: /dev/null was a regular file; it is the null device again" >&2
else
    : > /dev/null
    echo "warning: /dev/null is a regular file and could not be replaced; emptied it" >&2
fi
