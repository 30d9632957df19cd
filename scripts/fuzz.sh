#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, CMake preset "fuzz": clang, ASan + UBSan) in build-fuzz/
# and runs each for SECONDS (default 60) on a scratch copy of its corpus fuzz/corpus/<target>/.
#
#   scripts/fuzz.sh [SECONDS] [--merge] [--keep-going] [TARGET ...]
#
#   SECONDS       fuzzing time per target (default 60)
#   --merge       afterwards, add the new inputs that reach new coverage to fuzz/corpus/<target>/
#                 (libFuzzer -merge=1; review and commit them)
#   --keep-going  fork mode (-fork=1 -ignore_crashes/-ignore_timeouts/-ignore_ooms): go on after
#                 a crash for the whole time and keep every crashing input, to collect findings
#   TARGET        names as in fuzz/corpus (exr lens_json ...); default: all
#
# Limits: -timeout=10 (s), -rss_limit_mb=2048, -malloc_limit_mb=512 (one allocation that large is
# reported as out-of-memory at once, instead of ASan filling gigabytes: issue 60 asks every input
# to be handled in under 200 MB), -max_len per format.
#
# Prints per target: executions, exec/s, crashes/leaks/timeouts/out-of-memory (and slow inputs,
# over 10 s but under the timeout, which are listed without failing), the inputs that failed (build-fuzz/fuzz-runs/<target>/artifacts/), and the log. Exit 1 when any target
# failed. Reproduce one input with build-fuzz/bin/<target>_fuzzer <file>, or with the gcc build's
# replay: build/bin/<target>_fuzzer <file>.
#
# Environment: FLAREKIT_FUZZ_JOBS (build jobs, default nproc), FLAREKIT_FUZZ_NICE (nice level of
# the build and the runs, default 0).
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=$here/build-fuzz
jobs=${FLAREKIT_FUZZ_JOBS:-$(nproc)}
nice_level=${FLAREKIT_FUZZ_NICE:-0}

seconds=60
merge=0
keep_going=0
targets=()
for arg in "$@"; do
  case $arg in
    --merge) merge=1 ;;
    --keep-going) keep_going=1 ;;
    -h|--help) sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    ''|*[!0-9]*) targets+=("$arg") ;;
    *) seconds=$arg ;;
  esac
done
all=(exr exr_stack lens_json pbrt_lens rig_toml model_json capture_manifest capture_resume
     scene_json gltf raw_decode linear_image)
((${#targets[@]})) || targets=("${all[@]}")

# Largest input libFuzzer makes per target: a few times the largest seed.
declare -A max_len=(
  [exr]=32768 [exr_stack]=32768 [lens_json]=32768 [pbrt_lens]=4096 [rig_toml]=16384
  [model_json]=65536 [capture_manifest]=16384 [capture_resume]=16384 [scene_json]=16384
  [gltf]=16384 [raw_decode]=16384 [linear_image]=8192)
declare -A dict=(
  [lens_json]=json [model_json]=json [capture_manifest]=json [capture_resume]=json
  [scene_json]=json [gltf]=json [rig_toml]=toml)

for t in "${targets[@]}"; do
  [[ -d $here/fuzz/corpus/$t ]] || { echo "fuzz.sh: unknown target $t (known: ${all[*]})" >&2; exit 2; }
done

command -v clang++ >/dev/null || { echo "fuzz.sh: clang++ missing; run scripts/setup.sh --no-build" >&2; exit 1; }
echo "fuzz.sh: building $build (preset fuzz)"
nice -n "$nice_level" cmake --preset fuzz -S "$here" >/dev/null
start=$(date +%s)
nice -n "$nice_level" cmake --build "$build" -j"$jobs" --target flarekit_fuzzers | grep -v '^\[' || true
for t in "${targets[@]}"; do
  [[ -x $build/bin/${t}_fuzzer ]] || { echo "fuzz.sh: build failed ($build/bin/${t}_fuzzer missing)" >&2; exit 1; }
done
echo "fuzz.sh: built in $(( $(date +%s) - start )) s; fuzzing ${#targets[@]} targets for $seconds s each"

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:verify_asan_link_order=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

failed=0
summary=()
for t in "${targets[@]}"; do
  run=$build/fuzz-runs/$t
  rm -rf "$run"
  mkdir -p "$run/corpus" "$run/artifacts"
  cp -r "$here/fuzz/corpus/$t/." "$run/corpus/"
  args=(-max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=512
        -max_len="${max_len[$t]}"
        -artifact_prefix="$run/artifacts/" -print_final_stats=1)
  [[ -n ${dict[$t]:-} ]] && args+=(-dict="$here/fuzz/${dict[$t]}.dict")
  ((keep_going)) && args+=(-fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1)
  echo "fuzz.sh: $t ($seconds s) ..."
  status=0
  (cd "$run" && nice -n "$nice_level" "$build/bin/${t}_fuzzer" "${args[@]}" "$run/corpus" \
     >"$run/log" 2>&1) || status=$?
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$run/log" | tail -1 | grep -o '[0-9]*$' || true)
  rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$run/log" | tail -1 | grep -o '[0-9]*$' || true)
  if [[ -z $execs ]]; then  # fork mode, or killed before the final stats: the last status line
    line=$(grep -E '^#[0-9]+' "$run/log" | tail -1 || true)
    execs=$(sed -E 's/^#([0-9]+).*/\1/' <<<"$line")
    rate=$(grep -o 'exec/s:\? [0-9]*' <<<"$line" | grep -o '[0-9]*$' || true)
  fi
  count() { find "$run/artifacts" -maxdepth 1 -name "$1-*" | wc -l; }
  crashes=$(count crash) leaks=$(count leak) timeouts=$(count timeout) ooms=$(count oom)
  slow=$(count slow-unit)  # over 10 s but under -timeout: listed, not a failure
  problems=$((crashes + leaks + timeouts + ooms))
  if ((problems == 0 && status != 0)); then
    # A failure libFuzzer wrote no artifact for (e.g. an error in the harness itself).
    crashes=1 problems=1
  fi
  line=$(printf '%-17s %10s execs %6s exec/s  crashes %d  leaks %d  timeouts %d  oom %d  slow %d' \
         "$t" "${execs:-?}" "${rate:-?}" "$crashes" "$leaks" "$timeouts" "$ooms" "$slow")
  summary+=("$line")
  if ((slow && !problems)); then
    while IFS= read -r f; do summary+=("    slow: $f"); done < <(find "$run/artifacts" -maxdepth 1 -name 'slow-unit-*' | sort)
  fi
  if ((problems)); then
    failed=1
    while IFS= read -r f; do summary+=("    $f"); done < <(find "$run/artifacts" -maxdepth 1 -type f | sort)
    summary+=("    log: $run/log")
  fi
  if ((merge)); then
    nice -n "$nice_level" "$build/bin/${t}_fuzzer" -merge=1 -max_len="${max_len[$t]}" -timeout=10 \
      -rss_limit_mb=2048 "$here/fuzz/corpus/$t" "$run/corpus" >"$run/merge.log" 2>&1 ||
      echo "fuzz.sh: merge of $t failed (see $run/merge.log)" >&2
  fi
done

echo
echo "fuzz.sh: $seconds s per target, ASan + UBSan"
printf '%s\n' "${summary[@]}"
if ((failed)); then
  echo "fuzz.sh: FAILED; reproduce with $build/bin/<target>_fuzzer <input>" >&2
  exit 1
fi
echo "fuzz.sh: no crash, leak, timeout or out-of-memory"
