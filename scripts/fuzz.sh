#!/usr/bin/env bash
# Fuzzes the scene loaders with cargo-fuzz (libFuzzer + AddressSanitizer, nightly toolchain):
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     (default 600 s; scene_xml obj ply serialized hair vol)
# Each target starts from fuzz/seeds/<target> (the project's scenes and meshes and the
# bad-input catalogue) and keeps its growing corpus in fuzz/corpus/<target> (not committed).
# A crash stops the target and leaves the input in fuzz/artifacts/<target>/; copy it to
# fuzz/regressions/<target>/ with an .expect file so tests/fuzz_regressions.rs keeps it fixed.
set -euo pipefail
secs=${1:-600}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(scene_xml obj ply serialized hair vol)
cd "$(dirname "$0")/../fuzz"
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz
rustup toolchain list | grep -q nightly || { echo "cargo fuzz needs a nightly toolchain (rustup toolchain install nightly)" >&2; exit 1; }
mkdir -p logs
status=0
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t"
    extra=()
    [ -f "$t.dict" ] && extra+=("-dict=$t.dict")
    if cargo +nightly fuzz run -O "$t" "corpus/$t" "seeds/$t" -- \
        -max_total_time="$secs" -rss_limit_mb=4096 -timeout=20 "${extra[@]}" >"logs/$t.log" 2>&1; then
        verdict="no crash"
    else
        verdict="CRASH: $(ls -t "artifacts/$t" | head -1)"
        status=1
    fi
    runs=$(grep -Eo '^Done [0-9]+ runs in [0-9]+ second' "logs/$t.log" || grep -Eo '^#[0-9]+' "logs/$t.log" | tail -1)
    cov=$(grep -Eo 'cov: [0-9]+ ft: [0-9]+ corp: [0-9]+' "logs/$t.log" | tail -1)
    echo "$t: $runs; $cov; $verdict"
done
exit $status
