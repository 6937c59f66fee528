#!/usr/bin/env bash
# Builds nerve's Python package (python/) in a folder of its own and installs
# it into the Python that runs pip, with one progress line while cargo
# compiles (plain `pip install ./python` prints nothing for minutes and builds
# in nerve's own target folder). docs/python.md, "Installing".
#
#   bash python/install.sh                     # release build in python/target
#   PYTHON=.venv/bin/python bash python/install.sh
#   bash python/install.sh --dev               # the dev profile: quicker to build
#   CARGO_TARGET_DIR=target bash python/install.sh --dev   # reuse `cargo build --workspace`'s build
#   bash python/install.sh --target DIR        # any other argument goes to pip
#
# The Python needs maturin and numpy (`python3 -m pip install maturin numpy`).
# The whole log is kept in TARGET/pip-install.log; a failure prints its end.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
python=${PYTHON:-python3}
# absolute: pip runs maturin in python/, not here
target=$(realpath -m "${CARGO_TARGET_DIR:-$here/target}")
profile=""
pip_args=()
for a in "$@"; do
    case $a in
        --dev) profile="--profile dev" ;;
        *) pip_args+=("$a") ;;
    esac
done

if ! "$python" -c 'import maturin, numpy' 2>/dev/null; then
    echo "error: $python lacks maturin or numpy: run \`$python -m pip install maturin numpy\` first, or name another Python with PYTHON=..." >&2
    exit 1
fi
# maturin's own program, beside that Python's (a venv's bin/)
scripts=$("$python" -c 'import sysconfig; print(sysconfig.get_path("scripts"))')
export PATH="$scripts:$PATH"
mkdir -p "$target"
log=$target/pip-install.log
export MATURIN_PEP517_ARGS="${MATURIN_PEP517_ARGS:-} --target-dir $target $profile"

tty=false
[ -t 2 ] && tty=true
echo "building nerve's Python package in $target${profile:+ ($profile)} for $("$python" --version 2>&1); log: $log" >&2
start=$SECONDS
set +e
"$python" -m pip install -v --no-build-isolation --disable-pip-version-check "${pip_args[@]}" "$here" 2>&1 \
    | tee "$log" \
    | {
        n=0
        while IFS= read -r line; do
            case $line in
                *"Blocking waiting for file lock"*)
                    $tty && echo >&2
                    echo "  waiting for another cargo build to finish (they share $target)" >&2
                    ;;
                *" Compiling "*)
                    n=$((n + 1))
                    crate=${line#*Compiling }
                    crate=${crate%% *}
                    msg="  compiled $n crates, $((SECONDS - start)) s (now: $crate)"
                    if $tty; then
                        printf '\r%-78s' "$msg" >&2
                    elif ((n % 25 == 1)); then
                        echo "$msg" >&2
                    fi
                    ;;
            esac
        done
        $tty && printf '\r%-78s\r' "" >&2
        echo "  compiled $n crates in $((SECONDS - start)) s" >&2
    }
status=${PIPESTATUS[0]}
set -e
if [ "$status" -ne 0 ]; then
    echo "error: pip install failed (exit $status); the end of $log:" >&2
    tail -n 30 "$log" >&2
    exit "$status"
fi
echo "installed: $(grep -E '^Successfully installed' "$log" | tail -n 1 || echo 'nerve') ($((SECONDS - start)) s)" >&2
