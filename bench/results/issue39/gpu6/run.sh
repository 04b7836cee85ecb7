# Issue 39 item 3 on one H200 (branch gpu6): the script that ran is ../gpu7/run.sh with the
# bundle .whl/gpu6/b and no CAP (585 s), i.e. from the repository root on the device machine,
# after a call carrying [".whl/gpu/a"] that did `mkdir -p /tmp/parts && cp .whl/gpu/a/* /tmp/parts/`:
#   B=$(pwd)/.whl/gpu6/b bash bench/results/issue39/gpu7/run.sh STEP...
# (gpu7 added only CAP and the settable bundle.) STEP: tl:TREE:N or s25:TREE:N, see there.
B=${B:-$(pwd)/.whl/gpu6/b} exec bash "$(pwd)/bench/results/issue39/gpu7/run.sh" "$@"
