#!/bin/sh
# run_fuzz.sh FUZZER SEEDS WORK SECONDS [FLAG...]: runs a libFuzzer target for SECONDS on a
# fresh copy of its seed corpus in WORK/corpus (new inputs stay there, never in the source
# tree). A crash, leak, undefined behaviour, a 10 s input or more than 2 GB of memory fails
# the run and leaves the input in WORK/artifacts/. FLAGs (e.g. -dict=...) and then
# $ROUEN_FUZZ_ARGS are added to the libFuzzer command line; later flags win.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
export UBSAN_OPTIONS="print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
export LSAN_OPTIONS="suppressions=$here/lsan.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
fuzzer=$1 seeds=$2 work=$3 seconds=$4
shift 4
rm -rf "$work"
mkdir -p "$work/corpus" "$work/artifacts"
cp "$seeds"/* "$work/corpus/"
# shellcheck disable=SC2086
exec "$fuzzer" -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
  -artifact_prefix="$work/artifacts/" "$@" ${ROUEN_FUZZ_ARGS:-} "$work/corpus"
