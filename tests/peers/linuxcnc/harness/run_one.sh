#!/bin/bash
# Usage: run_one.sh PROGRAM.ngc [OUTPREFIX]
#
# Runs PROGRAM on the headless LinuxCNC 2.9 simulated mill (config/, see README.md) and
# prints the result JSON (time_s = machining time, exact to the 1 ms servo period).
# Writes OUTPREFIX.samples, OUTPREFIX.status.json, OUTPREFIX.result.json and
# OUTPREFIX.linuxcnc.log. OUTPREFIX defaults to $LCNC_OUT_DIR/runs/NAME, LCNC_OUT_DIR to
# the harness's own out/ directory (git-ignored).
#
# Environment: LCNC_OUT_DIR (output directory), LCNC_INI (INI file name in config/,
# default sim_mm.ini), LCNC_TIMEOUT (seconds allowed for the program, default 900).
set -u

if [ $# -lt 1 ] || [ $# -gt 2 ]; then
    echo "usage: $0 PROGRAM.ngc [OUTPREFIX]" >&2
    exit 2
fi
HERE=$(dirname "$(readlink -f "$0")")
PROG=$(readlink -f "$1")
if [ ! -f "$PROG" ]; then
    echo "$0: no such program: $1" >&2
    exit 2
fi
NAME=$(basename "$PROG" .ngc)
OUT_DIR=${LCNC_OUT_DIR:-$HERE/out}
OUT=$(readlink -m "${2:-$OUT_DIR/runs/$NAME}")
mkdir -p "$(dirname "$OUT")"
rm -f "$OUT.samples" "$OUT.status.json" "$OUT.result.json"

# LinuxCNC runs in a private copy of config/ (it rewrites the parameter file on exit),
# so the repository stays untouched.
RUNCFG=$(mktemp -d "${TMPDIR:-/tmp}/lcnc-harness.XXXXXX")
trap 'rm -rf "$RUNCFG"' EXIT
cp "$HERE"/config/* "$RUNCFG"/

export LCNC_PROGRAM="$PROG" LCNC_OUT="$OUT" LCNC_TIMEOUT="${LCNC_TIMEOUT:-900}"
# the INI's DISPLAY = run_display.py is looked up on PATH
export PATH="$HERE:$PATH"
if [ "$(id -u)" = 0 ]; then
    # uspace rtapi_app refuses to run as root without a fallback UID; nobody works
    export RTAPI_UID="${RTAPI_UID:-65534}"
    export RTAPI_FIFO_PATH="${RTAPI_FIFO_PATH:-/tmp/rtapi_fifo.lcnc}"
fi
# no X display: nothing may try to open a window
(cd "$RUNCFG" && env -u DISPLAY timeout 1200 linuxcnc "$RUNCFG/${LCNC_INI:-sim_mm.ini}") \
    > "$OUT.linuxcnc.log" 2>&1 < /dev/null

if [ ! -f "$OUT.status.json" ] || [ ! -f "$OUT.samples" ]; then
    echo "$0: LinuxCNC did not run the program; see $OUT.linuxcnc.log and /tmp/linuxcnc.debug.*" >&2
    exit 1
fi
/usr/bin/python3 - "$HERE" "$OUT" <<'PY'
import json, sys
sys.path.insert(0, sys.argv[1])
from analyze import analyze
out = sys.argv[2]
with open(out + ".status.json") as f:
    st = json.load(f)
res = analyze(out + ".samples")
res.update({k: st.get(k) for k in ("program", "outcome", "errors", "sampler_overruns", "wall_s")})
with open(out + ".result.json", "w") as f:
    json.dump(res, f, indent=1)
print(json.dumps(res))
PY
