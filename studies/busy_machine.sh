#!/usr/bin/env bash
# Time `fipy-hopper run` of a checkout's package beside one CPU-bound competing process (a
# Python busy loop), as docs/performance.md's "Beside a busy process" was measured:
#
#   studies/busy_machine.sh CODE_DIR CONFIG OUT [run options...]
#   e.g. studies/busy_machine.sh . studies/configs/reference.toml /tmp/busy_default
#        studies/busy_machine.sh . studies/configs/reference.toml /tmp/busy_t1 --threads 1
#
# CODE_DIR holds the fipy_hopper package to time (a checkout, or `git worktree add DIR COMMIT`
# for the code before); the Python is $PYTHON (default: python3).  Run once first to compile the
# kernels; run nothing else meanwhile.  Prints the wall-clock seconds of the whole command.
set -u
code=$1; cfg=$2; out=$3; shift 3
python=${PYTHON:-python3}
python3 -c "while True: pass" & competitor=$!
trap 'kill $competitor 2>/dev/null' EXIT
start=$(date +%s.%N)
"$python" -c "import sys; sys.path.insert(0, '$code'); from fipy_hopper.cli import main; sys.exit(main())" \
    run "$cfg" --out "$out" --force "$@" > "$out.log" 2>&1
rc=$?
end=$(date +%s.%N)
python3 -c "print('$code $* exit $rc: $(basename "$out") took', round($end - $start, 1), 's beside a busy process')"
exit $rc
