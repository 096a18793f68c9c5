#!/usr/bin/env bash
# Two test suites side by side, N rounds each: is the suite free of flakes on a loaded machine?
#
#     bash benchmarks/side_by_side.sh [ROUNDS] [WORK_FOLDER]
#
# Clones this repository's HEAD twice into WORK_FOLDER (default: a new folder under /tmp), then
# runs `make test` ROUNDS times (default 10) in each clone at the same time, each clone with a
# TMPDIR of its own (its kernels are cached in its own source tree). Prints one line per
# finished suite (clone, round, exit status, wall time, pytest's last line) and, at the end,
# how many of the 2 x ROUNDS suites passed; exits 1 if any failed. The logs stay in
# WORK_FOLDER/log{A,B}/. About 9 minutes a round on the 2-core machine.
set -u
rounds=${1:-10}
work=${2:-$(mktemp -d /tmp/side-by-side-XXXXXX)}
repo=$(git -C "$(dirname "$0")/.." rev-parse --show-toplevel)
mkdir -p "$work"
loop() {
    local x=$1
    git clone -q "$repo" "$work/clone$x"
    mkdir -p "$work/log$x/tmp"
    for i in $(seq 1 "$rounds"); do
        local start=$SECONDS
        (cd "$work/clone$x" && TMPDIR="$work/log$x/tmp" make test > "$work/log$x/round$i.log" 2>&1)
        local rc=$?
        echo "$rc" >> "$work/status$x"
        echo "clone $x round $i rc=$rc $((SECONDS - start)) s: $(tail -n 1 "$work/log$x/round$i.log")"
    done
}
loop A & a=$!
sleep 60  # the second clone starts while the first installs: they overlap from then on
loop B & b=$!
wait $a $b
failed=$(cat "$work"/status? | grep -vc '^0$')
echo "$((2 * rounds - failed)) of $((2 * rounds)) suites passed (two side by side, $(nproc) cores); logs in $work"
[ "$failed" -eq 0 ]
